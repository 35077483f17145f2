#include "export/tensor_file.h"

#include <stdexcept>

#include "export/little_endian.h"

namespace mbsdf {
namespace {

uint64_t elementCount(const TensorField& f) {
  uint64_t n = 1;
  for (uint64_t s : f.shape) n *= s;
  return n;
}

}  // namespace

std::string tensorFileBytes(const std::vector<TensorField>& fields) {
  std::string header("tensor_file", 12);  // the name and its terminating zero
  header.push_back(1);                    // version 1.0
  header.push_back(0);
  putLittleEndian(header, uint32_t(fields.size()));
  size_t headerSize = header.size();
  for (const TensorField& f : fields) headerSize += 2 + f.name.size() + 2 + 1 + 8 + 8 * f.shape.size();
  auto align8 = [](size_t n) { return (n + 7) / 8 * 8; };
  std::string data;
  size_t offset = align8(headerSize);
  for (const TensorField& f : fields) {
    const uint64_t n = elementCount(f);
    const bool isFloat = f.type == TensorField::Type::Float32;
    if (n != (isFloat ? f.floats.size() : f.bytes.size()))
      throw std::invalid_argument("tensor field " + f.name + ": data do not match its shape");
    putLittleEndian(header, uint16_t(f.name.size()));
    header += f.name;
    putLittleEndian(header, uint16_t(f.shape.size()));
    header.push_back(char(f.type));
    putLittleEndian(header, uint64_t(offset + data.size()));
    for (uint64_t s : f.shape) putLittleEndian(header, s);
    if (isFloat) {
      for (float v : f.floats) putFloat32(data, v);
    } else {
      data.append(reinterpret_cast<const char*>(f.bytes.data()), f.bytes.size());
    }
    data.resize(align8(data.size()), '\0');
  }
  header.resize(offset, '\0');
  return header + data;
}

}  // namespace mbsdf
