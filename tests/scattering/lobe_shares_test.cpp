// The integrated shares of a Gaussian lobe among a grid's bins (lobe_shares.h), against the
// spot's density integrated over each bin by composite Gauss–Legendre rules whose cells follow the
// bins' own edges (polar cells for a theta-phi grid, so that every cell lies inside one bin and the
// integrand is smooth there: an independent route with no edge approximated).
#include "scattering/lobe_shares.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "core/quadrature.h"
#include "core/rng.h"
#include "core/vecmath.h"

using namespace mbsdf;

namespace {

constexpr double kReach = 9.0;  // the spot's density beyond 9 sd is below 1e-17 of its peak

// The pieces of [lo, hi] between consecutive breakpoints `edge(k)`, each cut into cells no wider
// than `cell`, with 6 Gauss–Legendre nodes per cell: (node, weight, index of the piece's interval).
struct Node {
  double x, w;
  long k;
};
template <typename Edge>
std::vector<Node> compositeNodes(double lo, double hi, double cell, long kLo, const Edge& edge) {
  std::vector<Node> nodes;
  const QuadratureRule unit = gaussLegendre(6, 0.0, 1.0);
  for (long k = kLo;; ++k) {
    const double a = std::max(lo, edge(k)), b = std::min(hi, edge(k + 1));
    if (edge(k) >= hi) break;
    if (b <= a) continue;
    const int cells = std::max(1, int(std::ceil((b - a) / cell)));
    for (int c = 0; c < cells; ++c)
      for (size_t i = 0; i < unit.x.size(); ++i) {
        const double h = (b - a) / cells;
        nodes.push_back({a + h * (c + unit.x[i]), h * unit.w[i], k});
      }
  }
  return nodes;
}

double density(double x, double y, double cx, double cy, double sd) {
  const double dx = x - cx, dy = y - cy;
  return std::exp(-(dx * dx + dy * dy) / (2 * sd * sd)) / (2 * kPi * sd * sd);
}

std::map<int, double> referenceThetaPhi(const DirectionGrid& grid, const ThetaPhiGrid& g, double cx, double cy,
                                        double sd) {
  const double rc = std::hypot(cx, cy), phic = std::atan2(cy, cx);
  const double dphi = 2 * kPi / g.nPhi;
  const double reachPhi = kReach * sd < rc ? std::asin(kReach * sd / rc) : kPi;
  const auto radial = compositeNodes(std::max(0.0, rc - kReach * sd), std::min(1.0, rc + kReach * sd), sd / 2, 0,
                                     [&](long t) { return t > g.nTheta ? 2.0 : grid.ringEdgeSin(int(t)); });
  const long pLo = long(std::floor((phic - reachPhi) / dphi)) - 1;
  const auto azimuthal = compositeNodes(phic - reachPhi, phic + reachPhi, std::min(sd / (2 * rc), dphi / 4), pLo,
                                        [&](long p) { return double(p) * dphi; });
  std::map<int, double> shares;
  for (const Node& r : radial)
    for (const Node& a : azimuthal) {
      const int spoke = int(((a.k % g.nPhi) + g.nPhi) % g.nPhi);
      shares[int(r.k) * g.nPhi + spoke] +=
          density(r.x * std::cos(a.x), r.x * std::sin(a.x), cx, cy, sd) * r.x * r.w * a.w;
    }
  return shares;
}

std::map<int, double> referenceDisk(const DiskGrid& g, double cx, double cy, double sd) {
  auto nodes = [&](double c, int n) {
    return compositeNodes(c - kReach * sd, c + kReach * sd, sd / 2, 0, [&](long k) { return -1 + 2.0 * k / n; });
  };
  std::map<int, double> shares;
  for (const Node& y : nodes(cy, g.height))
    for (const Node& x : nodes(cx, g.width))
      if (x.x * x.x + y.x * y.x < 1) shares[int(y.k) * g.width + int(x.k)] += density(x.x, y.x, cx, cy, sd) * x.w * y.w;
  return shares;
}

// L1 distance between the closed form and the reference, over the union of their bins.
double distance(const std::vector<std::pair<int, double>>& got, const std::map<int, double>& ref, double* sum) {
  std::map<int, double> diff = ref;
  *sum = 0;
  for (const auto& [b, s] : got) {
    diff[b] -= s;
    *sum += s;
  }
  double l1 = 0;
  for (const auto& [b, d] : diff) l1 += std::abs(d);
  return l1;
}

}  // namespace

// Theta-phi grids from 8 x 16 to the paper's 75 x 300, spots from 1e-4 to 0.02 wide at the pole,
// around it, and from there to beyond the horizon: the L1 distance of the shares from the reference
// stays below 2e-5 of the spot (measured 9e-6: three-node rules on pieces three units of u wide),
// and the shares add up to the spot's part inside the unit disk within 2e-5.
TEST(LobeShares, ThetaPhiMatchesTheSpotIntegratedOverEachBin) {
  Sampler pick(11, 0, 0);
  double worst = 0;
  int cases = 0;
  for (const ThetaPhiGrid g : {ThetaPhiGrid{8, 16}, ThetaPhiGrid{30, 120}, ThetaPhiGrid{75, 300}})
    for (double sd : {1e-4, 1e-3, 5e-3, 2e-2}) {
      const DirectionGrid grid(g);
      for (int i = 0; i < 14; ++i) {
        // The pole itself, then distances from it of 0.3 to 300 sd, then distances from the horizon
        // of 300 sd down to -1 sd (the centre just beyond it is evanescent: no shares).
        const double f = double(i - 1) / 5;
        const double rc = i == 0   ? 0.0
                          : i <= 6 ? 0.3 * sd * std::pow(1000.0, f)
                                   : 1 - sd * std::pow(10.0, 2.5 - 0.5 * (i - 7));
        if (rc >= 1) {
          std::vector<std::pair<int, double>> got;
          EXPECT_FALSE(gaussianLobeShares(grid, rc, 0.0, sd, true, &got));
          continue;
        }
        if (rc < 0) continue;
        const double phi = 2 * kPi * pick.get1D();
        const double cx = rc * std::cos(phi), cy = rc * std::sin(phi);
        std::vector<std::pair<int, double>> got;
        ASSERT_TRUE(gaussianLobeShares(grid, cx, cy, sd, true, &got)) << rc << " " << sd;
        const std::map<int, double> ref = referenceThetaPhi(grid, g, cx, cy, sd);
        double sum = 0, refSum = 0;
        for (const auto& [b, s] : ref) refSum += s;
        const double l1 = distance(got, ref, &sum);
        for (const auto& [b, s] : got) {
          ASSERT_TRUE(std::isfinite(s) && s >= 0) << b;
          ASSERT_TRUE(b >= 0 && b < grid.binsPerHemisphere());
        }
        EXPECT_NEAR(sum, refSum, 2e-5) << "rc " << rc << " sd " << sd;
        EXPECT_LT(l1, 2e-5) << g.nTheta << " x " << g.nPhi << ", rc " << rc << ", sd " << sd;
        worst = std::max(worst, l1);
        ++cases;
      }
    }
  std::printf("%d spots: worst L1 distance %.2e\n", cases, worst);
}

// A disk grid's pixels are squares: the shares are exact products, to within the spot's tails
// beyond kLobeWindow sd (3e-7), which the outermost pixels take whether or not they lie inside the
// unit disk; a spot within kLobeWindow sd of the rim is left to the caller.
TEST(LobeShares, DiskPixelsAreExactProducts) {
  const DiskGrid g{33, 17};
  const DirectionGrid grid(g);
  Sampler pick(12, 0, 0);
  for (double sd : {1e-3, 1e-2, 5e-2})
    for (int i = 0; i < 20; ++i) {
      const double rc = (1 - kLobeWindow * sd) * std::sqrt(pick.get1D()), phi = 2 * kPi * pick.get1D();
      std::vector<std::pair<int, double>> got;
      ASSERT_TRUE(gaussianLobeShares(grid, rc * std::cos(phi), rc * std::sin(phi), sd, false, &got));
      for (auto& [b, s] : got) {
        ASSERT_GE(b, grid.binsPerHemisphere());  // the lower hemisphere's bins
        b -= grid.binsPerHemisphere();
      }
      double sum = 0;
      EXPECT_LT(distance(got, referenceDisk(g, rc * std::cos(phi), rc * std::sin(phi), sd), &sum), 1e-6) << rc;
      EXPECT_NEAR(sum, 1.0, 1e-12);
    }
  std::vector<std::pair<int, double>> got{{1, 1.0}};
  EXPECT_FALSE(gaussianLobeShares(grid, 0.0, 1 - kLobeWindow * 0.01 + 1e-9, 0.01, true, &got));
  EXPECT_TRUE(got.empty());
}

// A spot of no width, centred beyond the horizon or at no number, is left to the caller.
TEST(LobeShares, PointSpotsAreLeftToTheCaller) {
  const DirectionGrid grid(ThetaPhiGrid{30, 120});
  std::vector<std::pair<int, double>> got{{1, 1.0}};
  EXPECT_FALSE(gaussianLobeShares(grid, 0.5, 0.0, 0.0, true, &got));
  EXPECT_FALSE(gaussianLobeShares(grid, 0.5, 0.0, std::nan(""), true, &got));
  EXPECT_FALSE(gaussianLobeShares(grid, 0.6, 0.8, 1e-3, true, &got));
  EXPECT_FALSE(gaussianLobeShares(grid, std::nan(""), 0.1, 1e-3, true, &got));
  EXPECT_FALSE(gaussianLobeShares(DirectionGrid(DiskGrid{9, 9}), std::nan(""), 0.1, 1e-3, true, &got));
  EXPECT_TRUE(got.empty());
}
