// "No allocation per frame" (issue 3): after the first frames of a size, AirlightImageEvaluator
// and compositeFrame run without touching the heap. The global operator new of this test binary
// counts calls while `counting` is set.
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/lamp_effects.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<bool> counting{false};
std::atomic<long> allocations{0};
}  // namespace

// Replacement allocation functions pair malloc with free by design; GCC cannot see that the
// replaced operator new is what returned the pointer.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  if (counting.load(std::memory_order_relaxed)) allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
// The nothrow forms too (std::get_temporary_buffer's, for one): a replacement set must be whole,
// or a sanitizer's own nothrow new meets this free (ASan: alloc-dealloc-mismatch).
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  if (counting.load(std::memory_order_relaxed)) allocations.fetch_add(1, std::memory_order_relaxed);
  return std::malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t& t) noexcept { return operator new(n, t); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace fogbeam {
namespace {

// Every path of the image evaluator: view table, F table, moving tabulated and spot lamps
// (through `moving`: the pencil per pixel, or each lamp's map of the frame).
// `budget`: FastPathOptions::max_moving_lamps (0: none); with one, the lamps beyond it are
// ranked and left out every frame.
void expectSteadyFramesDoNotAllocate(MovingLampPath moving, int budget = 0) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(100.0);
  s.fog.albedo = 0.95;
  s.fog.phase = makeHenyeyGreenstein(0.85).value();
  s.camera.position_m = {0.0, 0.37, 1.2};
  s.camera.width = 96;
  s.camera.height = 54;
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  ASSERT_TRUE(low);
  auto lamp = [&](Vec3 p, double yawDeg, std::shared_ptr<const Profile> prof, LampMount mount) {
    SceneLamp l;
    l.name = "lamp";
    l.lamp.position_m = p;
    l.lamp.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), 0.0, 0.0);
    l.lamp.profile = std::move(prof);
    l.mount = mount;
    s.lamps.push_back(l);
  };
  lamp({2.2, 0.7, 0.65}, 0.0, *low, LampMount::Vehicle);
  lamp({25.0, -3.0, 8.0}, 0.0, makeProfile(IsotropicProfile{4000.0}).value(), LampMount::World);
  lamp({45.0, 3.5, 0.65}, 180.0, *low, LampMount::World);
  lamp({30.0, 3.5, 0.65}, 180.0, makeProfile(SpotProfile{20000.0, radians(4.0), radians(14.0)}).value(),
       LampMount::World);
  lamp({-300.0, 0.0, 0.65}, 0.0, *low, LampMount::World);  // behind, far: out of the frame (the cutoff)
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  SurfaceBuffers surf;
  renderSurfacesCpu(s, surf);
  FastPathOptions fast;
  fast.view_table_step_deg = 1.0;
  fast.moving_lamps = moving;
  fast.max_moving_lamps = budget;
  auto ev = AirlightImageEvaluator::build(s, AirlightMethod::Accurate, {}, 2, fast);
  ASSERT_TRUE(ev);
  AirlightImage img;
  FrameLayers layers;
  for (int warm = 0; warm < 2; ++warm) {
    ev->evaluate(s, surf, SubsamplingOptions{}, img);
    ev->evaluate(s, surf, SubsamplingOptions{.full = true}, img);
    compositeFrame(s.fog, surf, img, layers);
  }
  allocations = 0;
  counting = true;
  ev->evaluate(s, surf, SubsamplingOptions{}, img);
  ev->evaluate(s, surf, SubsamplingOptions{.full = true}, img);
  compositeFrame(s.fog, surf, img, layers);
  counting = false;
  EXPECT_EQ(allocations.load(), 0) << "heap allocations during two steady frames and a composite";
  EXPECT_GT(img.evaluated, 0u);
  EXPECT_EQ(img.moving_culled, 1u);
  EXPECT_EQ(img.moving_dropped, budget > 0 ? 2u - static_cast<std::size_t>(budget) : 0u);
}

TEST(NoAllocation, SteadyFramesDoNotAllocate) { expectSteadyFramesDoNotAllocate(MovingLampPath::Pencil); }

// The maps are rebuilt every frame (the frame's distances may change with nothing else moving):
// into the buffers of the frames before.
TEST(NoAllocation, SteadyFramesWithLampMapsDoNotAllocate) { expectSteadyFramesDoNotAllocate(MovingLampPath::Map); }

// A lamp budget (FastPathOptions::max_moving_lamps) ranks the lamps every frame, in place.
TEST(NoAllocation, SteadyFramesOverALampBudgetDoNotAllocate) {
  expectSteadyFramesDoNotAllocate(MovingLampPath::Pencil, 1);
}

// The glow and glare layers (lamp_effects.hpp, fast path): a steady scene reuses its glow curves,
// grids, flags and layers.
TEST(NoAllocation, SteadyGlowAndGlareFramesDoNotAllocate) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(100.0);
  s.fog.phase = makeHenyeyGreenstein(0.85).value();
  s.camera.width = 203;
  s.camera.height = 117;
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  ASSERT_TRUE(low);
  SceneLamp a;
  a.name = "oncoming low beam, a long name that does not fit a short string";
  a.lamp.position_m = {60.0, 3.5, 0.65};
  a.lamp.worldFromLamp = worldFromYawPitchRoll(radians(180.0), 0.0, 0.0);
  a.lamp.profile = *low;
  s.lamps.push_back(a);
  a.name = "street";
  a.lamp.position_m = {70.0, -3.0, 8.0};  // T ≈ 2.1: it glows
  a.lamp.profile = makeProfile(IsotropicProfile{4000.0}).value();
  s.lamps.push_back(a);
  // The driver's own low beam over the road: its glow and the veil of the road it lights (kept).
  s.camera.position_m = {0.0, 0.0, 1.2};
  a.name = "own low beam";
  a.mount = LampMount::Vehicle;
  a.lamp.position_m = {2.0, 0.6, 0.65};
  a.lamp.worldFromLamp = Mat3(1.0);
  a.lamp.profile = *low;
  s.lamps.push_back(a);
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  SurfaceBuffers surf;
  renderSurfacesCpu(s, surf);
  GlowOptions glow;
  glow.enabled = true;
  GlareOptions glare;
  glare.enabled = true;
  auto fx = LampEffects::build(s, glow, glare, std::make_shared<ThreadPool>(2));
  ASSERT_TRUE(fx);
  std::vector<float> glowLayer, glareLayer;
  LampEffectsReport rep;
  for (int warm = 0; warm < 2; ++warm) fx->evaluate(s, surf, glowLayer, glareLayer, rep);
  allocations = 0;
  counting = true;
  fx->evaluate(s, surf, glowLayer, glareLayer, rep);
  counting = false;
  EXPECT_EQ(allocations.load(), 0) << "heap allocations during a steady glow and glare frame";
  ASSERT_EQ(rep.lamps.size(), 3u);
  EXPECT_TRUE(rep.ground_veil);
  EXPECT_TRUE(rep.lamps[1].glow_from_table);
  EXPECT_GT(rep.lamps[1].glow_peak_cd_m2, 0.0);
}

}  // namespace
}  // namespace fogbeam
