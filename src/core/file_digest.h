// Content digests of input files (SHA-256, OpenSSL's EVP), so a resumed run can tell that a mesh,
// heightfield or NDF table changed under the same job text. The hex digest is what `sha256sum`
// prints for the same file.
#pragma once
#include <string>

namespace mbsdf {

// Throws InputError naming the file when it cannot be read.
std::string sha256OfFile(const std::string& path);

}  // namespace mbsdf
