#include "job/symmetry.h"

#include <map>
#include <stdexcept>

namespace mbsdf {

AzimuthalSymmetry::AzimuthalSymmetry(const Job& job, const DirectionGrid& grid) : grid_(grid) {
  const auto* tp = std::get_if<ThetaPhiGrid>(&grid.layout());
  if (!job.isotropic || !tp || !job.incidenceAll) throw std::logic_error("AzimuthalSymmetry: job is not reducible");
  nPhi_ = tp->nPhi;
  const int n = int(job.incidence.size()), perHemi = grid.binsPerHemisphere();
  std::map<int, int> indexOfBin;
  for (int i = 0; i < n; ++i) indexOfBin[job.incidence[size_t(i)].bin] = i;
  rep_.assign(size_t(n), -1);
  shift_.assign(size_t(n), 0);
  members_.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    const int bin = job.incidence[size_t(i)].bin, hemi = bin / perHemi, local = bin % perHemi;
    const int ringStart = hemi * perHemi + (local / nPhi_) * nPhi_;
    auto it = indexOfBin.find(ringStart);
    // Every bin of a ring has the same projected solid angle, so "all" holds whole rings.
    if (it == indexOfBin.end()) throw std::logic_error("AzimuthalSymmetry: incomplete ring");
    rep_[size_t(i)] = it->second;
    shift_[size_t(i)] = local % nPhi_;
    members_[size_t(it->second)].push_back(i);
  }
  for (int i = 0; i < n; ++i) count_ += rep_[size_t(i)] == i;
}

TileResult AzimuthalSymmetry::rotate(const TileResult& r, int target, int targetBin) const {
  TileResult out = r;
  out.tile = target;
  out.incidenceIndex = target;
  out.incidenceBin = targetBin;
  const int s = shift_[size_t(target)];
  if (s == 0) return out;
  for (int c = 0; c < kComponentCount; ++c) {
    if (r.value[size_t(c)].empty()) continue;
    for (int l = 0; l < r.nLambda; ++l)
      for (int b = 0; b < r.nBins; ++b) {
        // Exit bin b = (ring, p') takes the value of (ring, p' − s) of the representative.
        const int ring = b / nPhi_, p = b % nPhi_;
        const int from = ring * nPhi_ + ((p - s) % nPhi_ + nPhi_) % nPhi_;
        out.value[size_t(c)][size_t(l) * r.nBins + b] = r.value[size_t(c)][size_t(l) * r.nBins + from];
        out.stdError[size_t(c)][size_t(l) * r.nBins + b] = r.stdError[size_t(c)][size_t(l) * r.nBins + from];
      }
  }
  return out;
}

}  // namespace mbsdf
