// Float EXR images (OpenEXR): one FLOAT channel per named layer, written and read back.
#pragma once
#include <string>
#include <utility>
#include <vector>

namespace mbsdf {

struct ExrChannel {
  std::string name;
  std::vector<float> pixels;  // width * height, row-major, row 0 at the top
};

void writeExr(const std::string& path, int width, int height, const std::vector<ExrChannel>& channels);
// Reads every channel as float.
std::vector<ExrChannel> readExr(const std::string& path, int* width, int* height);

}  // namespace mbsdf
