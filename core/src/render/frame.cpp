// fogbeam — compositing a frame (fogbeam/render/frame.hpp).
//
// One pass over the pixels, in chunks spread over the caller's pool: each chunk's inputs are
// read once (the layer copies are taken from the chunk while it is in cache) and every output
// layer is written once. The transmittance T = e^{−K_t d} is a Highway kernel (double-precision
// exp, compiled per SIMD target by hwy/foreach_target.h and chosen at run time, as
// airlight_kernels_simd.cpp), and so are the sums of the colour layers; results are
// bit-identical to the scalar definition (compositeFrameScalar's arithmetic, kept in
// tests/render/test_composite.cpp):
//
//  * sums: the same float operations in the same order (front = A + G + V; composite =
//    L_s + front; overlay = front + I_a (1 − T)), and no fused multiply-add: GCC contracts
//    a·b + c into an FMA on targets that have one (AVX2, AVX-512) unless told not to, hence
//    -ffp-contract=off for this file (core/CMakeLists.txt: GCC and clang alike);
//  * T: Highway's Exp (≤ 1 ulp in double, its documentation) and std::exp (< 1 ulp, glibc)
//    can differ in the last bits of the double, but T is stored as float, which keeps 24 of the
//    53 bits: both round to the same float unless the double lies within a few ulp of a
//    midpoint between two floats (or below the normal floats). Those lanes — about 2^-20 of
//    all, with the margin below — are recomputed with std::exp, so the float is the scalar
//    one whenever both exps are within kMidpointMarginUlp/2 ulp of the true value.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/frame.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include <fogbeam/render/frame.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>

#ifndef FOGBEAM_FRAME_SCALAR_T_ONCE
#define FOGBEAM_FRAME_SCALAR_T_ONCE
namespace fogbeam::composite_detail {
// The scalar definition of one transmittance: T = e^{−K_t d}, 0 for sky (d = +inf).
inline float transmittanceScalar(double kt, float d) noexcept {
  return std::isinf(d) ? 0.0f : static_cast<float>(std::exp(-kt * static_cast<double>(d)));
}
// A double y rounds to float ambiguously when it is within this many double ulp of a float
// midpoint (bits 0–28 of its mantissa near 2^28). 2^12 ulp: far above the ≤ 2 ulp by which the
// two exps can differ, and still only 2^13 / 2^29 ≈ 1.5e-5 of the lanes go the scalar way.
constexpr std::int64_t kMidpointMarginUlp = 4096;
}  // namespace fogbeam::composite_detail
#endif

HWY_BEFORE_NAMESPACE();
namespace fogbeam::composite_detail::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// t[k] = T(d[k]) for k < n, bit-identical to transmittanceScalar (see the file comment).
void Transmittance(const float* d, std::size_t n, double kt, float* t) {
  const hn::ScalableTag<double> dd;
  const hn::Rebind<float, decltype(dd)> df;  // as many floats as doubles
  const hn::RebindToSigned<decltype(dd)> di;
  const std::size_t N = hn::Lanes(dd);
  const auto negKt = hn::Set(dd, -kt);
  const auto lowMask = hn::Set(di, (std::int64_t{1} << 29) - 1);  // the 29 bits float drops
  const auto midpoint = hn::Set(dd, 0x1p28);
  const auto margin = hn::Set(dd, static_cast<double>(kMidpointMarginUlp));
  const auto smallestNormal = hn::Set(dd, 0x1p-126);  // FLT_MIN: below it float rounds elsewhere
  const auto largest = hn::Set(dd, 0x1p127);
  std::size_t i = 0;
  for (; i + N <= n; i += N) {
    const auto dv32 = hn::LoadU(df, d + i);
    const auto dv = hn::PromoteTo(dd, dv32);
    const auto y = hn::CallExp(dd, hn::Mul(negKt, dv));  // (−K_t)·d = −(K_t·d) exactly
    const auto sky = hn::IsInf(dv);
    const auto tv = hn::DemoteTo(df, hn::IfThenZeroElse(sky, y));  // round to nearest, as static_cast
    // Ambiguous lanes: |low29 − 2^28| < margin, or y outside the normal floats (this includes
    // NaN: the comparisons are false).
    // (The low bits are compared as doubles: x86 before AVX-512 has no 64-bit integer <.)
    const auto low = hn::ConvertTo(dd, hn::And(hn::BitCast(di, y), lowMask));
    const auto nearMid = hn::Lt(hn::Abs(hn::Sub(low, midpoint)), margin);
    const auto inRange = hn::And(hn::Ge(y, smallestNormal), hn::Le(y, largest));
    const auto bad = hn::AndNot(sky, hn::Or(nearMid, hn::Not(inRange)));
    hn::StoreU(tv, df, t + i);
    if (HWY_UNLIKELY(!hn::AllFalse(dd, bad)))
      for (std::size_t k = i; k < i + N; ++k) t[k] = transmittanceScalar(kt, d[k]);
  }
  for (; i < n; ++i) t[i] = transmittanceScalar(kt, d[i]);
}

// composite = surface + front, overlay = front + I_a (1 − t), front = air (+ glow) (+ glare),
// per channel, for pixels [0, n) of interleaved RGB layers; glow, glare may be null.
void Sums(const float* surface, const float* air, const float* glow, const float* glare, const float* t,
          std::size_t n, float ia, float* composite, float* overlay) {
  const hn::ScalableTag<float> df;
  const std::size_t N = hn::Lanes(df);
  const auto one = hn::Set(df, 1.0f), iav = hn::Set(df, ia);
  std::size_t i = 0;
  for (; i + N <= n; i += N) {
    hn::Vec<decltype(df)> fr, fg, fb, sr, sg, sb;
    hn::LoadInterleaved3(df, air + 3 * i, fr, fg, fb);
    if (glow) {
      hn::Vec<decltype(df)> r, g, b;
      hn::LoadInterleaved3(df, glow + 3 * i, r, g, b);
      fr = hn::Add(fr, r);
      fg = hn::Add(fg, g);
      fb = hn::Add(fb, b);
    }
    if (glare) {
      hn::Vec<decltype(df)> r, g, b;
      hn::LoadInterleaved3(df, glare + 3 * i, r, g, b);
      fr = hn::Add(fr, r);
      fg = hn::Add(fg, g);
      fb = hn::Add(fb, b);
    }
    hn::LoadInterleaved3(df, surface + 3 * i, sr, sg, sb);
    hn::StoreInterleaved3(hn::Add(sr, fr), hn::Add(sg, fg), hn::Add(sb, fb), df, composite + 3 * i);
    const auto in = hn::Mul(iav, hn::Sub(one, hn::LoadU(df, t + i)));  // I_a (1 − T)
    hn::StoreInterleaved3(hn::Add(fr, in), hn::Add(fg, in), hn::Add(fb, in), df, overlay + 3 * i);
  }
  for (; i < n; ++i) {
    for (std::size_t c = 0; c < 3; ++c) {
      float front = air[3 * i + c];
      if (glow) front += glow[3 * i + c];
      if (glare) front += glare[3 * i + c];
      composite[3 * i + c] = surface[3 * i + c] + front;
      overlay[3 * i + c] = front + ia * (1.0f - t[i]);
    }
  }
}

}  // namespace fogbeam::composite_detail::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam {
namespace composite_detail {
HWY_EXPORT(Transmittance);
HWY_EXPORT(Sums);

// Pixels per task: 4096 px are 48 KiB per RGB layer, so a chunk's inputs are still in L2 when
// they are copied, and a 1080p frame makes ~500 tasks to balance over the pool.
constexpr std::size_t kChunkPixels = 4096;

struct Job {
  const SurfaceBuffers* surface;
  const AirlightImage* airlight;
  const float* glow;   // null when off
  const float* glare;  // null when off
  FrameLayers* out;
  std::size_t n;
  double kt;
  float ia;
};

void runChunk(const Job& job, std::size_t chunk) {
  const std::size_t p0 = chunk * kChunkPixels, p1 = std::min(job.n, p0 + kChunkPixels), m = p1 - p0;
  FrameLayers& o = *job.out;
  const float* dist = job.surface->distance.data() + p0;
  const float* surf = job.surface->rgb.data() + 3 * p0;
  const float* air = job.airlight->rgb.data() + 3 * p0;
  const float* glow = job.glow ? job.glow + 3 * p0 : nullptr;
  const float* glare = job.glare ? job.glare + 3 * p0 : nullptr;
  float* t = o.transmittance.data() + p0;
  HWY_DYNAMIC_DISPATCH(Transmittance)(dist, m, job.kt, t);
  HWY_DYNAMIC_DISPATCH(Sums)(surf, air, glow, glare, t, m, job.ia, o.composite.data() + 3 * p0,
                             o.overlay.data() + 3 * p0);
  // The layers that carry an input unchanged, copied from the chunk just read.
  std::memcpy(o.distance.data() + p0, dist, m * sizeof(float));
  std::memcpy(o.surface.data() + 3 * p0, surf, 3 * m * sizeof(float));
  std::memcpy(o.airlight.data() + 3 * p0, air, 3 * m * sizeof(float));
  if (glow) std::memcpy(o.glow.data() + 3 * p0, glow, 3 * m * sizeof(float));
  if (glare) std::memcpy(o.glare.data() + 3 * p0, glare, 3 * m * sizeof(float));
}
}  // namespace composite_detail

void compositeFrame(const Medium& fog, const SurfaceBuffers& surface, const AirlightImage& airlight, FrameLayers& out,
                    const EffectLayers& effects, ThreadPool* pool) {
  using namespace composite_detail;
  out.width = surface.width;
  out.height = surface.height;
  const auto n = static_cast<std::size_t>(surface.width) * static_cast<std::size_t>(surface.height);
  // resize() keeps the capacity: no allocation once the buffers have held a frame of this size.
  out.composite.resize(3 * n);
  out.airlight.resize(3 * n);
  out.surface.resize(3 * n);
  out.overlay.resize(3 * n);
  out.transmittance.resize(n);
  out.distance.resize(n);
  // A layer of the wrong size (an effect switched on after the buffers were sized) is left out
  // rather than read out of bounds.
  auto usable = [&](const std::vector<float>* v) { return v != nullptr && v->size() == 3 * n; };
  const bool glow = usable(effects.glow), glare = usable(effects.glare);
  if (glow) out.glow.resize(3 * n);
  else out.glow.clear();
  if (glare) out.glare.resize(3 * n);
  else out.glare.clear();
  const Job job{&surface, &airlight, glow ? effects.glow->data() : nullptr, glare ? effects.glare->data() : nullptr,
                &out, n, fog.extinction_per_m, static_cast<float>(fog.ambient_cd_m2)};
  const std::size_t chunks = (n + kChunkPixels - 1) / kChunkPixels;
  if (pool && pool->size() > 1 && chunks > 1) {
    // One pointer captured: std::function keeps it without allocating (no allocation per frame).
    const Job* j = &job;
    pool->parallelFor(chunks, [j](std::size_t c) { runChunk(*j, c); });
  } else {
    for (std::size_t c = 0; c < chunks; ++c) runChunk(job, c);
  }
}

std::vector<std::uint8_t> toneMapSrgb8(const std::vector<float>& rgb, double exposureEv) {
  const double scale = std::exp2(exposureEv);
  std::vector<std::uint8_t> out(rgb.size());
  for (std::size_t k = 0; k < rgb.size(); ++k) {
    const double x = std::max(0.0, static_cast<double>(rgb[k]) * scale);
    const double lin = x / (1.0 + x);
    const double s = lin <= 0.0031308 ? 12.92 * lin : 1.055 * std::pow(lin, 1.0 / 2.4) - 0.055;
    out[k] = static_cast<std::uint8_t>(std::clamp(std::lround(255.0 * s), 0L, 255L));
  }
  return out;
}

}  // namespace fogbeam
#endif
