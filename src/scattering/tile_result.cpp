#include "scattering/tile_result.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "core/direction_grid.h"

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
  std::memcpy(&s, &waveSamples, sizeof s);
  b.push_back(s);
  b.push_back(seconds);
  b.push_back(rounds);
  b.push_back(double(int(samplingStop)));
  b.push_back(multipleCheck);
  b.push_back(multipleReenabled ? 1.0 : 0.0);
  b.push_back(diffractionCheck);
  b.push_back(diffractionReenabled ? 1.0 : 0.0);
  for (int c = 0; c < kComponentCount; ++c) {
    b.push_back(double(value[c].size()));
    b.insert(b.end(), value[c].begin(), value[c].end());
    b.insert(b.end(), stdError[c].begin(), stdError[c].end());
  }
  for (const auto* v : {&truncated, &leaked, &missed}) {
    b.push_back(double(v->size()));
    b.insert(b.end(), v->begin(), v->end());
  }
  for (const auto& m : pathMoments) {
    b.push_back(double(m.size()));
    b.insert(b.end(), m.begin(), m.end());
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
  s = next();
  std::memcpy(&r.waveSamples, &s, sizeof s);
  r.seconds = next();
  r.rounds = int(next());
  r.samplingStop = SamplingStop(int(next()));
  r.multipleCheck = next();
  r.multipleReenabled = next() != 0;
  r.diffractionCheck = next();
  r.diffractionReenabled = next() != 0;
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
  for (auto& m : r.pathMoments) take(m, size_t(next()));
  return r;
}

void TileResult::poolPaths(const TileResult& more) {
  if (more.nLambda != nLambda || more.nBins != nBins) throw std::logic_error("poolPaths: different tables");
  const double na = double(samples), nb = double(more.samples), n = na + nb;
  for (int c = 0; c < kComponentCount; ++c) {
    if (more.value[c].empty()) continue;
    auto& v = value[c];
    auto& e = stdError[c];
    for (size_t i = 0; i < v.size(); ++i) {
      // Per-path sums recovered from mean and standard error: s1 = N m, s2 = N var + s1²/N with the
      // (N−1) normalisation of the single-run estimator (PathTally).
      auto sums = [](double N, double m, double se, double* s1, double* s2) {
        const double var = se * se * N;  // per-path variance (in units of f)
        *s1 = N * m;
        *s2 = var * (N - 1) + *s1 * *s1 / N;
      };
      double a1, a2, b1, b2;
      sums(na, v[i], e[i], &a1, &a2);
      sums(nb, more.value[c][i], more.stdError[c][i], &b1, &b2);
      const double s1 = a1 + b1, s2 = a2 + b2;
      v[i] = s1 / n;
      e[i] = std::sqrt(std::max(0.0, (s2 - s1 * s1 / n) / (n - 1)) / n);
    }
  }
  for (auto [mine, theirs] :
       {std::pair{&truncated, &more.truncated}, std::pair{&leaked, &more.leaked}, std::pair{&missed, &more.missed}})
    for (size_t l = 0; l < mine->size() && l < theirs->size(); ++l)
      (*mine)[l] = ((*mine)[l] * na + (*theirs)[l] * nb) / n;
  for (int c = 0; c < kComponentCount; ++c)  // means over all paths
    for (size_t i = 0; i < pathMoments[c].size() && i < more.pathMoments[c].size(); ++i)
      pathMoments[c][i] = (pathMoments[c][i] * na + more.pathMoments[c][i] * nb) / n;
  samples += more.samples;
  rays += more.rays;
  seconds += more.seconds;
  rounds += more.rounds;
}

std::vector<double> TileResult::pathEnergyStdError(const std::vector<Component>& comps, int side) const {
  for (Component c : comps)
    if (pathMoments[int(c)].empty()) return {};
  std::vector<double> se(size_t(nLambda), 0.0);
  if (samples < 2) return se;
  for (int l = 0; l < nLambda; ++l) {
    double m1 = 0, m2 = 0;
    for (Component c : comps)
      for (int sd = 0; sd < 2; ++sd) {
        if (side >= 0 && sd != side) continue;
        m1 += pathMoments[int(c)][size_t((sd * 2 + 0) * nLambda + l)];
        m2 += pathMoments[int(c)][size_t((sd * 2 + 1) * nLambda + l)];
      }
    const double n = double(samples);
    se[size_t(l)] = std::sqrt(std::max(0.0, m2 - m1 * m1) * n / (n - 1) / n);
  }
  return se;
}

std::vector<double> energyBalance(const TileResult& r, const DirectionGrid& grid, const std::vector<Component>& model,
                                  bool lossless) {
  std::vector<double> b(size_t(r.nLambda), -1.0);
  for (int l = 0; l < r.nLambda; ++l) {
    for (Component c : model)
      if (r.has(c))
        for (int bin = 0; bin < r.nBins; ++bin) b[size_t(l)] += r.at(c, l, bin) * grid.projectedSolidAngle(bin);
    for (const auto* v : {&r.truncated, &r.leaked, &r.missed})
      if (size_t(l) < v->size()) b[size_t(l)] += (*v)[size_t(l)];
    if (!lossless) b[size_t(l)] = std::max(0.0, b[size_t(l)]);
  }
  return b;
}

std::vector<double> energyStdError(const TileResult& r, Component c, int side, const DirectionGrid& grid) {
  std::vector<double> se = r.pathEnergyStdError({c}, side);
  if (!se.empty()) return se;
  // No path moments: the facet sum's per-bin error bounds add up (a bound); a wave estimator's
  // per-bin errors add in quadrature (bins estimated independently).
  const bool bound = c == Component::Coherent;
  se.assign(size_t(r.nLambda), 0.0);
  for (int l = 0; l < r.nLambda; ++l) {
    double sum = 0;
    for (int b = 0; b < r.nBins; ++b) {
      if (grid.isUpper(b) != (side == 0)) continue;
      const double e = r.stdError[int(c)][size_t(l) * r.nBins + b] * grid.projectedSolidAngle(b);
      if (std::isfinite(e)) sum += bound ? std::abs(e) : e * e;
    }
    se[size_t(l)] = bound ? sum : std::sqrt(sum);
  }
  return se;
}

std::vector<double> energyBalanceStdError(const TileResult& r, const DirectionGrid& grid,
                                          const std::vector<Component>& model) {
  std::vector<Component> traced;
  for (Component c : model)
    if (r.has(c) && !r.pathMoments[int(c)].empty()) traced.push_back(c);
  std::vector<double> var(size_t(r.nLambda), 0.0);
  if (!traced.empty()) {
    const std::vector<double> se = r.pathEnergyStdError(traced, -1);
    for (int l = 0; l < r.nLambda; ++l) var[size_t(l)] = se[size_t(l)] * se[size_t(l)];
  }
  for (Component c : model) {
    if (!r.has(c) || (r.samples > 0 && (c == Component::Coherent || c == Component::Multiple))) continue;
    for (int side : {0, 1}) {
      const std::vector<double> se = energyStdError(r, c, side, grid);
      for (int l = 0; l < r.nLambda; ++l) var[size_t(l)] += se[size_t(l)] * se[size_t(l)];
    }
  }
  for (double& v : var) v = std::sqrt(v);
  return var;
}

std::vector<double> relativeError(const TileResult& r, const std::vector<Component>& comps, const DirectionGrid& grid) {
  std::vector<double> out(size_t(r.nLambda), 0.0);
  for (int l = 0; l < r.nLambda; ++l) {
    double var = 0, mass = 0;
    for (int b = 0; b < r.nBins; ++b) {
      const double op = grid.projectedSolidAngle(b);
      double f = 0;
      for (Component c : comps) {
        if (!r.has(c)) continue;
        const size_t i = size_t(l) * size_t(r.nBins) + size_t(b);
        f += r.value[int(c)][i];
        var += std::pow(r.stdError[int(c)][i] * op, 2);
      }
      mass += std::abs(f) * op;
    }
    out[size_t(l)] = mass > 0 ? std::sqrt(var) / mass : 0.0;
  }
  return out;
}

SliceL1 sliceL1(const std::vector<double>& f, const std::vector<double>& err, int nLambda, const DirectionGrid& grid,
                double errorFactor) {
  const int nB = grid.binCount();
  SliceL1 out{std::vector<double>(size_t(nLambda), 0.0), std::vector<double>(size_t(nLambda), 0.0)};
  if (f.size() != size_t(nLambda) * size_t(nB) || err.size() != f.size())
    throw std::logic_error("sliceL1: table size mismatch");
  for (int l = 0; l < nLambda; ++l)
    for (int b = 0; b < nB; ++b) {
      const size_t i = size_t(l) * size_t(nB) + size_t(b);
      if (!std::isfinite(f[i]) || !std::isfinite(err[i])) continue;
      const double op = grid.projectedSolidAngle(b);
      out.deviation[size_t(l)] += errorFactor * std::abs(err[i]) * op;
      out.mass[size_t(l)] += std::abs(f[i]) * op;
    }
  return out;
}

}  // namespace mbsdf
