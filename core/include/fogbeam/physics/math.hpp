// fogbeam — small math helpers shared by the physics code.
// Vectors are GLM double vectors; lengths in metres, angles in radians inside code.
#pragma once

#include <glm/glm.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace fogbeam {

using Vec2 = glm::dvec2;
using Vec3 = glm::dvec3;
using Mat3 = glm::dmat3;

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kInvFourPi = 1.0 / (4.0 * std::numbers::pi);

[[nodiscard]] constexpr double radians(double deg) { return deg * (kPi / 180.0); }
[[nodiscard]] constexpr double degrees(double rad) { return rad * (180.0 / kPi); }

/// atan2(y, x) in (−π, π] within ~2 ulp of std::atan2 (0 at x = y = 0), inlined: the pencil
/// integrator takes three per ray (its azimuth, its angle from the lamp, its end), where the
/// libm call was ~15 ns each, ~7 % of a traffic frame. Written by hand because no Debian
/// package offers an inlinable scalar double atan2: the argument is reduced to
/// t = min/max ∈ [0, 1], then to [−0.2, 0.66] about π/4, and atan t = t + t z P(z)/Q(z),
/// z = t², is the Cephes rational approximation (S. L. Moshier, Cephes Math Library, atan.c;
/// relative error < 1e-16 on that range).
inline double fastAtan2(double y, double x) noexcept {
  const double ax = std::abs(x), ay = std::abs(y);
  const double sum = ax + ay;  // 0, NaN or ∞ when an argument is (or both are) zero, NaN, ∞
  if (!(sum > 0.0 && sum < std::numeric_limits<double>::infinity())) return std::atan2(y, x);
  const double mx = std::max(ax, ay), mn = std::min(ax, ay);
  double t = mn / mx, base = 0.0;
  if (t > 0.66) {
    base = 0.25 * kPi + 3.061616997868383e-17;  // π/4 to beyond double (Cephes' MOREBITS / 2)
    t = (t - 1.0) / (t + 1.0);
  }
  const double z = t * t;
  const double p = (((-8.750608600031904122785e-1 * z - 1.615753718733365076637e1) * z - 7.500855792314704667340e1) * z -
                    1.228866684490136173410e2) * z - 6.485021904942025371773e1;
  const double q = ((((z + 2.485846490142306297962e1) * z + 1.650270098316988542046e2) * z + 4.328810604912902668951e2) * z +
                    4.853903996359136964868e2) * z + 1.945506571482613964425e2;
  double a = base + (t + t * z * p / q);
  if (ay > ax) a = 0.5 * kPi - a;
  if (x < 0.0) a = kPi - a;
  return std::copysign(a, y);
}

/// Rotation worldFromBody for the ISO 8855 z-y'-x'' convention of the physics notes:
/// yaw about z, then pitch about the new y, then roll about the new x (radians).
/// Positive pitch tilts the nose *down* (right-hand rule about +y with z up).
/// Columns are the body's +x, +y, +z axes expressed in the world frame.
[[nodiscard]] Mat3 worldFromYawPitchRoll(double yaw, double pitch, double roll);

/// A rotation whose +x column is `axis` (normalised) and whose +z column is as close
/// to `upHint` as possible (world +z by default; +x is used when axis ∥ upHint).
[[nodiscard]] Mat3 worldFromAxis(const Vec3& axis, const Vec3& upHint = Vec3(0, 0, 1));

}  // namespace fogbeam
