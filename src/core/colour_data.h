// CIE 1931 2° colour-matching functions (see colour_data.cpp for the source).
#pragma once
#include <vector>

namespace mbsdf::data {
extern const double kCieLambdaStart_nm, kCieLambdaStep_nm;
extern const std::vector<double> kCieX, kCieY, kCieZ;
}  // namespace mbsdf::data
