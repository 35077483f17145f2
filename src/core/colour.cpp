#include "core/colour.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/colour_data.h"

namespace mbsdf {
namespace {

using Mat3 = std::array<std::array<double, 3>, 3>;

Colour3 mul(const Mat3& m, const Colour3& v) {
  return {m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2], m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
          m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]};
}
Mat3 mul(const Mat3& a, const Mat3& b) {
  Mat3 r{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) r[i][j] += a[i][k] * b[k][j];
  return r;
}
Mat3 inverse(const Mat3& m) {
  double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
               m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  Mat3 r;
  r[0][0] = (m[1][1] * m[2][2] - m[1][2] * m[2][1]) / det;
  r[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det;
  r[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det;
  r[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) / det;
  r[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det;
  r[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det;
  r[2][0] = (m[1][0] * m[2][1] - m[1][1] * m[2][0]) / det;
  r[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det;
  r[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det;
  return r;
}

// IEC 61966-2-1 (sRGB): XYZ (D65) -> linear RGB.
const Mat3 kXyzToSrgb = {
    {{3.2404542, -1.5371385, -0.4985314}, {-0.9692660, 1.8760108, 0.0415560}, {0.0556434, -0.2040259, 1.0572252}}};
// CIE 1931 RGB (primaries 700, 546.1, 435.8 nm; white E).
const Mat3 kXyzToCieRgb = {
    {{2.3706743, -0.9000405, -0.4706338}, {-0.5138850, 1.4253036, 0.0885814}, {0.0052982, -0.0146949, 1.0093968}}};
// Bradford cone response matrix (Lam 1985).
const Mat3 kBradford = {{{0.8951, 0.2664, -0.1614}, {-0.7502, 1.7135, 0.0367}, {0.0389, -0.0685, 1.0296}}};

Mat3 adaptEToD65() {
  Colour3 e = mul(kBradford, Colour3{1.0, 1.0, 1.0});
  Colour3 d65 = mul(kBradford, Colour3{0.95047, 1.0, 1.08883});
  Mat3 s{};
  for (int i = 0; i < 3; ++i) s[i][i] = d65[i] / e[i];
  return mul(inverse(kBradford), mul(s, kBradford));
}

double tableAt(const std::vector<double>& t, double lambda) {
  double f = (lambda - data::kCieLambdaStart_nm) / data::kCieLambdaStep_nm;
  if (f < 0 || f > double(t.size() - 1)) return 0.0;
  size_t i = std::min(size_t(f), t.size() - 2);
  double u = f - double(i);
  return t[i] + u * (t[i + 1] - t[i]);
}

}  // namespace

Colour3 cieXyzBar(double lambda_nm) {
  return {tableAt(data::kCieX, lambda_nm), tableAt(data::kCieY, lambda_nm), tableAt(data::kCieZ, lambda_nm)};
}

namespace {
double d65At(double lambda) {
  const std::vector<double>& t = data::kD65;
  const double f = (lambda - data::kD65LambdaStart_nm) / data::kD65LambdaStep_nm;
  if (f < 0 || f > double(t.size() - 1)) return 0.0;
  const size_t i = std::min(size_t(f), t.size() - 2);
  const double u = f - double(i);
  return t[i] + u * (t[i + 1] - t[i]);
}
}  // namespace

Colour3 cieXyzIntegral(double a, double b, Illuminant illuminant) {
  // Exact integral of the piecewise-linear interpolant (of the product, under D65): trapezoids on
  // the table nodes inside [a, b] plus the partial end intervals.
  Colour3 sum{0, 0, 0};
  if (b <= a) return sum;
  std::vector<double> nodes{a};
  for (double l = data::kCieLambdaStart_nm; l < b; l += data::kCieLambdaStep_nm)
    if (l > a) nodes.push_back(l);
  nodes.push_back(b);
  auto at = [illuminant](double l) {
    Colour3 c = cieXyzBar(l);
    if (illuminant == Illuminant::D65)
      for (double& v : c) v *= d65At(l) / 100.0;
    return c;
  };
  for (size_t i = 0; i + 1 < nodes.size(); ++i) {
    Colour3 f0 = at(nodes[i]), f1 = at(nodes[i + 1]);
    double h = nodes[i + 1] - nodes[i];
    for (int c = 0; c < 3; ++c) sum[c] += 0.5 * h * (f0[c] + f1[c]);
  }
  return sum;
}

Colour3 whitePoint(Illuminant illuminant) {
  if (illuminant == Illuminant::E) return {1, 1, 1};
  const Colour3 w = cieXyzIntegral(300, 830, Illuminant::D65);
  return {w[0] / w[1], 1.0, w[2] / w[1]};
}

Colour3 adaptXyzEToD65(const Colour3& xyz) {
  return mul(adaptEToD65(), xyz);
}

SpectrumToColour::SpectrumToColour(std::vector<double> lambda_nm, Illuminant illuminant)
    : lambda_(std::move(lambda_nm)) {
  const size_t n = lambda_.size();
  if (n == 0) throw std::invalid_argument("no wavelengths");
  std::vector<double> edges(n + 1);
  for (size_t i = 1; i < n; ++i) edges[i] = 0.5 * (lambda_[i - 1] + lambda_[i]);
  double first = n > 1 ? 0.5 * (lambda_[1] - lambda_[0]) : 5.0;
  double last = n > 1 ? 0.5 * (lambda_[n - 1] - lambda_[n - 2]) : 5.0;
  edges[0] = lambda_[0] - first;
  edges[n] = lambda_[n - 1] + last;
  double ySum = 0;
  w_.resize(n);
  for (size_t i = 0; i < n; ++i) {
    w_[i] = cieXyzIntegral(edges[i], edges[i + 1], illuminant);
    ySum += w_[i][1];
  }
  if (!(ySum > 0)) throw std::invalid_argument("the wavelengths lie outside the visible range of the CIE tables");
  for (auto& w : w_)
    for (double& c : w) c /= ySum;
}

SpectrumToColour SpectrumToColour::fromChannels(std::vector<Colour3> xyzPerChannel) {
  SpectrumToColour c;
  c.w_ = std::move(xyzPerChannel);
  return c;
}

Colour3 SpectrumToColour::xyz(const double* v) const {
  Colour3 r{0, 0, 0};
  for (size_t i = 0; i < w_.size(); ++i)
    for (int c = 0; c < 3; ++c) r[c] += w_[i][c] * v[i];
  return r;
}
Colour3 SpectrumToColour::linearSrgb(const double* v) const {
  return xyzToLinearSrgb(xyz(v));
}
std::vector<Colour3> SpectrumToColour::linearSrgbPerSample() const {
  std::vector<Colour3> out;
  for (const Colour3& w : w_) out.push_back(xyzToLinearSrgb(w));
  return out;
}
Colour3 SpectrumToColour::cieRgb(const double* v) const {
  return xyzToCieRgb(xyz(v));
}

Colour3 xyzToLinearSrgb(const Colour3& xyz) {
  static const Mat3 m = mul(kXyzToSrgb, adaptEToD65());
  return mul(m, xyz);
}
Colour3 linearSrgbToXyz(const Colour3& rgb) {
  static const Mat3 m = inverse(mul(kXyzToSrgb, adaptEToD65()));
  return mul(m, rgb);
}
Colour3 xyzToCieRgb(const Colour3& xyz) {
  return mul(kXyzToCieRgb, xyz);
}

}  // namespace mbsdf
