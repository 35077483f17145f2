// NVIDIA's measured BSDF file (`.mbsdf`, "NVIDIA ARC MBSDF V1"), the `bsdf_measurement` resource of
// MDL materials (Iray, Omniverse and other MDL renderers; the MDL specification, appendix on measured
// BSDF data), written from a stored table: the one renderer format that also holds a BTDF.
//
// Layout: the line "NVIDIA ARC MBSDF V1", metadata lines `KEY="value"`, then per part the line
// `MBSDF_DATA_REFLECTION=` or `MBSDF_DATA_TRANSMISSION=` and, little-endian, uint32 type (0 scalar,
// 1 RGB), uint32 nθ, uint32 nφ and nθ·nθ·nφ values (float32, three per value for RGB), index
// (θi · nθ + θo) · nφ + Δφ; the file ends after the last part. The data are isotropic: f (1/sr) of
// the incidence angle θi, the exit angle θo (from the normal on the reflected side, from the
// opposite normal on the transmitted side) and the azimuth difference Δφ = |φo − φi| ∈ [0, π]
// (0: towards the incidence's side), each on cells of equal width whose centres hold the values,
// as the MDL SDK's runtime places them: θ at (k + ½) π/2nθ, Δφ at (k + ½) π/nφ; between them it
// interpolates trilinearly (held at the edges). Values are the table's (BsdfLookup, averaged over the
// incidence azimuth for an anisotropic table), each incidence's row scaled so that its albedo, summed
// as the runtime sums it, is the table's hemispherical integral on that side.
//
// MDL runtimes use ½ [f(θi, θo, Δφ) + f(θo, θi, Δφ)], which is f itself for a reciprocal BRDF but not
// for a BTDF between media of different index (there f(i→o)/ηo² = f(o→i)/ηi², and the table's
// transmitted lobe at θo ≠ θi is mirrored to (θo, θi) at half height). The file holds the BTDF as the
// table computed it, so a runtime that does not symmetrise gets it right; for one that does, the
// exporter says how far the symmetrised table is from the true one.
#pragma once
#include <string>
#include <vector>

#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"

namespace mbsdf {

struct MbsdfExport {
  enum class Colour { scalar, rgb };
  Colour colour = Colour::scalar;
  int wavelength = 0;  // scalar: index into the table's wavelengths
  int nTheta = 45, nPhi = 90;
};

struct MbsdfFile {
  std::string bytes;
  bool transmission = false;         // the file holds a BTDF part
  bool anisotropic = false;          // the table is not isotropic
  std::vector<double> azimuths_deg;  // the incidence azimuths the file averages over
  double anisotropyL1 = 0;           // anisotropic table: L1 of the table's difference from its azimuthal mean / L1
  double btdfSymmetrisationL1 = 0;  // L1 of ½[f + fᵀ] − f over the BTDF / L1 (what a symmetrising runtime changes)
  double energyCorrection = 0;      // the largest relative scale that made a row's albedo the table's
  int negativeClamped = 0, values = 0;
};

// Light from above the surface: the reflected side, and the transmitted side when the model holds
// transmitted light. Throws InputError when the table holds no incidence from above or a slice is
// unfinished.
MbsdfFile mbsdfFile(const BsdfFileReader& file, const BsdfLookup& lookup, const MbsdfExport& options,
                    const std::string& description);

}  // namespace mbsdf
