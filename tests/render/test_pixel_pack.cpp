// Pixel packing for the shared-memory channels: binary16 conversion against known encodings
// and all 65 536 halves, the SIMD packer against the scalar definition on every target, and
// the RGBA8 table against toneMapSrgb8.
#include <fogbeam/render/airlight_kernels.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/pixel_pack.hpp>

#include <algorithm>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace fogbeam {
namespace {

TEST(PixelPack, HalfEncodingsAreIeee) {
  EXPECT_EQ(floatToHalf(1.0f), 0x3C00);
  EXPECT_EQ(floatToHalf(-2.0f), 0xC000);
  EXPECT_EQ(floatToHalf(0.0f), 0x0000);
  EXPECT_EQ(floatToHalf(-0.0f), 0x8000);
  EXPECT_EQ(floatToHalf(65504.0f), 0x7BFF);   // largest finite half
  EXPECT_EQ(floatToHalf(65520.0f), 0x7C00);   // rounds to infinity
  EXPECT_EQ(floatToHalf(std::ldexp(1.0f, -24)), 0x0001);  // smallest subnormal
  EXPECT_EQ(floatToHalf(std::ldexp(1.0f, -25)), 0x0000);  // half of it: ties to even (0)
  EXPECT_EQ(floatToHalf(0.1f), 0x2E66);
  EXPECT_EQ(floatToHalf(std::numeric_limits<float>::infinity()), 0x7C00);
  EXPECT_EQ(floatToHalf(std::nanf("")) & 0x7C00, 0x7C00);
  EXPECT_NE(floatToHalf(std::nanf("")) & 0x03FF, 0);
  EXPECT_EQ(floatToHalf(1.0f + std::ldexp(1.0f, -11)), 0x3C00);  // tie → even
  EXPECT_EQ(floatToHalf(1.0f + 3 * std::ldexp(1.0f, -11)), 0x3C02);  // tie → even (up)
}

TEST(PixelPack, EveryHalfRoundTrips) {
  for (std::uint32_t h = 0; h < 65536; ++h) {
    const auto v = static_cast<std::uint16_t>(h);
    const float f = halfToFloat(v);
    if (std::isnan(f)) continue;
    ASSERT_EQ(floatToHalf(f), v) << "half 0x" << std::hex << h;
  }
}

TEST(PixelPack, SimdPackerMatchesScalarOnEveryTarget) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-12.0f, 12.0f);
  const std::size_t n = 1027;
  std::vector<float> rgb(3 * n), alpha(n);
  for (float& v : rgb) {
    const float sign = u(rng), magnitude = u(rng);  // one draw each, in a defined order
    v = std::exp2(magnitude) * (sign < 0 ? -1.0f : 1.0f);
  }
  for (float& v : alpha) v = std::exp2(u(rng) / 4.0f) - 1.0f;
  rgb[0] = std::numeric_limits<float>::infinity();
  rgb[4] = 1e-7f;  // a subnormal half
  rgb[8] = 70000.0f;
  rgb[12] = -std::numeric_limits<float>::infinity();
  rgb[13] = std::nanf("");
  alpha[7] = std::numeric_limits<float>::infinity();
  std::vector<std::uint16_t> want(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t c = 0; c < 3; ++c) want[4 * i + c] = floatToHalf(clampToHalfRange(rgb[3 * i + c]));
    want[4 * i + 3] = floatToHalf(clampToHalfRange(alpha[i]));
  }
  // Beyond the half's range the frame saturates (65504, 0x7BFF), never +inf; NaN packs as 0.
  EXPECT_EQ(want[0], 0x7BFF);   // +inf
  EXPECT_EQ(want[10], 0x7BFF);  // 70000 (pixel 2, channel 2)
  EXPECT_EQ(want[4 * 4 + 0], 0xFBFF);  // −inf (pixel 4, channel 0)
  EXPECT_EQ(want[4 * 4 + 1], 0x0000);  // NaN
  EXPECT_EQ(want[4 * 7 + 3], 0x7BFF);  // alpha +inf
  for (const std::string& t : kernels::availableTargets()) {
    ASSERT_TRUE(kernels::forceTarget(t));
    std::vector<std::uint16_t> got(4 * n, 0xFFFF);
    packRgba16F(rgb.data(), alpha.data(), 1.0f, n, got.data());
    EXPECT_EQ(got, want) << "target " << t;
  }
  kernels::forceTarget("");
  std::vector<std::uint16_t> constant(4 * n);
  packRgba16F(rgb.data(), nullptr, 1.0f, n, constant.data());
  EXPECT_EQ(constant[3], 0x3C00);
  EXPECT_EQ(constant[4 * (n - 1) + 3], 0x3C00);
}

// packRgba8Srgb's definition, the scalar loop it was before its Highway kernel (2026-11-26):
// per channel x = max(v, 0)·2^EV, y = x/(1 + x) (1 where x is not finite), the code of the sRGB
// curve at ⌊y·16384 + 0.5⌋/16384.
std::vector<std::uint8_t> rgba8Definition(const std::vector<float>& rgb, double ev) {
  std::vector<std::uint8_t> out(rgb.size() / 3 * 4);
  const float gain = static_cast<float>(std::exp2(ev));
  for (std::size_t i = 0; i < rgb.size() / 3; ++i) {
    for (std::size_t c = 0; c < 3; ++c) {
      const float x = std::max(rgb[3 * i + c], 0.0f) * gain;
      const volatile float y = std::isfinite(x) ? x / (1.0f + x) : 1.0f;  // volatile: no fused multiply-add below
      const volatile float scaled = y * 16384.0f;
      const double q = static_cast<double>(static_cast<std::size_t>(scaled + 0.5f)) / 16384.0;
      const double srgb = q <= 0.0031308 ? 12.92 * q : 1.055 * std::pow(q, 1.0 / 2.4) - 0.055;
      out[4 * i + c] = static_cast<std::uint8_t>(std::lround(std::clamp(srgb, 0.0, 1.0) * 255.0));
    }
    out[4 * i + 3] = 255;
  }
  return out;
}

TEST(PixelPack, Rgba8SimdPackerMatchesItsDefinitionOnEveryTarget) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-14.0f, 14.0f);
  const std::size_t n = 4099;  // not a multiple of any vector: the scalar tail runs too
  std::vector<float> rgb(3 * n);
  for (float& v : rgb) {
    const float sign = u(rng), magnitude = u(rng);
    v = std::exp2(magnitude) * (sign < -10.0f ? -1.0f : 1.0f);
  }
  rgb[0] = std::numeric_limits<float>::infinity();
  rgb[1] = std::numeric_limits<float>::quiet_NaN();
  rgb[2] = -std::numeric_limits<float>::infinity();
  rgb[3] = 0.0f;
  rgb[4] = 3e38f;
  for (double ev : {-6.0, 0.0, 2.5}) {
    const std::vector<std::uint8_t> want = rgba8Definition(rgb, ev);
    for (const std::string& t : kernels::availableTargets()) {
      ASSERT_TRUE(kernels::forceTarget(t));
      std::vector<std::uint8_t> got(4 * n, 0);
      packRgba8Srgb(rgb.data(), n, ev, got.data());
      EXPECT_EQ(got, want) << "target " << t << ", EV " << ev;
    }
    kernels::forceTarget("");
  }
}

TEST(PixelPack, Rgba8MatchesToneMapWithinOneCode) {
  std::vector<float> rgb;
  for (int k = -200; k <= 200; ++k) rgb.push_back(std::exp2(static_cast<float>(k) / 20.0f));
  rgb.push_back(0.0f);
  rgb.push_back(0.0f);
  while (rgb.size() % 3) rgb.push_back(1.0f);
  for (double ev : {-4.0, 0.0, 1.0}) {
    const auto ref = toneMapSrgb8(rgb, ev);
    std::vector<std::uint8_t> got(rgb.size() / 3 * 4);
    packRgba8Srgb(rgb.data(), rgb.size() / 3, ev, got.data());
    for (std::size_t i = 0; i < rgb.size() / 3; ++i) {
      for (std::size_t c = 0; c < 3; ++c)
        EXPECT_NEAR(got[4 * i + c], ref[3 * i + c], 1) << "value " << rgb[3 * i + c] << " EV " << ev;
      EXPECT_EQ(got[4 * i + 3], 255);
    }
  }
}

}  // namespace
}  // namespace fogbeam
