#include "core/error.h"

#include <cerrno>
#include <cstring>

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

namespace mbsdf {

std::string osErrorMessage(const std::string& what, const std::string& path, int err) {
  const char* name = "";
  switch (err) {
    case ENOSPC:
      name = " (ENOSPC)";
      break;
    case EDQUOT:
      name = " (EDQUOT)";
      break;
    case EIO:
      name = " (EIO)";
      break;
    case EFBIG:
      name = " (EFBIG)";
      break;
    case EROFS:
      name = " (EROFS)";
      break;
    case EACCES:
      name = " (EACCES)";
      break;
    default:
      break;
  }
  return what + ": " + path + ": " + std::strerror(err) + name;
}

}  // namespace mbsdf
