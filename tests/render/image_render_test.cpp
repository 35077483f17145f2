// The preview's path tracer (render/image_render.h) against closed forms:
//  - furnace: a white Lambertian table on a sphere under a uniform environment of radiance 1 returns
//    the table's white in every pixel (a convex object sees only the environment), within the
//    standard error of the pixels' mean; every grazing angle of the sphere's rim is in the sweep;
//  - a flat mirror (a table whose light is all in the mirror bin) shows a small bright feature of
//    the environment at the pixel the law of reflection and the camera's projection give, as a spot
//    no wider than the feature and the table's bin;
//  - a statistical GGX conductor's table (its coherent component: depth-1 paths of the microflake
//    walk) renders like the closed-form GGX BRDF within the renders' noise;
//  - the same bytes for 1, 2 and 3 threads.
#include "render/image_render.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>

#include "optics/material.h"
#include "render/ggx_material.h"
#include "render/shapes.h"
#include "render/tabulated_material.h"
#include "render_tables.h"

using namespace mbsdf;

namespace {

Environment uniformEnvironment(float L) {
  return Environment(8, 4, std::vector<float>(8 * 4 * 3, L), "uniform");
}

// A white Lambertian reflector: f = 1/π.
std::string lambertianTable(bool isotropic = true, const std::function<bool(int)>& written = {}) {
  std::vector<double> thetas;
  for (double t = 5; t < 90; t += 10) thetas.push_back(t);
  return test::writeGreyTable(
      isotropic ? "lambert" : "lambert-partial", "n_theta = 9\nn_phi = 36", thetas,
      [](const Vec3&, int b, const DirectionGrid& g) { return g.isUpper(b) ? 1 / kPi : 0.0; }, isotropic, written);
}

double meanAbsDifference(const LinearImage& a, const LinearImage& b) {
  double d = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) d += std::abs(double(a.rgb[i]) - b.rgb[i]);
  return d / double(a.rgb.size());
}

// The same over the means of n × n pixel blocks.
double meanAbsBlockDifference(const LinearImage& a, const LinearImage& b, int n) {
  double d = 0;
  int blocks = 0;
  for (int by = 0; by + n <= a.height; by += n)
    for (int bx = 0; bx + n <= a.width; bx += n)
      for (int k = 0; k < 3; ++k) {
        double s = 0;
        for (int y = by; y < by + n; ++y)
          for (int x = bx; x < bx + n; ++x) {
            const size_t i = (size_t(y) * a.width + x) * 3 + size_t(k);
            s += double(a.rgb[i]) - b.rgb[i];
          }
        d += std::abs(s) / (n * n), ++blocks;
      }
  return d / blocks;
}

void expectWhiteFurnace(const TabulatedMaterial& m) {
  const Colour3 f = m.eval({0, 0, 1}, {0.3, 0, 0.9});  // the table's constant f = 1/π in colour
  const RenderScene scene(sphereMesh({0, 0, 0}, 1.0, 96, 192));
  const Camera camera({0, -5, 2}, {0, 0, 0}, {0, 0, 1}, 30, 64, 64);
  RenderSettings settings;
  settings.samplesPerPixel = 16;
  RenderCounts counts;
  const LinearImage img = renderImage(scene, camera, m, uniformEnvironment(1.f), settings, {}, &counts);
  EXPECT_EQ(counts.dropped, 0u);
  EXPECT_FALSE(m.reciprocityUsed());
  for (float v : img.rgb) ASSERT_TRUE(std::isfinite(v));
  for (int k = 0; k < 3; ++k) {
    // The pixels wholly on the sphere (their four corners' rays hit it), rim included.
    double sum = 0, sum2 = 0;
    int n = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        bool covered = true;
        for (int c = 0; c < 4; ++c)
          covered &= bool(scene.intersect(camera.eye(), camera.rayDirection(x + c % 2, y + c / 2)));
        if (!covered) continue;
        const double v = img.rgb[(size_t(y) * img.width + x) * 3 + size_t(k)];
        sum += v, sum2 += v * v, ++n;
      }
    ASSERT_GT(n, 1000);
    const double mean = sum / n, se = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n);
    EXPECT_NEAR(mean, kPi * f[size_t(k)], 4 * se + 1e-6) << "channel " << k;
    EXPECT_NEAR(kPi * f[size_t(k)], 1.0, 0.02) << "a grey table renders grey";
  }
}

}  // namespace

TEST(ImageRender, WhiteFurnaceSphere) {
  const BsdfFileReader file(lambertianTable());
  const TabulatedMaterial m(file, "GS");
  expectWhiteFurnace(m);
  EXPECT_FALSE(m.unfinishedReplaced());
}

// A partial file (a run still going): a list of incidences without a rule between them, every other
// slice missing; the nearest finished slice stands in, says so, and the furnace still holds.
TEST(ImageRender, PartialTableUsesTheNearestFinishedSlice) {
  const BsdfFileReader file(lambertianTable(false, [](int i) { return i % 2 == 0; }));
  const TabulatedMaterial m(file, "GS");
  expectWhiteFurnace(m);
  EXPECT_TRUE(m.unfinishedReplaced());
}

TEST(ImageRender, FlatMirrorReflectsAFeatureWhereReflectionPutsIt) {
  std::vector<double> thetas;
  for (double t = 1; t < 90; t += 2) thetas.push_back(t);
  const BsdfFileReader file(
      test::writeGreyTable("mirror-render", "n_theta = 45\nn_phi = 180", thetas, test::mirrorBin));
  const TabulatedMaterial m(file, "GS");
  // A black sky with one bright disk of 1.5° radius.
  const Vec3 feature = sphericalDirection(radians(48), radians(80));
  const int W = 1440, H = 720;
  std::vector<float> rgb(size_t(W) * H * 3, 0.f);
  const Environment grid(W, H, rgb, "probe");
  for (int r = 0; r < H; ++r)
    for (int c = 0; c < W; ++c)
      if (dot(grid.pixelCentre(c, r), feature) > std::cos(radians(1.5)))
        for (int k = 0; k < 3; ++k) rgb[(size_t(r) * W + c) * 3 + size_t(k)] = 100.f;
  const Environment env(W, H, rgb, "probe");
  const RenderScene scene(planeMesh(20));
  const Vec3 eye{0, -3, 2.5};
  const Camera camera(eye, {0, 0, 0}, {0, 0, 1}, 40, 128, 128);
  RenderSettings settings;
  settings.samplesPerPixel = 16;
  settings.showEnvironment = false;
  const LinearImage img = renderImage(scene, camera, m, env, settings);
  // The law of reflection: the eye's mirror image sees the feature through the plane z = 0.
  const Vec3 image{eye.x, eye.y, -eye.z};
  const Vec3 p = image + (-image.z / feature.z) * feature;
  const auto expected = camera.project(p - eye);
  ASSERT_TRUE(expected);
  double sum = 0, cx = 0, cy = 0, peak = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) peak = std::max(peak, double(img.rgb[(size_t(y) * img.width + x) * 3 + 1]));
  ASSERT_GT(peak, 1.0) << "no reflection";
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const double v = img.rgb[(size_t(y) * img.width + x) * 3 + 1];
      if (v < 0.05 * peak) continue;
      sum += v, cx += v * (x + 0.5), cy += v * (y + 0.5);
    }
  cx /= sum, cy /= sum;
  double spread = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const double v = img.rgb[(size_t(y) * img.width + x) * 3 + 1];
      if (v >= 0.05 * peak) spread += v * (std::pow(x + 0.5 - cx, 2) + std::pow(y + 0.5 - cy, 2));
    }
  // Camera angle per pixel: 40° over 128 pixels near the centre. The table's mirror is symmetric
  // about the true mirror direction (bin centres at the incidences' mirror directions, the two bins
  // beside φ = 180° shared): the centroid sits on the expected pixel to within a pixel. The spot's
  // RMS radius is at most the feature's (1.5°) and a bin's width (2°) added in quadrature, generously.
  const double degPerPixel = 40.0 / 128;
  EXPECT_NEAR(cx, expected->first, 1.0);
  EXPECT_NEAR(cy, expected->second, 1.0);
  EXPECT_LT(std::sqrt(spread / sum) * degPerPixel, std::hypot(1.5, 2.0));
}

TEST(ImageRender, StatisticalGgxMatchesTheClosedForm) {
  std::vector<double> thetas;
  for (double t = 1.5; t < 90; t += 3) thetas.push_back(t);
  const std::string path = test::computeTable(
      "ggx-al",
      "[geometry]\nkind = \"statistical\"\nndf = \"ggx\"\nalpha = 0.3\n[material]\nkind = \"conductor\"\n"
      "name = \"Al\"\n[spectrum]\nwavelengths_nm = [450.0, 550.0, 650.0]\n[directions]\nn_theta = 30\n"
      "n_phi = 120\nincidence = " +
          test::incidenceList(thetas) +
          "\nincidence_sampling = \"exact\"\nsymmetry = \"isotropic\"\n[sampling]\npaths_per_slice = 200000\n");
  const BsdfFileReader file(path);
  const TabulatedMaterial table(file, "GS");
  Material al;
  ASSERT_TRUE(builtinMaterial("Al", &al));
  const GgxConductorMaterial ggx(0.3, al.iorAt({0.45, 0.55, 0.65}),
                                 SpectrumToColour({450.0, 550.0, 650.0}).linearSrgbPerSample());
  const RenderScene scene(sphereMesh({0, 0, 0}, 1.0, 96, 192));
  const Camera camera({0, -5, 2}, {0, 0, 0}, {0, 0, 1}, 30, 96, 96);
  const Environment env = Environment::builtIn("studio", 512);
  RenderSettings settings;
  settings.samplesPerPixel = 64;
  settings.showEnvironment = false;
  // Each render with its own seed: with one seed the two would share their random numbers and their
  // noise would cancel.
  const LinearImage fromTable = renderImage(scene, camera, table, env, settings);
  settings.seed = 2;
  const LinearImage closed = renderImage(scene, camera, ggx, env, settings);
  settings.seed = 3;
  const LinearImage closedAgain = renderImage(scene, camera, ggx, env, settings);
  const GgxConductorMaterial rougher(0.36, al.iorAt({0.45, 0.55, 0.65}),
                                     SpectrumToColour({450.0, 550.0, 650.0}).linearSrgbPerSample());
  settings.seed = 4;
  const LinearImage fromRougher = renderImage(scene, camera, rougher, env, settings);
  // Per pixel the noise dominates at 64 samples; over 8 × 8 blocks it drops eightfold while a wrong
  // BRDF's difference stays. Two renders of the same BRDF differ by noise alone: the table's render
  // may differ from the closed form's by half as much again (its noise is another estimator's), and a
  // surface 20 % rougher must not pass.
  const double noise = meanAbsDifference(closed, closedAgain), d = meanAbsDifference(fromTable, closed);
  const double blockNoise = meanAbsBlockDifference(closed, closedAgain, 8);
  const double blockD = meanAbsBlockDifference(fromTable, closed, 8);
  const double blockRougher = meanAbsBlockDifference(fromRougher, closed, 8);
  RecordProperty("mean_abs_pixel_difference", std::to_string(d));
  std::printf(
      "GGX Al alpha 0.3, 96 x 96, 64 spp: mean |table - closed form| per pixel %.5f (two closed-form renders: "
      "%.5f); over 8 x 8 blocks %.5f (%.5f); closed form alpha 0.36 over blocks %.5f\n",
      d, noise, blockD, blockNoise, blockRougher);
  EXPECT_LT(d, 1.5 * noise);
  EXPECT_LT(blockD, 1.5 * blockNoise);
  EXPECT_GT(blockRougher, 1.5 * blockNoise);
}

TEST(ImageRender, SameBytesForAnyThreadCount) {
  const BsdfFileReader file(lambertianTable());
  const TabulatedMaterial m(file, "GS");
  const RenderScene scene(shaderBallMesh());
  const Camera camera({0, -5, 2}, {0, 0, 0}, {0, 0, 1}, 30, 40, 40);
  const Environment env = Environment::builtIn("sky", 256);
  RenderSettings settings;
  settings.samplesPerPixel = 4;
  std::vector<LinearImage> images;
  for (int threads : {1, 2, 3}) {
    const tbb::global_control c(tbb::global_control::max_allowed_parallelism, size_t(threads));
    images.push_back(renderImage(scene, camera, m, env, settings));
  }
  EXPECT_EQ(images[0].rgb, images[1].rgb);
  EXPECT_EQ(images[0].rgb, images[2].rgb);
}
