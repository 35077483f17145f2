#include "core/direction_grid.h"

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <memory>
#include <vector>

#include "core/rng.h"

using namespace mbsdf;

TEST(DirectionGrid, ThetaPhiMeasuresSumToSphere) {
  DirectionGrid g(ThetaPhiGrid{75, 300});
  double om = 0, op = 0;
  for (int b = 0; b < g.binCount(); ++b) {
    om += g.solidAngle(b);
    op += g.projectedSolidAngle(b);
  }
  EXPECT_NEAR(om, 4 * kPi, 1e-9);
  EXPECT_NEAR(op, 2 * kPi, 1e-9);  // π per hemisphere
  EXPECT_EQ(g.binCount(), 45000);
}

TEST(DirectionGrid, DiskMeasuresSumToSphere) {
  DirectionGrid g(DiskGrid{64, 64});
  double om = 0, op = 0;
  for (int b = 0; b < g.binCount(); ++b) {
    om += g.solidAngle(b);
    op += g.projectedSolidAngle(b);
  }
  EXPECT_NEAR(op, 2 * kPi, 2e-4);
  EXPECT_NEAR(om, 4 * kPi, 0.02);  // rim pixels: 1/cos singularity, midpoint quadrature
  // Interior pixel: projected solid angle is the pixel area 4/(WH) (Falster et al. 2020, Eq. 11).
  EXPECT_NEAR(g.projectedSolidAngle(g.binOf({0.01, 0.01, 1})), 4.0 / (64 * 64), 1e-12);
}

// A disk grid's measures are computed once per size and process and shared: grids built at once
// from many TBB tasks (the lock is taken inside a task) are all equal, with the measures'
// symmetries of the disk (the rim pixels are computed alone, each by its own quadrature).
TEST(DirectionGrid, DiskMeasuresSharedAcrossThreadsAndSymmetric) {
  const DiskGrid layout{37, 21};
  std::vector<std::unique_ptr<DirectionGrid>> grids(16);
  tbb::parallel_for(0, 16, [&](int i) { grids[size_t(i)] = std::make_unique<DirectionGrid>(layout); });
  const DirectionGrid& g0 = *grids[0];
  for (const auto& g : grids)
    for (int b = 0; b < g0.binCount(); ++b) {
      ASSERT_EQ(g->solidAngle(b), g0.solidAngle(b));
      ASSERT_EQ(g->projectedSolidAngle(b), g0.projectedSolidAngle(b));
    }
  for (int j = 0; j < layout.height; ++j)
    for (int i = 0; i < layout.width; ++i) {
      const int b = j * layout.width + i, mirrored = (layout.height - 1 - j) * layout.width + (layout.width - 1 - i);
      EXPECT_NEAR(g0.projectedSolidAngle(b), g0.projectedSolidAngle(mirrored), 1e-12);
      EXPECT_NEAR(g0.solidAngle(b), g0.solidAngle(mirrored), 1e-9 + 1e-6 * g0.solidAngle(b));
    }
}

TEST(DirectionGrid, CentresAndSamplesFallInTheirBins) {
  for (DirectionGrid::Layout l :
       {DirectionGrid::Layout(ThetaPhiGrid{9, 24}), DirectionGrid::Layout(DiskGrid{16, 16})}) {
    DirectionGrid g(l);
    Sampler s(1, 0, 0);
    for (int b = 0; b < g.binCount(); ++b) {
      if (g.projectedSolidAngle(b) <= 0) continue;
      EXPECT_EQ(g.binOf(g.centre(b)), b) << g.kind();
      for (int k = 0; k < 20; ++k) {
        DirectionSample u = g.sampleUniform(b, s);
        DirectionSample c = g.sampleCosine(b, s);
        ASSERT_EQ(g.binOf(u.w), b) << g.kind();
        ASSERT_EQ(g.binOf(c.w), b) << g.kind();
        ASSERT_NEAR(length(u.w), 1.0, 1e-12);
      }
    }
  }
}

// The polynomial angles behind the fast bin search stay within the bound the search relies on,
// with a margin of 4 (a dense sweep of their domain, ends included).
TEST(DirectionGrid, PolynomialAnglesWithinTheirBound) {
  double acosErr = 0, atanErr = 0;
  const int n = 1 << 20;
  for (int i = 0; i <= n; ++i) {
    const double x = double(i) / n;
    acosErr = std::max(acosErr, std::abs(detail::approxAcos(x) - std::acos(x)));
    atanErr = std::max(atanErr, std::abs(detail::approxAtan(x) - std::atan(x)));
  }
  EXPECT_LT(acosErr, detail::kApproxAngleError / 4);
  EXPECT_LT(atanErr, detail::kApproxAngleError / 4);
}

// binOf's fast search must put every direction where the grid's rule (θ = acos|z|, φ = atan2(y, x)
// in [0, 2π), scaled and truncated) puts it: random directions, directions exactly on ring and
// azimuth edges and a few ulps either side of them, the poles, the horizon and signed zeros.
TEST(DirectionGrid, FastBinSearchFollowsTheGridsRule) {
  auto ruleBin = [](const ThetaPhiGrid& g, const Vec3& wIn) {
    const Vec3 w = normalize(wIn);
    const int t = std::min(g.nTheta - 1, int(safeAcos(std::abs(w.z)) / (0.5 * kPi) * g.nTheta));
    const int p = std::min(g.nPhi - 1, int(sphericalPhi(w) / (2 * kPi) * g.nPhi));
    return (w.z >= 0 ? 0 : g.nTheta * g.nPhi) + t * g.nPhi + p;
  };
  for (const ThetaPhiGrid layout : {ThetaPhiGrid{30, 120}, ThetaPhiGrid{75, 300}, ThetaPhiGrid{1, 1},
                                    ThetaPhiGrid{7, 13}, ThetaPhiGrid{1000, 4096}}) {
    const DirectionGrid g(layout);
    std::vector<Vec3> ws = {{0, 0, 1},      {0, 0, -1},     {1, 0, 0},        {-1, 0, 0},   {0, 1, 0},       {0, -1, 0},
                            {-0.0, 0.0, 1}, {0.0, -0.0, 1}, {-0.0, -0.0, -1}, {1, -0.0, 0}, {-1, -0.0, -0.0}};
    Sampler s(7, 0, 0);
    for (int i = 0; i < 200000; ++i) {
      const double z = 2 * s.get1D() - 1, phi = 2 * kPi * s.get1D(), r = safeSqrt(1 - z * z);
      ws.push_back({r * std::cos(phi), r * std::sin(phi), z});
    }
    // Edges: every ring edge at a few azimuths, every azimuth edge at a few polar angles, each
    // exactly and nudged by 1 to 3 ulps in each coordinate.
    std::vector<Vec3> edges;
    for (int t = 0; t <= layout.nTheta; ++t)
      for (double phi : {0.1, 1.0, 2.5, 4.0, 6.0})
        edges.push_back(sphericalDirection(t * 0.5 * kPi / layout.nTheta, phi));
    for (int p = 0; p <= layout.nPhi; ++p)
      for (double theta : {0.01, 0.3, 1.0, 1.5, 1.5707})
        edges.push_back(sphericalDirection(theta, p * 2 * kPi / layout.nPhi));
    for (const Vec3& e : edges)
      for (int a = 0; a < 3; ++a)
        for (double toward : {-1.0, 1.0}) {
          Vec3 w = e;
          ws.push_back(w);
          for (int k = 0; k < 3; ++k) {
            w[a] = std::nextafter(w[a], toward);
            ws.push_back(w);
            ws.push_back({w.x, w.y, -w.z});
          }
        }
    // A fine lattice of |z| and of the azimuth's ratio min(|x|, |y|) / max(|x|, |y|) in every octant
    // (steps of 2⁻¹⁴ and 2⁻¹²: the ends of the search's cells among them), exactly and an ulp either side.
    for (int i = 0; i <= 1 << 14; ++i) {
      const double z = std::ldexp(double(i), -14), r = safeSqrt(1 - z * z);
      for (double zz : {std::nextafter(z, 0.0), z, std::nextafter(z, 2.0)}) {
        ws.push_back({r * 0.6, r * 0.8, zz});
        ws.push_back({-r * 0.28, r * 0.96, -zz});
      }
    }
    for (int i = 0; i <= 1 << 12; ++i) {
      const double ratio = std::ldexp(double(i), -12);
      for (double q : {std::nextafter(ratio, 0.0), ratio, std::nextafter(ratio, 2.0)})
        for (int o = 0; o < 8; ++o) {
          const double big = 0.5 / std::sqrt(1 + q * q), small = q * big, z = std::sqrt(0.75);
          const double ax = (o & 4) ? small : big, ay = (o & 4) ? big : small;
          ws.push_back({(o & 1) ? -ax : ax, (o & 2) ? -ay : ay, z});
        }
    }
    // Directions a caller did not normalise (the rule's bin is normalize(w)'s): scaled, and off unit
    // length by a little more than the fast path takes as given.
    const size_t given = ws.size();
    for (size_t i = 0; i < given; i += 3) {
      ws.push_back(ws[i] * 1.7);
      ws.push_back(ws[i] * (1 + 1e-13));
    }
    for (const Vec3& w : ws)
      ASSERT_EQ(g.binOf(w), ruleBin(layout, w))
          << layout.nTheta << "x" << layout.nPhi << " w = (" << w.x << ", " << w.y << ", " << w.z << ")";
  }
}

// The pole and horizon bins, counted by hand: a theta-phi grid's first and last rings; on an 8 x 8
// disk, per quadrant of 4 x 4 pixels with corners at multiples of 1/4, the pixel at the centre and
// the 8 whose far corner (a, b)/4 lies outside the unit circle (a² + b² > 16), less the corner
// pixel, which lies outside it entirely (an empty bin).
TEST(DirectionGrid, PoleAndHorizonBins) {
  const DirectionGrid tp{ThetaPhiGrid{6, 8}};
  for (int b = 0; b < tp.binCount(); ++b) {
    const int ring = (b % tp.binsPerHemisphere()) / 8;
    EXPECT_EQ(tp.atPoleOrHorizon(b), ring == 0 || ring == 5) << b;
  }
  const DirectionGrid disk{DiskGrid{8, 8}};
  int flagged = 0;
  for (int b = 0; b < disk.binsPerHemisphere(); ++b) {
    flagged += disk.atPoleOrHorizon(b) && disk.projectedSolidAngle(b) > 0;
    EXPECT_EQ(disk.atPoleOrHorizon(b), disk.atPoleOrHorizon(b + disk.binsPerHemisphere()));
  }
  EXPECT_EQ(flagged, 4 * 8);
  // An odd disk: the middle pixel holds the centre in its interior; its neighbours do not.
  const DirectionGrid odd{DiskGrid{5, 5}};
  EXPECT_TRUE(odd.atPoleOrHorizon(2 * 5 + 2));
  EXPECT_FALSE(odd.atPoleOrHorizon(2 * 5 + 1));
  EXPECT_FALSE(odd.atPoleOrHorizon(1 * 5 + 2));
  EXPECT_TRUE(odd.atPoleOrHorizon(0));
}

TEST(DirectionGrid, UniformSampleWeightsAverageToOne) {
  // weight = cos θ / mean cos over the bin: its mean over uniform samples is 1.
  DirectionGrid g(ThetaPhiGrid{10, 20});
  Sampler s(3, 0, 0);
  for (int b : {0, 55, 199, 250}) {
    double sum = 0;
    const int n = 20000;
    for (int k = 0; k < n; ++k) sum += g.sampleUniform(b, s).weight;
    EXPECT_NEAR(sum / n, 1.0, 0.01);
  }
}

TEST(Sampler, KeyedAndUniform) {
  Sampler a(5, 1, 2), b(5, 1, 2), c(5, 1, 3), d(6, 1, 2);
  double x = a.get1D();
  EXPECT_EQ(x, b.get1D());
  EXPECT_NE(x, c.get1D());
  EXPECT_NE(x, d.get1D());
  // Moments of the uniform distribution over many keys.
  double m1 = 0, m2 = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    Sampler s(1, 0, uint64_t(i));
    double u = s.get1D();
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    m1 += u;
    m2 += u * u;
  }
  EXPECT_NEAR(m1 / n, 0.5, 4 * std::sqrt(1.0 / 12 / n));
  EXPECT_NEAR(m2 / n, 1.0 / 3, 0.003);
  // setDimension replays a dimension.
  Sampler e(9, 9, 9);
  e.setDimension(4);
  double v4 = e.get1D();
  Sampler f(9, 9, 9);
  for (int i = 0; i < 8; ++i) f.get1D();  // two doubles per block: dimension 4 = 9th double
  EXPECT_EQ(v4, f.get1D());
}
