// Frames while the ego lamps' view tables are built ([render] pending_tables, frame_renderer.hpp;
// docs/service.md, "How a frame is made", step 5): with "per-pixel" no frame waits and every frame
// shows the fog it was asked for, the lamps evaluated per pixel until the tables are taken; in
// lock-step (wait = true) the tables are taken table_adopt_frames frames after their build
// started, so runs repeat byte for byte. Small frames (65 × 37) of tests/data/service/small.toml:
// the road plane, a street lamp, the ego's left low beam, 80 m visibility.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/scene/scene.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace fogbeam::plugin {
namespace {

constexpr int kWidth = 65, kHeight = 37;
const std::string kSmall = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/small.toml";

ServiceConfig configWith(std::vector<std::string> settings) {
  settings.push_back("render.table_cache=\"off\"");  // every build is a build: nothing from ~/.cache
  auto c = loadServiceConfig(kSmall, settings);
  EXPECT_TRUE(c) << (c ? "" : c.error().message);
  if (!c) return {};
  c->channels.at(0).width = kWidth;
  c->channels.at(0).height = kHeight;
  c->channels.at(0).format = "rgba16f-linear";
  return std::move(c).value();
}

Scene worldOf(const ServiceConfig& c) {
  auto w = loadScene(c.scene_path);
  EXPECT_TRUE(w) << (w ? "" : w.error().message);
  return w ? std::move(w).value() : Scene{};
}

/// The ego at the origin looking down +x with its low beam on; the fog `visibility_m` (0: the
/// configuration's, no environment message).
ipc::SimSnapshot stateWith(float visibility_m) {
  ipc::SimSnapshot s;
  s.ego.stamp.valid = true;
  s.lamps.value.lights = ipc::light::kLowBeam;
  s.lamps.stamp.valid = true;
  if (visibility_m > 0.0f) {
    s.environment.value.visibility_m = visibility_m;
    s.environment.value.albedo = 1.0f;
    s.environment.value.g = 0.85f;
    s.environment.stamp.valid = true;
  }
  return s;
}

/// Per-pixel luminance (R + G + B) of a 3-per-pixel layer.
std::vector<double> luminance(const std::vector<float>& layer) {
  std::vector<double> l(layer.size() / 3);
  for (std::size_t k = 0; k < l.size(); ++k)
    l[k] = static_cast<double>(layer[3 * k]) + static_cast<double>(layer[3 * k + 1]) + static_cast<double>(layer[3 * k + 2]);
  return l;
}

/// The 95th percentile of |a − b| / b over pixels whose b is above 1 % of b's 99.5th percentile
/// (the accuracy measure).
double p95Relative(const std::vector<double>& a, const std::vector<double>& b) {
  std::vector<double> sorted = b;
  std::sort(sorted.begin(), sorted.end());
  const double floor = 0.01 * sorted[static_cast<std::size_t>(0.995 * static_cast<double>(sorted.size() - 1))];
  std::vector<double> rel;
  for (std::size_t k = 0; k < a.size(); ++k)
    if (b[k] > floor) rel.push_back(std::abs(a[k] - b[k]) / b[k]);
  EXPECT_GT(rel.size(), a.size() / 4);
  std::sort(rel.begin(), rel.end());
  return rel[static_cast<std::size_t>(0.95 * static_cast<double>(rel.size() - 1))];
}

TEST(PendingTables, FramesBeforeTheTablesAreEvaluatedPerPixelAndAgreeWithThem) {
  const ServiceConfig cfg = configWith({"render.table_adopt_frames=2"});
  auto r = ChannelRenderer::create(cfg, 0, worldOf(cfg), nullptr);
  ASSERT_TRUE(r) << r.error().message;
  RenderedFrame f1, f2, f3;
  const ipc::SimSnapshot s = stateWith(0.0f);
  // Frame 1 does not wait; frame 2 (the fog has held for two frames) starts the build and does
  // not wait; frame 4 (= 2 + 2) takes the tables, waiting for them if need be.
  ASSERT_TRUE((*r)->render(s, ipc::Clock::now(), true, f1));
  ASSERT_TRUE((*r)->render(s, ipc::Clock::now(), true, f2));
  EXPECT_TRUE(f1.pending);
  EXPECT_TRUE(f2.pending);
  ASSERT_TRUE((*r)->render(s, ipc::Clock::now(), true, f3));
  EXPECT_TRUE(f3.pending);
  ASSERT_TRUE((*r)->render(s, ipc::Clock::now(), true, f3));
  EXPECT_FALSE(f3.pending);
  EXPECT_EQ(f1.layers.airlight, f2.layers.airlight);  // the same per-pixel frame twice
  // The per-pixel frame and the tables' frame are two approximations of the same airlight (the
  // pencil per pixel; view tables at small.toml's coarse 1° step).
  const double p95 = p95Relative(luminance(f1.layers.airlight), luminance(f3.layers.airlight));
  std::printf("per-pixel frame against the tables' frame: p95 %.2e\n", p95);
  EXPECT_LT(p95, 0.01);
  EXPECT_NE(f1.layers.airlight, f3.layers.airlight);  // two paths indeed
}

TEST(PendingTables, AFogChangeIsShownAtOnce) {
  const ServiceConfig cfg = configWith({"render.table_adopt_frames=1"});
  auto r = ChannelRenderer::create(cfg, 0, worldOf(cfg), nullptr);
  ASSERT_TRUE(r) << r.error().message;
  RenderedFrame f;
  for (int k = 0; k < 3; ++k) ASSERT_TRUE((*r)->render(stateWith(80.0f), ipc::Clock::now(), true, f));
  ASSERT_FALSE(f.pending);  // 80 m tables in use
  const std::vector<double> at80 = luminance(f.layers.airlight);
  RenderedFrame g;
  ASSERT_TRUE((*r)->render(stateWith(40.0f), ipc::Clock::now(), true, g));
  EXPECT_TRUE(g.pending);  // 40 m tables building, the frame shows 40 m anyway
  // Transmittance of the new fog on every surface pixel.
  const double kt = extinctionFromVisibility(40.0);
  for (std::size_t k = 0; k < g.layers.distance.size(); ++k) {
    const double d = g.layers.distance[k];
    if (std::isfinite(d)) {
      ASSERT_NEAR(g.layers.transmittance[k], std::exp(-kt * d), 1e-4 * std::exp(-kt * d) + 1e-7);
    }
  }
  // Its airlight is that of a renderer whose tables are for 40 m.
  const ServiceConfig cfg40 = configWith({"render.table_adopt_frames=1", "fog.visibility_m=40"});
  auto r40 = ChannelRenderer::create(cfg40, 0, worldOf(cfg40), nullptr);
  ASSERT_TRUE(r40) << r40.error().message;
  RenderedFrame h;
  for (int k = 0; k < 3; ++k) ASSERT_TRUE((*r40)->render(stateWith(0.0f), ipc::Clock::now(), true, h));
  ASSERT_FALSE(h.pending);
  const std::vector<double> at40 = luminance(h.layers.airlight);
  const double p95 = p95Relative(luminance(g.layers.airlight), at40);
  const double p95Old = p95Relative(at80, at40);
  std::printf("fog 80 -> 40 m, pending frame against 40 m tables: p95 %.2e (80 m frame: %.2e)\n", p95, p95Old);
  EXPECT_LT(p95, 0.01);
  EXPECT_GT(p95Old, 0.1);  // the change is one a stale frame would show
}

TEST(PendingTables, LockStepRunsRepeatByteForByte) {
  // Fog changes at frames 5 and 10; a build starts once a fog has held for two frames and is
  // taken 2 frames later: the same frames on every run.
  const ServiceConfig cfg = configWith({"render.table_adopt_frames=2"});
  std::vector<std::vector<std::byte>> runs[2];
  std::vector<bool> pending[2];
  for (int run = 0; run < 2; ++run) {
    auto r = ChannelRenderer::create(cfg, 0, worldOf(cfg), nullptr);
    ASSERT_TRUE(r) << r.error().message;
    for (int frame = 1; frame <= 13; ++frame) {
      const float vis = frame < 5 ? 80.0f : (frame < 10 ? 60.0f : 45.0f);
      RenderedFrame f;
      ASSERT_TRUE((*r)->render(stateWith(vis), ipc::Clock::now(), true, f));
      runs[run].push_back(f.packed);
      pending[run].push_back(f.pending);
    }
  }
  EXPECT_EQ(runs[0], runs[1]);
  EXPECT_EQ(pending[0], pending[1]);
  // 80 m built from frame 2, taken at 4; 60 m wanted from 5, built from 6, taken at 8; 45 m
  // wanted from 10, built from 11, taken at 13.
  const std::vector<bool> expected{true, true, true, false, true, true, true, false, false, true, true, true, false};
  EXPECT_EQ(pending[0], expected);
}

// Bending at any angle: tables are built for the angle asked for and serve angles within
// [ego] bending_tolerance_deg (0.05° by default) of it; frames beyond show their exact angle per
// pixel until tables for it are in use. A low beam bent 2.4° against one mounted turned 2.4°;
// with a 0.5° tolerance, 2° tables serve 2.4° and the frame shows 2°, which the comparison must
// see; a bending signal that jitters by 0.03° keeps to tables.
TEST(PendingTables, BendingAtAnyAngle) {
  auto bendingCfg = [](std::vector<std::string> extra) {
    extra.push_back("render.table_adopt_frames=1");
    ServiceConfig c = configWith(std::move(extra));
    c.ego.lamps.at(0).bending = true;
    return c;
  };
  // One frame per angle, in lock-step.
  auto framesOf = [](const ServiceConfig& c, const std::vector<float>& angles, std::vector<RenderedFrame>& frames) {
    auto r = ChannelRenderer::create(c, 0, worldOf(c), nullptr);
    ASSERT_TRUE(r) << r.error().message;
    frames.assign(angles.size(), RenderedFrame{});
    for (std::size_t k = 0; k < angles.size(); ++k) {
      ipc::SimSnapshot s = stateWith(0.0f);
      s.lamps.value.bending_deg = angles[k];
      ASSERT_TRUE((*r)->render(s, ipc::Clock::now(), true, frames[k]));
    }
  };
  auto mountedAt = [&](float deg) {
    ServiceConfig turned = configWith({"render.table_adopt_frames=1"});
    SceneLamp& l = turned.ego.lamps.at(0).lamp;
    l.lamp.worldFromLamp = worldFromYawPitchRoll(radians(static_cast<double>(deg)), 0.0, 0.0) * l.lamp.worldFromLamp;
    std::vector<RenderedFrame> f;
    framesOf(turned, {0.0f, 0.0f, 0.0f, 0.0f}, f);
    EXPECT_FALSE(f.back().pending);
    return luminance(f.back().layers.airlight);
  };
  const auto lum = [](const RenderedFrame& f) { return luminance(f.layers.airlight); };
  const std::vector<double> at24 = mountedAt(2.4f), at243 = mountedAt(2.43f);

  std::vector<RenderedFrame> exact, wide, jitter;
  framesOf(bendingCfg({}), {2.4f, 2.4f, 2.4f, 2.4f}, exact);
  EXPECT_TRUE(exact.front().pending);
  EXPECT_FALSE(exact.back().pending);
  framesOf(bendingCfg({"ego.bending_tolerance_deg=0.5"}), {2.0f, 2.0f, 2.0f, 2.0f, 2.4f, 2.4f}, wide);
  EXPECT_FALSE(wide.back().pending);  // 2° tables serve 2.4°
  framesOf(bendingCfg({}), {2.4f, 2.43f, 2.4f, 2.43f, 2.4f, 2.43f, 2.4f}, jitter);
  EXPECT_FALSE(jitter[jitter.size() - 2].pending);
  EXPECT_FALSE(jitter.back().pending);  // 2.4° wanted, served by the 2.43° tables built at frame 2

  const double tablesP95 = p95Relative(lum(exact.back()), at24);
  const double pendingP95 = p95Relative(lum(exact.front()), at24);
  const double wideP95 = p95Relative(lum(wide.back()), at24);
  const double jitterP95 = p95Relative(lum(jitter.back()), at24);
  const double jitterTablesP95 = p95Relative(lum(jitter.back()), at243);
  std::printf("bent 2.4° against mounted 2.4°: tables p95 %.2e, pending frame %.2e; 2° tables (tolerance 0.5°) "
              "%.2e; jittering 2.40/2.43°: %.2e (against mounted 2.43°: %.2e)\n",
              tablesP95, pendingP95, wideP95, jitterP95, jitterTablesP95);
  EXPECT_LT(tablesP95, 1e-5);
  EXPECT_LT(pendingP95, 0.01);
  EXPECT_GT(wideP95, 10.0 * tablesP95 + 1e-3);
  EXPECT_LT(jitterTablesP95, 1e-5);  // the frame is the 2.43° tables' frame
  EXPECT_LT(jitterP95, 0.01);
}

// The fog ladder ([render] fog_ladder_ratio, 1.2 by default; docs/service.md, "The fog ladder"):
// while the 80 m tables serve, the idle frames build rungs around 80 m (one a frame here:
// fog_ladder_adopt_frames = 1); a ramp to 50 m afterwards (a new fog every frame) reads the two
// rungs around each frame's fog and is never pending; its last frame is within 1 % (p95) of a
// renderer whose tables are for that fog; the run repeats byte for byte (lock-step).
TEST(PendingTables, AFogRampReadsTheFogLadder) {
  const std::vector<std::string> settings{"render.table_adopt_frames=1", "render.fog_ladder_adopt_frames=1"};
  constexpr int kSteady = 12, kRamp = 12;
  const float last = 50.0f;
  auto run = [&](std::vector<RenderedFrame>& frames) {
    const ServiceConfig cfg = configWith(settings);
    auto r = ChannelRenderer::create(cfg, 0, worldOf(cfg), nullptr);
    ASSERT_TRUE(r) << r.error().message;
    frames.resize(kSteady + kRamp + 1);
    for (int k = 0; k < kSteady + kRamp; ++k) {
      const double t = k < kSteady ? 0.0 : static_cast<double>(k - kSteady + 1) / kRamp;
      const auto v = static_cast<float>(80.0 * std::pow(static_cast<double>(last) / 80.0, t));
      ASSERT_TRUE((*r)->render(stateWith(k + 1 == kSteady + kRamp ? last : v), ipc::Clock::now(), true, frames[static_cast<std::size_t>(k)]));
    }
    // The high beam switched on as the fog goes on changing: the rungs hold the low beam alone,
    // so the frame goes per pixel (a new ladder for the new lamps).
    ipc::SimSnapshot high = stateWith(48.0f);
    high.lamps.value.lights |= ipc::light::kHighBeam;
    ASSERT_TRUE((*r)->render(high, ipc::Clock::now(), true, frames.back()));
  };
  std::vector<RenderedFrame> a, b;
  run(a);
  int ladder = 0;
  for (int k = kSteady; k < kSteady + kRamp; ++k) {
    const RenderedFrame& f = a[static_cast<std::size_t>(k)];
    EXPECT_FALSE(f.pending) << "ramp frame " << k - kSteady;
    EXPECT_EQ(f.fog_rungs, 2) << "ramp frame " << k - kSteady;
    ladder += f.fog_rungs == 2 ? 1 : 0;
  }
  EXPECT_FALSE(a[kSteady - 1].pending);
  EXPECT_EQ(a[kSteady - 1].fog_rungs, 0);  // the steady frames read the 80 m tables
  EXPECT_TRUE(a.back().pending);
  EXPECT_EQ(a.back().fog_rungs, 0);
  // The last ramp frame (50 m) against 50 m tables.
  std::vector<std::string> at50 = settings;
  at50.push_back("fog.visibility_m=50");
  const ServiceConfig cfg50 = configWith(at50);
  auto r50 = ChannelRenderer::create(cfg50, 0, worldOf(cfg50), nullptr);
  ASSERT_TRUE(r50) << r50.error().message;
  RenderedFrame h;
  for (int k = 0; k < 3; ++k) ASSERT_TRUE((*r50)->render(stateWith(0.0f), ipc::Clock::now(), true, h));
  ASSERT_FALSE(h.pending);
  const RenderedFrame& at50Frame = a[kSteady + kRamp - 1];
  const double p95 = p95Relative(luminance(at50Frame.layers.airlight), luminance(h.layers.airlight));
  const double p95Steady = p95Relative(luminance(a[kSteady - 1].layers.airlight), luminance(h.layers.airlight));
  std::printf("fog ramp 80 -> 50 m: %d of %d frames from two rungs; the 50 m frame against 50 m tables p95 %.2e "
              "(the 80 m frame: %.2e)\n",
              ladder, kRamp, p95, p95Steady);
  EXPECT_LT(p95, 0.01);
  EXPECT_GT(p95Steady, 0.1);
  run(b);
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].layers.airlight, b[k].layers.airlight) << "frame " << k;
    EXPECT_EQ(a[k].packed, b[k].packed) << "frame " << k;
  }
}

// The bending ladder ([render] bending_ladder_step_deg, 1° by default; docs/service.md, "The
// bending ladder"): while the 0° tables serve, the idle frames build bending rungs around 0°
// (one a frame here: fog_ladder_adopt_frames = 1), then fog rungs; a wheel that then turns
// 0.1° further every frame reads the two rungs around each frame's angle, each through its turn,
// builds the next rung ahead and is never pending; its last frame is within 1 % (p95) of a
// renderer whose low beam is mounted at that angle; the run repeats byte for byte (lock-step).
TEST(PendingTables, ATurningWheelReadsTheBendingLadder) {
  constexpr int kSteady = 12, kTurn = 16;
  constexpr float kRate = 0.1f;  // deg a frame
  auto bendingCfg = [](std::vector<std::string> extra) {
    extra.push_back("render.table_adopt_frames=1");
    extra.push_back("render.fog_ladder_adopt_frames=1");
    ServiceConfig c = configWith(std::move(extra));
    c.ego.lamps.at(0).bending = true;
    return c;
  };
  auto run = [&](const ServiceConfig& cfg, std::vector<RenderedFrame>& frames) {
    auto r = ChannelRenderer::create(cfg, 0, worldOf(cfg), nullptr);
    ASSERT_TRUE(r) << r.error().message;
    frames.assign(kSteady + kTurn, RenderedFrame{});
    for (int k = 0; k < kSteady + kTurn; ++k) {
      ipc::SimSnapshot s = stateWith(0.0f);
      s.lamps.value.bending_deg = k < kSteady ? 0.0f : kRate * static_cast<float>(k - kSteady + 1);
      ASSERT_TRUE((*r)->render(s, ipc::Clock::now(), true, frames[static_cast<std::size_t>(k)]));
    }
  };
  std::vector<RenderedFrame> a, b, off;
  run(bendingCfg({}), a);
  int turned = 0;
  for (int k = kSteady; k < kSteady + kTurn; ++k) {
    const RenderedFrame& f = a[static_cast<std::size_t>(k)];
    EXPECT_FALSE(f.pending) << "turning frame " << k - kSteady;
    turned += f.bending_rungs == 2 ? 1 : 0;
  }
  EXPECT_GE(turned, kTurn - 2);  // frames on a rung's own angle read it alone
  EXPECT_EQ(a[kSteady - 1].bending_rungs, 0);  // the steady frames read the 0° tables
  // Without the ladder the same frames go per pixel.
  run(bendingCfg({"render.bending_ladder_step_deg=0"}), off);
  for (int k = kSteady; k < kSteady + kTurn; ++k) EXPECT_TRUE(off[static_cast<std::size_t>(k)].pending);

  // The last frame against the lamp mounted at its angle (tables built for it).
  const float last = kRate * static_cast<float>(kTurn);
  ServiceConfig turnedCfg = configWith({"render.table_adopt_frames=1"});
  SceneLamp& l = turnedCfg.ego.lamps.at(0).lamp;
  l.lamp.worldFromLamp = worldFromYawPitchRoll(radians(static_cast<double>(last)), 0.0, 0.0) * l.lamp.worldFromLamp;
  auto rt = ChannelRenderer::create(turnedCfg, 0, worldOf(turnedCfg), nullptr);
  ASSERT_TRUE(rt) << rt.error().message;
  RenderedFrame h;
  for (int k = 0; k < 3; ++k) ASSERT_TRUE((*rt)->render(stateWith(0.0f), ipc::Clock::now(), true, h));
  ASSERT_FALSE(h.pending);
  const double p95 = p95Relative(luminance(a.back().layers.airlight), luminance(h.layers.airlight));
  const double p95Steady = p95Relative(luminance(a[kSteady - 1].layers.airlight), luminance(h.layers.airlight));
  std::printf("wheel turning 0 -> %.1f deg at %.1f deg a frame: %d of %d frames from two turned rungs; the last against "
              "the lamp mounted at %.1f deg p95 %.2e (the 0 deg frame: %.2e)\n",
              static_cast<double>(last), static_cast<double>(kRate), turned, kTurn, static_cast<double>(last), p95,
              p95Steady);
  EXPECT_LT(p95, 0.01);
  EXPECT_GT(p95Steady, 5.0 * p95);
  run(bendingCfg({}), b);
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].layers.airlight, b[k].layers.airlight) << "frame " << k;
    EXPECT_EQ(a[k].packed, b[k].packed) << "frame " << k;
  }
}

TEST(PendingTables, PreviousWaitsForTheFirstTables) {
  const ServiceConfig cfg = configWith({"render.pending_tables=\"previous\""});
  auto r = ChannelRenderer::create(cfg, 0, worldOf(cfg), nullptr);
  ASSERT_TRUE(r) << r.error().message;
  RenderedFrame f;
  ASSERT_TRUE((*r)->render(stateWith(0.0f), ipc::Clock::now(), true, f));
  EXPECT_FALSE(f.pending);
  EXPECT_GT(f.timings.table_wait_ms, 0.0);
}

}  // namespace
}  // namespace fogbeam::plugin
