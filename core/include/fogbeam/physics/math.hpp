// fogbeam — small math helpers shared by the physics code.
// Vectors are GLM double vectors; lengths in metres, angles in radians inside code.
#pragma once

#include <glm/glm.hpp>
#include <numbers>

namespace fogbeam {

using Vec2 = glm::dvec2;
using Vec3 = glm::dvec3;
using Mat3 = glm::dmat3;

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kInvFourPi = 1.0 / (4.0 * std::numbers::pi);

[[nodiscard]] constexpr double radians(double deg) { return deg * (kPi / 180.0); }
[[nodiscard]] constexpr double degrees(double rad) { return rad * (180.0 / kPi); }

/// Rotation worldFromBody for the ISO 8855 z-y'-x'' convention of the physics notes:
/// yaw about z, then pitch about the new y, then roll about the new x (radians).
/// Positive pitch tilts the nose *down* (right-hand rule about +y with z up).
/// Columns are the body's +x, +y, +z axes expressed in the world frame.
[[nodiscard]] Mat3 worldFromYawPitchRoll(double yaw, double pitch, double roll);

/// A rotation whose +x column is `axis` (normalised) and whose +z column is as close
/// to `upHint` as possible (world +z by default; +x is used when axis ∥ upHint).
[[nodiscard]] Mat3 worldFromAxis(const Vec3& axis, const Vec3& upHint = Vec3(0, 0, 1));

}  // namespace fogbeam
