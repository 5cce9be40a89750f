// The automatic exposure of rgba8-srgb channels ([[channel]] exposure_ev = "auto", the default;
// docs/service.md): a frame is packed at its own automatic EV (render/exposure.hpp) on the first
// frame, then adapted over the simulation time between frames when frames wait for their inputs
// (lock-step, replay), so that the same states give the same bytes; a fixed exposure_ev packs at
// that EV. Small frames (65 × 37) of tests/data/service/small.toml.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/render/exposure.hpp>
#include <fogbeam/render/pixel_pack.hpp>
#include <fogbeam/scene/scene.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace fogbeam::plugin {
namespace {

constexpr int kWidth = 65, kHeight = 37;
const std::string kSmall = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/small.toml";

ServiceConfig rgba8Config(bool automatic, double ev = 0.0) {
  auto c = loadServiceConfig(kSmall, {"render.table_cache=\"off\""});
  EXPECT_TRUE(c) << (c ? "" : c.error().message);
  if (!c) return {};
  ChannelConfig& ch = c->channels.at(0);
  ch.width = kWidth;
  ch.height = kHeight;
  ch.format = "rgba8-srgb";
  ch.exposure_auto = automatic;
  ch.exposure_ev = ev;
  return std::move(c).value();
}

/// The ego at the origin heading `yaw_deg` with `lights` on, at simulation time `t_s`.
ipc::SimSnapshot stateAt(double t_s, std::uint32_t lights, float yaw_deg = 0.0f) {
  ipc::SimSnapshot s;
  s.ego.stamp.valid = true;
  s.ego.value.pose.yaw_deg = yaw_deg;
  s.ego.stamp.sim_time_s = t_s;
  s.lamps.value.lights = lights;
  s.lamps.stamp.valid = true;
  return s;
}

/// The frame's bytes are its composite packed at `ev`.
void expectPackedAt(const RenderedFrame& f, double ev) {
  std::vector<std::uint8_t> want(4 * static_cast<std::size_t>(kWidth) * kHeight);
  packRgba8Srgb(f.layers.composite.data(), want.size() / 4, ev, want.data());
  ASSERT_EQ(f.packed.size(), want.size());
  EXPECT_EQ(std::memcmp(f.packed.data(), want.data(), want.size()), 0) << "EV " << ev;
}

TEST(FrameExposure, AutomaticExposureAdaptsOverSimulationTime) {
  const ServiceConfig cfg = rgba8Config(true);
  ASSERT_TRUE(cfg.channels.at(0).autoExposure());
  auto world = loadScene(cfg.scene_path);
  ASSERT_TRUE(world) << world.error().message;
  auto r = ChannelRenderer::create(cfg, 0, *world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  auto targetOf = [](const RenderedFrame& f) { return autoExposureEv(f.layers.composite, f.layers.width, f.layers.height); };

  // The first frame: its own EV.
  RenderedFrame f;
  ASSERT_TRUE((*r)->render(stateAt(10.0, ipc::light::kLowBeam | ipc::light::kHighBeam), ipc::Clock::now(), true, f));
  const double ev1 = f.exposure_ev;
  EXPECT_DOUBLE_EQ(ev1, targetOf(f));
  expectPackedAt(f, ev1);

  // Turned round 0.25 s later (the street lamp out of view): a frame whose own EV differs; the frame's EV moves towards it by
  // 1 − e^(−0.25 s / τ), τ_down towards a lower EV, τ_up towards a higher one.
  ASSERT_TRUE((*r)->render(stateAt(10.25, ipc::light::kLowBeam, 180.0f), ipc::Clock::now(), true, f));
  const double target2 = targetOf(f);
  ASSERT_GT(std::abs(target2 - ev1), 0.25) << ev1 << " " << target2;
  const ExposureAdaptationOptions o;
  const double tau = target2 < ev1 ? o.tau_down_s : o.tau_up_s;
  const double ev2 = target2 + (ev1 - target2) * std::exp(-0.25 / tau);
  EXPECT_NEAR(f.exposure_ev, ev2, 1e-9);
  expectPackedAt(f, f.exposure_ev);

  // The same simulation time again (a repeated state): no time passed, the EV stays.
  ASSERT_TRUE((*r)->render(stateAt(10.25, ipc::light::kLowBeam, 180.0f), ipc::Clock::now(), true, f));
  EXPECT_NEAR(f.exposure_ev, ev2, 1e-9);

  // Time went back (a looped scenario, a new host): the adaptation starts again.
  ASSERT_TRUE((*r)->render(stateAt(0.0, ipc::light::kLowBeam, 180.0f), ipc::Clock::now(), true, f));
  EXPECT_DOUBLE_EQ(f.exposure_ev, targetOf(f));
}

TEST(FrameExposure, AFixedExposurePacksAtIt) {
  const ServiceConfig cfg = rgba8Config(false, -1.5);
  ASSERT_FALSE(cfg.channels.at(0).autoExposure());
  auto world = loadScene(cfg.scene_path);
  ASSERT_TRUE(world) << world.error().message;
  auto r = ChannelRenderer::create(cfg, 0, *world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  RenderedFrame f;
  for (double t : {0.0, 0.5}) {
    ASSERT_TRUE((*r)->render(stateAt(t, t == 0.0 ? ipc::light::kLowBeam : 0u), ipc::Clock::now(), true, f));
    EXPECT_EQ(f.exposure_ev, -1.5);
    expectPackedAt(f, -1.5);
  }
}

}  // namespace
}  // namespace fogbeam::plugin
