#include "io/noise_rounding.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace mbsdf {

double roundToSignificantBits(double x, int bits) {
  if (x == 0 || !std::isfinite(x)) return x;
  if (bits < 1) throw std::invalid_argument("roundToSignificantBits: at least one bit");
  if (bits >= 53) return x;
  // x = m 2^e with |m| in [1, 2): the last kept place is 2^(e - bits + 1). Scaling by powers of two
  // is exact, and nearbyint rounds to nearest even in the default rounding mode.
  const int place = std::ilogb(x) - bits + 1;
  return std::ldexp(std::nearbyint(std::ldexp(x, -place)), place);
}

double roundToNoise(double x, double sigma) {
  if (x == 0 || !std::isfinite(x) || !(sigma > 0) || !std::isfinite(sigma)) return x;
  // The last kept place 2^p with 2^p <= sigma / kNoiseSteps: p = floor(log2(sigma / kNoiseSteps)),
  // i.e. ilogb of it; the significant bits from x's leading place e down to p are e - p + 1.
  const int place = std::ilogb(sigma / kNoiseSteps);
  const int bits = std::clamp(std::ilogb(x) - place + 1, 1, 53);
  return roundToSignificantBits(x, bits);
}

void roundRowToNoise(std::vector<double>& values, const std::vector<double>& sigma) {
  if (sigma.empty()) return;
  if (sigma.size() != values.size()) throw std::logic_error("roundRowToNoise: rows of different sizes");
  for (size_t k = 0; k < values.size(); ++k) values[k] = roundToNoise(values[k], sigma[k]);
}

void roundErrorRow(std::vector<double>& sigma) {
  for (double& s : sigma) s = roundToSignificantBits(s, kErrorBits);
}

void roundEstimate(double& f, double& sigma) {
  f = roundToNoise(f, sigma);
  sigma = roundToSignificantBits(sigma, kErrorBits);
}

}  // namespace mbsdf
