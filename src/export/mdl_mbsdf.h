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
// interpolates trilinearly (held at the edges).
//
// What a runtime does with the data (the MDL SDK's prepare_mbsdfs_part and libbsdf's
// measured_sample): it evaluates ½ [f(θi, θo, Δφ) + f(θo, θi, Δφ)], takes each row's albedo from
// those values, and scales all light, reflected and transmitted, by the inverse of the largest row
// albedo of either part where that exceeds 1. A reciprocal BRDF is unchanged by that; a BTDF between
// media of different index is not (f(i→o)/ηo² = f(o→i)/ηi²): its lobe at θo ≠ θi is halved and
// mirrored to (θo, θi), its row albedos change (1.47 at 1° for frosted BK7) and the bound then dims
// every direction. So each part holds a symmetric table, the table's f (BsdfLookup, averaged over the
// incidence azimuth for an anisotropic table) made symmetric and scaled as d(θi) d(θo) f, with d
// chosen so that every row's albedo, summed as the runtime sums it, is the table's hemispherical
// integral on that side: the runtime reads it as it is, with the table's albedo from every direction.
// What that changes in a BTDF's lobe is measured (lobeChangeL1) and reported.
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

// What making one part symmetric with the table's row albedos did.
struct MbsdfBalance {
  double runtimeAlbedoError = 0;  // the largest relative error of a row albedo a runtime would have had
  double residual = 0;            // the largest relative error of a row albedo left after balancing
  double lobeChangeL1 = 0;        // L1 of the stored part's difference from the table's f / L1
};

struct MbsdfFile {
  std::string bytes;
  bool transmission = false;         // the file holds a BTDF part
  bool anisotropic = false;          // the table is not isotropic
  std::vector<double> azimuths_deg;  // the incidence azimuths the file averages over
  double anisotropyL1 = 0;           // anisotropic table: L1 of the table's difference from its azimuthal mean / L1
  MbsdfBalance reflectionBalance, transmissionBalance;
  int negativeClamped = 0, values = 0;
};

// Light from above the surface: the reflected side, and the transmitted side when the model holds
// transmitted light. Throws InputError when the table holds no incidence from above or a slice is
// unfinished.
MbsdfFile mbsdfFile(const BsdfFileReader& file, const BsdfLookup& lookup, const MbsdfExport& options,
                    const std::string& description);

}  // namespace mbsdf
