// The order amplitudes of a periodic heightfield for every grating order at once, by FFT (the
// "integration in the Fourier domain" Falster et al. 2020 leave to future work).
//
// docs/physics.md §5 with the copy sum written by Poisson summation (orders_estimator.h) needs, per
// order G = 2π(a/Lx, b/Ly), the amplitude
//   Ĥ_G(q_z, k2) = Σ_T V_T (g_T A_T) e^{i (G·c_T,xy + q_z c_T,z)}
// summed over the facets T with the phase taken at the facet centroid c_T (the one-point rule,
// exact for the linear part of the phase; its error is O((κ·d)²/24) for the facet's edge vectors d
// and κ = G + q_z ∇h_T, small where the light goes, since stationary phase puts the power where
// κ ≈ 0). Over a flat facet the Kirchhoff factor is linear in k2 = n_o k0 ωo (kirchhoff.h):
//   reflection:   g A = (r − 1)(a·k1) − (r + 1)(a·k2)
//   transmission: g A = t (kt·m) A + t (a·k2)
// with the facet's area vector a = m A and r, t at the local angle of ωi, so g A = X + B·k2 with X
// and B = (Bx, By, Bz) fixed for a given ωi and wavelength. The q_z dependence sits in
// e^{i q_z (z − z̄)} only; it is interpolated between Chebyshev nodes q_n on the range of q_z the
// exit directions need (barycentric form; node count from the bandwidth Q·max|z − z̄|, error
// < 1e-7). Per node, each of the 4 fields x 2 polarisations x 2 facet orientations of the grid
// (the two triangles of a cell have their centroids on two lattices offset by (2/3, 1/3) and
// (1/3, 2/3) texel) is one 2-D FFT of the heightfield's size, which gives Ĥ for every G.
//
// Texels are split into r x r smaller facets of the same planes (r a power of 2) until they are
// below `maxTexel_um`: the one-point sum is periodic in G with period 2π/texel, so the texel must be
// well below λ / (n_i + n_o) for the propagating orders not to alias.
// Shadowing V_T (towards ωi) is one ray per facet centroid, shared by all wavelengths and nodes.
// Masking (towards ωo) is not in the tables: no facet can be masked or face away from an exit
// direction whose elevation exceeds the steepest facet slope (`maxSlope()`); below that the
// caller subtracts the masked facets' terms (`facetTerm`).
#pragma once
#include <tbb/enumerable_thread_specific.h>

#include <array>
#include <map>
#include <mutex>
#include <complex>
#include <cstdint>
#include <vector>

#include "core/fftw.h"
#include "core/vecmath.h"
#include "geometry/embree_scene.h"
#include "geometry/microgeometry.h"
#include "optics/material.h"
#include "scattering/wave_common.h"

namespace mbsdf {

// The texel the one-point rule needs: λ_min / (kFourierTexelsPerPeriod (n_i + n_o)), a fraction of
// the shortest period 2π/|G| among the propagating orders; and the power-of-2 split that gets a
// heightfield's texel below it.
inline constexpr double kFourierTexelsPerPeriod = 4.0;
// n_i + n_o at its largest for one wavelength: reflection 2 n_outside; a dielectric also transmits.
double indexSum(const Material& material, double lambda_um);
double fourierMaxTexel(const Material& material, const std::vector<double>& lambda_um);
int fourierRefinement(double texel, double maxTexel);

class HeightfieldSpectrum {
 public:
  // `grid` must describe `geometry` (heightGridOf); the scene is used for the shadow rays. Texels
  // larger than maxTexel_um are split (by powers of 2) into smaller facets of the same planes.
  HeightfieldSpectrum(const Microgeometry& geometry, const HeightGrid& grid, const PeriodicScene& scene,
                      double maxTexel_um);

  // The facets lit from ωi (front-facing and unshadowed), one ray per centroid; counts rays.
  std::vector<uint8_t> lit(const Vec3& wi, bool fromAbove, uint64_t* rays) const;

  // X and B per facet and polarisation for one incidence, wavelength and side.
  // Stored per quantity k = pol * 4 + field (field 0..3 = X, Bx, By, Bz; pol 0 = s, 1 = p), lattice
  // by lattice, so that each FFT reads one contiguous array.
  struct FacetFields {
    size_t cells = 0;
    std::array<std::vector<Complex>, 8> v;
    Complex at(int k, size_t t) const { return v[size_t(k)][(t & 1) * cells + t / 2]; }
    Complex& at(int k, size_t t) { return v[size_t(k)][(t & 1) * cells + t / 2]; }
  };
  FacetFields fields(const Vec3& wi, bool fromAbove, int l, double k0, double nI, double nO, bool transmission,
                     const wave::Media& media, const std::vector<uint8_t>& lit) const;

  // The Chebyshev nodes in q_z for a range of exit directions, and the barycentric weights that
  // interpolate e^{i q_z (z − z̄)} between them (error < 1e-7 of the amplitude).
  struct QzNodes {
    double zc = 0;
    std::vector<double> q, bw;
    // Weights w_n at qz (size q.size()), including the factor e^{i qz z̄}: Ĥ(qz) = Σ_n w_n Ĥ(q_n).
    void weights(double qz, Complex* w) const;
    // The same one node at a time, from a compact state per qz (O(1) per weight; for the many
    // exit nodes of the speckle path): state(qz) once, then weight(n, state).
    struct State {
      double qz = 0, sum = 0;
      Complex phase;
      int hit = -1;  // qz on node `hit`
    };
    State state(double qz) const;
    Complex weight(size_t n, const State& s) const {
      if (s.hit >= 0) return size_t(s.hit) == n ? s.phase : Complex(0.0);
      return s.phase * (bw[n] / (s.qz - q[n]) / s.sum);
    }
  };
  QzNodes qzNodes(double qzMin, double qzMax) const;

  // Ĥ at the node q_n for orders a in [a0, a1], b in [b0, b1] (indices taken modulo the grid: the
  // one-point sum is periodic in G), without the e^{i q_n z̄} factor:
  //   (*out)[((pol * 4 + field) * na + (a − a0)) * nb + (b − b0)],  field 0..3 = X, Bx, By, Bz.
  // 16 FFTs (4 fields x 2 polarisations x 2 facet lattices), in parallel.
  void nodeTables(const FacetFields& f, double qn, long a0, long a1, long b0, long b1, std::vector<Complex>* out) const;

  // X + B·k2 from (X, Bx, By, Bz) stored `stride` apart: a facet's, or a table's Ĥ at one order.
  static Complex combine(const Complex* t, size_t stride, const Vec3& k2) {
    return t[0] + k2.x * t[stride] + k2.y * t[2 * stride] + k2.z * t[3 * stride];
  }

  // The term of one facet in Ĥ_G (s, p), for the masking correction; q the full k1 − k2.
  std::array<Complex, 2> facetTerm(const FacetFields& f, size_t t, const Vec3& q, const Vec3& k2) const;

  size_t facets() const { return centroid_.size(); }
  const Vec3& centroid(size_t t) const { return centroid_[t]; }
  const Vec3& normal(size_t t) const { return normal_[t]; }  // unit, facing up
  unsigned parent(size_t t) const { return parent_[t]; }     // the geometry's triangle holding facet t
  // The facets split from the geometry's triangle p (one when texels are not split).
  const uint32_t* childrenBegin(size_t p) const { return children_.data() + childStart_[p]; }
  const uint32_t* childrenEnd(size_t p) const { return children_.data() + childStart_[p + 1]; }
  size_t parents() const { return childStart_.size() - 1; }
  int refinement() const { return refine_; }
  // The steepest facet slope |∇h|: exit directions with tan(elevation) above it are free of
  // masking and back-facing facets.
  double maxSlope() const { return maxSlope_; }
  // Facet data, one wavelength's fields, the e^{i q z} phases and two transform buffers per thread.
  double memoryBytes() const;
  int nx() const { return nx_; }
  int ny() const { return ny_; }

 private:
  const PeriodicScene& scene_;
  int nx_ = 0, ny_ = 0, refine_ = 1;
  double sizeX_, sizeY_, zc_ = 0, zHalf_ = 0, maxSlope_ = 0;
  std::vector<Vec3> centroid_, normal_, area_;  // area_: a = m A (unit normal times area), facing up
  std::vector<uint32_t> parent_, childStart_, children_;
  // The 2-D transform pruned to the orders asked for: in-place backward transforms of every row
  // (length nx), then of only the needed columns (length ny), copied out contiguously. Plans are
  // shared (new-array execution); the column plan per column count, made on first use.
  fftw::Plan rowPlan_;
  mutable std::mutex columnPlanMutex_;
  mutable std::map<int, fftw::Plan> columnPlans_;
  fftw_plan columnPlan(int columns) const;
  // Per worker thread: the grid buffer and the column buffer, kept between calls.
  struct Scratch {
    fftw::Buffer<fftw_complex> grid, columns;
    size_t columnCapacity = 0;
  };
  mutable tbb::enumerable_thread_specific<Scratch> scratch_;
};

}  // namespace mbsdf
