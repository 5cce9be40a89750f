// The service's frame renderer with the issue 7 additions (frame_renderer.hpp): glow and glare
// of the lamps that are on, the GPU airlight stage of the GL surface pass, and rig lamps with an
// aperture expanded into point lamps. Small frames (65 × 37) of tests/data/service/small.toml's
// world: the road plane, a 4000 cd street lamp at (20, −3, 8) m, 80 m visibility.
#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/scene/scene.hpp>

#include <gtest/gtest.h>

#include "test_scale.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

namespace fogbeam::plugin {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 65, kHeight = 37;  // odd: a pixel centre lies on the image centre

const std::string kSmall = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/small.toml";

/// small.toml with `settings` (--set), then `layer` (TOML text, paths relative to small.toml),
/// at 65 × 37, linear RGBA16F.
ServiceConfig configWith(const std::vector<std::string>& settings, const std::string& layer = "") {
  auto c = loadServiceConfig(kSmall, settings);
  EXPECT_TRUE(c) << (c ? "" : c.error().message);
  if (!c) return {};
  if (!layer.empty()) {
    const Status s = applyServiceLayer(*c, layer, "test layer", fs::path(kSmall).parent_path().string());
    EXPECT_TRUE(s) << (s ? "" : s.error().message);
    const Status v = validate(*c);
    EXPECT_TRUE(v) << (v ? "" : v.error().message);
  }
  c->channels.at(0).width = kWidth;
  c->channels.at(0).height = kHeight;
  c->channels.at(0).format = "rgba16f-linear";
  return std::move(c).value();
}

/// A layer whose ego rig is one bending low beam and whose class 0 rig is one low beam, with
/// `lampKeys` (an aperture) added to the traffic lamp, and to the ego lamp when `ego`.
std::string rigLayer(const std::string& lampKeys, bool ego) {
  const std::string profile = "profile = \"../../../config/lamps/low_beam.ies\"\n";
  return "[ego]\n[[ego.lamp]]\nrole = \"low-beam\"\nname = \"ego left low beam\"\nposition_m = [2.2, 0.7, 0.65]\n"
         "bending = true\n" + profile + (ego ? lampKeys : "") +
         "\n[[traffic_class]]\nclass = 0\n[[traffic_class.lamp]]\nrole = \"low-beam\"\nname = \"left low beam\"\n"
         "position_m = [3.7, 0.7, 0.65]\n" + profile + lampKeys;
}

Scene worldOf(const ServiceConfig& c) {
  auto w = loadScene(c.scene_path);
  EXPECT_TRUE(w) << (w ? "" : w.error().message);
  return w ? std::move(w).value() : Scene{};
}

/// The ego at (x, 0, 0) looking down +x with `lights`; an oncoming car (class 0, yaw 180°, on
/// the other lane at y = 3.5 m) at `carX` when given, with `carLights`.
ipc::SimSnapshot stateAt(double egoX, std::uint32_t lights, std::optional<double> carX = std::nullopt,
                         std::uint32_t carLights = ipc::light::kLowBeam, ipc::Clock::time_point now = {}) {
  ipc::SimSnapshot s;
  s.ego.value.pose.position_m = {egoX, 0.0, 0.0};
  s.ego.stamp.valid = true;
  s.lamps.value.lights = lights;
  s.lamps.stamp.valid = true;
  if (carX) {
    ipc::TrafficEntry e;
    e.object.id = 1;
    e.object.pose.position_m = {*carX, 3.5, 0.0};
    e.object.pose.yaw_deg = 180.0f;
    e.object.lights = carLights;
    e.stamp.valid = true;
    e.stamp.received = now;
    s.traffic.push_back(e);
  }
  return s;
}

double sum(const std::vector<float>& v) { return std::accumulate(v.begin(), v.end(), 0.0); }

/// R + G + B of pixel (i, j) of a 3-per-pixel layer (3 × the luminance for white light).
double at(const std::vector<float>& layer, int i, int j) {
  const std::size_t k = 3 * (static_cast<std::size_t>(j) * kWidth + static_cast<std::size_t>(i));
  return static_cast<double>(layer[k]) + static_cast<double>(layer[k + 1]) + static_cast<double>(layer[k + 2]);
}

// The street lamp's pixel seen from x = −40 (pinhole projection of its direction in the camera
// frame, x forward; the eye as stateAt places it).
std::pair<int, int> streetLampPixelFromMinus40(const Scene& world) {
  const Vec3 eye{-40.0, 0.37, 1.2};
  const Vec3 d = world.lamps.at(0).lamp.position_m - eye;
  const double focal = 0.5 * kWidth / std::tan(radians(30.0));
  return {static_cast<int>(0.5 * kWidth - focal * d.y / d.x), static_cast<int>(0.5 * kHeight - focal * d.z / d.x)};
}

// The frame from x = −40 with the same config but glow off.
bool renderWithoutGlow(const ServiceConfig& cfg, const Scene& world, RenderedFrame& out) {
  ServiceConfig off = cfg;
  off.effects.glow.enabled = false;
  auto r0 = ChannelRenderer::create(off, 0, world, nullptr);
  return r0 && (*r0)->render(stateAt(-40.0, ipc::light::kLowBeam), ipc::Clock::now(), true, out);
}

const LampEffectsReport::Lamp* lampNamed(const LampEffectsReport& r, const std::string& name) {
  for (const auto& l : r.lamps)
    if (l.name == name) return &l;
  return nullptr;
}

// [render] max_moving_lamps: with a budget of one lamp, of two oncoming cars (one low beam each)
// the far one is left out of the frame and counted; the frame is the one with the near car alone
// (within the cutoff: the lamps' shares of it differ), and without the budget both are there.
TEST(ChannelRendererEffects, TrafficBeyondTheLampBudgetIsLeftOutDimmestFirst) {
  auto frameWith = [](const std::vector<std::string>& set, const std::vector<double>& cars, RenderedFrame& f) {
    const ServiceConfig cfg = configWith(set, rigLayer("", false));
    auto r = ChannelRenderer::create(cfg, 0, worldOf(cfg), nullptr);
    ASSERT_TRUE(r) << r.error().message;
    ipc::SimSnapshot s = stateAt(0.0, 0);
    for (std::size_t k = 0; k < cars.size(); ++k) {
      ipc::TrafficEntry e;
      e.object.id = static_cast<std::uint32_t>(k + 1);
      e.object.pose.position_m = {cars[k], 3.5, 0.0};
      e.object.pose.yaw_deg = 180.0f;
      e.object.lights = ipc::light::kLowBeam;
      e.stamp.valid = true;
      e.stamp.received = ipc::Clock::now();
      s.traffic.push_back(e);
    }
    ASSERT_TRUE((*r)->render(s, ipc::Clock::now(), true, f));
  };
  RenderedFrame budget, nearOnly, both;
  frameWith({"render.max_moving_lamps=1", "render.subsampling=false"}, {30.0, 90.0}, budget);
  frameWith({"render.max_moving_lamps=1", "render.subsampling=false"}, {30.0}, nearOnly);
  frameWith({"render.max_moving_lamps=0", "render.subsampling=false"}, {30.0, 90.0}, both);
  EXPECT_EQ(budget.traffic_lamps_dropped, 1u);
  EXPECT_EQ(nearOnly.traffic_lamps_dropped, 0u);
  EXPECT_EQ(both.traffic_lamps_dropped, 0u);
  const std::vector<float>& a = budget.layers.airlight;
  ASSERT_EQ(a.size(), nearOnly.layers.airlight.size());
  double diff = 0.0, farLight = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    diff = std::max(diff, static_cast<double>(std::abs(a[k] - nearOnly.layers.airlight[k])));
    farLight = std::max(farLight, static_cast<double>(both.layers.airlight[k] - a[k]));
  }
  EXPECT_LE(diff, 1e-3);      // [render] moving_lamp_cutoff_cd_m2, the default
  EXPECT_GT(farLight, 1e-2);  // the far car's light, which the budget left out
}

TEST(ChannelRendererEffects, GlareOfAnOncomingCarRisesAsItApproaches) {
  const ServiceConfig cfg = configWith({"glare.enabled=true"});
  const Scene world = worldOf(cfg);
  auto r = ChannelRenderer::create(cfg, 0, world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  const auto now = ipc::Clock::now();
  const double kt = cfg.fog.extinction_per_m;
  double previousCar = 0.0, previousTotal = 0.0;
  for (const double carX : {120.0, 80.0, 50.0, 30.0}) {
    RenderedFrame f;
    ASSERT_TRUE((*r)->render(stateAt(0.0, ipc::light::kLowBeam, carX, ipc::light::kLowBeam, now), now, true, f));
    const LampEffectsReport& fx = f.effects;
    const auto* car = lampNamed(fx, "left low beam");
    ASSERT_NE(car, nullptr);
    ASSERT_TRUE(car->visible) << "car at " << carX;
    // Direct light at the eye, E = I e^{−K_t R} / R²: positive, rising as R falls, and below the
    // bound the low beam's peak intensity (26 410 cd, config/lamps/README.md) sets.
    const double R = car->distance_m;
    EXPECT_GT(car->eye_illuminance_lx, previousCar) << "car at " << carX;
    EXPECT_LE(car->eye_illuminance_lx, 26410.0 * std::exp(-kt * R) / (R * R));
    // (K_t from the fog as a message carries it, a float: 1e-6.)
    EXPECT_NEAR(car->eye_illuminance_lx, car->intensity_cd * std::exp(-kt * R) / (R * R),
                1e-6 * car->eye_illuminance_lx);
    EXPECT_GT(fx.eye_illuminance_lx, previousTotal);
    EXPECT_GT(fx.veiling_luminance_cd_m2, 0.0);
    std::printf("  car at %5.1f m: E_car %.3e lx (I %.0f cd), E total %.3e lx, L_v centre %.3e cd/m2, glare %.2f ms\n",
                R, car->eye_illuminance_lx, car->intensity_cd, fx.eye_illuminance_lx, fx.veiling_luminance_cd_m2,
                1e3 * fx.glare_seconds);
    previousCar = car->eye_illuminance_lx;
    previousTotal = fx.eye_illuminance_lx;
    // The glare layer is the veiling luminance per pixel: at the centre pixel, the report's
    // centre value (white lamps: R = G = B).
    ASSERT_EQ(f.layers.glare.size(), 3u * kWidth * kHeight);
    EXPECT_NEAR(at(f.layers.glare, kWidth / 2, kHeight / 2) / 3.0, fx.veiling_luminance_cd_m2,
                0.01 * fx.veiling_luminance_cd_m2);
    EXPECT_TRUE(f.layers.glow.empty());  // glow off
    EXPECT_GT(f.timings.effects_ms, 0.0);
  }
}

// The default glow (the multiple-scattering tables): brightest at the lamp's image and falling
// away from it, present at any optical distance (the tables start at K_t R = 0.25), none on
// surfaces nearer than half the lamp's distance; in the composite.
TEST(ChannelRendererEffects, TableGlowPeaksAtTheLampAndFallsAwayFromIt) {
  const ServiceConfig cfg = configWith({"glow.enabled=true"});
  const Scene world = worldOf(cfg);
  auto r = ChannelRenderer::create(cfg, 0, world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  RenderedFrame f;
  ASSERT_TRUE((*r)->render(stateAt(-40.0, ipc::light::kLowBeam), ipc::Clock::now(), true, f));
  const auto* lamp = lampNamed(f.effects, "street lamp");
  ASSERT_NE(lamp, nullptr);
  EXPECT_TRUE(lamp->glow_from_table);
  EXPECT_EQ(lamp->apsf_terms, 0);
  EXPECT_GT(lamp->glow_peak_cd_m2, 0.0);
  ASSERT_EQ(f.layers.glow.size(), 3u * kWidth * kHeight);
  const auto [li, lj] = streetLampPixelFromMinus40(world);
  ASSERT_TRUE(li >= 0 && li < kWidth && lj >= 0 && lj < kHeight);
  const double atLamp = at(f.layers.glow, li, lj), left = at(f.layers.glow, li - 20, lj),
               right = at(f.layers.glow, li + 20, lj);
  EXPECT_GT(left, 0.0);
  EXPECT_GT(right, 0.0);
  EXPECT_GT(atLamp, 2.0 * std::max(left, right));
  // The road a few metres ahead is nearer than half the street lamp's distance: none of its glow
  // (with the driver's low beams off: theirs and the veil of the road they light are there).
  RenderedFrame dark;
  ASSERT_TRUE((*r)->render(stateAt(-40.0, 0), ipc::Clock::now(), true, dark));
  EXPECT_LT(at(dark.layers.glow, kWidth / 2, kHeight - 1), 1e-3 * atLamp);
  EXPECT_GT(at(f.layers.glow, kWidth / 2, kHeight - 1), at(dark.layers.glow, kWidth / 2, kHeight - 1));
  std::printf("  street lamp at %.1f m (K_t R %.2f): table glow at its pixel %.3e cd/m2, 20 px left %.3e, right %.3e\n",
              lamp->distance_m, lamp->optical_distance, atLamp, left, right);
  RenderedFrame near;
  ASSERT_TRUE((*r)->render(stateAt(-3.0, ipc::light::kLowBeam), ipc::Clock::now(), true, near));
  const auto* nearLamp = lampNamed(near.effects, "street lamp");
  ASSERT_NE(nearLamp, nullptr);
  EXPECT_LT(nearLamp->optical_distance, 1.1);
  EXPECT_GT(sum(near.layers.glow), 0.0);
  // The composite is the frame without the glow plus the glow layer, and plus what the glow's
  // fog light ([glow] surfaces, on by default) adds to the surface layer: never darker there.
  RenderedFrame g;
  ASSERT_TRUE(renderWithoutGlow(cfg, world, g));
  double fogLight = 0.0;
  for (std::size_t k = 0; k < g.layers.composite.size(); ++k) {
    const double added = static_cast<double>(f.layers.surface[k]) - static_cast<double>(g.layers.surface[k]);
    ASSERT_GE(added, -1e-5 * (1.0 + static_cast<double>(g.layers.surface[k]))) << k;
    fogLight += added;
    const double want = static_cast<double>(g.layers.composite[k]) + static_cast<double>(f.layers.glow[k]) + added;
    ASSERT_NEAR(f.layers.composite[k], want, 1e-4 * std::max(want, 1e-3)) << k;
  }
  std::printf("  fog light on the surfaces: %.4g cd/m2 summed over the frame's channels (glow layer %.4g)\n", fogLight,
              sum(f.layers.glow));
}

TEST(ChannelRendererEffects, ApsfGlowSurroundsAVisibleLampAndAddsToTheComposite) {
  const ServiceConfig cfg = configWith({"glow.enabled=true", "glow.model=\"apsf\""});
  const Scene world = worldOf(cfg);
  auto r = ChannelRenderer::create(cfg, 0, world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  RenderedFrame f;
  // From x = −40 the street lamp is 60 m away (K_t R = 2.3 ≥ fade_in 2), 6.5° above the axis.
  ASSERT_TRUE((*r)->render(stateAt(-40.0, ipc::light::kLowBeam), ipc::Clock::now(), true, f));
  const auto* lamp = lampNamed(f.effects, "street lamp");
  ASSERT_NE(lamp, nullptr);
  EXPECT_TRUE(lamp->visible);
  EXPECT_GT(lamp->apsf_terms, 0);
  EXPECT_GT(lamp->glow_peak_cd_m2, 0.0);
  EXPECT_DOUBLE_EQ(f.effects.veiling_luminance_cd_m2, 0.0);  // glare off
  EXPECT_TRUE(f.layers.glare.empty());
  ASSERT_EQ(f.layers.glow.size(), 3u * kWidth * kHeight);
  // The lamp's pixel (pinhole projection of its direction in the camera frame, x forward).
  const auto [li, lj] = streetLampPixelFromMinus40(world);
  ASSERT_TRUE(li >= 0 && li < kWidth && lj >= 0 && lj < kHeight);
  // The glow layer is the multiple-scattering halo that single scattering (the airlight layer)
  // misses: nothing at the lamp's own image, where single scattering dominates, and a halo
  // around it, here on the sky 20 px (~18°) to either side; none on the road in front, which is
  // nearer than half the lamp's distance (the glow builds up along the last half of the way).
  const double left = at(f.layers.glow, li - 20, lj), right = at(f.layers.glow, li + 20, lj);
  EXPECT_GT(left, 0.0);
  EXPECT_GT(right, 0.0);
  EXPECT_LT(at(f.layers.glow, li, lj), 0.5 * std::min(left, right));
  EXPECT_EQ(at(f.layers.glow, kWidth / 2, kHeight - 1), 0.0);
  std::printf("  street lamp at %.1f m (K_t R %.2f): glow at the lamp's pixel (%d, %d) %.3e cd/m2, 20 px left %.3e, "
              "right %.3e; %.2f ms\n",
              lamp->distance_m, lamp->optical_distance, li, lj, at(f.layers.glow, li, lj), left, right,
              1e3 * f.effects.glow_seconds);
  // Nearer than K_t R = 1.1 (29 m in this fog; from x = −3 the lamp is 24 m away) a lamp has no
  // glow (it fades in from 1.1, GlowOptions).
  RenderedFrame near;
  ASSERT_TRUE((*r)->render(stateAt(-3.0, ipc::light::kLowBeam), ipc::Clock::now(), true, near));
  const auto* nearLamp = lampNamed(near.effects, "street lamp");
  ASSERT_NE(nearLamp, nullptr);
  EXPECT_TRUE(nearLamp->visible);
  EXPECT_LT(nearLamp->optical_distance, 1.1);
  EXPECT_EQ(sum(near.layers.glow), 0.0);
  // It is in the composite and in the overlay: both are the frame without glow plus the glow.
  RenderedFrame g;
  ASSERT_TRUE(renderWithoutGlow(cfg, world, g));
  double worst = 0.0;
  for (std::size_t k = 0; k < g.layers.composite.size(); ++k) {
    // Plus the fog light the glow adds to the surface layer ([glow] surfaces, on by default).
    const double added = static_cast<double>(f.layers.surface[k]) - static_cast<double>(g.layers.surface[k]);
    const double want = static_cast<double>(g.layers.composite[k]) + static_cast<double>(f.layers.glow[k]) + added;
    worst = std::max(worst, std::abs(static_cast<double>(f.layers.composite[k]) - want) / std::max(want, 1e-6));
    EXPECT_NEAR(f.layers.overlay[k], g.layers.overlay[k] + f.layers.glow[k], 1e-5f * (1.0f + f.layers.overlay[k]));
  }
  EXPECT_LT(worst, 1e-5);
}

TEST(ChannelRendererEffects, OffGivesNoLayersAndZeroFigures) {
  const ServiceConfig cfg = configWith({});
  ASSERT_FALSE(cfg.effects.glow.enabled || cfg.effects.glare.enabled);
  const Scene world = worldOf(cfg);
  auto r = ChannelRenderer::create(cfg, 0, world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  const auto now = ipc::Clock::now();
  RenderedFrame f;
  ASSERT_TRUE((*r)->render(stateAt(0.0, ipc::light::kLowBeam, 40.0, ipc::light::kLowBeam, now), now, true, f));
  EXPECT_TRUE(f.layers.glow.empty());
  EXPECT_TRUE(f.layers.glare.empty());
  EXPECT_TRUE(f.effects.lamps.empty());
  EXPECT_EQ(f.effects.eye_illuminance_lx, 0.0);
  EXPECT_EQ(f.effects.veiling_luminance_cd_m2, 0.0);
  EXPECT_EQ(f.timings.effects_ms, 0.0);
  EXPECT_GT(sum(f.layers.airlight), 0.0);  // the frame itself is there
}

TEST(ChannelRendererEffects, LampsSwitchedOffByLightBitsGiveNoGlare) {
  const ServiceConfig cfg = configWith({"glare.enabled=true", "glow.enabled=true"});
  const Scene world = worldOf(cfg);
  auto r = ChannelRenderer::create(cfg, 0, world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  const auto now = ipc::Clock::now();
  RenderedFrame dark, lit;
  // Ego at −40 with its low beam on: the street lamp is in view; the car 60 m ahead, dark
  // (position lamps: its rig has none) or with its low beam.
  const std::uint32_t ego = ipc::light::kLowBeam;
  ASSERT_TRUE((*r)->render(stateAt(-40.0, ego, 20.0, ipc::light::kPosition, now), now, true, dark));
  ASSERT_TRUE((*r)->render(stateAt(-40.0, ego, 20.0, ipc::light::kLowBeam, now), now, true, lit));
  EXPECT_EQ(lampNamed(dark.effects, "left low beam"), nullptr);  // its bit is off: not in the frame
  const auto* car = lampNamed(lit.effects, "left low beam");
  ASSERT_NE(car, nullptr);
  EXPECT_TRUE(car->visible);
  // Both frames see the street lamp (always on); only the lit one also the car.
  EXPECT_NEAR(lit.effects.eye_illuminance_lx - dark.effects.eye_illuminance_lx, car->eye_illuminance_lx,
              1e-9 * lit.effects.eye_illuminance_lx);
  EXPECT_GT(lit.effects.veiling_luminance_cd_m2, dark.effects.veiling_luminance_cd_m2);
  EXPECT_GT(sum(lit.layers.glare), sum(dark.layers.glare));
  // The driver's own lamps, on in both frames, have no glare and nothing at the eye: the bonnet
  // hides them (LampEffects); with the tables they glow.
  const auto* own = lampNamed(lit.effects, "ego left low beam");
  ASSERT_NE(own, nullptr);
  EXPECT_TRUE(own->own);
  EXPECT_FALSE(own->visible);
  EXPECT_EQ(own->eye_illuminance_lx, 0.0);
  EXPECT_GT(own->glow_peak_cd_m2, 0.0);
}

// --- rig lamps with an aperture -----------------------------------------------------------

TEST(RigApertures, ExpandIntoPointsThatSwitchAndBendAsTheirLamp) {
  const ServiceConfig cfg = configWith({}, rigLayer("aperture = \"rectangle\"\naperture_size_m = [0.2, 0.1]\n", true));
  ASSERT_EQ(cfg.ego.lamps.size(), 1u);
  const RigLamp& lamp = cfg.ego.lamps[0];
  ASSERT_EQ(lamp.lamp.aperture.shape, ApertureShape::Rectangle);
  const std::vector<RigPoint> points = expandRig(cfg.ego);
  ASSERT_EQ(points.size(), 9u);  // 3 × 3 Gauss–Legendre (aperture_samples default 3)
  Vec3 colour{0.0}, centroid{0.0};
  for (std::size_t k = 0; k < points.size(); ++k) {
    EXPECT_EQ(points[k].rig_lamp, 0u);
    EXPECT_EQ(points[k].lamp.name, "ego left low beam [" + std::to_string(k + 1) + "/9]");
    EXPECT_EQ(points[k].lamp.lamp.profile, lamp.lamp.lamp.profile);
    colour += points[k].lamp.lamp.color;
    centroid += points[k].lamp.lamp.color.x * points[k].lamp.lamp.position_m;
  }
  // Weights sum to 1 (the lamp's intensity is kept) and average to the lamp's centre.
  EXPECT_NEAR(colour.x, 1.0, 1e-12);
  EXPECT_NEAR(glm::length(centroid - lamp.lamp.lamp.position_m), 0.0, 1e-12);

  // Placed at a pose with bending: the face turns as one piece about the vertical through the
  // lamp's centre. The weighted centre lands where the lamp itself is placed, distances between
  // points are kept, and every point stays in the placed lamp's y–z plane.
  const Mat3 R = worldFromYawPitchRoll(radians(30.0), radians(2.0), 0.0);
  const Vec3 O{10.0, 5.0, 0.3};
  const Mat3 bend = worldFromYawPitchRoll(radians(12.0), 0.0, 0.0);
  const Vec3 centre = O + R * lamp.lamp.lamp.position_m;
  const Mat3 orientation = R * bend * lamp.lamp.lamp.worldFromLamp;
  std::vector<SceneLamp> placed;
  Vec3 placedCentroid{0.0};
  for (const RigPoint& p : points) {
    placed.push_back(placeRigPoint(p, lamp, R, O, &bend));
    placedCentroid += p.lamp.lamp.color.x * placed.back().lamp.position_m;
    EXPECT_NEAR(glm::dot(placed.back().lamp.position_m - centre, orientation[0]), 0.0, 1e-12);
    EXPECT_LT(glm::length(placed.back().lamp.worldFromLamp[0] - orientation[0]), 1e-12);
  }
  EXPECT_LT(glm::length(placedCentroid - centre), 1e-12);
  for (std::size_t a = 0; a < points.size(); ++a)
    for (std::size_t b = a + 1; b < points.size(); ++b)
      EXPECT_NEAR(glm::length(placed[a].lamp.position_m - placed[b].lamp.position_m),
                  glm::length(points[a].lamp.lamp.position_m - points[b].lamp.lamp.position_m), 1e-12);
  // Without bending, the same points at the pose: the face is the lamp's unbent face.
  const SceneLamp straight = placeRigPoint(points[0], lamp, R, O, nullptr);
  EXPECT_LT(glm::length(straight.lamp.position_m - (O + R * points[0].lamp.lamp.position_m)), 1e-12);
}

TEST(RigApertures, TrafficLampPointsAreRenderedAndSwitchTogether) {
  const std::string disc = "aperture = \"disc\"\naperture_size_m = 0.2\n";
  const ServiceConfig withFace = configWith({"glare.enabled=true"}, rigLayer(disc, false));
  const ServiceConfig point = configWith({"glare.enabled=true"}, rigLayer("", false));
  const Scene world = worldOf(withFace);
  auto a = ChannelRenderer::create(withFace, 0, world, nullptr);
  auto b = ChannelRenderer::create(point, 0, world, nullptr);
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_TRUE(b) << b.error().message;
  const auto now = ipc::Clock::now();
  RenderedFrame fa, fb, off;
  ASSERT_TRUE((*a)->render(stateAt(0.0, 0, 30.0, ipc::light::kLowBeam, now), now, true, fa));
  ASSERT_TRUE((*b)->render(stateAt(0.0, 0, 30.0, ipc::light::kLowBeam, now), now, true, fb));
  ASSERT_TRUE((*a)->render(stateAt(0.0, 0, 30.0, ipc::light::kPosition, now), now, true, off));
  // A disc of default samples: 2 rings × 6 angles, every point in the frame while its bit is on,
  // none when it is off.
  std::size_t n = 0, nOff = 0;
  for (const auto& l : fa.effects.lamps) n += l.name.rfind("left low beam [", 0) == 0;
  for (const auto& l : off.effects.lamps) nOff += l.name.rfind("left low beam [", 0) == 0;
  EXPECT_EQ(n, 12u);
  EXPECT_EQ(nOff, 0u);
  EXPECT_NE(lampNamed(fb.effects, "left low beam"), nullptr);
  // 30 m away a 0.2 m lens is a point to within far less than a per cent: the airlight and the
  // glare of its points (each weighted by its colour) sum to the point lamp's. Glare away from
  // the lamp's image (the image centre, 5° from it): next to the image the CIE function's
  // 1/θ³ makes a pixel's value depend on where within it each point falls.
  const double airA = sum(fa.layers.airlight), airB = sum(fb.layers.airlight);
  EXPECT_NEAR(airA, airB, 0.01 * airB);
  const double glareA = at(fa.layers.glare, kWidth / 2, kHeight / 2), glareB = at(fb.layers.glare, kWidth / 2, kHeight / 2);
  EXPECT_NEAR(glareA, glareB, 0.01 * glareB);
  std::printf("  disc (12 points) / point lamp at 30 m: airlight sum %.6f, glare at the centre %.6f\n", airA / airB,
              glareA / glareB);
  EXPECT_GT(airA, sum(off.layers.airlight));  // and the lamp's light is really in the frame
  EXPECT_GT(glareA, at(off.layers.glare, kWidth / 2, kHeight / 2));
}

TEST(RigApertures, EgoLampPointsSwitchByTheirLampsBit) {
  // Two ego lamps: a low beam with a 3 × 3 face (9 points) and a high beam, a point; and the
  // low beam alone. Airlight adds up lamp by lamp, so with every pixel evaluated:
  //  * low beam bit: the same frame as the low beam's rig alone (its 9 points on, the high beam off);
  //  * low + high = both + none: the high beam bit lights exactly the rest.
  // Each point is a vehicle lamp with view tables of its own, whose insets around the lamp's
  // image keep their size whatever the step: 19 lamps' tables in the two renderers, most of the
  // time (52 s under ASan). FOGBEAM_TEST_SCALE thins the face, points per axis by √scale but
  // at least 2 (2 × 2 at 0.25, 9 lamps' tables): still several points, each switching with
  // the lamp's bit, and the sums add up exactly whatever their number.
  const int perAxis = static_cast<int>(test::scaled(3, 2, std::sqrt(test::scale())));
  const std::string lamps = "../../../config/lamps/";
  const std::string low = "[[ego.lamp]]\nrole = \"low-beam\"\nname = \"low\"\nposition_m = [2.2, 0.7, 0.65]\nprofile = \"" +
                          lamps + "low_beam.ies\"\naperture = \"rectangle\"\naperture_size_m = [0.2, 0.1]\n" +
                          "aperture_samples = " + std::to_string(perAxis) + "\n";
  const std::string high = "[[ego.lamp]]\nrole = \"high-beam\"\nname = \"high\"\nposition_m = [2.2, 0.55, 0.65]\n"
                           "profile = \"" + lamps + "high_beam.ies\"\n";
  // View tables at 4° (the config's 1° costs 16× more to build): the sums below add up exactly
  // whatever the step, and the tables' accuracy is tests/render's subject.
  const ServiceConfig both = configWith({"render.subsampling=false", "render.view_table_step_deg=4.0"}, "[ego]\n" + low + high);
  const ServiceConfig lowOnly = configWith({"render.subsampling=false", "render.view_table_step_deg=4.0"}, "[ego]\n" + low);
  ASSERT_EQ(expandRig(both.ego).size(), static_cast<std::size_t>(perAxis * perAxis + 1));
  const Scene world = worldOf(both);
  auto r = ChannelRenderer::create(both, 0, world, nullptr);
  auto r1 = ChannelRenderer::create(lowOnly, 0, world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  ASSERT_TRUE(r1) << r1.error().message;
  const auto now = ipc::Clock::now();
  auto airlight = [&](ChannelRenderer& renderer, std::uint32_t lights) {
    RenderedFrame f;
    EXPECT_TRUE(renderer.render(stateAt(0.0, lights), now, true, f));
    return sum(f.layers.airlight);
  };
  const double none = airlight(**r, 0), lowOn = airlight(**r, ipc::light::kLowBeam);
  const double highOn = airlight(**r, ipc::light::kHighBeam);
  const double bothOn = airlight(**r, ipc::light::kLowBeam | ipc::light::kHighBeam);
  const double lowAlone = airlight(**r1, ipc::light::kLowBeam);
  std::printf("  airlight sums: none %.1f, low %.1f (its rig alone %.1f), high %.1f, both %.1f\n", none, lowOn, lowAlone,
              highOn, bothOn);
  EXPECT_GT(lowOn, none);
  EXPECT_GT(highOn, none);
  EXPECT_NEAR(lowOn, lowAlone, 1e-5 * lowOn);
  EXPECT_NEAR(lowOn + highOn, bothOn + none, 1e-5 * bothOn);
}

// LampEffectsReport's figures are luminous (× the colour's mean), and an aperture point's colour
// carries its weight (expandAperture): the points' figures add up to the lamp's.
TEST(RigApertures, ReportedGlareFiguresOfAnApertureLampAreThePointLamps) {
  const ServiceConfig withFace = configWith({"glare.enabled=true"}, rigLayer("aperture = \"disc\"\naperture_size_m = 0.2\n", false));
  const ServiceConfig point = configWith({"glare.enabled=true"}, rigLayer("", false));
  const Scene world = worldOf(withFace);
  auto a = ChannelRenderer::create(withFace, 0, world, nullptr);
  auto b = ChannelRenderer::create(point, 0, world, nullptr);
  ASSERT_TRUE(a && b);
  const auto now = ipc::Clock::now();
  RenderedFrame fa, fb;
  ASSERT_TRUE((*a)->render(stateAt(0.0, 0, 30.0, ipc::light::kLowBeam, now), now, true, fa));
  ASSERT_TRUE((*b)->render(stateAt(0.0, 0, 30.0, ipc::light::kLowBeam, now), now, true, fb));
  EXPECT_NEAR(fa.effects.eye_illuminance_lx, fb.effects.eye_illuminance_lx, 0.01 * fb.effects.eye_illuminance_lx);
  EXPECT_NEAR(fa.effects.veiling_luminance_cd_m2, fb.effects.veiling_luminance_cd_m2,
              0.01 * fb.effects.veiling_luminance_cd_m2);
}

// --- the GPU airlight stage -------------------------------------------------------------------

bool environmentFailure(const std::string& why) {
  return why.rfind("no EGL available", 0) == 0 || why.rfind("could not create an OpenGL", 0) == 0 ||
         why.rfind("EGL platform", 0) == 0 || why.rfind("OpenGL 4.3 or later", 0) == 0;
}

TEST(ChannelRendererGpu, NeedsTheGlSurfacePass) {
  const ServiceConfig cfg = configWith({"render.surface=\"auto\"", "render.airlight=\"gpu\""});
  const Scene world = worldOf(cfg);
  auto r = ChannelRenderer::create(cfg, 0, world, nullptr);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("airlight = \"gpu\" needs the GL surface pass"), std::string::npos)
      << r.error().message;
}

// Suite name from "Gl": scripts/asan.sh runs tests that open a GL context (by that prefix) with
// leak detection off, Mesa's driver leaking at exit.
TEST(GlChannelRenderer, GpuAirlightMatchesTheCpuAccuratePath) {
  auto glGpu = GlSurfacePass::create();
  if (!glGpu) {
    const char* require = std::getenv("FOGBEAM_REQUIRE_GL");
    if (environmentFailure(glGpu.error().message) && !(require && std::string(require) == "1")) {
      GTEST_SKIP() << "no usable EGL/OpenGL: " << glGpu.error().message;
    }
    FAIL() << glGpu.error().message;
  }
  auto glCpu = GlSurfacePass::create();
  ASSERT_TRUE(glCpu) << glCpu.error().message;
  // The CPU side at its most exact: every pixel, traffic per ray, fine ego view tables.
  const std::vector<std::string> common{"render.surface=\"gl\"", "render.subsampling=false",
                                        "render.moving_lamps=\"per-ray\"", "render.view_table_step_deg=0.25",
                                        "glare.enabled=true"};
  std::vector<std::string> gpuSet = common;
  gpuSet.push_back("render.airlight=\"gpu\"");
  const ServiceConfig gpuCfg = configWith(gpuSet);
  const ServiceConfig cpuCfg = configWith(common);
  const Scene world = worldOf(cpuCfg);
  auto gpu = ChannelRenderer::create(gpuCfg, 0, world, glGpu->get());
  auto cpu = ChannelRenderer::create(cpuCfg, 0, world, glCpu->get());
  ASSERT_TRUE(gpu) << gpu.error().message;
  ASSERT_TRUE(cpu) << cpu.error().message;
  EXPECT_TRUE((*glGpu)->airlightEnabled());
  const auto now = ipc::Clock::now();
  // Ego low and high beams, the street lamp, an oncoming car 40 m ahead.
  const auto state = stateAt(0.0, ipc::light::kLowBeam | ipc::light::kHighBeam, 40.0, ipc::light::kLowBeam, now);
  RenderedFrame g, c;
  ASSERT_TRUE((*gpu)->render(state, now, true, g));
  ASSERT_TRUE((*cpu)->render(state, now, true, c));
  EXPECT_FALSE(g.pending);
  ASSERT_EQ(g.layers.airlight.size(), c.layers.airlight.size());
  const double sg = sum(g.layers.airlight), sc = sum(c.layers.airlight);
  ASSERT_GT(sc, 0.0);
  std::vector<double> rel;
  for (int j = 0; j < kHeight; ++j)
    for (int i = 0; i < kWidth; ++i) {
      const double cv = at(c.layers.airlight, i, j);
      if (cv > 1e-3) rel.push_back(std::abs(at(g.layers.airlight, i, j) - cv) / cv);
    }
  std::sort(rel.begin(), rel.end());
  const double p95 = rel.empty() ? 0.0 : rel[rel.size() * 95 / 100];
  std::printf("  GPU / CPU airlight sum %.5f, p95 per pixel %.2e over %zu px; GPU %s: surface %.1f ms, airlight %.1f ms; "
              "CPU airlight %.1f ms\n",
              sg / sc, p95, rel.size(), (*glGpu)->description().c_str(), g.timings.surface_ms, g.timings.airlight_ms,
              c.timings.airlight_ms);
  EXPECT_NEAR(sg / sc, 1.0, 0.02);
  EXPECT_LT(p95, 0.05);
  // The same surfaces, and the glare of the same lamps, whichever path made the airlight.
  EXPECT_NEAR(g.effects.eye_illuminance_lx, c.effects.eye_illuminance_lx, 1e-6 * c.effects.eye_illuminance_lx);
  EXPECT_NEAR(sum(g.layers.surface), sum(c.layers.surface), 1e-4 * sum(c.layers.surface));
}

}  // namespace
}  // namespace fogbeam::plugin
