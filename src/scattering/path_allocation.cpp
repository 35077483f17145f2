#include "scattering/path_allocation.h"

#include <algorithm>
#include <cmath>

#include "scattering/reciprocity.h"

namespace mbsdf {
namespace {

// Incidence bins of one hemisphere grouped by projected solid angle: equal within 1e-9 relative
// (the same ring of a theta-phi grid, a bin and its mirror image), at most kMaxGroups groups
// (log-spaced buckets beyond that: the model is a model, the grouping keeps it cheap).
struct Groups {
  std::vector<double> omega;  // a group's projected solid angle (its members' mean)
  std::vector<double> count;  // incidence bins in the group
  std::vector<int> groupOf;   // per incidence index on this side, its group (−1: other side)
};
constexpr size_t kMaxGroups = 1024;

Groups groupBySize(const DirectionGrid& grid, const std::vector<int>& incidenceBins, bool upper) {
  std::vector<std::pair<double, int>> sized;  // (Ω⊥, incidence index)
  for (size_t i = 0; i < incidenceBins.size(); ++i)
    if (grid.isUpper(incidenceBins[i]) == upper) sized.emplace_back(grid.projectedSolidAngle(incidenceBins[i]), int(i));
  std::sort(sized.begin(), sized.end());
  Groups g;
  g.groupOf.assign(incidenceBins.size(), -1);
  if (sized.empty()) return g;
  const double lo = std::max(sized.front().first, 1e-300), hi = std::max(sized.back().first, lo);
  const double logSpan = std::log(hi / lo);
  std::vector<double> sum;
  double last = -1;
  long lastBucket = -1;
  for (const auto& [omega, i] : sized) {
    bool next;
    if (sized.size() <= kMaxGroups)
      next = last < 0 || omega > last * (1 + 1e-9);
    else {
      const long bucket =
          logSpan > 0
              ? std::min(long(kMaxGroups) - 1, long(std::log(std::max(omega, lo) / lo) / logSpan * double(kMaxGroups)))
              : 0;
      next = bucket != lastBucket;
      lastBucket = bucket;
    }
    if (next) {
      sum.push_back(0);
      g.count.push_back(0);
    }
    sum.back() += omega;
    g.count.back() += 1;
    g.groupOf[size_t(i)] = int(sum.size()) - 1;
    last = omega;
  }
  for (size_t k = 0; k < sum.size(); ++k) g.omega.push_back(sum[k] / g.count[k]);
  return g;
}

}  // namespace

std::vector<double> equalErrorPathShares(const DirectionGrid& grid, const std::vector<int>& incidenceBins,
                                         bool transmits) {
  // Σ √Ω⊥ over a hemisphere's exit bins, and over those that are no incidence bin (no partner).
  std::vector<char> isIncidence(size_t(grid.binCount()), 0);
  for (int b : incidenceBins) isIncidence[size_t(b)] = 1;
  double all[2] = {0, 0}, unpaired[2] = {0, 0};
  for (int b = 0; b < grid.binCount(); ++b) {
    const double omega = grid.projectedSolidAngle(b);
    if (!(omega > 0)) continue;
    const int side = grid.isUpper(b) ? 0 : 1;
    all[side] += std::sqrt(omega);
    if (!isIncidence[size_t(b)]) unpaired[side] += std::sqrt(omega);
  }
  std::vector<double> share(incidenceBins.size(), 1.0);
  for (int side = 0; side < 2; ++side) {
    Groups g = groupBySize(grid, incidenceBins, side == 0);
    const size_t n = g.omega.size();
    std::vector<double> paths(n, 1.0), next(n);
    // Fixed-point iteration N_g ∝ (Σ_o √(Ω⊥(o) w))², normalised to the largest; a fixed count of
    // steps (it settles to 1e-4 within about ten on the paper's grid) so every rank computes the same.
    for (int step = 0; step < 64 && n > 0; ++step) {
      for (size_t a = 0; a < n; ++a) {
        const double own = g.omega[a];
        double e = unpaired[side] + (transmits ? all[1 - side] : 0.0);
        for (size_t b = 0; b < n; ++b) {
          const double o = g.omega[b], w = reciprocalPairWeight(o, own, paths[b] / paths[a]);
          e += g.count[b] * std::sqrt(o * w);
        }
        e += std::sqrt(own) - std::sqrt(own * 0.5);  // its own bin: no partner (w = 1, not the ½ counted)
        next[a] = e * e;
      }
      const double top = *std::max_element(next.begin(), next.end());
      for (size_t a = 0; a < n; ++a) paths[a] = top > 0 ? next[a] / top : 1.0;
    }
    for (size_t i = 0; i < incidenceBins.size(); ++i)
      if (g.groupOf[i] >= 0) share[i] = paths[size_t(g.groupOf[i])];
  }
  return share;
}

std::vector<uint64_t> equalErrorSlicePaths(const DirectionGrid& grid, const std::vector<int>& incidenceBins,
                                           bool transmits, uint64_t pathsPerSlice) {
  const std::vector<double> share = equalErrorPathShares(grid, incidenceBins, transmits);
  std::vector<uint64_t> paths(share.size());
  for (size_t i = 0; i < share.size(); ++i)
    paths[i] =
        std::max<uint64_t>(1, std::min<uint64_t>(pathsPerSlice, uint64_t(std::ceil(share[i] * double(pathsPerSlice)))));
  return paths;
}

}  // namespace mbsdf
