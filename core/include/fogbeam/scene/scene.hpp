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
#include <fogbeam/scene/effects.hpp>
#include <fogbeam/util/result.hpp>

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

/// Half-angles of a pinhole frustum, radians, each measured from the view axis (+x) towards
/// its own side: left (+y), right (−y), up (+z), down (−z). A side whose edge lies beyond the
/// axis (the whole view to one side of it) has a negative half-angle. A centred camera has
/// left = right = fov_x / 2 and up = down = fovY() / 2.
struct FrustumAngles {
  double left = 0.0, right = 0.0, up = 0.0, down = 0.0;
};

/// A pinhole camera with square pixels, centred by default, off-axis (an asymmetric frustum,
/// e.g. one channel of a multi-screen simulator cab) when `principal_px` is set. Pixel (i, j),
/// i to the right and j down, samples the ray through its centre. The image point (x, y) looks
/// along camera-frame (f, cx − x, cy − y) (x forward, y left, z up), f = focalLengthPixels()
/// and (cx, cy) = principalPoint().
///
/// Thread-safety: a plain value; const member functions may be called from any thread.
struct Camera {
  Vec3 position_m{0.0, 0.0, 1.2};
  Mat3 worldFromCamera{1.0};  ///< columns: camera +x (view axis), +y (left), +z (up) in world
  /// Horizontal field of view, radians, in (0, π), of the centred camera with this width and
  /// focal length: it sets f = (width / 2) / tan(fov_x / 2). For a centred camera it is the
  /// field of view; for an off-axis one the frustum's own angles are frustum().
  double fov_x = radians(60.0);
  int width = 640;   ///< pixels, ≥ 1
  int height = 360;  ///< pixels, ≥ 1
  /// Principal point: where the view axis (+x) meets the image plane, pixels from the top-left
  /// corner (x right, y down); any finite value, inside the image or not. Empty (default): the
  /// image centre (width / 2, height / 2), a centred camera.
  std::optional<Vec2> principal_px;

  /// The off-axis camera of a frustum given by its half-angles (radians, each in (−89°, 89°),
  /// left + right > 0, up + down > 0) and image size in pixels (width in [1, 16384]):
  ///   f = width / (tan left + tan right),  cx = f tan left,  cy = f tan up,
  /// and the height must equal f (tan up + tan down) within 0.5 px, otherwise the pixels would
  /// not be square (an error says so). `height` = 0 derives it, rounded to the nearest pixel
  /// (then the down edge is off by at most half a pixel; the other three are exact). Position
  /// and orientation are the defaults; set them on the result.
  [[nodiscard]] static Result<Camera> fromFrustum(const FrustumAngles& halfAngles, int width, int height = 0);

  /// The camera that sees pixels [x0, x0 + w) × [y0, y0 + h) of this one: the same pose and
  /// focal length, the principal point shifted by (−x0, −y0). Its pixel (i, j) samples the ray
  /// of this camera's pixel (x0 + i, y0 + j). Offsets may be negative or extend past the
  /// image; w and h are pixels, ≥ 1.
  [[nodiscard]] Camera crop(int x0, int y0, int w, int h) const;

  /// Principal point in pixels: principal_px, or the image centre when it is empty.
  [[nodiscard]] Vec2 principalPoint() const noexcept;
  /// True when the principal point is the image centre (empty or set to exactly that).
  [[nodiscard]] bool isCentred() const noexcept;
  /// The frustum's half-angles (radians) through the image's outer edges.
  [[nodiscard]] FrustumAngles frustum() const noexcept;

  /// Unit direction (world) of the ray through image point (x, y) in pixels, x to the right
  /// and y down from the top-left corner; pixel (i, j) has its centre at (i + 0.5, j + 0.5).
  [[nodiscard]] Vec3 rayDirection(double x, double y) const noexcept;
  /// Focal length in pixels: (width / 2) / tan(fov_x / 2).
  [[nodiscard]] double focalLengthPixels() const noexcept;
  /// Vertical field of view (radians) implied by the focal length, height and principal
  /// point: frustum().up + frustum().down, 2 atan((height / 2) / f) when centred.
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
  std::optional<std::string> gltf_path;  ///< absolute or relative to the working directory
  SceneEffects effects;                  ///< [glow], [glare], [render]: all off / CPU by default
};

/// Parses a scene. `baseDir` resolves relative profile and glTF paths. Errors name the file,
/// line and key: "night.toml:12: [[lamp]] #2: unknown key 'intensty_cd'".
[[nodiscard]] Result<Scene> parseScene(std::string_view text, const std::string& name, const std::string& baseDir);
[[nodiscard]] Result<Scene> loadScene(const std::string& path);

}  // namespace fogbeam
