// compositeFrame (SIMD, chunks over a pool) against its scalar definition: the per-pixel loop
// that compositeFrame was until 2026-11-26, kept here verbatim as the reference. Every layer
// must be bit-identical, on every compiled SIMD target, with and without a pool, for sizes that
// are not multiples of the vector length or of the chunk, with the effect layers on and off.
#include <fogbeam/render/airlight_kernels.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>

namespace fogbeam {
namespace {

// The scalar definition (frame.cpp before the SIMD pass), unchanged.
void compositeFrameScalar(const Medium& fog, const SurfaceBuffers& surface, const AirlightImage& airlight,
                          FrameLayers& out, const EffectLayers& effects) {
  out.width = surface.width;
  out.height = surface.height;
  const auto n = static_cast<std::size_t>(surface.width) * static_cast<std::size_t>(surface.height);
  out.composite.resize(3 * n);
  out.airlight.assign(airlight.rgb.begin(), airlight.rgb.end());
  out.surface.assign(surface.rgb.begin(), surface.rgb.end());
  out.overlay.resize(3 * n);
  out.transmittance.resize(n);
  out.distance.assign(surface.distance.begin(), surface.distance.end());
  auto usable = [&](const std::vector<float>* v) { return v != nullptr && v->size() == 3 * n; };
  const bool glow = usable(effects.glow), glare = usable(effects.glare);
  if (glow) out.glow.assign(effects.glow->begin(), effects.glow->end());
  else out.glow.clear();
  if (glare) out.glare.assign(effects.glare->begin(), effects.glare->end());
  else out.glare.clear();
  const double kt = fog.extinction_per_m;
  const auto ia = static_cast<float>(fog.ambient_cd_m2);
  for (std::size_t k = 0; k < n; ++k) {
    const float d = surface.distance[k];
    const float t = std::isinf(d) ? 0.0f : static_cast<float>(std::exp(-kt * static_cast<double>(d)));
    out.transmittance[k] = t;
    for (std::size_t c = 0; c < 3; ++c) {
      float front = airlight.rgb[3 * k + c];
      if (glow) front += (*effects.glow)[3 * k + c];
      if (glare) front += (*effects.glare)[3 * k + c];
      out.composite[3 * k + c] = surface.rgb[3 * k + c] + front;
      out.overlay[3 * k + c] = front + ia * (1.0f - t);
    }
  }
}

// Index of the first value whose bits differ, or -1.
long firstDifference(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return 0;
  for (std::size_t k = 0; k < a.size(); ++k)
    if (std::memcmp(&a[k], &b[k], sizeof(float)) != 0) return static_cast<long>(k);
  return -1;
}

void expectIdentical(const FrameLayers& got, const FrameLayers& want, const std::string& what) {
  EXPECT_EQ(got.width, want.width) << what;
  EXPECT_EQ(got.height, want.height) << what;
  const std::pair<const char*, std::pair<const std::vector<float>*, const std::vector<float>*>> layers[] = {
      {"composite", {&got.composite, &want.composite}},
      {"airlight", {&got.airlight, &want.airlight}},
      {"surface", {&got.surface, &want.surface}},
      {"overlay", {&got.overlay, &want.overlay}},
      {"transmittance", {&got.transmittance, &want.transmittance}},
      {"distance", {&got.distance, &want.distance}},
      {"glow", {&got.glow, &want.glow}},
      {"glare", {&got.glare, &want.glare}},
  };
  for (const auto& [name, pair] : layers) {
    ASSERT_EQ(pair.first->size(), pair.second->size()) << what << ": " << name;
    const long k = firstDifference(*pair.first, *pair.second);
    EXPECT_EQ(k, -1) << what << ": layer " << name << " differs first at " << k << ": "
                     << (k >= 0 ? (*pair.first)[static_cast<std::size_t>(k)] : 0.0f) << " vs "
                     << (k >= 0 ? (*pair.second)[static_cast<std::size_t>(k)] : 0.0f);
  }
}

struct Inputs {
  SurfaceBuffers surface;
  AirlightImage air;
  std::vector<float> glow, glare;
};

// Distances: sky, 0, near, far (to 5 km: T underflows to float subnormals and 0 at
// K_t d > 87 and > 103), and random in between; luminances over six decades.
Inputs makeInputs(int w, int h, unsigned seed) {
  Inputs in;
  in.surface.resize(w, h);
  const auto n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  in.air.width = w;
  in.air.height = h;
  in.air.rgb.resize(3 * n);
  in.glow.resize(3 * n);
  in.glare.resize(3 * n);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (std::size_t k = 0; k < n; ++k) {
    const float r = u(rng);
    float d;
    if (r < 0.2f) d = std::numeric_limits<float>::infinity();
    else if (r < 0.22f) d = 0.0f;
    else if (r < 0.3f) d = 5000.0f * u(rng);
    else d = 300.0f * u(rng);
    in.surface.distance[k] = d;
    for (std::size_t c = 0; c < 3; ++c) {
      in.surface.rgb[3 * k + c] = std::pow(10.0f, -4.0f + 6.0f * u(rng));
      in.air.rgb[3 * k + c] = std::pow(10.0f, -5.0f + 5.0f * u(rng));
      in.glow[3 * k + c] = 0.01f * u(rng);
      in.glare[3 * k + c] = 0.001f * u(rng);
    }
  }
  return in;
}

Medium fogOf(double visibility, double ambient) {
  Medium m;
  m.extinction_per_m = extinctionFromVisibility(visibility);
  m.ambient_cd_m2 = ambient;
  return m;
}

TEST(Composite, BitIdenticalToScalarOnEveryTargetWithAndWithoutPool) {
  ThreadPool pool(3);  // more threads than cores: chunks finish in any order
  const Inputs in = makeInputs(1283, 157, 7);  // 201 431 px: 49 chunks of 4096 and a tail of 727
  const Medium fogs[] = {fogOf(100.0, 0.0), fogOf(30.0, 0.05), fogOf(1e6, 1.0)};
  const std::vector<float>* none = nullptr;
  const std::pair<const std::vector<float>*, const std::vector<float>*> effects[] = {
      {none, none}, {&in.glow, none}, {&in.glow, &in.glare}};
  std::vector<std::string> targets = kernels::availableTargets();
  ASSERT_FALSE(targets.empty());
  for (const std::string& target : targets) {
    ASSERT_TRUE(kernels::forceTarget(target));
    for (const Medium& fog : fogs)
      for (const auto& [glow, glare] : effects) {
        const EffectLayers fx{glow, glare};
        FrameLayers want, serial, parallel;
        compositeFrameScalar(fog, in.surface, in.air, want, fx);
        compositeFrame(fog, in.surface, in.air, serial, fx);
        compositeFrame(fog, in.surface, in.air, parallel, fx, &pool);
        const std::string what = target + ", K_t " + std::to_string(fog.extinction_per_m) +
                                 (glow ? ", glow" : "") + (glare ? ", glare" : "");
        expectIdentical(serial, want, what + ", no pool");
        expectIdentical(parallel, want, what + ", pool");
      }
  }
  kernels::forceTarget("");
}

// The transmittance of every float distance in the range that matters, one per float value
// step of ~1e-4 m up to 40 optical depths: 2^22 values, so a few dozen of them fall within the
// midpoint margin where frame.cpp's SIMD exp hands over to std::exp; all must match the scalar.
TEST(Composite, TransmittanceBitIdenticalOverAWideSweep) {
  const int w = 2048, h = 2048;
  SurfaceBuffers surf;
  surf.resize(w, h);
  const Medium fog = fogOf(100.0, 0.5);
  const double maxD = 40.0 / fog.extinction_per_m;
  for (std::size_t k = 0; k < surf.distance.size(); ++k)
    surf.distance[k] = static_cast<float>(maxD * static_cast<double>(k) / static_cast<double>(surf.distance.size()));
  AirlightImage air;
  air.width = w;
  air.height = h;
  air.rgb.assign(surf.rgb.size(), 0.25f);
  FrameLayers want, got;
  compositeFrameScalar(fog, surf, air, want, {});
  for (const std::string& target : kernels::availableTargets()) {
    ASSERT_TRUE(kernels::forceTarget(target));
    compositeFrame(fog, surf, air, got);
    EXPECT_EQ(firstDifference(got.transmittance, want.transmittance), -1) << target;
    EXPECT_EQ(firstDifference(got.overlay, want.overlay), -1) << target;
  }
  kernels::forceTarget("");
}

// An effect layer of the wrong size is left out (as before), and buffers shrink and grow with
// the frame.
TEST(Composite, WrongSizedEffectLayerLeftOutAndSizesChange) {
  ThreadPool pool(2);
  const Medium fog = fogOf(80.0, 0.02);
  FrameLayers got, want;
  for (const auto& [w, h] : {std::pair{64, 48}, std::pair{7, 3}, std::pair{300, 200}}) {
    const Inputs in = makeInputs(w, h, static_cast<unsigned>(w));
    const std::vector<float> shortLayer(5, 1.0f);
    compositeFrameScalar(fog, in.surface, in.air, want, EffectLayers{&shortLayer, &in.glare});
    compositeFrame(fog, in.surface, in.air, got, EffectLayers{&shortLayer, &in.glare}, &pool);
    EXPECT_TRUE(got.glow.empty());
    expectIdentical(got, want, std::to_string(w) + "x" + std::to_string(h));
  }
}

}  // namespace
}  // namespace fogbeam
