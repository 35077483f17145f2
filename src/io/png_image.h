// 8-bit RGB PNG images (libpng), written and read back.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace mbsdf {

struct RgbImage {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // width * height * 3, row-major, row 0 at the top
};

// The PNG file's bytes, for embedding (a data: URI).
std::vector<uint8_t> encodePng(const RgbImage& image);
// WriteError when the bytes do not reach the disk.
void writePng(const std::string& path, const RgbImage& image);
RgbImage readPng(const std::string& path);

}  // namespace mbsdf
