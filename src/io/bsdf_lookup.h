// Values of a stored table between its bins: f(ωi → ωo) of one model (GS, GM, WS, WM or a
// component) at one wavelength, for the exporters and `microbsdf eval`. The table holds bin averages
// (docs/output.md); a value between bins is interpolated bilinearly between the centres of the four
// nearest bins of the exit direction's hemisphere — in (θ, φ) on a theta-phi grid (φ periodic; inside
// the first ring's centres towards the first ring's mean at the pole, where all azimuths meet; held at
// the last ring's centres towards the horizon), in (x, y) on the disk grid
// (pixels outside the disk, which hold no directions, get no weight). Between incidences the same
// rule applies to the incidence bins when the table holds every bin of the incidence's hemisphere
// (incidence = "all"), otherwise the nearest incidence in angle is used (`nearestOnly`). An isotropic
// table (tableIsIsotropic) instead turns the pair of directions about the normal so that ωi lies at
// the azimuth of an incidence it holds at each θ — exact for such a table — and interpolates linearly
// in θi between the two nearest such rings of incidences (held beyond the first and last).
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "core/vecmath.h"
#include "io/bsdf_file.h"

namespace mbsdf {

// A grid's continuous coordinates of a unit direction on its hemisphere, the integers at the bins'
// centres: (ring, sector) on a theta-phi grid (u < 0 inside the first ring's centres, v in
// [−½, nφ − ½)), (column, row) on the disk grid. The interpolation below is bilinear in them.
struct GridCoords {
  double u, v;
};
GridCoords gridCoords(const DirectionGrid& grid, const Vec3& w);
// The bin at integer coordinates (i along u, j along v; j periodic on a theta-phi grid) of the upper
// or lower hemisphere; −1 outside the grid.
int binAtCoords(const DirectionGrid& grid, int i, int j, bool upper);

// The (bin, weight) pairs of the interpolation above at direction w (any length): the weights sum to
// 1, the bins lie on w's side and hold directions.
std::vector<std::pair<int, double>> interpolationWeights(const DirectionGrid& grid, const Vec3& w);

// Whether the table is the same at every incidence azimuth (the file's `symmetry` attribute says
// isotropic): its exporters then write one azimuth.
bool tableIsIsotropic(const BsdfFileReader& file);

class BsdfLookup {
 public:
  // Reads the finished slices of `model` as they are needed (InputError at once when the file lacks
  // one of its components). Not for use from several threads at once.
  BsdfLookup(const BsdfFileReader& file, const std::string& model);

  // The table's rows: its wavelengths, or its colour channels (BsdfFileReader::channelCount); "at
  // wavelength l" below means at row l.
  int wavelengthCount() const { return nL_; }
  // f of incidence slice `incidence` towards wo (any length, either hemisphere) at wavelength l.
  double eval(int incidence, const Vec3& wo, int l) const;
  // f(wi → wo) at wavelength l: between incidences as above. wi points away from the surface
  // towards the light; InputError when the table holds no incidence on wi's side.
  double eval(const Vec3& wi, const Vec3& wo, int l) const;
  // The rule between incidences made explicit: eval(wi, wo, l) = Σ weight · eval(incidence,
  // turnedAboutZ(wo, turn), l) over these (the weights sum to 1; turn is the angle about the normal by which
  // an isotropic table's pair of directions is turned onto the incidence's azimuth, else 0). Reads no
  // slice. InputError when the table holds no incidence on wi's side.
  struct IncidenceWeight {
    int incidence;
    double turn;
    double weight;
  };
  std::vector<IncidenceWeight> incidenceWeights(const Vec3& wi) const;
  // One incidence's slice, nλ × nBins (read from the file when first needed; InputError when the slice
  // is not finished). Callers on several threads read each slice once under their own lock first.
  const std::vector<double>& slice(int incidence) const;
  // Whether the table holds a finished incidence from above (below) the surface.
  bool holdsIncidencesFrom(bool above) const { return above ? hasUpper_ : hasLower_; }
  // Whether eval(wi, …) falls back to the nearest incidence (an anisotropic table without every bin).
  bool nearestOnly() const { return !allIncidenceBins_ && !isotropic_; }
  // How eval(wi, …) finds values between incidences, in words.
  const char* incidenceRule() const {
    return isotropic_          ? "turned onto the table's incidences and interpolated in theta (isotropic)"
           : allIncidenceBins_ ? "interpolated between incidence bins"
                               : "from the nearest slice";
  }
  // Σ_b f_b Ω⊥_b over one hemisphere of exit bins (upper: reflected for light from above): the
  // table's own hemispherical integral of slice `incidence` at wavelength l.
  double hemisphericalIntegral(int incidence, int l, bool upper) const;
  // The same for light from wi, between incidences as eval(wi, …) is.
  double hemisphericalIntegral(const Vec3& wi, int l, bool upper) const;
  const std::string& model() const { return model_; }

 private:
  const BsdfFileReader& file_;
  const DirectionGrid& grid_;
  std::string model_;
  int nL_ = 0, nB_ = 0;
  // Per incidence: nλ × nBins, read when first needed (a large table's eval touches a few slices).
  mutable std::vector<std::vector<double>> slices_;
  std::vector<int> incidenceOfBin_;  // incidence index of each bin, or −1
  bool allIncidenceBins_ = false;
  bool isotropic_ = false;
  struct Ring {
    double theta, phi;  // the incidence's angle from the normal of its side, and its azimuth (radians)
    int incidence;
  };
  std::vector<Ring> ringsUpper_, ringsLower_;  // ascending θ
  bool hasUpper_ = false, hasLower_ = false;   // incidences from above, from below
};

}  // namespace mbsdf
