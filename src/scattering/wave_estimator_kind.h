// The names of the wave estimators (docs/estimators.md: area, paper, orders, exact, fft) as a closed
// set, parsed once where a job or a command line names one; wave_estimator.h builds them.
#pragma once
#include <optional>
#include <string>
#include <string_view>

namespace mbsdf {

// The wave estimators (docs/estimators.md), a closed set parsed once from its name.
enum class WaveEstimatorKind { Area, Paper, Orders, Exact, Fft };
inline constexpr WaveEstimatorKind kWaveEstimatorKinds[] = {WaveEstimatorKind::Area, WaveEstimatorKind::Paper,
                                                            WaveEstimatorKind::Orders, WaveEstimatorKind::Exact,
                                                            WaveEstimatorKind::Fft};
std::string waveEstimatorName(WaveEstimatorKind k);
// Whether the estimator has no sampling noise (`exact`, `fft`): its cost and result do not depend on
// wave_samples_per_bin.
constexpr bool deterministicEstimator(WaveEstimatorKind k) {
  return k == WaveEstimatorKind::Exact || k == WaveEstimatorKind::Fft;
}
// The estimator of that name, or none.
std::optional<WaveEstimatorKind> parseWaveEstimator(std::string_view name);
// The estimator of that name; std::invalid_argument for any other.
WaveEstimatorKind waveEstimatorKind(std::string_view name);

}  // namespace mbsdf
