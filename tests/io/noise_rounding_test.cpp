// Rounding to the noise, checked against its promise over sweeps of magnitudes and error ratios
// (from far below a float's precision to errors larger than the value) and against an independent
// rounding of float32 bit patterns.
#include "io/noise_rounding.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

using namespace mbsdf;

namespace {
// x (a float) rounded to `bits` significant bits by integer arithmetic on its IEEE pattern: add half
// of the dropped part (minus one when the kept part is even, for ties to even) and clear it.
float roundFloatBits(float x, int bits) {
  const int drop = 24 - bits;
  if (drop <= 0) return x;
  uint32_t u = std::bit_cast<uint32_t>(x);
  const uint32_t keptLsb = (u >> drop) & 1u;
  u += (1u << (drop - 1)) - 1u + keptLsb;
  u &= ~((1u << drop) - 1u);
  return std::bit_cast<float>(u);
}
}  // namespace

TEST(NoiseRounding, SignificantBitsMatchFloatBitArithmetic) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> mantissa(1.0, 2.0);
  std::uniform_int_distribution<int> exponent(-100, 100), bits(1, 24);
  for (int k = 0; k < 200000; ++k) {
    const float x = float(std::ldexp(mantissa(rng), exponent(rng))) * (k % 2 ? -1.0f : 1.0f);
    const int b = bits(rng);
    ASSERT_EQ(float(roundToSignificantBits(x, b)), roundFloatBits(x, b)) << x << " at " << b << " bits";
  }
  // Ties go to even: 1 + 2^-8 at 8 bits is halfway between 1 and 1 + 2^-7.
  EXPECT_EQ(roundToSignificantBits(1 + std::ldexp(1.0, -8), 8), 1.0);
  EXPECT_EQ(roundToSignificantBits(1 + 3 * std::ldexp(1.0, -8), 8), 1 + std::ldexp(1.0, -6));
  EXPECT_EQ(roundToSignificantBits(0.0, 3), 0.0);
  EXPECT_TRUE(std::isnan(roundToSignificantBits(std::nan(""), 3)));
  EXPECT_EQ(roundToSignificantBits(-INFINITY, 3), -INFINITY);
}

// Every value moves by at most σ/32, lands on the grid of σ/16's power-of-two place (the bits below
// are zero: what deflate then removes), keeps its sign, never becomes zero or infinite, and a second
// rounding changes nothing.
TEST(NoiseRounding, WithinAThirtySecondOfTheErrorOverEveryScale) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (double logX = -300; logX <= 300; logX += 7.3)
    for (double logRatio = -12; logRatio <= 3; logRatio += 0.37) {
      const double x = std::pow(10.0, logX) * (1 + unit(rng)) * (unit(rng) < 0.5 ? -1 : 1);
      const double sigma = std::abs(x) * std::pow(10.0, logRatio) * (1 + unit(rng));
      const double y = roundToNoise(x, sigma);
      ASSERT_LE(std::abs(y - x), sigma / (2 * kNoiseSteps)) << x << " ± " << sigma;
      ASSERT_TRUE(std::isfinite(y));
      ASSERT_NE(y, 0.0);
      ASSERT_EQ(std::signbit(y), std::signbit(x));
      const double place = std::ldexp(1.0, std::ilogb(sigma / kNoiseSteps));
      if (std::abs(y) >= place) {
        ASSERT_EQ(std::fmod(y, place), 0.0) << y << " off the grid of " << place;
      }
      ASSERT_EQ(roundToNoise(y, sigma), y);
    }
}

// A value rounded to its noise has at most 24 significant bits while its error exceeds 2^-19 of
// it: single precision holds it exactly, so the float32 table stores the rounded value itself.
TEST(NoiseRounding, FloatHoldsTheRoundedValueExactly) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> mantissa(1.0, 2.0), logRatio(-5.7, 1.0);
  for (int k = 0; k < 100000; ++k) {
    const double x = std::ldexp(mantissa(rng), int(k % 200) - 100);
    const double y = roundToNoise(x, x * std::pow(10.0, logRatio(rng)));
    ASSERT_EQ(double(float(y)), y) << x;
  }
}

TEST(NoiseRounding, DeterministicValuesKeepEveryBit) {
  const double x = 0.1234567890123;
  EXPECT_EQ(roundToNoise(x, 0.0), x);
  EXPECT_EQ(roundToNoise(x, -1.0), x);
  EXPECT_EQ(roundToNoise(x, std::nan("")), x);
  EXPECT_EQ(roundToNoise(x, INFINITY), x);
  EXPECT_EQ(roundToNoise(0.0, 1.0), 0.0);
  EXPECT_TRUE(std::isnan(roundToNoise(std::nan(""), 1.0)));
  // An error far below the value's own precision: every bit kept.
  EXPECT_EQ(roundToNoise(x, 1e-300), x);
}

TEST(NoiseRounding, ErrorsKeepTheirSignificantBits) {
  std::vector<double> sigma{0.0, 1.0 / 3, 2.5e-7, 1e30, std::nan("")};
  const std::vector<double> before = sigma;
  roundErrorRow(sigma);
  EXPECT_EQ(sigma[0], 0.0);
  EXPECT_TRUE(std::isnan(sigma[4]));
  for (size_t k = 1; k < 4; ++k) EXPECT_LE(std::abs(sigma[k] - before[k]), std::ldexp(before[k], -kErrorBits));
  std::vector<double> values{1.0, 2.0};
  EXPECT_THROW(roundRowToNoise(values, {1.0}), std::logic_error);
  // One estimate: the value by its unrounded error, then the error.
  double f = 0.123456789, se = 1.0 / 3000;
  roundEstimate(f, se);
  EXPECT_EQ(f, roundToNoise(0.123456789, 1.0 / 3000));
  EXPECT_EQ(se, roundToSignificantBits(1.0 / 3000, kErrorBits));
}
