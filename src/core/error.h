// Errors caused by user input (job files, meshes, heightfields). They carry where the problem is
// (file, line, key) so the message can name it; the program exits non-zero without touching the
// output file (DESIGN.md, non-negotiable 7).
#pragma once
#include <stdexcept>
#include <string>

namespace mbsdf {

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "file:line: key: message" with the parts that are known.
std::string formatLocation(const std::string& file, int line, const std::string& key);

}  // namespace mbsdf
