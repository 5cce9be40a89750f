// fogbeam — packing frame layers into the pixel formats of the shared-memory channels
// (docs/shm.md): RGBA16F (IEEE binary16) and RGBA8 sRGB. The RGBA16F packer is a Highway
// kernel (F16C conversion on AVX2/AVX-512, chosen at run time); the scalar floatToHalf() is its
// definition and is used for the tail.
//
// Thread-safety: pure functions on caller-owned buffers; disjoint ranges may run in parallel.
#pragma once

#include <cstddef>
#include <cstdint>

namespace fogbeam {

/// IEEE-754 binary16 of `v`, rounded to nearest even; overflow → ±inf, NaN stays NaN.
[[nodiscard]] std::uint16_t floatToHalf(float v) noexcept;
/// The float value of a binary16.
[[nodiscard]] float halfToFloat(std::uint16_t h) noexcept;

/// The largest finite binary16, 65504.
inline constexpr float kHalfMax = 65504.0f;
/// `v` clamped to [−kHalfMax, kHalfMax], NaN to 0: what packRgba16F packs, so that a frame never
/// carries an infinity or a NaN (a lamp's image, or a traffic lamp at the eye, is brighter than
/// 65504 cd/m²: it saturates there instead of becoming +inf in the host's compositing).
[[nodiscard]] inline float clampToHalfRange(float v) noexcept {
  if (!(v == v)) return 0.0f;
  return v > kHalfMax ? kHalfMax : (v < -kHalfMax ? -kHalfMax : v);
}

/// out[4i..4i+3] = half(clampToHalfRange(rgb[3i..3i+2])), half(clampToHalfRange(alpha ? alpha[i] :
/// alphaConstant)), i < n. Composite linear: alpha null, alphaConstant 1. Overlay: rgb = overlay
/// layer, alpha = transmittance.
void packRgba16F(const float* rgb, const float* alpha, float alphaConstant, std::size_t n, std::uint16_t* out);

/// out[4i..4i+3] = the tone-mapped sRGB of rgb[3i..3i+2] (toneMapSrgb8's curve: x = L·2^EV,
/// Reinhard, sRGB transfer, through a 16384-entry table) and 255.
void packRgba8Srgb(const float* rgb, std::size_t n, double exposureEv, std::uint8_t* out);

}  // namespace fogbeam
