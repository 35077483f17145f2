// CIE 1931 2° colour-matching functions and the CIE standard illuminant D65 (see colour_data.cpp for
// the sources).
#pragma once
#include <vector>

namespace mbsdf::data {
extern const double kCieLambdaStart_nm, kCieLambdaStep_nm;
extern const std::vector<double> kCieX, kCieY, kCieZ;
extern const double kD65LambdaStart_nm, kD65LambdaStep_nm;
extern const std::vector<double> kD65;
}  // namespace mbsdf::data
