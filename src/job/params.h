// One typed dictionary for every parameter of a job file (pbrt-v4's ParameterDictionary with
// ReportUnused; Mitsuba's unreferenced-property check). Every lookup records the key; after the job
// is built, reportUnused() turns any key nobody asked for into an error naming file, line and key
// (with the registry's nearest name). Type errors and range errors name the same. Every lookup is
// of a key the registry (job_keys.h) holds, as its registered type.
#pragma once
#include <toml++/toml.h>

#include <initializer_list>

#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "job/job_keys.h"

namespace mbsdf {

class ParamDict {
 public:
  // Parses a TOML file; a syntax error becomes an InputError naming file, line and column.
  static ParamDict parseFile(const std::string& path);
  static ParamDict parseString(const std::string& text, const std::string& sourceName);

  // Sub-table (empty dictionary if absent); a non-table value is an error.
  ParamDict table(const std::string& key) const;
  bool has(const std::string& key) const;
  // No key at all (an absent table, or a file of nothing but comments and blank lines).
  bool empty() const;

  double getDouble(const std::string& key, double def) const;
  int64_t getInt(const std::string& key, int64_t def) const;
  bool getBool(const std::string& key, bool def) const;
  std::string getString(const std::string& key, const std::string& def) const;
  std::vector<double> getDoubles(const std::string& key, const std::vector<double>& def) const;
  std::vector<std::string> getStrings(const std::string& key, const std::vector<std::string>& def) const;
  // Raw node access for structured values (marks the key used); nullptr if absent.
  const toml::node* node(const std::string& key) const;

  // Range checks that throw InputError naming the key.
  double positive(const std::string& key, double def) const;
  double nonNegative(const std::string& key, double def) const;
  int64_t positiveInt(const std::string& key, int64_t def) const;

  [[noreturn]] void fail(const std::string& key, const std::string& message) const;
  std::string where(const std::string& key) const;  // "file:line: key 'a.b'"
  std::string path(const std::string& key) const;   // "a.b"
  const std::string& file() const { return state_->file; }
  const std::string& sourceText() const { return state_->text; }

  // Throws InputError listing every key (with its line) that no lookup asked for.
  void reportUnused() const;

 private:
  struct State {
    std::string file, text;
    toml::table root;
    std::set<std::string> used;
  };
  ParamDict(std::shared_ptr<State> s, const toml::table* t, std::string prefix)
      : state_(std::move(s)), table_(t), prefix_(std::move(prefix)) {}
  const toml::node* lookup(const std::string& key) const;
  void expect(const std::string& key, std::initializer_list<KeyType> types) const;
  std::shared_ptr<State> state_;
  const toml::table* table_ = nullptr;
  std::string prefix_;
};

}  // namespace mbsdf
