// fogbeam — the scene of one frame: fog, camera, lamps, Lambertian planes, optional glTF.
//
// A scene file is TOML (docs/scene.md documents every key with units and defaults); units are
// metres, degrees, candela and cd/m² in the file, radians inside code. Frames follow
// docs/physics.md: x forward, y left, z up; yaw about z, pitch about the new y (positive =
// nose down), roll about the new x; every object looks along its +x with +z up.
//
// Thread-safety: plain values; loading is reentrant.
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/util/result.hpp>

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

/// A centred pinhole camera with square pixels. Pixel (i, j), i to the right and j down,
/// samples the ray through its centre.
struct Camera {
  Vec3 position_m{0.0, 0.0, 1.2};
  Mat3 worldFromCamera{1.0};  ///< columns: camera +x (view axis), +y (left), +z (up) in world
  double fov_x = radians(60.0);  ///< horizontal field of view, radians, in (0, π)
  int width = 640;
  int height = 360;

  /// Unit direction (world) of the ray through image point (x, y) in pixels, x to the right
  /// and y down from the top-left corner; pixel (i, j) has its centre at (i + 0.5, j + 0.5).
  [[nodiscard]] Vec3 rayDirection(double x, double y) const noexcept;
  /// Focal length in pixels: (width / 2) / tan(fov_x / 2).
  [[nodiscard]] double focalLengthPixels() const noexcept;
  /// Vertical field of view (radians) implied by fov_x and the aspect ratio.
  [[nodiscard]] double fovY() const noexcept;
};

/// An infinite Lambertian plane.
struct Plane {
  Vec3 point_m{0.0};
  Vec3 normal{0.0, 0.0, 1.0};  ///< unit
  double reflectance = 0.15;   ///< Lambertian albedo ρ ∈ [0, 1]
};

/// A lamp of the scene, with the name shown in reports ("lamp[2]" when unnamed).
/// Where a lamp is fixed. A vehicle lamp keeps its pose relative to the camera from frame to
/// frame (the ego car's headlamps seen from the driver's eye), so the image evaluator may cache
/// its airlight per view direction (kernels::ViewTable); a world lamp may move relative to it.
enum class LampMount { World, Vehicle };

struct SceneLamp {
  std::string name;
  Lamp lamp;
  LampMount mount = LampMount::World;  ///< scene key `mount` = "world" | "vehicle"
};

struct Scene {
  std::string source;  ///< file path, for messages
  Medium fog;
  Camera camera;
  std::vector<SceneLamp> lamps;
  std::vector<Plane> planes;
  std::optional<std::string> gltf_path;  ///< absolute or relative to the working directory
};

/// Parses a scene. `baseDir` resolves relative profile and glTF paths. Errors name the file,
/// line and key: "night.toml:12: [[lamp]] #2: unknown key 'intensty_cd'".
[[nodiscard]] Result<Scene> parseScene(std::string_view text, const std::string& name, const std::string& baseDir);
[[nodiscard]] Result<Scene> loadScene(const std::string& path);

}  // namespace fogbeam
