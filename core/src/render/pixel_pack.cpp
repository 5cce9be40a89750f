// fogbeam — scalar parts of the pixel packers (fogbeam/render/pixel_pack.hpp).
#include <fogbeam/render/pixel_pack.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>

namespace fogbeam {

std::uint16_t floatToHalf(float v) noexcept {
  const std::uint32_t x = std::bit_cast<std::uint32_t>(v);
  const std::uint32_t sign = (x >> 16) & 0x8000u;
  const std::uint32_t absx = x & 0x7FFFFFFFu;
  if (absx >= 0x7F800000u) return static_cast<std::uint16_t>(sign | 0x7C00u | (absx > 0x7F800000u ? 0x200u : 0u));
  if (absx >= 0x477FF000u) return static_cast<std::uint16_t>(sign | 0x7C00u);  // rounds above 65504: inf
  if (absx < 0x38800000u) {
    // Subnormal half (or zero): value = m · 2^−24. Shift the 24-bit significand into place and
    // round to nearest even.
    if (absx < 0x33000000u) return static_cast<std::uint16_t>(sign);  // below half the smallest subnormal
    const std::uint32_t e = absx >> 23;
    const std::uint32_t m = (absx & 0x7FFFFFu) | 0x800000u;
    const std::uint32_t shift = 126u - e;  // 14 … 24
    std::uint32_t h = m >> shift;
    const std::uint32_t rem = m & ((1u << shift) - 1u), half = 1u << (shift - 1u);
    if (rem > half || (rem == half && (h & 1u))) ++h;
    return static_cast<std::uint16_t>(sign | h);
  }
  // Normal: rebias the exponent (127 → 15), round the 23-bit mantissa to 10 bits, nearest even.
  std::uint32_t h = ((absx - 0x38000000u) >> 13);
  const std::uint32_t rem = absx & 0x1FFFu;
  if (rem > 0x1000u || (rem == 0x1000u && (h & 1u))) ++h;
  return static_cast<std::uint16_t>(sign | h);
}

float halfToFloat(std::uint16_t h) noexcept {
  const std::uint32_t sign = static_cast<std::uint32_t>(h & 0x8000u) << 16;
  const std::uint32_t e = (h >> 10) & 0x1Fu, m = h & 0x3FFu;
  if (e == 0) {
    const float v = std::ldexp(static_cast<float>(m), -24);
    return sign ? -v : v;
  }
  if (e == 31) return std::bit_cast<float>(sign | 0x7F800000u | (m << 13));
  return std::bit_cast<float>(sign | ((e + 112u) << 23) | (m << 13));
}

namespace pack {
// pixel_pack_simd.cpp: the loop below as a Highway kernel, byte for byte (the table widened).
void packRgba8SrgbSimd(const float* rgb, std::size_t n, float gain, const std::int32_t* table, std::uint8_t* out);
}  // namespace pack

void packRgba8Srgb(const float* rgb, std::size_t n, double exposureEv, std::uint8_t* out) {
  // y = x/(1 + x) ∈ [0, 1) is tabulated at 16384 steps: the sRGB curve's steepest 8-bit step
  // (at black, 1/(255·12.92) ≈ 3e-4 in y) spans five entries, so the table never skips a code.
  // The definition, per channel: x = max(v, 0)·2^EV, y = x/(1 + x) (1 where x is not finite),
  // code = table[⌊y·16384 + 0.5⌋]; the SIMD kernel computes exactly that (32-bit entries, for
  // its gathers).
  static const std::array<std::int32_t, 16385> table = [] {
    std::array<std::int32_t, 16385> t{};
    for (std::size_t i = 0; i < t.size(); ++i) {
      const double y = static_cast<double>(i) / 16384.0;
      const double s = y <= 0.0031308 ? 12.92 * y : 1.055 * std::pow(y, 1.0 / 2.4) - 0.055;
      t[i] = static_cast<std::int32_t>(std::lround(std::clamp(s, 0.0, 1.0) * 255.0));
    }
    return t;
  }();
  pack::packRgba8SrgbSimd(rgb, n, static_cast<float>(std::exp2(exposureEv)), table.data(), out);
}

}  // namespace fogbeam
