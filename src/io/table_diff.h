// What differs between two tables of the same grid — a designed and a produced surface, two seeds,
// two estimators — and whether it differs beyond the noise both files state (`microbsdf diff`).
// Per incidence slice and component:
//   energy   Σ_b f_b Ω⊥_b of each hemisphere, per wavelength, from /stats with their standard errors:
//            ΔE and z = ΔE / √(σ_A² + σ_B²);
//   table    L1 = Σ |f_B − f_A| Ω⊥ / Σ f_A Ω⊥ over bins and rows, beside the L1 that noise alone would
//            give, √(2/π) Σ √(σ_A² + σ_B²) Ω⊥ / Σ f_A Ω⊥ (the mean of |N(0, σ²)|), and the chi-square of
//            the bins' z-scores as a z-score of its own, (Σ z² − n)/√(2n): about N(0, 1) when the two
//            tables differ by noise only. Bins both files compute without error (a deterministic
//            estimator) count as differing when they differ by more than 1e-9 relative. Files that keep
//            errors per slice only are judged by their stated relative L1 errors instead.
//   colour   the reflected and transmitted colour (the hemispherical albedo's spectrum) under D65 as CIE
//            L*a*b* (Y = 1 for a perfect reflector), their CIEDE2000 difference (Sharma, Wu & Dalal
//            2005, by Little CMS) beside the ΔE00 a one-standard-error change of the albedo makes (the
//            noise's scale); per exit bin the colour of π f (its reflectance factor), the largest ΔE00
//            among the bins whose luminance differs beyond noise (|ΔY| > 4σ; without per-bin errors,
//            bins holding 1 % of the peak), and its direction;
//   lobe     the main lobe's direction (the mean direction of the reflected bins weighted by their
//            squared luminance) in each, and the angle between them.
// Refuses tables on different grids, wavelengths (or colour channels) or incidences, saying which.
#pragma once
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

#include "core/colour.h"
#include "io/bsdf_file.h"
#include "io/png_image.h"

namespace mbsdf {

// CIE 1976 L*a*b* of XYZ relative to a white point (Y = 1), and the CIEDE2000 difference.
Colour3 xyzToLab(const Colour3& xyz, const Colour3& white);
double deltaE2000(const Colour3& lab1, const Colour3& lab2);

struct ComponentDiff {
  std::string component;
  std::vector<double> energyA, energyB, energyZ;  // per wavelength, both hemispheres summed
  double l1 = 0, l1Noise = 0;                     // relative L1 of the difference and of noise alone
  double chi2Z = 0;                               // (Σ z² − n)/√(2n) over bins with an error
  size_t binsWithError = 0, binsBeyond4 = 0;      // |z| > 4 (expected 6.3e-5 n from noise)
  size_t deterministicDiffering = 0;              // bins without error in both that differ
  bool perSliceErrors = false;
  bool beyondNoise = false;
};

struct SliceDiff {
  int incidence = 0;
  double theta_deg = 0, phi_deg = 0;
  std::vector<ComponentDiff> components;
  bool colour = false;  // the colour entries below are set (visible wavelengths)
  double deltaE00Reflected = 0, deltaE00Transmitted = 0;
  double deltaE00ReflectedNoise = 0, deltaE00TransmittedNoise = 0;  // ΔE00 of a one-standard-error change
  double maxBinDeltaE00 = 0, maxBinTheta_deg = 0, maxBinPhi_deg = 0;
  double lobeA_theta = 0, lobeA_phi = 0, lobeB_theta = 0, lobeB_phi = 0, lobeShift_deg = 0;
};

struct TableDiff {
  std::string fileA, fileB;
  std::vector<std::string> onlyInA, onlyInB;  // components one file lacks
  std::vector<SliceDiff> slices;
  bool beyondNoise() const;
  std::string text() const;
  std::string csv() const;
  nlohmann::json json() const;
};

// Compares every slice finished in both files. Throws InputError when the grids, the rows
// (wavelengths or colour channels) or the incidences differ.
TableDiff diffTables(const BsdfFileReader& a, const BsdfFileReader& b, const std::string& nameA,
                     const std::string& nameB);

// Both slices (false colour, log2 of the reflected f) and the z-score map of their difference
// (diverging, ±5), side by side with labels, for incidence index `inc` and one model or component.
RgbImage diffImage(const BsdfFileReader& a, const BsdfFileReader& b, int inc, const std::string& model, int size);

}  // namespace mbsdf
