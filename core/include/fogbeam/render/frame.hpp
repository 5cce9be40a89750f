// fogbeam — compositing a frame from its surface and airlight layers, and display mapping.
//
//   composite    = L_s + A_m + G + V          (L_s already holds the ambient in-scatter)
//   transmittance T = e^{−K_t d}                (0 for sky)
//   overlay      = (A_m + G + V + I_a (1 − T), T)  so a host image generator does host · T + A
//
// G: the glow of multiple scattering around lamps, V: the driver's veiling luminance (disability
// glare), both optional (render/lamp_effects.hpp; empty layers when off). Both are light added in
// front of the surfaces, so they go with the in-scattered light into the overlay.
//
// All layers are linear cd/m² (white lamps give R = G = B = luminance), rows top to bottom.
//
// Cost (compositeFrame; 2-core Xeon @ 2.5 GHz, AVX-512, Release, 2026-11-26, `fogbeam bench`
// medians): one pass in chunks of 4096 pixels over the pool, every input read once and every
// layer written once, T by a SIMD exp. Back to back in one process: 1280×720 7.6–8.1 → 2.6–2.7 ms,
// 1920×1080 20.3–21.4 → 8.3–8.9 ms (pool of 2; one thread: 5.0–6.3 and 16.5–18.6 ms, bound by
// memory: 8 layers written, ~170 MB a 1080p frame); `fogbeam bench` 7.2 → 3.6 ms, 18.8 → 9.7 ms. The result is bit-identical to the
// scalar definition (the per-pixel loop of the formulas above, in float, T = float(exp(−K_t d))
// in double): frame.cpp explains why, tests/render/test_composite.cpp checks it on every SIMD
// target.
//
// Thread-safety: pure functions on caller-owned buffers; compositeFrame uses `pool` (one
// parallelFor), so calls that share a pool must not overlap (ThreadPool's own rule).
#pragma once

#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/surface.hpp>

#include <cstdint>
#include <vector>

namespace fogbeam {

class ThreadPool;

struct FrameLayers {
  int width = 0, height = 0;
  std::vector<float> composite;      ///< 3 per pixel
  std::vector<float> airlight;       ///< 3 per pixel: in-scattered lamp light A_m
  std::vector<float> surface;        ///< 3 per pixel: L_s
  std::vector<float> overlay;        ///< 3 per pixel: A_m + I_a (1 − T)
  std::vector<float> transmittance;  ///< 1 per pixel
  std::vector<float> distance;       ///< 1 per pixel, metres, +inf for sky
  std::vector<float> glow;           ///< 3 per pixel: G, empty when glow is off
  std::vector<float> glare;          ///< 3 per pixel: V, empty when glare is off
};

/// The optional layers of LampEffects::evaluate (3 floats per pixel each; null or empty: off).
struct EffectLayers {
  const std::vector<float>* glow = nullptr;
  const std::vector<float>* glare = nullptr;
};

/// Fills every layer of `out` from `surface` (L_s, d), `airlight` (A_m, the same size) and the
/// effect layers, with `fog`'s K_t [1/m] and I_a [cd/m²]. Reuses the buffers' capacity: after
/// the first frame of a size it does not allocate. `pool`: spreads the pixels over its threads
/// (null: the calling thread alone); the result does not depend on it.
void compositeFrame(const Medium& fog, const SurfaceBuffers& surface, const AirlightImage& airlight, FrameLayers& out,
                    const EffectLayers& effects = {}, ThreadPool* pool = nullptr);

/// Display mapping of linear luminance: x = L · 2^exposureEv / (1 cd/m²), Reinhard x/(1 + x)
/// per channel, then the sRGB transfer curve, 8 bits. At EV 0, 1 cd/m² shows as mid-grey
/// (display 0.5 before the sRGB curve); each +1 EV doubles the scene's brightness.
[[nodiscard]] std::vector<std::uint8_t> toneMapSrgb8(const std::vector<float>& rgb, double exposureEv);

}  // namespace fogbeam
