// Zemax OpticStudio's tabular BSDF file (the BSDF Data Interchange format of Radiant Imaging, read by
// OpticStudio's tabular BSDF scattering model; Rykowski 2008, "BSDF Data Interchange File Format
// Specification"), written from a stored table for optical-design and stray-light tools.
//
// The format tabulates f about the specular direction: for every sample rotation and angle of
// incidence, a block "TIS <value>" and one row per scatter azimuth of f (1/sr) at every scatter
// radial angle. Radial angle r is the angle from the specular direction s; azimuth a turns about s
// from e1, the direction from s towards the surface normal (at normal incidence the limit of it as
// the incidence tilts towards its azimuth), counter-clockwise seen from outside the surface
// (e2 = s × e1): ωo = cos r s + sin r (cos a e1 + sin a e2); directions below the horizon hold 0.
// AngleOfIncidence is θi (the specular angle of a reflection); SampleRotation is the incidence
// azimuth φi of the table (rotating the sample by it brings that incidence into the instrument's
// plane of incidence; an isotropic table — the file's `symmetry` attribute — writes its first azimuth
// only): one rotation writes `Symmetry Asymmetrical`, several `ASymmetrical4D` (the format
// description's spelling). TIS is the table's own hemispherical integral Σ f Ω⊥ over the reflected
// bins — all the model reflects, its specular lobe included (the table holds no separate specular
// ray). f between the table's bins comes from BsdfLookup (bilinear between bin centres).
//
// One file holds one wavelength (SpectralContent Monochrome) or the CIE tristimulus values of all of
// them (SpectralContent XYZ: a TristimulusX, TristimulusY and TristimulusZ data set, each weighted as
// `slice`'s colours are, Y of a flat spectrum 1), and one side: reflected (ScatterType BRDF) or
// transmitted (BTDF). For a BTDF the format's centre is the direct transmission — here the refracted
// direction t of Snell's law with `eta` — and AngleOfIncidence holds its angle from the opposite
// normal θt (the format's "specular transmitted angle"); azimuth 0 points from t towards that
// normal, e2 = t × e1. The table's incidences must form a θ × φ grid (every listed θ at every listed
// φ, as incidence = "all" on a theta-phi grid does).
#pragma once
#include <string>
#include <vector>

#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"

namespace mbsdf {

struct ZemaxExport {
  int wavelength = 0;               // index into the table's wavelengths (Monochrome)
  bool xyz = false;                 // SpectralContent XYZ: CIE X, Y, Z of every wavelength, three data sets
  bool transmission = false;        // ScatterType BTDF: the transmitted side
  double eta = 1.0;                 // BTDF: the lower medium's index over the upper's (real parts), for Snell
  std::vector<double> radial_deg;   // scatter radial angles, ascending from 0
  std::vector<double> azimuth_deg;  // scatter azimuths, ascending in [0, 360)
};

// The default angles: radial 0, 0.25, 0.5, 0.75, 1, 2, …, 180 degrees; azimuth every 5 degrees.
ZemaxExport defaultZemaxExport();

// The file's text. Throws InputError when the incidences are not a θ × φ grid above the surface, a
// slice is unfinished, or (BTDF) an incidence is totally reflected.
std::string zemaxBsdfText(const BsdfFileReader& file, const BsdfLookup& lookup, const ZemaxExport& options,
                          const std::string& source);

}  // namespace mbsdf
