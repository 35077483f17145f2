#include "scattering/wave_estimator.h"

#include <stdexcept>

#include "scattering/area_estimator.h"
#include "scattering/orders_estimator.h"
#include "scattering/paper_estimator.h"

namespace mbsdf {

std::unique_ptr<WaveEstimator> makeWaveEstimator(const WaveContext& ctx) {
  if (ctx.settings.estimator == "area") return std::make_unique<AreaWaveEstimator>(ctx);
  if (ctx.settings.estimator == "paper") return std::make_unique<PaperWaveEstimator>(ctx);
  if (ctx.settings.estimator == "orders") return std::make_unique<OrdersWaveEstimator>(ctx);
  throw std::invalid_argument("unknown wave estimator '" + ctx.settings.estimator + "'");
}

}  // namespace mbsdf
