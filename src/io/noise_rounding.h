// Values rounded to their noise (docs/output.md "Rounding to the noise"): a Monte Carlo estimate
// f ± σ holds no information in the mantissa bits far below σ, yet those bits are random and are
// what keeps a compressed table large. Keeping only the bits a value's own error leaves meaningful
// is the "bit rounding" of Klöwer, Razinger, Dominguez, Düben & Palmer (2021, Nature Computational
// Science 1, 713), which netCDF-C 4.9 ships as its quantize mode.
#pragma once
#include <vector>

namespace mbsdf {

// A value keeps the binary digits whose last place is at most σ / kNoiseSteps: rounded to nearest,
// it moves by at most σ / (2 kNoiseSteps), and its rounding error's variance (uniform over the last
// place) is at most σ² / (12 kNoiseSteps²), 0.03 % of its own.
inline constexpr double kNoiseSteps = 16;
// A standard error keeps this many significant bits (relative rounding at most 2^-9): an error
// estimated from n hits is itself uncertain by about 1/√(2n), far coarser.
inline constexpr int kErrorBits = 8;

// x rounded to nearest (ties to even) at `bits` significant binary digits (bits >= 1). Zero, and
// what is not finite, unchanged.
double roundToSignificantBits(double x, int bits);

// x rounded to the coarsest power-of-two place not above sigma / kNoiseSteps, keeping at least one
// significant bit (a value never becomes zero) and at most 53. Unchanged where sigma is zero,
// negative or not finite (a deterministic value keeps every bit).
double roundToNoise(double x, double sigma);

// A stored table's row: values[k] rounded to noise by sigma[k] (same layout; sigma may be
// empty: unchanged).
void roundRowToNoise(std::vector<double>& values, const std::vector<double>& sigma);

// A row of standard errors rounded to kErrorBits significant bits.
void roundErrorRow(std::vector<double>& sigma);

// One estimate f ± sigma as a table stores it: f rounded to the noise of its unrounded error,
// then the error to kErrorBits bits.
void roundEstimate(double& f, double& sigma);

}  // namespace mbsdf
