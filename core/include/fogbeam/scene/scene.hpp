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
#include <fogbeam/physics/aperture.hpp>
#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/scene/camera.hpp>
#include <fogbeam/scene/effects.hpp>
#include <fogbeam/util/result.hpp>

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

/// An infinite Lambertian plane.
struct Plane {
  Vec3 point_m{0.0};
  Vec3 normal{0.0, 0.0, 1.0};  ///< unit
  double reflectance = 0.15;   ///< Lambertian albedo ρ ∈ [0, 1]
};

/// A bounded flat Lambertian rectangle: the points corner + s·edge_u + t·edge_v, s, t ∈ [0, 1]
/// (metres, world frame). Both sides are surfaces (the one facing the eye is seen).
struct Quad {
  Vec3 corner_m{0.0};
  Vec3 edge_u_m{1.0, 0.0, 0.0};
  Vec3 edge_v_m{0.0, 1.0, 0.0};
  double reflectance = 0.05;
};

/// The ego car's bonnet, seen from the driver's seat: a horizontal plate of the car's body in
/// the frame the ego's lamps are placed in (a scene file: its world frame, where the vehicle
/// lamps stand; the service's rig: the vehicle frame, x forward, y left, z up from the ground).
/// It stops the rays that would reach the road, the fog and the ego's own lamps below its edge —
/// in the surface pass and, through the distances, the airlight — as a real bonnet hides the
/// headlamps' images and the first metres of their beams (docs/scene.md, `[bonnet]`).
struct Bonnet {
  double rear_m = 0.8;    ///< x of its rear edge (the windscreen's foot)
  double front_m = 2.3;   ///< x of its front edge
  double left_m = 0.85;   ///< y of its left edge
  double right_m = -0.85; ///< y of its right edge
  double height_m = 0.9;  ///< z of the plate
  double reflectance = 0.05;  ///< Lambertian ρ (dark paint)
  /// The plate as a Quad in the bonnet's own frame, then placed by `worldFromFrame` (rotation)
  /// and `origin_m` (that frame's origin in the world).
  [[nodiscard]] Quad quad(const Mat3& worldFromFrame = Mat3(1.0), const Vec3& origin_m = Vec3(0.0)) const;
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
  /// The lamp's emitting face as written (keys `aperture`, `aperture_size_m`, `aperture_samples`;
  /// physics/aperture.hpp). Renderers treat every SceneLamp as a point lamp and ignore this:
  /// lamps with a face reach them expanded into point lamps (expandSceneLamp), which parseScene
  /// does for Scene::lamps and the service's frame renderer for rig lamps once they are placed.
  Aperture aperture{};
};

/// The point lamps that stand for `lamp` (expandAperture): "name [k/N]", k from 1, each with a
/// Point aperture, the same mount and profile; {lamp} itself when its aperture is a point.
[[nodiscard]] std::vector<SceneLamp> expandSceneLamp(const SceneLamp& lamp);

struct Scene {
  std::string source;  ///< file path, for messages
  Medium fog;
  Camera camera;
  std::vector<SceneLamp> lamps;  ///< point lamps: parseScene expands lamps with an aperture
  std::vector<Plane> planes;
  /// The ego vehicle's body seen from the eye (the bonnet, `[bonnet]`): bounded surfaces that
  /// hide what lies behind them, drawn by every surface renderer.
  std::vector<Quad> body;
  std::optional<std::string> gltf_path;  ///< absolute or relative to the working directory
  SceneEffects effects;                  ///< [glow], [glare], [render]: all off / CPU by default
};

/// Parses a scene. `baseDir` resolves relative profile and glTF paths. Errors name the file,
/// line and key: "night.toml:12: [[lamp]] #2: unknown key 'intensty_cd'".
[[nodiscard]] Result<Scene> parseScene(std::string_view text, const std::string& name, const std::string& baseDir);
[[nodiscard]] Result<Scene> loadScene(const std::string& path);

}  // namespace fogbeam
