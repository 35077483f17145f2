// Slice images: EXR and PNG read back with the right size and channels, and the disk projection
// puts a flat mirror's specular direction at the expected pixel.
#include "io/slice_export.h"

#include <gtest/gtest.h>

#include "cluster/output_schema_of.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "geometry/generators.h"
#include "core/error.h"
#include "io/colour_bar.h"
#include "io/exr_image.h"
#include "io/png_image.h"
#include "scattering/path_tracer.h"

using namespace mbsdf;

namespace {
std::string writeMirrorFile() {
  Job job = loadJobFromString(
      "[geometry]\nkind = \"flat\"\nsize_um = [4.0, 4.0]\n[material]\nname = \"mirror\"\n"
      "[directions]\ngrid = \"disk\"\nwidth = 33\nheight = 33\nincidence = [[30.0, 0.0]]\nincidence_sampling = "
      "\"exact\"\n"
      "[spectrum]\nwavelengths_nm = [450.0, 550.0, 650.0]\n[effects]\ncomponents = [\"coherent\", \"multiple\"]\n",
      "t.toml", "");
  DirectionGrid grid(job.gridLayout);
  PeriodicScene scene(job.geometry);
  PathTracerSettings s;
  s.paths = 2000;
  PathTracer tracer(scene, job.material, job.lambda_um(), grid, s);
  std::string path = (std::filesystem::temp_directory_path() / "microbsdf_slice_test.h5").string();
  BsdfFileWriter w(path, outputSchemaOf(job), grid);
  w.writeTile(tracer.run(0, 0, job.incidence[0].bin, sphericalDirection(radians(30.0), 0.0)));
  w.finish();
  return path;
}
}  // namespace

TEST(SliceExport, ImagesHaveSizeChannelsAndTheSpecularPixel) {
  BsdfFileReader f(writeMirrorFile());
  auto dir = std::filesystem::temp_directory_path();
  SliceRequest req;
  req.theta_deg = 30;
  req.size = 128;
  req.both = true;
  exportSlice(f, req, (dir / "slice.exr").string());
  int w = 0, h = 0;
  auto ch = readExr((dir / "slice.exr").string(), &w, &h);
  EXPECT_EQ(w, 256);
  EXPECT_EQ(h, 128);
  std::set<std::string> names;
  for (auto& c : ch) names.insert(c.name);
  for (const char* n : {"450.0nm", "550.0nm", "650.0nm", "mean", "R", "G", "B", "Y"}) EXPECT_TRUE(names.count(n)) << n;
  // Specular direction of (30°, 0°): ωo = (−sin 30°, 0, cos 30°) -> x = −0.5, y = 0: pixel (32, 64).
  const auto& mean = std::find_if(ch.begin(), ch.end(), [](auto& c) { return c.name == "mean"; })->pixels;
  size_t argmax = size_t(std::max_element(mean.begin(), mean.end()) - mean.begin());
  int ix = int(argmax % 256), iy = int(argmax / 256);
  EXPECT_NEAR(ix, 32, 3);
  EXPECT_NEAR(iy, 64, 3);
  EXPECT_GT(mean[size_t(64) * 256 + 32], 0.0f);
  // The transmission half of a mirror is black.
  for (int y = 0; y < 128; ++y)
    for (int x = 128; x < 256; ++x) ASSERT_EQ(mean[size_t(y) * 256 + x], 0.0f);
  // A white mirror is neutral in true colour: R = G = B at the specular pixel.
  const auto& R = std::find_if(ch.begin(), ch.end(), [](auto& c) { return c.name == "R"; })->pixels;
  const auto& B = std::find_if(ch.begin(), ch.end(), [](auto& c) { return c.name == "B"; })->pixels;
  EXPECT_NEAR(R[argmax] / B[argmax], 1.0, 0.05);

  for (const char* style : {"true", "false"}) {
    req.style = style;
    req.both = false;
    std::string png = (dir / (std::string("slice-") + style + ".png")).string();
    exportSlice(f, req, png);
    RgbImage img = readPng(png);
    EXPECT_EQ(img.width, 128);
    EXPECT_EQ(img.height, std::string(style) == "false" ? 128 + colourBarHeight(128) : 128);  // scale below the disk
    // The specular pixel is the brightest (sum of channels) in the disk part.
    int best = 0, bx = 0, by = 0;
    for (int y = 0; y < 128; ++y)
      for (int x = 0; x < 128; ++x) {
        const uint8_t* p = &img.rgb[(size_t(y) * 128 + x) * 3];
        if (p[0] + p[1] + p[2] > best) {
          best = p[0] + p[1] + p[2];
          bx = x;
          by = y;
        }
      }
    EXPECT_NEAR(bx, 32, 3) << style;
    EXPECT_NEAR(by, 64, 3) << style;
  }
}

// The false-colour scale: a tick under each decade of f (f = 1 at log2 f = 0, the middle of
// [−10, 10]; f = 10 at 3.32/20 of the width further right), none between, numbers under the ticks.
TEST(SliceExport, ColourBarTicksSitAtDecadesWithTheirValues) {
  for (int size : {128, 256, 512}) {
    RgbImage img;
    img.width = 2 * size;
    img.height = colourBarHeight(size);
    img.rgb.assign(size_t(img.width) * img.height * 3, 7);
    drawColourBar(img, 0, size, -10, 10);
    const int s = std::max(1, size / 128), tickRow = std::max(8, size / 16) + 1;
    auto grey = [&](int x, int y) { return img.rgb[(size_t(y) * img.width + x) * 3]; };
    auto xOf = [&](double log2f) { return int(std::lround((log2f + 10) / 20 * img.width)); };
    EXPECT_EQ(grey(xOf(0), tickRow), 235) << size;
    EXPECT_EQ(grey(xOf(std::log2(10.0)), tickRow), 235) << size;
    EXPECT_EQ(grey(xOf(std::log2(0.1)), tickRow), 235) << size;
    EXPECT_EQ(grey(xOf(1.6), tickRow), 0) << size;  // between 1 and 10: no tick
    int ink = 0;                                    // the numbers and the unit below the ticks
    for (int y = tickRow + 3 * s; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) ink += grey(x, y) > 100;
    EXPECT_GT(ink, 50 * s * s) << size;
    // The ramp is unchanged: falseColour from left to right.
    EXPECT_EQ(img.rgb[0], uint8_t(std::lround(std::clamp(falseColour(0.5 / img.width)[0], 0.0, 1.0) * 255)));
  }
}

TEST(SliceExport, FalseColourNeedsARange) {
  // A slice of any file: the range is checked before the file's values are read.
  SliceRequest req;
  req.style = "false";
  req.log2Min = req.log2Max = 3;
  EXPECT_THROW(checkFalseColourRange(req), InputError);
  req.log2Max = 4;
  EXPECT_NO_THROW(checkFalseColourRange(req));
}

TEST(SliceExport, FalseColourScaleIsMonotoneAndSrgbEncodes) {
  double prev = -1;
  for (int i = 0; i <= 100; ++i) {
    Colour3 c = falseColour(i / 100.0);
    double lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    EXPECT_GT(lum, prev - 1e-12);
    prev = lum;
  }
  EXPECT_NEAR(srgbEncode(0.0), 0.0, 1e-12);
  EXPECT_NEAR(srgbEncode(1.0), 1.0, 1e-12);
  EXPECT_NEAR(srgbEncode(0.18), 0.4613561, 1e-6);  // IEC 61966-2-1
}
