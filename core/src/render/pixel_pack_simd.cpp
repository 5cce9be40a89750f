// fogbeam — the RGBA16F packer as a Highway kernel (fogbeam/render/pixel_pack.hpp): three
// interleaved float channels and an alpha in, four interleaved binary16 out. On AVX2/AVX-512
// the conversion is the F16C instruction (round to nearest even, as floatToHalf()); other
// targets convert with floatToHalf() (see the comment in PackRgba16F).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/pixel_pack_simd.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/highway.h>

#include <fogbeam/render/pixel_pack.hpp>

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
  for (; i + N <= n; i += N) {
    hn::Vec<decltype(df)> r, g, b;
    hn::LoadInterleaved3(df, rgb + 3 * i, r, g, b);
    const auto a = alpha ? hn::LoadU(df, alpha + i) : hn::Set(df, alphaConstant);
    hn::StoreInterleaved4(hn::BitCast(du, hn::DemoteTo(dh, r)), hn::BitCast(du, hn::DemoteTo(dh, g)),
                          hn::BitCast(du, hn::DemoteTo(dh, b)), hn::BitCast(du, hn::DemoteTo(dh, a)), du,
                          out + 4 * i);
  }
#endif
  for (; i < n; ++i) {
    for (std::size_t c = 0; c < 3; ++c) out[4 * i + c] = floatToHalf(rgb[3 * i + c]);
    out[4 * i + 3] = floatToHalf(alpha ? alpha[i] : alphaConstant);
  }
}

}  // namespace fogbeam::pack::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam {
namespace pack {
HWY_EXPORT(PackRgba16F);
}
void packRgba16F(const float* rgb, const float* alpha, float alphaConstant, std::size_t n, std::uint16_t* out) {
  HWY_DYNAMIC_DISPATCH(pack::PackRgba16F)(rgb, alpha, alphaConstant, n, out);
}
}  // namespace fogbeam
#endif
