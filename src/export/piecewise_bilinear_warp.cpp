#include "export/piecewise_bilinear_warp.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace mbsdf {
namespace {

// The last index i in [0, n − 2] with below(i) true (below is monotone: true, then false), or 0.
template <typename Below>
int findInterval(int n, Below below) {
  int first = 1, size = n - 2;
  while (size > 0) {
    const int half = size >> 1, middle = first + half;
    if (below(middle)) {
      first = middle + 1;
      size -= half + 1;
    } else {
      size = half;
    }
  }
  return std::clamp(first - 1, 0, n - 2);
}

// The root in [0, 1] of the integral of a linear density from a (at 0) to b (at 1) reaching `area`:
// a t + (b − a) t² / 2 = area, in the form without cancellation (exact also where a ≈ b or a = 0), so
// that sample() is the exact inverse of invert() — the map renderers use to find a table's nodes.
double invertLinear(double a, double b, double area) {
  const double denominator = a + std::sqrt(std::max(0.0, a * a + 2 * area * (b - a)));
  return denominator > 0 ? 2 * area / denominator : 0.0;
}

}  // namespace

PiecewiseBilinearWarp::PiecewiseBilinearWarp(std::vector<float> values, int nx, int ny) : nx_(nx), ny_(ny) {
  if (nx < 2 || ny < 2 || values.size() != size_t(nx) * size_t(ny))
    throw std::invalid_argument("PiecewiseBilinearWarp: a grid of at least 2 x 2 values");
  data_.assign(values.begin(), values.end());
  conditional_.assign(data_.size(), 0.0);
  marginal_.assign(size_t(ny), 0.0);
  for (int y = 0; y < ny; ++y)
    for (int x = 0; x + 1 < nx; ++x)
      conditional_[size_t(y * nx + x + 1)] = cond(y, x) + 0.5 * (value(y, x) + value(y, x + 1));
  for (int y = 0; y + 1 < ny; ++y)
    marginal_[size_t(y + 1)] = marginal_[size_t(y)] + 0.5 * (cond(y, nx - 1) + cond(y + 1, nx - 1));
  const double total = marginal_.back();
  if (!(total > 0) || !std::isfinite(total))
    throw std::invalid_argument("PiecewiseBilinearWarp: the values must have a positive, finite integral");
  for (double& v : data_) v /= total;
  for (double& v : conditional_) v /= total;
  for (double& v : marginal_) v /= total;
}

WarpSample PiecewiseBilinearWarp::sample(double u, double v) const {
  constexpr double eps = std::numeric_limits<float>::epsilon();
  u = std::clamp(u, eps, 1 - eps);
  v = std::clamp(v, eps, 1 - eps);
  // The row: the marginal density is linear between the rows' integrals r0 and r1.
  const int row = findInterval(ny_, [&](int i) { return marginal_[size_t(i)] < v; });
  const double r0 = cond(row, nx_ - 1), r1 = cond(row + 1, nx_ - 1);
  const double ty = invertLinear(r0, r1, v - marginal_[size_t(row)]);
  // The column, conditional on ty: the running integral interpolated between the two rows.
  const double target = u * ((1 - ty) * r0 + ty * r1);
  auto running = [&](int col) { return (1 - ty) * cond(row, col) + ty * cond(row + 1, col); };
  const int col = findInterval(nx_, [&](int i) { return running(i) < target; });
  const double c0 = (1 - ty) * value(row, col) + ty * value(row + 1, col);
  const double c1 = (1 - ty) * value(row, col + 1) + ty * value(row + 1, col + 1);
  const double tx = invertLinear(c0, c1, target - running(col));
  return {(col + tx) / (nx_ - 1), (row + ty) / (ny_ - 1), ((1 - tx) * c0 + tx * c1) * (nx_ - 1) * (ny_ - 1)};
}

WarpSample PiecewiseBilinearWarp::invert(double x, double y) const {
  const double px = std::clamp(x, 0.0, 1.0) * (nx_ - 1), py = std::clamp(y, 0.0, 1.0) * (ny_ - 1);
  const int col = std::min(int(px), nx_ - 2), row = std::min(int(py), ny_ - 2);
  const double tx = px - col, ty = py - row;
  const double c0 = (1 - ty) * value(row, col) + ty * value(row + 1, col);
  const double c1 = (1 - ty) * value(row, col + 1) + ty * value(row + 1, col + 1);
  const double r0 = cond(row, nx_ - 1), r1 = cond(row + 1, nx_ - 1);
  const double running = (1 - ty) * cond(row, col) + ty * cond(row + 1, col) + tx * (c0 + 0.5 * tx * (c1 - c0));
  const double rowTotal = (1 - ty) * r0 + ty * r1;
  const double u = rowTotal > 0 ? running / rowTotal : tx;
  const double v = marginal_[size_t(row)] + ty * (r0 + 0.5 * ty * (r1 - r0));
  return {u, v, ((1 - tx) * c0 + tx * c1) * (nx_ - 1) * (ny_ - 1)};
}

double PiecewiseBilinearWarp::pdf(double x, double y) const {
  return invert(x, y).pdf;
}

}  // namespace mbsdf
