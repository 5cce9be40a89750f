// fogbeam — the RGBA16F packer as a Highway kernel (fogbeam/render/pixel_pack.hpp): three
// interleaved float channels and an alpha in, four interleaved binary16 out. On AVX2/AVX-512
// the conversion is the F16C instruction (round to nearest even, as floatToHalf()); other
// targets convert with floatToHalf() (see the comment in PackRgba16F).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/pixel_pack_simd.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/highway.h>

#include <fogbeam/render/pixel_pack.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

HWY_BEFORE_NAMESPACE();
namespace fogbeam::pack::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

void PackRgba16F(const float* rgb, const float* alpha, float alphaConstant, std::size_t n, std::uint16_t* out) {
  std::size_t i = 0;
  // Only where the hardware converts (F16C, on Highway's AVX2 and AVX-512 targets): Highway
  // 1.0.3 emulates DemoteTo(float16) elsewhere by truncation, which would make the channels'
  // bits depend on the CPU. The other targets take the scalar, correctly rounded path.
#if HWY_TARGET == HWY_AVX2 || HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
  const hn::ScalableTag<float> df;
  const hn::Rebind<hwy::float16_t, decltype(df)> dh;
  const hn::RebindToUnsigned<decltype(dh)> du;
  const std::size_t N = hn::Lanes(df);
  // clampToHalfRange, a vector at a time: NaN lanes to 0 (Min and Max return an operand for them).
  const auto kMax = hn::Set(df, kHalfMax), kMin = hn::Set(df, -kHalfMax);
  auto clamp = [&](hn::Vec<decltype(df)> v) { return hn::IfThenZeroElse(hn::IsNaN(v), hn::Min(hn::Max(v, kMin), kMax)); };
  for (; i + N <= n; i += N) {
    hn::Vec<decltype(df)> r, g, b;
    hn::LoadInterleaved3(df, rgb + 3 * i, r, g, b);
    const auto a = alpha ? hn::LoadU(df, alpha + i) : hn::Set(df, alphaConstant);
    hn::StoreInterleaved4(hn::BitCast(du, hn::DemoteTo(dh, clamp(r))), hn::BitCast(du, hn::DemoteTo(dh, clamp(g))),
                          hn::BitCast(du, hn::DemoteTo(dh, clamp(b))), hn::BitCast(du, hn::DemoteTo(dh, clamp(a))), du,
                          out + 4 * i);
  }
#endif
  for (; i < n; ++i) {
    for (std::size_t c = 0; c < 3; ++c) out[4 * i + c] = floatToHalf(clampToHalfRange(rgb[3 * i + c]));
    out[4 * i + 3] = floatToHalf(clampToHalfRange(alpha ? alpha[i] : alphaConstant));
  }
}

// RGBA8 sRGB (packRgba8Srgb's definition, pixel_pack.cpp): per channel x = max(v, 0)·gain,
// y = x/(1 + x) (1 where x is not finite), code = table[⌊y·16384 + 0.5⌋] — the same float
// operations in the same order (no fused multiply-add: -ffp-contract=off for this file,
// core/CMakeLists.txt), so the bytes are the scalar loop's; the
// table is widened to 32 bits for the gather. Four codes make one little-endian word R, G, B, 255.
void PackRgba8Srgb(const float* rgb, std::size_t n, float gain, const std::int32_t* table, std::uint8_t* out) {
  const hn::ScalableTag<float> df;
  const hn::RebindToSigned<decltype(df)> di;
  const hn::RebindToUnsigned<decltype(df)> du;
  const std::size_t N = hn::Lanes(df);
  const auto g = hn::Set(df, gain), one = hn::Set(df, 1.0f), scale = hn::Set(df, 16384.0f), half = hn::Set(df, 0.5f);
  const auto inf = hn::Set(df, std::numeric_limits<float>::infinity());
  auto code = [&](hn::Vec<decltype(df)> v) {
    const auto x = hn::Mul(hn::Max(v, hn::Zero(df)), g);
    // false for ±inf and NaN; a NaN input is caught before Max, which gives 0 for it on x86
    // where std::max(NaN, 0) stays NaN.
    const auto finite = hn::And(hn::Lt(hn::Abs(x), inf), hn::Eq(v, v));
    const auto y = hn::IfThenElse(finite, hn::Div(x, hn::Add(one, x)), one);
    const auto idx = hn::ConvertTo(di, hn::Add(hn::Mul(y, scale), half));  // y ≥ 0: truncation = floor
    return hn::BitCast(du, hn::GatherIndex(di, table, idx));
  };
  std::size_t i = 0;
  for (; i + N <= n; i += N) {
    hn::Vec<decltype(df)> r, gr, b;
    hn::LoadInterleaved3(df, rgb + 3 * i, r, gr, b);
    const auto word = hn::Or(hn::Or(code(r), hn::ShiftLeft<8>(code(gr))),
                             hn::Or(hn::ShiftLeft<16>(code(b)), hn::Set(du, 0xFF000000u)));
    hn::StoreU(word, du, reinterpret_cast<std::uint32_t*>(out + 4 * i));
  }
  for (; i < n; ++i) {
    for (std::size_t c = 0; c < 3; ++c) {
      const float x = std::max(rgb[3 * i + c], 0.0f) * gain;
      const float y = std::isfinite(x) ? x / (1.0f + x) : 1.0f;
      out[4 * i + c] = static_cast<std::uint8_t>(table[static_cast<std::size_t>(y * 16384.0f + 0.5f)]);
    }
    out[4 * i + 3] = 255;
  }
}

}  // namespace fogbeam::pack::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam {
namespace pack {
HWY_EXPORT(PackRgba16F);
HWY_EXPORT(PackRgba8Srgb);
void packRgba8SrgbSimd(const float* rgb, std::size_t n, float gain, const std::int32_t* table, std::uint8_t* out) {
  HWY_DYNAMIC_DISPATCH(PackRgba8Srgb)(rgb, n, gain, table, out);
}
}
void packRgba16F(const float* rgb, const float* alpha, float alphaConstant, std::size_t n, std::uint16_t* out) {
  HWY_DYNAMIC_DISPATCH(pack::PackRgba16F)(rgb, alpha, alphaConstant, n, out);
}
}  // namespace fogbeam
#endif
