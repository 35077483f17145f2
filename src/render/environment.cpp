#include "render/environment.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/error.h"
#include "io/exr_image.h"

namespace mbsdf {

namespace {

double luminance(double r, double g, double b) {
  return 0.2126 * r + 0.7152 * g + 0.0722 * b;  // linear sRGB (Rec. 709) relative luminance
}

// Whether w lies in the rectangle of half angles (a, b) about the direction `centre`, measured
// along the azimuthal and polar directions at the centre.
bool inSoftBox(const Vec3& w, double theta_deg, double phi_deg, double a_deg, double b_deg) {
  const double th = radians(theta_deg), ph = radians(phi_deg);
  const Vec3 c = sphericalDirection(th, ph);
  const Vec3 along{-std::sin(ph), std::cos(ph), 0.0};  // towards increasing φ
  const Vec3 up = cross(along, c);                     // towards decreasing θ
  const double z = dot(w, c);
  if (z <= 0) return false;
  return std::abs(std::atan2(dot(w, along), z)) <= radians(a_deg) &&
         std::abs(std::atan2(dot(w, up), z)) <= radians(b_deg);
}

Colour3 studio(const Vec3& w) {
  if (inSoftBox(w, 40, 235, 14, 10)) return {12, 12, 12};
  if (inSoftBox(w, 60, 320, 18, 14)) return {3, 3, 3};
  if (inSoftBox(w, 12, 120, 30, 3)) return {5, 5, 5};
  if (w.z < 0) return {0.05, 0.05, 0.05};  // the floor
  // Walls brighten towards the ceiling, with a faint warm-cool split so that shapes read.
  const double t = w.z;
  const double warm = 0.5 + 0.5 * w.x;
  return {0.12 + 0.10 * t + 0.02 * warm, 0.12 + 0.10 * t, 0.12 + 0.10 * t + 0.02 * (1 - warm)};
}

Colour3 sky(const Vec3& w) {
  if (dot(w, sphericalDirection(radians(35), radians(240))) >= std::cos(radians(2.5))) return {2000, 1900, 1750};
  if (w.z < 0) return {0.10, 0.08, 0.06};
  const double h = std::pow(1 - w.z, 4);  // towards the horizon: whiter
  return {0.15 + 0.55 * h, 0.30 + 0.45 * h, 0.80 + 0.10 * h};
}

}  // namespace

Environment::Environment(int width, int height, std::vector<float> rgb, std::string what)
    : width_(width), height_(height), rgb_(std::move(rgb)), name_(std::move(what)) {
  if (width_ < 1 || height_ < 1 || rgb_.size() != size_t(width_) * height_ * 3)
    throw std::invalid_argument(name_ + ": the environment map has no pixels or the wrong size");
  for (float v : rgb_)
    if (!std::isfinite(v) || v < 0)
      throw std::invalid_argument(name_ + ": the environment map holds a negative or non-finite radiance");
  cosEdge_.resize(size_t(height_) + 1);
  for (int r = 0; r <= height_; ++r) cosEdge_[size_t(r)] = std::cos(kPi * r / height_);
  cosEdge_[0] = 1, cosEdge_[size_t(height_)] = -1;
  // Pixel weights: luminance × solid angle. A black map is sampled uniformly in solid angle.
  std::vector<double> weight(size_t(width_) * height_);
  double total = 0;
  for (int r = 0; r < height_; ++r)
    for (int c = 0; c < width_; ++c) {
      const size_t p = size_t(r) * width_ + c;
      weight[p] = luminance(rgb_[3 * p], rgb_[3 * p + 1], rgb_[3 * p + 2]) * rowSolidAngle(r);
      total += weight[p];
    }
  if (!(total > 0))
    for (int r = 0; r < height_; ++r)
      for (int c = 0; c < width_; ++c) total += weight[size_t(r) * width_ + c] = rowSolidAngle(r);
  pixelProb_.resize(weight.size());
  rowCdf_.assign(size_t(height_) + 1, 0.0);
  pixelCdf_.assign(size_t(width_ + 1) * height_, 0.0);
  for (int r = 0; r < height_; ++r) {
    double* cdf = &pixelCdf_[size_t(r) * (width_ + 1)];
    for (int c = 0; c < width_; ++c) cdf[c + 1] = cdf[c] + weight[size_t(r) * width_ + c];
    const double rowTotal = cdf[width_];
    for (int c = 0; c < width_; ++c) pixelProb_[size_t(r) * width_ + c] = weight[size_t(r) * width_ + c] / total;
    for (int c = 1; c <= width_; ++c) cdf[c] = rowTotal > 0 ? cdf[c] / rowTotal : double(c) / width_;
    rowCdf_[size_t(r) + 1] = rowCdf_[size_t(r)] + rowTotal / total;
  }
  rowCdf_[size_t(height_)] = 1;
}

Environment Environment::builtIn(const std::string& name, int width) {
  Colour3 (*f)(const Vec3&) = nullptr;
  if (name == "studio") f = studio;
  if (name == "sky") f = sky;
  if (!f) throw InputError("unknown environment \"" + name + "\" (built in: studio, sky; or an .exr file)");
  const int height = width / 2;
  std::vector<float> rgb(size_t(width) * height * 3);
  // Each pixel the mean of 4 × 4 points spread evenly in solid angle over it: soft edges, no aliasing.
  auto cosEdge = [&](int r) { return r == 0 ? 1.0 : r == height ? -1.0 : std::cos(kPi * r / height); };
  for (int r = 0; r < height; ++r)
    for (int c = 0; c < width; ++c) {
      Colour3 sum{0, 0, 0};
      for (int k = 0; k < 16; ++k) {
        const double u = (k % 4 + 0.5) / 4, v = (k / 4 + 0.5) / 4;
        const double z = cosEdge(r) + v * (cosEdge(r + 1) - cosEdge(r));
        const double phi = 2 * kPi * (c + u) / width, s = safeSqrt(1 - z * z);
        const Colour3 L = f({s * std::cos(phi), s * std::sin(phi), z});
        for (int i = 0; i < 3; ++i) sum[size_t(i)] += L[size_t(i)] / 16;
      }
      for (int i = 0; i < 3; ++i) rgb[(size_t(r) * width + c) * 3 + size_t(i)] = float(sum[size_t(i)]);
    }
  return Environment(width, height, std::move(rgb), name);
}

Environment Environment::fromExr(const std::string& path) {
  int w = 0, h = 0;
  std::vector<ExrChannel> channels;
  try {
    channels = readExr(path, &w, &h);
  } catch (const std::exception& e) {
    throw InputError(path + ": cannot read the environment map: " + e.what());
  }
  auto find = [&](const char* name) -> const ExrChannel* {
    for (const ExrChannel& c : channels)
      if (c.name == name) return &c;
    return nullptr;
  };
  const ExrChannel *R = find("R"), *G = find("G"), *B = find("B");
  if (!(R && G && B)) {
    if (channels.size() != 1) throw InputError(path + ": an environment map needs channels R, G, B (or one channel)");
    R = G = B = &channels[0];
  }
  std::vector<float> rgb(size_t(w) * h * 3);
  for (size_t p = 0; p < size_t(w) * h; ++p) {
    rgb[3 * p] = R->pixels[p], rgb[3 * p + 1] = G->pixels[p], rgb[3 * p + 2] = B->pixels[p];
    for (int i = 0; i < 3; ++i)
      if (!std::isfinite(rgb[3 * p + size_t(i)]) || rgb[3 * p + size_t(i)] < 0)
        throw InputError(path + ": pixel (" + std::to_string(p % size_t(w)) + ", " + std::to_string(p / size_t(w)) +
                         ") holds a negative or non-finite radiance");
  }
  return Environment(w, h, std::move(rgb), path);
}

std::pair<int, int> Environment::pixelOf(const Vec3& wIn) const {
  const Vec3 w = normalize(wIn);
  const int r = std::clamp(int(safeAcos(w.z) / kPi * height_), 0, height_ - 1);
  const int c = std::clamp(int(sphericalPhi(w) / (2 * kPi) * width_), 0, width_ - 1);
  return {c, r};
}

Vec3 Environment::pixelCentre(int c, int r) const {
  const double z = 0.5 * (cosEdge_[size_t(r)] + cosEdge_[size_t(r) + 1]), s = safeSqrt(1 - z * z);
  const double phi = 2 * kPi * (c + 0.5) / width_;
  return {s * std::cos(phi), s * std::sin(phi), z};
}

Colour3 Environment::radiance(const Vec3& w) const {
  const auto [c, r] = pixelOf(w);
  const float* p = &rgb_[(size_t(r) * width_ + c) * 3];
  return {p[0], p[1], p[2]};
}

double Environment::pdf(const Vec3& w) const {
  const auto [c, r] = pixelOf(w);
  return pixelProb_[size_t(r) * width_ + c] / rowSolidAngle(r);
}

Environment::Sample Environment::sample(double u1, double u2) const {
  // The row by the marginal CDF, the pixel by the row's conditional CDF, then z and φ uniformly
  // within the pixel (uniform in solid angle); the remainders of u1, u2 within the chosen intervals
  // are the in-pixel numbers.
  const int r =
      std::clamp(int(std::upper_bound(rowCdf_.begin(), rowCdf_.end(), u1) - rowCdf_.begin()) - 1, 0, height_ - 1);
  const double rowP = rowCdf_[size_t(r) + 1] - rowCdf_[size_t(r)];
  const double v = rowP > 0 ? std::clamp((u1 - rowCdf_[size_t(r)]) / rowP, 0.0, 1.0) : 0.5;
  const double* cdf = &pixelCdf_[size_t(r) * (width_ + 1)];
  const int c = std::clamp(int(std::upper_bound(cdf, cdf + width_ + 1, u2) - cdf) - 1, 0, width_ - 1);
  const double colP = cdf[c + 1] - cdf[c];
  const double u = colP > 0 ? std::clamp((u2 - cdf[c]) / colP, 0.0, 1.0) : 0.5;
  const double z = cosEdge_[size_t(r)] + v * (cosEdge_[size_t(r) + 1] - cosEdge_[size_t(r)]);
  const double phi = 2 * kPi * (c + u) / width_, s = safeSqrt(1 - z * z);
  Sample out;
  out.w = {s * std::cos(phi), s * std::sin(phi), z};
  const float* p = &rgb_[(size_t(r) * width_ + c) * 3];
  out.L = {p[0], p[1], p[2]};
  out.pdf = pixelProb_[size_t(r) * width_ + c] / rowSolidAngle(r);
  return out;
}

}  // namespace mbsdf
