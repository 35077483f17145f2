// A density on the unit square that interpolates a grid of values bilinearly, with the inversion
// method's warp from uniform samples to it and back (marginal in y, conditional in x; continuous,
// both inverses in closed form). This is the warp of Dupuy & Jakob 2018 ("An Adaptive
// Parameterization for Efficient Material Acquisition and Rendering", §5), the one Mitsuba 3 and
// pbrt-v4 build from an RGL `.bsdf` file's `vndf` and `luminance` fields: the RGL exporter
// (export/rgl_bsdf.h) must place its samples where a renderer's warp will look for them, so it
// samples the very warp the renderer inverts. Grid values are taken as the renderer reads them
// (float32); the arithmetic is double.
#pragma once
#include <cstddef>
#include <vector>

namespace mbsdf {

struct WarpSample {
  double x = 0, y = 0;  // a point of [0, 1]²
  double pdf = 0;       // the normalised density there
};

class PiecewiseBilinearWarp {
 public:
  // values: ny rows of nx values (x fastest), ≥ 0 with a positive integral; nx, ny ≥ 2. Node (i, j)
  // sits at (i / (nx − 1), j / (ny − 1)).
  PiecewiseBilinearWarp(std::vector<float> values, int nx, int ny);

  // The point a uniform sample (u, v) maps to, and the density there.
  WarpSample sample(double u, double v) const;
  // The uniform sample that maps to point (x, y), and the density at (x, y).
  WarpSample invert(double x, double y) const;
  // The normalised density at (x, y).
  double pdf(double x, double y) const;

 private:
  double cond(int row, int col) const { return conditional_[std::size_t(row) * std::size_t(nx_) + std::size_t(col)]; }
  double value(int row, int col) const { return data_[std::size_t(row) * std::size_t(nx_) + std::size_t(col)]; }

  int nx_, ny_;
  std::vector<double> data_;         // the values scaled so that the density integrates to 1
  std::vector<double> conditional_;  // per row: the running integral along x (patch widths 1)
  std::vector<double> marginal_;     // the running integral of the rows' integrals along y
};

}  // namespace mbsdf
