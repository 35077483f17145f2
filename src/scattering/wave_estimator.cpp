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

std::unique_ptr<WaveEstimator> makeWaveEstimator(const WaveContext& ctx) {
  if (ctx.settings.estimator == "area") return std::make_unique<AreaWaveEstimator>(ctx);
  if (ctx.settings.estimator == "paper") return std::make_unique<PaperWaveEstimator>(ctx);
  if (ctx.settings.estimator == "orders") return std::make_unique<OrdersWaveEstimator>(ctx);
  if (ctx.settings.estimator == "exact") return std::make_unique<OrdersWaveEstimator>(ctx, OrderAmplitudes::Exact);
  if (ctx.settings.estimator == "fft") return makeFftWaveEstimator(ctx);
  throw std::invalid_argument("unknown wave estimator '" + ctx.settings.estimator + "'");
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
