#include "render/camera.h"

#include <cmath>
#include <stdexcept>

namespace mbsdf {

Camera::Camera(const Vec3& eye, const Vec3& target, const Vec3& up, double fovY_deg, int width, int height)
    : eye_(eye), width_(width), height_(height) {
  forward_ = normalize(target - eye);
  right_ = cross(forward_, up);
  if (!(length(right_) > 1e-9) || !(fovY_deg > 0 && fovY_deg < 180) || width < 1 || height < 1)
    throw std::invalid_argument("camera: degenerate view (up along the view, field of view or size)");
  right_ = normalize(right_);
  up_ = cross(right_, forward_);
  tanHalfY_ = std::tan(radians(fovY_deg) / 2);
  aspect_ = double(width) / height;
}

Vec3 Camera::rayDirection(double x, double y) const {
  const double sx = (2 * x / width_ - 1) * tanHalfY_ * aspect_, sy = (1 - 2 * y / height_) * tanHalfY_;
  return normalize(forward_ + sx * right_ + sy * up_);
}

std::optional<std::pair<double, double>> Camera::project(const Vec3& d) const {
  const double z = dot(d, forward_);
  if (!(z > 0)) return std::nullopt;
  const double sx = dot(d, right_) / z, sy = dot(d, up_) / z;
  return std::make_pair((sx / (tanHalfY_ * aspect_) + 1) * width_ / 2, (1 - sy / tanHalfY_) * height_ / 2);
}

}  // namespace mbsdf
