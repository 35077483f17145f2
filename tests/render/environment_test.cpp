// The environment light (render/environment.h): its sampling density is a density (integrates to 1
// over the sphere) and is the one sample() reports; the estimator L / pdf of sample() integrates the
// map's radiance to its exact value Σ L Ω over the pixels, within its own standard error; maps are
// read back from EXR, and bad maps are refused naming the file.
#include "render/environment.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "core/error.h"
#include "core/rng.h"
#include "io/exr_image.h"

using namespace mbsdf;

namespace {

// Exact ∫ L dω of a piecewise-constant map: Σ over pixels of L × the pixel's solid angle.
Colour3 exactIntegral(const Environment& env) {
  Colour3 sum{0, 0, 0};
  for (int r = 0; r < env.height(); ++r) {
    const double omega =
        (std::cos(kPi * r / env.height()) - std::cos(kPi * (r + 1) / env.height())) * 2 * kPi / env.width();
    for (int c = 0; c < env.width(); ++c) {
      const Colour3 L = env.radiance(env.pixelCentre(c, r));
      for (int k = 0; k < 3; ++k) sum[size_t(k)] += L[size_t(k)] * omega;
    }
  }
  return sum;
}

}  // namespace

TEST(Environment, DensityIntegratesToOneAndMatchesTheSamples) {
  for (const char* name : {"studio", "sky"}) {
    const Environment env = Environment::builtIn(name, 256);
    double total = 0;
    for (int r = 0; r < env.height(); ++r) {
      const double omega =
          (std::cos(kPi * r / env.height()) - std::cos(kPi * (r + 1) / env.height())) * 2 * kPi / env.width();
      for (int c = 0; c < env.width(); ++c) total += env.pdf(env.pixelCentre(c, r)) * omega;
    }
    EXPECT_NEAR(total, 1.0, 1e-9) << name;
    for (uint64_t i = 0; i < 2000; ++i) {
      Sampler s(3, 0, i);
      const double u1 = s.get1D(), u2 = s.get1D();
      const Environment::Sample e = env.sample(u1, u2);
      ASSERT_NEAR(length(e.w), 1.0, 1e-12);
      ASSERT_GT(e.pdf, 0) << name;
      EXPECT_NEAR(e.pdf, env.pdf(e.w), 1e-9 * e.pdf) << name << " sample " << i;
      const Colour3 L = env.radiance(e.w);
      for (int k = 0; k < 3; ++k) EXPECT_EQ(e.L[size_t(k)], L[size_t(k)]);
    }
  }
}

TEST(Environment, ImportanceSamplingIntegratesTheMap) {
  const Environment env = Environment::builtIn("sky", 256);  // a sun 10⁴ times the sky
  const Colour3 exact = exactIntegral(env);
  const int n = 20000;
  for (int k = 0; k < 3; ++k) {
    double sum = 0, sum2 = 0;
    for (int i = 0; i < n; ++i) {
      Sampler s(11, 0, uint64_t(i));
      const double u1 = s.get1D(), u2 = s.get1D();
      const Environment::Sample e = env.sample(u1, u2);
      const double x = e.L[size_t(k)] / e.pdf;
      sum += x, sum2 += x * x;
    }
    const double mean = sum / n, se = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n);
    EXPECT_NEAR(mean, exact[size_t(k)], 4 * se + 1e-12 * exact[size_t(k)]) << "channel " << k;
    // Luminance-proportional sampling: the estimator's spread is a small part of the integral.
    EXPECT_LT(se, 0.01 * exact[size_t(k)]) << "channel " << k;
  }
}

TEST(Environment, StudioKeyLightWhereDocumented) {
  const Environment env = Environment::builtIn("studio");
  const Colour3 key = env.radiance(sphericalDirection(radians(40), radians(235)));
  EXPECT_NEAR(key[0], 12, 1e-6);
  const Colour3 floor = env.radiance({0, 0, -1});
  EXPECT_NEAR(floor[1], 0.05, 1e-6);
}

TEST(Environment, ExrRoundTripAndRefusals) {
  const std::string path = (std::filesystem::temp_directory_path() / "microbsdf_env_test.exr").string();
  const int w = 16, h = 8;
  std::vector<ExrChannel> ch{{"R", {}}, {"G", {}}, {"B", {}}};
  for (int p = 0; p < w * h; ++p)
    for (int k = 0; k < 3; ++k) ch[size_t(k)].pixels.push_back(float(p % w + 10 * k));
  writeExr(path, w, h, ch);
  const Environment env = Environment::fromExr(path);
  EXPECT_EQ(env.width(), w);
  EXPECT_EQ(env.height(), h);
  const Colour3 L = env.radiance(env.pixelCentre(5, 3));
  EXPECT_EQ(L[0], 5);
  EXPECT_EQ(L[2], 25);
  ch[1].pixels[17] = -1;
  writeExr(path, w, h, ch);
  try {
    Environment::fromExr(path);
    FAIL() << "a negative radiance was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("(1, 1)"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Environment::fromExr(path + ".missing.exr"), InputError);
  EXPECT_THROW(Environment::builtIn("forest"), InputError);
}
