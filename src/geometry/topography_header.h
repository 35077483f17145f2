// What the topography readers share: text trimmed of white space, numbers parsed whole, and the
// `name = value` headers of SDF (text) and GSF, each value kept with its line for messages.
#pragma once
#include <charconv>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace mbsdf {

// Without leading and trailing spaces, tabs, CRs and LFs.
std::string trimmed(std::string_view s);

// The number `s` spells, all of it (std::from_chars: no locale, no leading '+'); none otherwise.
template <class T>
std::optional<T> parseWhole(std::string_view s) {
  T v{};
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  return v;
}

class KeyValueHeader {
 public:
  // `format` names the header in messages ("SDF", "GSF"); `path` the file.
  KeyValueHeader(std::string path, std::string format) : path_(std::move(path)), format_(std::move(format)) {}
  // Records `name = value` of line `lineNo`; false when the line has no '='.
  bool add(const std::string& line, int lineNo);
  bool has(const std::string& name) const { return values_.count(name) != 0; }
  // The value, or `def` when given and the name is absent; InputError ("the <format> header has no
  // <name>") otherwise.
  std::string text(const std::string& name, std::optional<std::string> def = std::nullopt) const;
  // The value as a finite double or an integer; InputError naming the line otherwise.
  double number(const std::string& name, std::optional<double> def = std::nullopt) const;
  int64_t integer(const std::string& name, std::optional<int64_t> def = std::nullopt) const;

 private:
  const std::pair<std::string, int>* find(const std::string& name, bool required) const;
  [[noreturn]] void notANumber(const std::string& name) const;
  std::string path_, format_;
  std::map<std::string, std::pair<std::string, int>> values_;  // name -> (value, line)
};

}  // namespace mbsdf
