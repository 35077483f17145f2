#include "scattering/wave_estimator.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "scattering/tile_result.h"

#include "scattering/area_estimator.h"
#include "scattering/fft_estimator.h"
#include "scattering/orders_estimator.h"
#include "scattering/paper_estimator.h"

namespace mbsdf {

std::string waveEstimatorName(WaveEstimatorKind k) {
  switch (k) {
    case WaveEstimatorKind::Area:
      return "area";
    case WaveEstimatorKind::Paper:
      return "paper";
    case WaveEstimatorKind::Orders:
      return "orders";
    case WaveEstimatorKind::Exact:
      return "exact";
    case WaveEstimatorKind::Fft:
      return "fft";
  }
  return "?";
}

std::optional<WaveEstimatorKind> parseWaveEstimator(std::string_view name) {
  for (WaveEstimatorKind k : kWaveEstimatorKinds)
    if (waveEstimatorName(k) == name) return k;
  return std::nullopt;
}

WaveEstimatorKind waveEstimatorKind(std::string_view name) {
  if (const auto k = parseWaveEstimator(name)) return *k;
  throw std::invalid_argument("unknown wave estimator '" + std::string(name) + "'");
}

std::unique_ptr<WaveEstimator> makeWaveEstimator(const WaveContext& ctx) {
  switch (ctx.settings.estimator) {
    case WaveEstimatorKind::Area:
      return std::make_unique<AreaWaveEstimator>(ctx);
    case WaveEstimatorKind::Paper:
      return std::make_unique<PaperWaveEstimator>(ctx);
    case WaveEstimatorKind::Orders:
      return std::make_unique<OrdersWaveEstimator>(ctx);
    case WaveEstimatorKind::Exact:
      return std::make_unique<OrdersWaveEstimator>(ctx, OrderAmplitudes::Exact);
    case WaveEstimatorKind::Fft:
      return makeFftWaveEstimator(ctx);
  }
  throw std::logic_error("makeWaveEstimator: no such estimator");
}

void addWaveComponents(TileResult& tile, const WaveTileResult& wave, bool incoherent, bool lost) {
  const size_t n = size_t(tile.nLambda) * tile.nBins;
  auto combine = [&](Component out, const std::vector<double>& a, const std::vector<double>& ae, Component sub) {
    const auto& b = tile.value[int(sub)];
    const auto& be = tile.stdError[int(sub)];
    if (a.size() != n || b.size() != n) throw std::logic_error("addWaveComponents: size mismatch");
    auto& v = tile.value[int(out)];
    auto& e = tile.stdError[int(out)];
    v.resize(n);
    e.resize(n);
    for (size_t i = 0; i < n; ++i) {
      if (!wave.computed.empty() && !wave.computed[i % size_t(tile.nBins)]) {
        v[i] = e[i] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      v[i] = a[i] - b[i];
      e[i] = std::sqrt(ae[i] * ae[i] + be[i] * be[i]);
    }
  };
  if (incoherent) combine(Component::Incoherent, wave.fws, wave.fwsErr, Component::Coherent);
  if (lost) combine(Component::Lost, wave.pmsk, wave.pmskErr, Component::GeoMasked);
}

}  // namespace mbsdf
