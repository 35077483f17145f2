#include "io/exr_image.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>

#include <stdexcept>

#include "io/output_target.h"

namespace mbsdf {

void writeExr(const std::string& path, int width, int height, const std::vector<ExrChannel>& channels) {
  Imf::Header header(width, height);
  for (const auto& c : channels) {
    if (c.pixels.size() != size_t(width) * height) throw std::invalid_argument("EXR channel size mismatch: " + c.name);
    header.channels().insert(c.name, Imf::Channel(Imf::FLOAT));
  }
  // A failed write leaves an existing image as it was.
  writeViaPartial(path, [&](const std::string& partial) {
    Imf::OutputFile file(partial.c_str(), header);
    Imf::FrameBuffer fb;
    for (const auto& c : channels)
      fb.insert(c.name, Imf::Slice(Imf::FLOAT, (char*)c.pixels.data(), sizeof(float), sizeof(float) * width));
    file.setFrameBuffer(fb);
    file.writePixels(height);
  });
}

std::vector<ExrChannel> readExr(const std::string& path, int* width, int* height) {
  Imf::InputFile file(path.c_str());
  Imath::Box2i dw = file.header().dataWindow();
  int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
  std::vector<ExrChannel> out;
  for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it)
    out.push_back({it.name(), std::vector<float>(size_t(w) * h)});
  Imf::FrameBuffer fb;
  for (auto& c : out) fb.insert(c.name, Imf::Slice::Make(Imf::FLOAT, c.pixels.data(), dw));
  file.setFrameBuffer(fb);
  file.readPixels(dw.min.y, dw.max.y);
  *width = w;
  *height = h;
  return out;
}

}  // namespace mbsdf
