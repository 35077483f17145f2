// Appending little-endian binary values to a byte string, as the binary formats written here (the
// RGL tensor file, MDL's measured BSDF) store them whatever the host's byte order.
#pragma once
#include <cstdint>
#include <cstring>
#include <string>

namespace mbsdf {

template <typename T>
void putLittleEndian(std::string& out, T value) {
  for (std::size_t i = 0; i < sizeof(T); ++i) out.push_back(char((uint64_t(value) >> (8 * i)) & 0xff));
}

inline void putFloat32(std::string& out, float v) {
  uint32_t bits;
  std::memcpy(&bits, &v, 4);
  putLittleEndian(out, bits);
}

}  // namespace mbsdf
