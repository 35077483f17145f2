// Content digests of input files (SHA-256, OpenSSL's EVP), so a resumed run can tell that a mesh,
// heightfield or NDF table changed under the same job text. The hex digest is what `sha256sum`
// prints for the same file.
#pragma once
#include <string>

namespace mbsdf {

// A file the job reads (mesh, heightfield, NDF table) and its content digest: a resumed run checks
// that each is unchanged.
struct InputFile {
  std::string key;  // the job key that names it, e.g. "geometry.file"
  std::string path;
  std::string sha256;
};

// Throws InputError naming the file when it cannot be read.
std::string sha256OfFile(const std::string& path);

}  // namespace mbsdf
