// fogbeam — the pinhole camera of a view: pose, image size, centred or off-axis frustum, and the
// ray through each pixel. Frames follow docs/physics.md: the camera looks along its +x, +y left,
// +z up; image x to the right, y down from the top-left corner. Lengths in metres, angles in
// radians, image sizes in pixels.
//
// Thread-safety: plain values; const member functions may be called from any thread.
#pragma once

#include <fogbeam/physics/math.hpp>
#include <fogbeam/util/result.hpp>

#include <optional>

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

/// Camera::rayDirection for many pixels: the focal length and the principal point (a tangent
/// each per call) computed once. The same arithmetic as rayDirection, so the same bits.
/// Immutable once built (thread-safe); unaffected by later changes to the camera.
struct PixelRays {
  explicit PixelRays(const Camera& c) noexcept
      : focal_px(c.focalLengthPixels()), centre_px(c.principalPoint()), worldFromCamera(c.worldFromCamera) {}
  /// The unit world direction through image point (x, y), pixels (pixel centres at +0.5).
  [[nodiscard]] Vec3 direction(double x, double y) const noexcept {
    return glm::normalize(worldFromCamera * Vec3(focal_px, centre_px.x - x, centre_px.y - y));
  }
  double focal_px;
  Vec2 centre_px;
  Mat3 worldFromCamera;
};

}  // namespace fogbeam
