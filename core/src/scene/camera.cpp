#include <fogbeam/scene/scene.hpp>

#include <cmath>

namespace fogbeam {

double Camera::focalLengthPixels() const noexcept { return 0.5 * width / std::tan(0.5 * fov_x); }

double Camera::fovY() const noexcept { return 2.0 * std::atan(0.5 * height / focalLengthPixels()); }

Vec3 Camera::rayDirection(double x, double y) const noexcept {
  // Camera frame: +x forward, +y left, +z up. Image x grows to the right (−y), image y down (−z).
  const double f = focalLengthPixels();
  const Vec3 local(f, 0.5 * width - x, 0.5 * height - y);
  return glm::normalize(worldFromCamera * local);
}

}  // namespace fogbeam
