// Binning of directions on the full sphere (docs/physics.md §2). Bin index = hemisphere * binsPerHemisphere
// + local index, upper hemisphere (z >= 0) first. Two layouts, a closed set of value types:
//  - ThetaPhiGrid: n_theta x n_phi bins per hemisphere, uniform in theta on [0, pi/2] and phi on
//    [0, 2 pi) (the paper's tabulation, 75 x 300).
//  - DiskGrid: orthographic projection of the hemisphere onto the unit disk, W x H pixels over
//    [-1, 1]^2 (the paper's path-tracing image, Eq. 11); pixels outside the disk are empty bins.
#pragma once
#include <atomic>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "core/rng.h"
#include "core/vecmath.h"

namespace mbsdf {

// An incidence of a job: the direction asked for and the sphere bin of the grid it lies in.
struct IncidenceDirection {
  double theta_deg = 0, phi_deg = 0;  // requested (or bin centre for "all")
  int bin = 0;                        // sphere bin of the grid
};

struct ThetaPhiGrid {
  int nTheta = 75, nPhi = 300;
};
struct DiskGrid {
  int width = 64, height = 64;
};

// A direction sampled inside a bin, with the Monte Carlo weight that makes the estimator of a
// cosine-weighted average over the bin unbiased.
struct DirectionSample {
  Vec3 w;
  double weight = 1.0;
};

// A grid's bin measures, per bin of a hemisphere: solid angle, projected solid angle and, for a
// disk grid, the centroid (x, y) of pixel ∩ unit disk.
struct GridMeasures {
  std::vector<double> omega, omegaProj, centre;
};

class DirectionGrid {
 public:
  using Layout = std::variant<ThetaPhiGrid, DiskGrid>;
  explicit DirectionGrid(Layout layout);

  const Layout& layout() const { return layout_; }
  std::string kind() const;
  int binsPerHemisphere() const { return perHemisphere_; }
  int binCount() const { return 2 * perHemisphere_; }

  // Bin containing w (w need not be normalised). z == 0 goes to the upper hemisphere.
  int binOf(const Vec3& w) const;
  // Solid angle and projected solid angle (integral of |cos theta|) of a bin.
  double solidAngle(int bin) const { return measures().omega[size_t(bin % perHemisphere_)]; }
  double projectedSolidAngle(int bin) const { return measures().omegaProj[size_t(bin % perHemisphere_)]; }
  bool isUpper(int bin) const { return bin < perHemisphere_; }
  // Representative direction (bin centre in the grid's own parametrisation).
  Vec3 centre(int bin) const;
  // Uniform in solid angle inside the bin; weight = |cos theta| / mean |cos theta| over the bin.
  DirectionSample sampleUniform(int bin, double u1, double u2) const;
  // Density proportional to |cos theta| inside the bin (weight 1 for cosine-weighted averages).
  DirectionSample sampleCosine(int bin, double u1, double u2) const;
  // The two samplers above with their two numbers drawn from `s` in the order every estimator
  // uses (the azimuth's u2 first), so that a sample's numbers do not depend on the compiler.
  DirectionSample sampleUniform(int bin, Sampler& s) const;
  DirectionSample sampleCosine(int bin, Sampler& s) const;
  // Bounding box of the bin's directions projected on the xy plane (x = sin θ cos φ, y = sin θ sin φ).
  void xyBounds(int bin, double* xmin, double* xmax, double* ymin, double* ymax) const;
  // Whether the bin reaches normal incidence or the horizon of its hemisphere: a theta-phi grid's
  // first and last rings, a disk grid's pixels at the disk's centre and those its rim cuts.
  bool atPoleOrHorizon(int bin) const;
  // Bin for an incidence direction given in degrees (theta in [0, 180], phi any).
  int binOfAngles(double theta_deg, double phi_deg) const;
  // Theta-phi layout: sin θ of ring edge t (t = 0 … n_theta), the radius of that edge's circle in
  // the xy plane of directions.
  double ringEdgeSin(int t) const { return ringSin_[size_t(t)]; }

 private:
  Layout layout_;
  int perHemisphere_ = 0;
  // The measures: a theta-phi grid's in closed form when it is made; a disk grid's by quadrature
  // (about 0.1 s of one core for 128 x 128), from the process's cache when first asked, so that
  // making a grid only to find bins (as reading a job with listed incidences does) costs nothing.
  class MeasuresPtr {  // an atomic pointer that copies its value
   public:
    MeasuresPtr() = default;
    MeasuresPtr(const MeasuresPtr& o) : p_(o.load()) {}
    MeasuresPtr& operator=(const MeasuresPtr& o) {
      store(o.load());
      return *this;
    }
    const GridMeasures* load() const { return p_.load(std::memory_order_acquire); }
    void store(const GridMeasures* p) const { p_.store(p, std::memory_order_release); }

   private:
    mutable std::atomic<const GridMeasures*> p_{nullptr};
  };
  std::shared_ptr<const GridMeasures> thetaPhiMeasures_;
  MeasuresPtr measures_;
  const GridMeasures& measures() const {
    const GridMeasures* m = measures_.load();
    return m ? *m : diskMeasuresNow();
  }
  const GridMeasures& diskMeasuresNow() const;
  std::vector<double> ringSin_;  // theta-phi layout: sin of the ring edges, t · (π/2) / n_theta
  // Theta-phi layout: the ring of every cell of |z|, and the azimuth bin of every octant's cell of
  // the ratio min(|x|, |y|) / max(|x|, |y|), where a cell lies inside one (0xffff where an edge
  // crosses it; direction_grid.cpp, thetaPhiBin). Empty for grids too fine for 16-bit bin numbers.
  std::vector<uint16_t> thetaCells_, phiCells_;
  int thetaPhiBin(const ThetaPhiGrid& g, const Vec3& w, bool normalised) const;
};

namespace detail {
// Polynomial arccosine and arctangent for the grid's fast bin search (Abramowitz & Stegun 1964,
// Eqs. 4.4.46 and 4.4.49), within kApproxAngleError radians on their domains; exposed for the test
// that checks that bound.
constexpr double kApproxAngleError = 1e-7;
double approxAcos(double x);  // x in [0, 1]
double approxAtan(double x);  // x in [0, 1]
}  // namespace detail

}  // namespace mbsdf
