#include "scattering/tile_result.h"

#include <cstring>
#include <stdexcept>

namespace mbsdf {

std::vector<double> TileResult::serialize() const {
  std::vector<double> b;
  b.push_back(tile);
  b.push_back(incidenceIndex);
  b.push_back(incidenceBin);
  b.push_back(nLambda);
  b.push_back(nBins);
  double s;
  static_assert(sizeof(uint64_t) == sizeof(double));
  std::memcpy(&s, &samples, sizeof s);
  b.push_back(s);
  std::memcpy(&s, &rays, sizeof s);
  b.push_back(s);
  b.push_back(seconds);
  for (int c = 0; c < kComponentCount; ++c) {
    b.push_back(double(value[c].size()));
    b.insert(b.end(), value[c].begin(), value[c].end());
    b.insert(b.end(), stdError[c].begin(), stdError[c].end());
  }
  for (const auto* v : {&truncated, &leaked, &missed}) {
    b.push_back(double(v->size()));
    b.insert(b.end(), v->begin(), v->end());
  }
  return b;
}

TileResult TileResult::deserialize(const std::vector<double>& b) {
  size_t i = 0;
  auto next = [&]() {
    if (i >= b.size()) throw std::runtime_error("truncated TileResult message");
    return b[i++];
  };
  TileResult r;
  r.tile = int(next());
  r.incidenceIndex = int(next());
  r.incidenceBin = int(next());
  r.nLambda = int(next());
  r.nBins = int(next());
  double s = next();
  std::memcpy(&r.samples, &s, sizeof s);
  s = next();
  std::memcpy(&r.rays, &s, sizeof s);
  r.seconds = next();
  auto take = [&](std::vector<double>& v, size_t n) {
    if (i + n > b.size()) throw std::runtime_error("truncated TileResult message");
    v.assign(b.begin() + i, b.begin() + i + n);
    i += n;
  };
  for (int c = 0; c < kComponentCount; ++c) {
    size_t n = size_t(next());
    take(r.value[c], n);
    take(r.stdError[c], n);
  }
  for (auto* v : {&r.truncated, &r.leaked, &r.missed}) take(*v, size_t(next()));
  return r;
}

}  // namespace mbsdf
