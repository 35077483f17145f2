#include "core/colour.h"

#include <gtest/gtest.h>

using namespace mbsdf;

TEST(Colour, MatchingFunctionsIntegrateToTabulatedValues) {
  // CIE 015: the 1 nm tables sum to 106.865 (x̄), 106.857 (ȳ), 106.892 (z̄) over 360–830 nm.
  Colour3 s = cieXyzIntegral(360, 830);
  EXPECT_NEAR(s[0], 106.865, 0.02);
  EXPECT_NEAR(s[1], 106.857, 0.02);
  EXPECT_NEAR(s[2], 106.892, 0.02);
  EXPECT_DOUBLE_EQ(cieXyzBar(555)[1], 1.0);
  EXPECT_NEAR(cieXyzBar(600)[0], 1.0622, 1e-9);
  EXPECT_EQ(cieXyzBar(900)[1], 0.0);
}

TEST(Colour, EqualEnergyIsNeutral) {
  std::vector<double> lambda;
  for (double l = 362.5; l < 830; l += 5) lambda.push_back(l);
  SpectrumToColour conv(lambda);
  std::vector<double> one(lambda.size(), 1.0);
  Colour3 xyz = conv.xyz(one.data());
  EXPECT_NEAR(xyz[1], 1.0, 1e-12);
  EXPECT_NEAR(xyz[0], 1.0, 1e-3);
  EXPECT_NEAR(xyz[2], 1.0, 1e-3);
  Colour3 rgb = conv.linearSrgb(one.data());
  EXPECT_NEAR(rgb[0], rgb[1], 2e-3);
  EXPECT_NEAR(rgb[2], rgb[1], 2e-3);
  Colour3 cie = conv.cieRgb(one.data());
  for (double c : cie) EXPECT_NEAR(c, 1.0, 2e-3);
  // The paper's 8 samples over 400–700 nm: still neutral in CIE RGB up to the truncated tails.
  std::vector<double> l8;
  for (int i = 0; i < 8; ++i) l8.push_back(400 + (i + 0.5) * 37.5);
  SpectrumToColour c8(l8);
  std::vector<double> one8(8, 1.0);
  EXPECT_NEAR(c8.xyz(one8.data())[1], 1.0, 1e-12);
}

TEST(Colour, MonochromaticLightsHaveTheirHue) {
  SpectrumToColour conv({450, 550, 650});
  double blue[] = {1, 0, 0}, green[] = {0, 1, 0}, red[] = {0, 0, 1};
  Colour3 b = conv.linearSrgb(blue), g = conv.linearSrgb(green), r = conv.linearSrgb(red);
  EXPECT_GT(b[2], b[0]);
  EXPECT_GT(b[2], b[1]);
  EXPECT_GT(g[1], g[0]);
  EXPECT_GT(g[1], g[2]);
  EXPECT_GT(r[0], r[1]);
  EXPECT_GT(r[0], r[2]);
}
