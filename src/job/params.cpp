#include "job/params.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/error.h"

namespace mbsdf {

ParamDict ParamDict::parseString(const std::string& text, const std::string& sourceName) {
  auto s = std::make_shared<State>();
  s->file = sourceName;
  s->text = text;
  try {
    s->root = toml::parse(s->text, sourceName);
  } catch (const toml::parse_error& e) {
    const auto& b = e.source().begin;
    throw InputError(sourceName + ":" + std::to_string(b.line) + ":" + std::to_string(b.column) +
                     ": malformed TOML: " + std::string(e.description()));
  }
  const toml::table* root = &s->root;
  return ParamDict(s, root, "");
}

ParamDict ParamDict::parseFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open job file");
  // A job's text is keys and short lists: 22 500 listed incidences take under 1 MB. Read no more
  // than the limit, so that a device or a wrong file (/dev/zero, an HDF5 table) is refused at once
  // instead of being read until memory runs out.
  constexpr size_t kMaxJobBytes = size_t(16) << 20;
  std::string text(kMaxJobBytes + 1, '\0');
  f.read(text.data(), std::streamsize(text.size()));
  if (f.bad()) throw InputError(path + ": cannot read job file");
  text.resize(size_t(f.gcount()));
  if (text.size() > kMaxJobBytes)
    throw InputError(path + ": larger than 16 MiB, which no job file is (is it a job file?)");
  return parseString(text, path);
}

std::string ParamDict::path(const std::string& key) const {
  return prefix_.empty() ? key : prefix_ + "." + key;
}

std::string ParamDict::where(const std::string& key) const {
  int line = 0;
  if (table_) {
    if (const toml::node* n = table_->get(key))
      line = int(n->source().begin.line);
    else
      line = int(table_->source().begin.line);
  }
  return formatLocation(state_->file, line, path(key));
}

void ParamDict::fail(const std::string& key, const std::string& message) const {
  throw InputError(where(key) + ": " + message);
}

void ParamDict::expect(const std::string& key, std::initializer_list<KeyType> types) const {
  // The parser may read only registered keys, as their registered type: the registry is what
  // `microbsdf keys` and the job reference show, so a key read here but missing there is a bug.
  const JobKey* k = findJobKey(path(key));
  if (!k) throw std::logic_error("the parser reads '" + path(key) + "', which src/job/job_keys.cpp does not register");
  if (std::find(types.begin(), types.end(), k->type) == types.end())
    throw std::logic_error("the parser reads '" + path(key) + "' as another type than its registered " +
                           std::string(keyTypeName(k->type)));
}

const toml::node* ParamDict::lookup(const std::string& key) const {
  if (!table_) return nullptr;
  const toml::node* n = table_->get(key);
  if (n) state_->used.insert(path(key));
  return n;
}

bool ParamDict::empty() const {
  return !table_ || table_->empty();
}

bool ParamDict::has(const std::string& key) const {
  return table_ && table_->contains(key);
}

const toml::node* ParamDict::node(const std::string& key) const {
  expect(key, {KeyType::Table, KeyType::String, KeyType::Strings, KeyType::Number, KeyType::Numbers, KeyType::Integer,
               KeyType::Boolean, KeyType::StringOrNumbers, KeyType::NumbersOrTable});
  return lookup(key);
}

ParamDict ParamDict::table(const std::string& key) const {
  expect(key, {KeyType::Table, KeyType::NumbersOrTable});
  const toml::node* n = lookup(key);
  if (!n) return ParamDict(state_, nullptr, path(key));
  if (!n->is_table()) fail(key, "expected a table [" + path(key) + "]");
  return ParamDict(state_, n->as_table(), path(key));
}

double ParamDict::getDouble(const std::string& key, double def) const {
  expect(key, {KeyType::Number, KeyType::Numbers});
  const toml::node* n = lookup(key);
  if (!n) return def;
  if (auto v = n->value<double>()) {
    if (!std::isfinite(*v)) fail(key, "must be a finite number");
    return *v;
  }
  fail(key, "expected a number");
}

int64_t ParamDict::getInt(const std::string& key, int64_t def) const {
  expect(key, {KeyType::Integer});
  const toml::node* n = lookup(key);
  if (!n) return def;
  if (n->is_integer()) return *n->value<int64_t>();
  fail(key, "expected an integer");
}

bool ParamDict::getBool(const std::string& key, bool def) const {
  expect(key, {KeyType::Boolean});
  const toml::node* n = lookup(key);
  if (!n) return def;
  if (n->is_boolean()) return *n->value<bool>();
  fail(key, "expected true or false");
}

std::string ParamDict::getString(const std::string& key, const std::string& def) const {
  expect(key, {KeyType::String, KeyType::StringOrNumbers});
  const toml::node* n = lookup(key);
  if (!n) return def;
  if (n->is_string()) return *n->value<std::string>();
  fail(key, "expected a string");
}

std::vector<double> ParamDict::getDoubles(const std::string& key, const std::vector<double>& def) const {
  expect(key, {KeyType::Number, KeyType::Numbers, KeyType::NumbersOrTable});
  const toml::node* n = lookup(key);
  if (!n) return def;
  if (auto v = n->value<double>(); v && !n->is_array()) {
    if (!std::isfinite(*v)) fail(key, "must be a finite number");
    return {*v};
  }
  const toml::array* a = n->as_array();
  if (!a) fail(key, "expected a number or an array of numbers");
  std::vector<double> out;
  for (const auto& e : *a) {
    auto v = e.value<double>();
    if (!v || !std::isfinite(*v)) fail(key, "expected an array of finite numbers");
    out.push_back(*v);
  }
  return out;
}

std::vector<std::string> ParamDict::getStrings(const std::string& key, const std::vector<std::string>& def) const {
  expect(key, {KeyType::String, KeyType::Strings});
  const toml::node* n = lookup(key);
  if (!n) return def;
  if (n->is_string()) return {*n->value<std::string>()};
  const toml::array* a = n->as_array();
  if (!a) fail(key, "expected a string or an array of strings");
  std::vector<std::string> out;
  for (const auto& e : *a) {
    auto v = e.value<std::string>();
    if (!v) fail(key, "expected an array of strings");
    out.push_back(*v);
  }
  return out;
}

double ParamDict::positive(const std::string& key, double def) const {
  double v = getDouble(key, def);
  if (!(v > 0)) fail(key, fmt::format("must be > 0 (got {:g})", v));
  return v;
}
double ParamDict::nonNegative(const std::string& key, double def) const {
  double v = getDouble(key, def);
  if (!(v >= 0)) fail(key, fmt::format("must be >= 0 (got {:g})", v));
  return v;
}
int64_t ParamDict::positiveInt(const std::string& key, int64_t def) const {
  int64_t v = getInt(key, def);
  if (v <= 0) fail(key, "must be a positive integer (got " + std::to_string(v) + ")");
  return v;
}

void ParamDict::reportUnused() const {
  std::vector<std::string> unused;
  auto walk = [&](auto&& self, const toml::table& t, const std::string& prefix) -> void {
    for (const auto& [k, v] : t) {
      std::string p = prefix.empty() ? std::string(k.str()) : prefix + "." + std::string(k.str());
      if (!state_->used.count(p)) {
        const std::string nearest = nearestJobKey(p);
        unused.push_back(formatLocation(state_->file, int(v.source().begin.line), p) + ": unknown key" +
                         (nearest.empty() ? "" : " (did you mean '" + nearest + "'?)") +
                         "; `microbsdf keys` lists every key");
      } else if (v.is_table()) {
        self(self, *v.as_table(), p);
      }
    }
  };
  walk(walk, state_->root, "");
  if (unused.empty()) return;
  std::string msg;
  for (size_t i = 0; i < unused.size(); ++i) msg += (i ? "\n" : "") + unused[i];
  throw InputError(msg);
}

}  // namespace mbsdf
