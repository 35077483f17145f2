#include "scattering/reciprocity.h"

#include <stdexcept>

namespace mbsdf {

ReciprocalPairs::ReciprocalPairs(std::vector<int> incidenceBins, int nBins, int binsPerHemisphere)
    : incidenceBins_(std::move(incidenceBins)),
      incidenceOfBin_(std::size_t(nBins), -1),
      rank_(incidenceBins_.size()),
      binsPerHemisphere_(binsPerHemisphere) {
  for (std::size_t i = 0; i < incidenceBins_.size(); ++i) {
    const int b = incidenceBins_[i];
    if (b < 0 || b >= nBins || incidenceOfBin_[std::size_t(b)] >= 0)
      throw std::invalid_argument("ReciprocalPairs: incidence bins must be distinct sphere bins");
    incidenceOfBin_[std::size_t(b)] = int(i);
    rank_[i] = sideCount_[upper(b) ? 0 : 1]++;
  }
}

bool ReciprocalPairs::computes(int i, int exitBin) const {
  const int j = incidenceOf(exitBin);
  const int bi = incidenceBin(i);
  if (j < 0 || j == i || upper(bi) != upper(exitBin)) return true;
  const long n = sideCount_[upper(bi) ? 0 : 1];
  const long d = ((long(rank_[std::size_t(j)]) - long(rank_[std::size_t(i)])) % n + n) % n;
  return 2 * d < n || (2 * d == n && i < j);
}

std::vector<uint8_t> ReciprocalPairs::exitMask(int i) const {
  std::vector<uint8_t> m(incidenceOfBin_.size());
  for (std::size_t b = 0; b < m.size(); ++b) m[b] = computes(i, int(b)) ? 1 : 0;
  return m;
}

double ReciprocalPairs::computedFraction() const {
  double done = 0, all = 0;
  for (int n : sideCount_) {
    done += n + double(n) * (n - 1) / 2;
    all += double(n) * n;
  }
  return all > 0 ? done / all : 1.0;
}

}  // namespace mbsdf
