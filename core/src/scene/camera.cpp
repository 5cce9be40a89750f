// fogbeam — the pinhole camera (camera.hpp).
#include <fogbeam/scene/camera.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <string>

namespace fogbeam {

namespace {

constexpr int kMaxImageSide = 16384;         // pixels, as the scene file's width and height
constexpr double kMaxHalfAngle = radians(89.0);  // tan stays below 57.3: f stays well conditioned

std::string fmtDeg(double rad) {
  std::array<char, 32> buf{};
  std::snprintf(buf.data(), buf.size(), "%.6g", degrees(rad));
  return std::string(buf.data()) + " deg";
}

std::string fmtPx(double px) {
  std::array<char, 32> buf{};
  std::snprintf(buf.data(), buf.size(), "%.6g", px);
  return std::string(buf.data()) + " px";
}

}  // namespace

Result<Camera> Camera::fromFrustum(const FrustumAngles& h, int w, int height) {
  const std::array<std::pair<const char*, double>, 4> sides{
      {{"left", h.left}, {"right", h.right}, {"up", h.up}, {"down", h.down}}};
  for (const auto& [name, angle] : sides)
    if (!(std::abs(angle) < kMaxHalfAngle))
      return Error{std::string("frustum: ") + name + " half-angle must be in (-89, 89) deg, found " + fmtDeg(angle)};
  if (!(h.left + h.right > 0.0))
    return Error{"frustum: left + right must be > 0 deg, found " + fmtDeg(h.left + h.right)};
  if (!(h.up + h.down > 0.0)) return Error{"frustum: up + down must be > 0 deg, found " + fmtDeg(h.up + h.down)};
  if (w < 1 || w > kMaxImageSide)
    return Error{"frustum: width must be in [1, 16384] px, found " + std::to_string(w)};
  if (height < 0 || height > kMaxImageSide)
    return Error{"frustum: height must be in [1, 16384] px (or 0 to derive it), found " + std::to_string(height)};

  const double tl = std::tan(h.left), tr = std::tan(h.right), tu = std::tan(h.up), td = std::tan(h.down);
  Camera c;
  c.width = w;
  // fov_x is the centred camera's field of view for the same f and width: f = w / (tl + tr).
  c.fov_x = 2.0 * std::atan(0.5 * (tl + tr));
  const double f = c.focalLengthPixels();
  const double exactHeight = f * (tu + td);  // pixels; square pixels fix it
  if (height == 0) {
    const double rounded = std::round(exactHeight);
    if (!(rounded >= 1.0 && rounded <= kMaxImageSide))
      return Error{"frustum: the derived height " + fmtPx(exactHeight) + " is outside [1, 16384] px"};
    c.height = static_cast<int>(rounded);
  } else {
    if (!(std::abs(exactHeight - height) <= 0.5))
      return Error{"frustum: height " + std::to_string(height) + " px does not give square pixels: width " +
                   std::to_string(w) + " px over left + right implies f = " + fmtPx(f) +
                   ", so up + down needs a height of " + fmtPx(exactHeight) + " (within 0.5 px)"};
    c.height = height;
  }
  c.principal_px = Vec2(f * tl, f * tu);
  return c;
}

Camera Camera::crop(int x0, int y0, int w, int h) const {
  Camera c = *this;
  const double f = focalLengthPixels();
  c.width = w;
  c.height = h;
  c.fov_x = 2.0 * std::atan(0.5 * w / f);  // keeps f (to rounding)
  c.principal_px = principalPoint() - Vec2(x0, y0);
  return c;
}

Vec2 Camera::principalPoint() const noexcept {
  // 0.5 · width exactly as the centred formulas always wrote it: centred results stay bit-identical.
  return principal_px ? *principal_px : Vec2(0.5 * width, 0.5 * height);
}

bool Camera::isCentred() const noexcept {
  return !principal_px || (principal_px->x == 0.5 * width && principal_px->y == 0.5 * height);
}

FrustumAngles Camera::frustum() const noexcept {
  const double f = focalLengthPixels();
  const Vec2 c = principalPoint();
  return {std::atan(c.x / f), std::atan((width - c.x) / f), std::atan(c.y / f), std::atan((height - c.y) / f)};
}

double Camera::focalLengthPixels() const noexcept { return 0.5 * width / std::tan(0.5 * fov_x); }

double Camera::fovY() const noexcept {
  if (isCentred()) return 2.0 * std::atan(0.5 * height / focalLengthPixels());
  const FrustumAngles a = frustum();
  return a.up + a.down;
}

Vec3 Camera::rayDirection(double x, double y) const noexcept {
  // Camera frame: +x forward, +y left, +z up. Image x grows to the right (−y), image y down (−z).
  const double f = focalLengthPixels();
  const Vec2 c = principalPoint();
  const Vec3 local(f, c.x - x, c.y - y);
  return glm::normalize(worldFromCamera * local);
}

}  // namespace fogbeam
