// The pinhole camera, centred and off-axis: crop equivalence (an off-axis camera is a window of
// a larger centred one), frustum edges at the requested angles, centred results unchanged.
#include <fogbeam/physics/math.hpp>
#include <fogbeam/scene/scene.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace fogbeam {
namespace {

Camera centred(int w, int h, double fovDeg) {
  Camera c;
  c.position_m = {3.0, -1.0, 1.4};
  c.worldFromCamera = worldFromYawPitchRoll(radians(12.0), radians(4.0), radians(-3.0));
  c.fov_x = radians(fovDeg);
  c.width = w;
  c.height = h;
  return c;
}

double maxRayDifference(const Camera& window, const Camera& big, int x0, int y0) {
  double worst = 0.0;
  for (int j = 0; j < window.height; ++j)
    for (int i = 0; i < window.width; ++i) {
      const Vec3 a = window.rayDirection(i + 0.5, j + 0.5);
      const Vec3 b = big.rayDirection(x0 + i + 0.5, y0 + j + 0.5);
      worst = std::max(worst, glm::length(a - b));
    }
  return worst;
}

// Windows of a 320×180 centred camera: one straddling the axis, one wholly right of it (a
// negative left half-angle), one below it (negative up), one past the image's corner.
TEST(Camera, OffAxisRaysEqualTheRaysOfTheSamePixelsOfALargerCentredCamera) {
  const Camera big = centred(320, 180, 70.0);
  const double f = big.focalLengthPixels();
  struct Window {
    int x0, y0, w, h;
  };
  for (const Window& win : {Window{40, 20, 100, 90}, Window{200, 10, 120, 60}, Window{10, 120, 64, 48},
                            Window{280, 150, 80, 50}}) {
    SCOPED_TRACE("window at " + std::to_string(win.x0) + "," + std::to_string(win.y0));
    // Built from its frustum's half-angles alone, as a cab channel is specified.
    const FrustumAngles angles{std::atan((160.0 - win.x0) / f), std::atan((win.x0 + win.w - 160.0) / f),
                               std::atan((90.0 - win.y0) / f), std::atan((win.y0 + win.h - 90.0) / f)};
    Result<Camera> r = Camera::fromFrustum(angles, win.w, win.h);
    ASSERT_TRUE(r) << r.error().message;
    Camera cam = std::move(r).value();
    cam.position_m = big.position_m;
    cam.worldFromCamera = big.worldFromCamera;
    EXPECT_FALSE(cam.isCentred());
    EXPECT_NEAR(cam.focalLengthPixels(), f, 1e-9 * f);
    EXPECT_NEAR(cam.principalPoint().x, 160.0 - win.x0, 1e-9);
    EXPECT_NEAR(cam.principalPoint().y, 90.0 - win.y0, 1e-9);
    EXPECT_LT(maxRayDifference(cam, big, win.x0, win.y0), 1e-12);
    // The same window by Camera::crop.
    const Camera cropped = big.crop(win.x0, win.y0, win.w, win.h);
    EXPECT_EQ(cropped.width, win.w);
    EXPECT_EQ(cropped.height, win.h);
    EXPECT_LT(maxRayDifference(cropped, big, win.x0, win.y0), 1e-12);
  }
}

TEST(Camera, FrustumEdgesPointAtTheGivenAngles) {
  const FrustumAngles want{radians(35.0), radians(15.0), radians(10.0), radians(20.0)};
  Result<Camera> r = Camera::fromFrustum(want, 1000);  // height derived
  ASSERT_TRUE(r) << r.error().message;
  const Camera& cam = *r;  // identity orientation: camera frame = world frame
  const double f = cam.focalLengthPixels();
  EXPECT_NEAR(f, 1000.0 / (std::tan(want.left) + std::tan(want.right)), 1e-9);
  EXPECT_EQ(cam.height, static_cast<int>(std::round(f * (std::tan(want.up) + std::tan(want.down)))));
  const Vec2 c = cam.principalPoint();
  // Rays through the middle of each edge, in the plane of the view axis: left edge x = 0 turns
  // left (+y), right edge x = W right, top edge y = 0 up (+z), bottom edge y = H down.
  const Vec3 left = cam.rayDirection(0.0, c.y), right = cam.rayDirection(cam.width, c.y);
  const Vec3 up = cam.rayDirection(c.x, 0.0), down = cam.rayDirection(c.x, cam.height);
  EXPECT_NEAR(std::atan2(left.y, left.x), want.left, 1e-12);
  EXPECT_NEAR(std::atan2(-right.y, right.x), want.right, 1e-12);
  EXPECT_NEAR(std::atan2(up.z, up.x), want.up, 1e-12);
  // The derived height is rounded: the bottom edge is within half a pixel of the request.
  EXPECT_NEAR(std::atan2(-down.z, down.x), want.down, 0.5 / f);
  EXPECT_NEAR(std::abs(cam.rayDirection(c.x, c.y).x), 1.0, 1e-15) << "the principal point looks along +x";
  const FrustumAngles got = cam.frustum();
  EXPECT_NEAR(got.left, want.left, 1e-12);
  EXPECT_NEAR(got.right, want.right, 1e-12);
  EXPECT_NEAR(got.up, want.up, 1e-12);
  EXPECT_NEAR(got.down, want.down, 0.5 / f);
  EXPECT_NEAR(cam.fovY(), got.up + got.down, 1e-15);
  // A corner: (1, tan left, tan up) normalised.
  const Vec3 corner = cam.rayDirection(0.0, 0.0);
  EXPECT_NEAR(corner.y / corner.x, std::tan(want.left), 1e-12);
  EXPECT_NEAR(corner.z / corner.x, std::tan(want.up), 1e-12);
}

TEST(Camera, SymmetricFrustumIsTheCentredCamera) {
  const Camera c = centred(640, 360, 60.0);
  const FrustumAngles a = c.frustum();
  EXPECT_NEAR(a.left, radians(30.0), 1e-15);
  EXPECT_DOUBLE_EQ(a.left, a.right);
  EXPECT_DOUBLE_EQ(a.up, a.down);
  Result<Camera> r = Camera::fromFrustum(a, 640, 360);
  ASSERT_TRUE(r) << r.error().message;
  Camera o = std::move(r).value();
  o.position_m = c.position_m;
  o.worldFromCamera = c.worldFromCamera;
  EXPECT_LT(maxRayDifference(o, c, 0, 0), 1e-12);
}

// Centred cameras keep the formulas they always had, bit for bit (images must not change).
TEST(Camera, CentredResultsAreBitIdenticalToTheCentredFormulas) {
  Camera c = centred(333, 197, 47.0);
  const double f = 0.5 * c.width / std::tan(0.5 * c.fov_x);
  EXPECT_TRUE(c.isCentred());
  EXPECT_EQ(c.focalLengthPixels(), f);
  EXPECT_EQ(c.fovY(), 2.0 * std::atan(0.5 * c.height / f));
  Camera explicitCentre = c;
  explicitCentre.principal_px = Vec2(0.5 * c.width, 0.5 * c.height);
  EXPECT_TRUE(explicitCentre.isCentred());
  for (int j = 0; j < c.height; j += 7)
    for (int i = 0; i < c.width; i += 5) {
      const double x = i + 0.5, y = j + 0.5;
      const Vec3 want = glm::normalize(c.worldFromCamera * Vec3(f, 0.5 * c.width - x, 0.5 * c.height - y));
      ASSERT_EQ(c.rayDirection(x, y), want) << i << "," << j;
      ASSERT_EQ(explicitCentre.rayDirection(x, y), want) << i << "," << j;
    }
}

TEST(Camera, PixelRaysAreRayDirectionBitForBit) {
  // PixelRays hoists rayDirection's focal length and principal point out of pixel loops; the
  // image evaluator's results must not change with it (centred and off-axis cameras).
  for (const Camera& cam : {centred(1280, 720, 60.0), centred(320, 180, 75.0).crop(40, 10, 200, 120)}) {
    const PixelRays rays(cam);
    for (double y : {0.5, 33.25, 119.5, 717.5})
      for (double x : {0.5, 17.75, 199.5, 1279.5}) {
        const Vec3 a = cam.rayDirection(x, y), b = rays.direction(x, y);
        EXPECT_EQ(a.x, b.x);
        EXPECT_EQ(a.y, b.y);
        EXPECT_EQ(a.z, b.z);
      }
  }
}

TEST(Camera, FromFrustumRejectsNonSquarePixelsAndBadAngles) {
  const FrustumAngles ok{radians(30.0), radians(30.0), radians(20.0), radians(20.0)};
  // f = 640 / (2 tan 30°) = 554.26 px, so the height is 2 f tan 20° = 403.46 px.
  EXPECT_TRUE(Camera::fromFrustum(ok, 640, 403));
  EXPECT_FALSE(Camera::fromFrustum(ok, 640, 404)) << "0.54 px off";
  const Result<Camera> bad = Camera::fromFrustum(ok, 640, 360);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("square pixels"), std::string::npos) << bad.error().message;
  EXPECT_NE(bad.error().message.find("403.46"), std::string::npos) << bad.error().message;
  EXPECT_FALSE(Camera::fromFrustum({radians(-20.0), radians(10.0), ok.up, ok.down}, 640));
  EXPECT_FALSE(Camera::fromFrustum({ok.left, ok.right, radians(-5.0), radians(5.0)}, 640));
  EXPECT_FALSE(Camera::fromFrustum({radians(89.0), ok.right, ok.up, ok.down}, 640));
  EXPECT_FALSE(Camera::fromFrustum(ok, 0));
  // A negative half-angle is fine as long as the frustum has width: all to the right of the axis.
  const Result<Camera> side = Camera::fromFrustum({radians(-10.0), radians(50.0), ok.up, ok.down}, 640);
  ASSERT_TRUE(side) << side.error().message;
  EXPECT_LT(side->principalPoint().x, 0.0);
}

}  // namespace
}  // namespace fogbeam
