#include "geometry/topography_header.h"

#include <cmath>

#include "core/error.h"

namespace mbsdf {

std::string trimmed(std::string_view s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string_view::npos) return "";
  return std::string(s.substr(b, s.find_last_not_of(" \t\r\n") - b + 1));
}

bool KeyValueHeader::add(const std::string& line, int lineNo) {
  const auto eq = line.find('=');
  if (eq == std::string::npos) return false;
  values_[trimmed(std::string_view(line).substr(0, eq))] = {trimmed(std::string_view(line).substr(eq + 1)), lineNo};
  return true;
}

const std::pair<std::string, int>* KeyValueHeader::find(const std::string& name, bool required) const {
  const auto it = values_.find(name);
  if (it != values_.end()) return &it->second;
  if (required) throw InputError(path_ + ": the " + format_ + " header has no " + name);
  return nullptr;
}

void KeyValueHeader::notANumber(const std::string& name) const {
  const auto& [value, line] = *find(name, true);
  throw InputError(path_ + ": line " + std::to_string(line) + ": " + name + " = '" + value + "' is not a number");
}

std::string KeyValueHeader::text(const std::string& name, std::optional<std::string> def) const {
  const auto* v = find(name, !def);
  return v ? v->first : *def;
}

double KeyValueHeader::number(const std::string& name, std::optional<double> def) const {
  const auto* v = find(name, !def);
  if (!v) return *def;
  const std::optional<double> x = parseWhole<double>(v->first);
  if (!x || !std::isfinite(*x)) notANumber(name);
  return *x;
}

int64_t KeyValueHeader::integer(const std::string& name, std::optional<int64_t> def) const {
  const auto* v = find(name, !def);
  if (!v) return *def;
  const std::optional<int64_t> x = parseWhole<int64_t>(v->first);
  if (!x) notANumber(name);
  return *x;
}

}  // namespace mbsdf
