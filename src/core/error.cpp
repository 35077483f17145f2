#include "core/error.h"

namespace mbsdf {

std::string formatLocation(const std::string& file, int line, const std::string& key) {
  std::string s = file;
  if (line > 0) {
    s += ':';
    s += std::to_string(line);
  }
  if (!key.empty()) {
    if (!s.empty()) s += ": ";
    s += "key '";
    s += key;
    s += "'";
  }
  return s;
}

}  // namespace mbsdf
