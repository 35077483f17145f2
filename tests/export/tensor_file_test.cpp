// The tensor file's layout against its description (Mitsuba's TensorFile): the 12-byte name with its
// zero, version 1.0, the field count, per field name length, name, rank, type code, data offset and
// shape (little-endian), and each field's data at an 8-byte-aligned offset.
#include "export/tensor_file.h"

#include <gtest/gtest.h>

#include <cstring>
#include <stdexcept>

namespace mbsdf {
namespace {

template <typename T>
T readAt(const std::string& bytes, size_t at) {
  T v = 0;
  for (size_t i = 0; i < sizeof(T); ++i) v |= T(uint64_t(uint8_t(bytes[at + i])) << (8 * i));
  return v;
}

TEST(TensorFile, LayoutFollowsTheFormat) {
  TensorField text{"description", TensorField::Type::UInt8, {3}, {}, {'a', 'b', 'c'}};
  TensorField grid{"ndf", TensorField::Type::Float32, {2, 3}, {1, 2, 3, 4, 5, 6.5f}, {}};
  const std::string f = tensorFileBytes({text, grid});
  ASSERT_EQ(std::memcmp(f.data(), "tensor_file\0", 12), 0);
  EXPECT_EQ(f[12], 1);
  EXPECT_EQ(f[13], 0);
  EXPECT_EQ(readAt<uint32_t>(f, 14), 2u);
  size_t at = 18;
  auto field = [&](const std::string& name, uint8_t type, std::vector<uint64_t> shape) {
    EXPECT_EQ(readAt<uint16_t>(f, at), name.size());
    EXPECT_EQ(f.substr(at + 2, name.size()), name);
    at += 2 + name.size();
    EXPECT_EQ(readAt<uint16_t>(f, at), shape.size());
    EXPECT_EQ(uint8_t(f[at + 2]), type);
    const uint64_t offset = readAt<uint64_t>(f, at + 3);
    EXPECT_EQ(offset % 8, 0u) << name;
    at += 11;
    for (uint64_t s : shape) {
      EXPECT_EQ(readAt<uint64_t>(f, at), s);
      at += 8;
    }
    return offset;
  };
  const uint64_t textAt = field("description", 1, {3});
  const uint64_t gridAt = field("ndf", 10, {2, 3});
  EXPECT_EQ(f.substr(textAt, 3), "abc");
  float last;
  const uint32_t bits = readAt<uint32_t>(f, gridAt + 5 * 4);
  std::memcpy(&last, &bits, 4);
  EXPECT_EQ(last, 6.5f);
  EXPECT_EQ(f.size(), gridAt + 6 * 4 + 0 /* 24 bytes: already aligned */);
}

TEST(TensorFile, RefusesDataThatDoNotMatchTheShape) {
  TensorField bad{"sigma", TensorField::Type::Float32, {2, 2}, {1, 2, 3}, {}};
  EXPECT_THROW(tensorFileBytes({bad}), std::invalid_argument);
}

}  // namespace
}  // namespace mbsdf
