// The tensor file of Mitsuba (the container of the RGL material database's `.bsdf` files): the
// 12 bytes "tensor_file\0", version 1.0, a field count, then per field its name, shape, element type
// and the offset of its data; all little-endian, each field's data aligned to 8 bytes.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace mbsdf {

struct TensorField {
  enum class Type : uint8_t { UInt8 = 1, Float32 = 10 };  // the format's codes for these types
  std::string name;
  Type type = Type::Float32;
  std::vector<uint64_t> shape;
  std::vector<float> floats;   // Float32 data, row-major (last index fastest)
  std::vector<uint8_t> bytes;  // UInt8 data
};

// The file's bytes. Throws std::invalid_argument when a field's data do not match its shape.
std::string tensorFileBytes(const std::vector<TensorField>& fields);

}  // namespace mbsdf
