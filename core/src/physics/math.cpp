#include <fogbeam/physics/math.hpp>

#include <cmath>

namespace fogbeam {

Mat3 worldFromYawPitchRoll(double yaw, double pitch, double roll) {
  // R = Rz(yaw) · Ry(pitch) · Rx(roll) (intrinsic z-y'-x''). With the right-hand rule a
  // positive rotation about +y takes +x towards −z: the nose goes down, as ISO 8855 wants.
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  const double cp = std::cos(pitch), sp = std::sin(pitch);
  const double cr = std::cos(roll), sr = std::sin(roll);
  const Mat3 rz(Vec3(cy, sy, 0), Vec3(-sy, cy, 0), Vec3(0, 0, 1));    // columns
  const Mat3 ry(Vec3(cp, 0, -sp), Vec3(0, 1, 0), Vec3(sp, 0, cp));
  const Mat3 rx(Vec3(1, 0, 0), Vec3(0, cr, sr), Vec3(0, -sr, cr));
  return rz * ry * rx;
}

Mat3 worldFromAxis(const Vec3& axis, const Vec3& upHint) {
  const Vec3 x = glm::normalize(axis);
  Vec3 up = upHint;
  if (std::abs(glm::dot(glm::normalize(up), x)) > 0.999999) up = Vec3(1, 0, 0);
  if (std::abs(glm::dot(up, x)) > 0.999999) up = Vec3(0, 1, 0);
  const Vec3 y = glm::normalize(glm::cross(up, x));
  const Vec3 z = glm::cross(x, y);
  return Mat3(x, y, z);
}

}  // namespace fogbeam
