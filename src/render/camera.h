// A pinhole camera for the material preview: a perspective projection with a vertical field of view,
// pixel (x, y) continuous with x to the right and y downwards, (0, 0) the top-left corner of the image.
#pragma once
#include <optional>
#include <utility>

#include "core/vecmath.h"

namespace mbsdf {

class Camera {
 public:
  // Looking from `eye` at `target`, `up` roughly upwards in the image (not along the view).
  Camera(const Vec3& eye, const Vec3& target, const Vec3& up, double fovY_deg, int width, int height);
  const Vec3& eye() const { return eye_; }
  // Unit direction of the ray through the continuous pixel position (x, y).
  Vec3 rayDirection(double x, double y) const;
  // The continuous pixel position a direction from the eye projects to; empty behind the camera.
  std::optional<std::pair<double, double>> project(const Vec3& direction) const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  Vec3 eye_, forward_, right_, up_;
  double tanHalfY_, aspect_;
  int width_, height_;
};

}  // namespace mbsdf
