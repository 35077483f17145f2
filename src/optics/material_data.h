// Tabulated optical constants (see material_data.cpp for the source).
#pragma once
#include <vector>

namespace mbsdf::data {
extern const std::vector<double> kMetalLambda_nm;
extern const std::vector<double> kAgEta, kAgK, kAlEta, kAlK, kAuEta, kAuK, kCuEta, kCuK;
}  // namespace mbsdf::data
