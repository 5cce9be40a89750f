// Overlapped frames ([render] overlap_frames; frame_pipeline.hpp, docs/service.md, "Overlapped
// frames"): the surface pass of frame N+1 runs on the pipeline's thread while the airlight, glow,
// glare, composite and packing of frame N run on its worker. The frames must be the bytes of the
// same states rendered in sequence: replay-like runs with traffic, a fog change (table builds
// taken by frame count while another frame is in flight), glow, glare, the automatic exposure
// and two channels; lock-step serve runs repeat byte for byte; errors stop the pipeline with
// every thread joined. Small frames of tests/data/service/small.toml (CPU surfaces) and, where
// EGL works, the GL surface pass and the GPU airlight.
#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/plugin/frame_pipeline.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/plugin/service.hpp>
#include <fogbeam/plugin/service_config.hpp>

#include <gtest/gtest.h>

#include "service_test_support.hpp"

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace fogbeam::plugin {
namespace {

using namespace std::chrono_literals;

const std::string kSmall = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/small.toml";
const std::string kScenario = std::string(FOGBEAM_TEST_DATA_DIR) + "/scenarios/timing.toml";

/// small.toml with `settings`, tables never from ~/.cache and coarse (4°: fast to build; the
/// tables' accuracy is not what is tested), and two channels: the main view 96×54 RGBA8 sRGB
/// (automatic exposure, adapted over simulation time) and a side view 30° left, 64×36 overlay.
ServiceConfig twoChannels(std::vector<std::string> settings) {
  test::holdTheTestFogsTables();
  settings.insert(settings.begin(), {"render.table_cache=\"off\"", "render.view_table_step_deg=4.0"});
  auto c = loadServiceConfig(kSmall, settings);
  EXPECT_TRUE(c) << (c ? "" : c.error().message);
  if (!c) return {};
  ChannelConfig& main = c->channels.at(0);
  main.width = 96;
  main.height = 54;
  main.format = "rgba8-srgb";
  main.exposure_auto = true;
  ChannelConfig side = main;
  side.name = "side";
  side.width = 64;
  side.height = 36;
  side.yaw_deg = 30.0;
  side.format = "rgba16f-overlay";
  c->channels.push_back(side);
  return std::move(c).value();
}

/// The timing scenario (ego weaving, high beam 2–4 s, an oncoming car) at 0.25 s steps, the fog
/// 80 m until frame `fogChange`, 50 m from there on.
std::vector<ScenarioState> statesOf(std::size_t count, std::size_t fogChange) {
  auto scenario = loadScenario(kScenario);
  EXPECT_TRUE(scenario) << (scenario ? "" : scenario.error().message);
  std::vector<ScenarioState> states;
  if (!scenario) return states;
  for (std::size_t k = 0; k < count; ++k) {
    ScenarioState s = evaluate(*scenario, 0.25 * static_cast<double>(k));
    if (k >= fogChange) {
      s.environment.visibility_m = 50.0f;
      s.environment.extinction_per_m = 0.0f;
    }
    states.push_back(std::move(s));
  }
  return states;
}

/// What a sink was given, frame by frame and channel by channel; fails on (frame, channel)
/// when asked to.
class Capture final : public FrameSink {
 public:
  struct Frame {
    std::size_t channel = 0;
    std::uint64_t frame = 0;
    std::vector<std::byte> packed;
    std::vector<float> composite;
    ipc::FrameMeta meta;
    bool pending = false;
  };
  Status consume(std::size_t channel, const RenderedFrame& frame, const FrameBookkeeping& book) override {
    if (failAt && failAt->first == book.frame && failAt->second == channel) return Error{"sink refuses this frame"};
    frames.push_back(Frame{channel, book.frame, frame.packed, frame.layers.composite, wireMeta(frame, book), frame.pending});
    return Ok{};
  }
  std::vector<Frame> frames;
  std::optional<std::pair<std::uint64_t, std::size_t>> failAt;
};

/// `states` through a pipeline of `cfg` as replay drives it (tables awaited): submit() per state
/// and a flush() at the end, overlapped or not as cfg says; frame numbers from 1.
Capture replay(const ServiceConfig& cfg, const std::vector<ScenarioState>& states, std::unique_ptr<GlSurfacePass> gl,
               bool expectOverlap) {
  Capture sink;
  auto world = loadScene(cfg.scene_path);
  EXPECT_TRUE(world) << (world ? "" : world.error().message);
  if (!world) return sink;
  auto pipeline = FramePipeline::create(cfg, *world, std::move(gl), true);
  EXPECT_TRUE(pipeline) << (pipeline ? "" : pipeline.error().message);
  if (!pipeline) return sink;
  FramePipeline& p = **pipeline;
  EXPECT_EQ(p.overlapping(), expectOverlap);
  ipc::StateStore store;
  std::uint32_t sequence = 1;
  for (std::size_t k = 0; k < states.size(); ++k) {
    const auto now = ipc::Clock::now();
    applyState(states[k], store, sequence, now);
    FrameBookkeeping book;
    book.frame = k + 1;
    const Status s = p.submit(*store.snapshot(), now, book, sink);
    EXPECT_TRUE(s) << "frame " << k + 1 << ": " << (s ? "" : s.error().message);
    if (!s) return sink;
    // Overlapped, a frame reaches the sink one submit later; in sequence at once.
    EXPECT_EQ(p.inFlight(), expectOverlap);
    EXPECT_EQ(p.handed(), expectOverlap ? k : k + 1);
  }
  const Status s = p.flush(sink);
  EXPECT_TRUE(s) << (s ? "" : s.error().message);
  EXPECT_FALSE(p.inFlight());
  EXPECT_EQ(p.handed(), states.size());
  return sink;
}

/// The two runs gave the same frames: same order, bytes, composite layer, metadata (less the
/// stage times and latency, which are measured) and pending flags.
void expectSameFrames(const Capture& sequential, const Capture& overlapped) {
  ASSERT_EQ(sequential.frames.size(), overlapped.frames.size());
  for (std::size_t i = 0; i < sequential.frames.size(); ++i) {
    const Capture::Frame& a = sequential.frames[i];
    const Capture::Frame& b = overlapped.frames[i];
    SCOPED_TRACE("frame " + std::to_string(a.frame) + " channel " + std::to_string(a.channel));
    ASSERT_EQ(a.frame, b.frame);
    ASSERT_EQ(a.channel, b.channel);
    EXPECT_TRUE(a.packed == b.packed) << "packed pixels differ";
    EXPECT_TRUE(a.composite == b.composite) << "composite layers differ";
    EXPECT_EQ(a.pending, b.pending);
    EXPECT_EQ(a.meta.frame, b.meta.frame);
    EXPECT_EQ(a.meta.sim_time_s, b.meta.sim_time_s);
    EXPECT_EQ(a.meta.position_m, b.meta.position_m);
    EXPECT_EQ(a.meta.yaw_deg, b.meta.yaw_deg);
    EXPECT_EQ(a.meta.fov_x_deg, b.meta.fov_x_deg);
    EXPECT_EQ(a.meta.lights, b.meta.lights);
    EXPECT_EQ(a.meta.ego_sequence, b.meta.ego_sequence);
    EXPECT_EQ(a.meta.lamp_sequence, b.meta.lamp_sequence);
    EXPECT_EQ(a.meta.environment_sequence, b.meta.environment_sequence);
    EXPECT_EQ(a.meta.traffic_count, b.meta.traffic_count);
  }
}

/// The run is one the comparison can fail on: frames in order, channel by channel, that differ
/// from one another, with traffic, and the tables both pending and in use (a build taken while
/// another frame was in flight).
void expectAnEventfulRun(const Capture& c, std::size_t frames, std::size_t channels) {
  ASSERT_EQ(c.frames.size(), frames * channels);
  std::size_t changed = 0;  // main-view frames unlike the one before
  const std::vector<std::byte>* previous = nullptr;
  bool traffic = false, pending = false, tables = false;
  for (std::size_t i = 0; i < c.frames.size(); ++i) {
    EXPECT_EQ(c.frames[i].frame, i / channels + 1);
    EXPECT_EQ(c.frames[i].channel, i % channels);
    if (c.frames[i].channel == 0) {
      if (previous && !(*previous == c.frames[i].packed)) ++changed;
      previous = &c.frames[i].packed;
    }
    traffic = traffic || c.frames[i].meta.traffic_count > 0;
    pending = pending || c.frames[i].pending;
    tables = tables || !c.frames[i].pending;
  }
  EXPECT_GT(changed, frames / 2);
  EXPECT_TRUE(traffic);
  EXPECT_TRUE(pending);
  EXPECT_TRUE(tables);
}

TEST(FrameOverlap, ReplayWithTrafficAndAFogChangeGivesTheSequentialBytes) {
  // 14 frames; tables for 80 m built from frame 2 and taken at frame 5, the fog 50 m from frame
  // 7, its tables built from frame 8 and taken at frame 11 (table_adopt_frames = 3).
  const std::vector<std::string> settings{"render.table_adopt_frames=3", "glow.enabled=true", "glare.enabled=true"};
  ServiceConfig seq = twoChannels(settings);
  seq.overlap_frames = "off";
  ServiceConfig ovl = seq;
  ovl.overlap_frames = "on";
  const auto states = statesOf(14, 6);
  const Capture a = replay(seq, states, nullptr, false);
  const Capture b = replay(ovl, states, nullptr, true);
  expectAnEventfulRun(a, states.size(), 2);
  expectSameFrames(a, b);
}

TEST(FrameOverlap, PendingTablesPreviousAwaitsBuildsInFlightTheSameWay) {
  // pending_tables = "previous": a fog change makes the frame build its tables at once (stage 1,
  // on the pipeline's thread) while the previous frame's airlight reads the old ones.
  ServiceConfig seq = twoChannels({"render.pending_tables=\"previous\""});
  seq.overlap_frames = "off";
  ServiceConfig ovl = seq;
  ovl.overlap_frames = "on";
  const auto states = statesOf(8, 4);
  const Capture a = replay(seq, states, nullptr, false);
  const Capture b = replay(ovl, states, nullptr, true);
  ASSERT_EQ(a.frames.size(), 16u);
  // The fog change shows in the transmittance-bearing overlay.
  EXPECT_NE(a.frames[2 * 3 + 1].packed, a.frames[2 * 4 + 1].packed);
  expectSameFrames(a, b);
}

/// A GL surface pass, or nullopt with the test skipped (no EGL here, unless FOGBEAM_REQUIRE_GL=1).
std::unique_ptr<GlSurfacePass> glOrSkip(bool& skipped) {
  auto gl = GlSurfacePass::create();
  skipped = false;
  if (gl) return std::move(gl).value();
  const char* require = std::getenv("FOGBEAM_REQUIRE_GL");
  if (!(require && std::string(require) == "1")) {
    skipped = true;
    return nullptr;
  }
  ADD_FAILURE() << gl.error().message;
  skipped = true;
  return nullptr;
}

// Named GlChannelRenderer.* so that ctest runs it with the GL tests' environment.
TEST(GlChannelRenderer, OverlappedFramesAreTheSequentialBytes) {
  bool skipped = false;
  auto glA = glOrSkip(skipped);
  if (skipped) GTEST_SKIP() << "no usable EGL/OpenGL";
  auto glB = GlSurfacePass::create();
  ASSERT_TRUE(glB) << glB.error().message;
  ServiceConfig seq = twoChannels({"render.surface=\"gl\"", "render.table_adopt_frames=3", "glare.enabled=true"});
  seq.overlap_frames = "off";
  ServiceConfig ovl = seq;
  ovl.overlap_frames = "on";
  const auto states = statesOf(10, 5);
  const Capture a = replay(seq, states, std::move(glA), false);
  const Capture b = replay(ovl, states, std::move(glB).value(), true);
  expectAnEventfulRun(a, states.size(), 2);
  expectSameFrames(a, b);
}

TEST(GlChannelRenderer, OverlappedGpuAirlightFramesAreTheSequentialBytes) {
  // The GPU airlight comes with the surface pass (stage 3): each begun frame keeps its own.
  bool skipped = false;
  auto glA = glOrSkip(skipped);
  if (skipped) GTEST_SKIP() << "no usable EGL/OpenGL";
  auto glB = GlSurfacePass::create();
  ASSERT_TRUE(glB) << glB.error().message;
  ServiceConfig seq = twoChannels({"render.surface=\"gl\"", "render.airlight=\"gpu\""});
  for (ChannelConfig& c : seq.channels) {  // llvmpipe: ~50 µs per pixel
    c.width /= 2;
    c.height /= 2;
  }
  seq.overlap_frames = "off";
  ServiceConfig ovl = seq;
  ovl.overlap_frames = "on";
  const auto states = statesOf(4, 2);
  const Capture a = replay(seq, states, std::move(glA), false);
  const Capture b = replay(ovl, states, std::move(glB).value(), true);
  ASSERT_EQ(a.frames.size(), 8u);
  EXPECT_NE(a.frames[0].packed, a.frames[6].packed);
  expectSameFrames(a, b);
}

/// Threads of this process now (/proc/self/task).
std::size_t threadCount() {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator("/proc/self/task")) ++n;
  return n;
}

TEST(FrameOverlap, AnErrorStopsThePipelineWithEveryThreadJoined) {
  ServiceConfig cfg = twoChannels({"render.table_adopt_frames=2", "render.threads=2"});
  cfg.overlap_frames = "on";
  const auto states = statesOf(8, 100);
  auto world = loadScene(cfg.scene_path);
  ASSERT_TRUE(world) << world.error().message;
  const std::size_t before = threadCount();
  for (const bool failInFlush : {false, true}) {
    SCOPED_TRACE(failInFlush ? "error in flush()" : "error in submit()");
    auto pipeline = FramePipeline::create(cfg, *world, nullptr, true);
    ASSERT_TRUE(pipeline) << pipeline.error().message;
    FramePipeline& p = **pipeline;
    ASSERT_TRUE(p.overlapping());
    EXPECT_GT(threadCount(), before);  // the worker (and the renderers' pools)
    Capture sink;
    // The sink refuses channel 1 of frame 4, handed over by the 5th submit (or by the flush
    // after the 4th).
    sink.failAt = std::pair<std::uint64_t, std::size_t>{4, 1};
    ipc::StateStore store;
    std::uint32_t sequence = 1;
    auto submit = [&](std::size_t k, std::size_t* failed) {
      const auto now = ipc::Clock::now();
      applyState(states[k], store, sequence, now);
      FrameBookkeeping book;
      book.frame = k + 1;
      return p.submit(*store.snapshot(), now, book, sink, failed);
    };
    for (std::size_t k = 0; k < 4; ++k) ASSERT_TRUE(submit(k, nullptr)) << "frame " << k + 1;
    std::size_t failed = 99;
    const Status s = failInFlush ? p.flush(sink, &failed) : submit(4, &failed);
    ASSERT_FALSE(s);
    EXPECT_EQ(s.error().message, "sink refuses this frame");
    EXPECT_EQ(failed, 1u);
    // Frames 1–3 on both channels and frame 4's channel 0 went out, in order; nothing after.
    ASSERT_EQ(sink.frames.size(), 7u);
    EXPECT_EQ(sink.frames.back().frame, 4u);
    EXPECT_EQ(sink.frames.back().channel, 0u);
    EXPECT_EQ(p.handed(), 3u);
    EXPECT_FALSE(p.inFlight());
    // Stopped: every later call gives the error again and neither renders nor calls the sink.
    sink.failAt.reset();
    failed = 99;
    const Status again = submit(5, &failed);
    ASSERT_FALSE(again);
    EXPECT_EQ(again.error().message, "sink refuses this frame");
    EXPECT_EQ(failed, 1u);
    EXPECT_FALSE(p.flush(sink));
    const auto now = ipc::Clock::now();
    EXPECT_FALSE(p.step(*store.snapshot(), now, FrameBookkeeping{}, sink));
    EXPECT_EQ(sink.frames.size(), 7u);
    pipeline->reset();
    // The worker, the pools and the table builds are joined.
    EXPECT_TRUE(test::waitFor([&] { return threadCount() <= before; }, 5000ms)) << threadCount() << " > " << before;
  }
}

TEST(FrameOverlap, TheRendererKeepsTwoFramesInFlightAtMost) {
  ServiceConfig cfg = twoChannels({});
  auto world = loadScene(cfg.scene_path);
  ASSERT_TRUE(world) << world.error().message;
  auto r = ChannelRenderer::create(cfg, 0, *world, nullptr);
  ASSERT_TRUE(r) << r.error().message;
  ChannelRenderer& c = **r;
  const auto states = statesOf(3, 100);
  ipc::StateStore store;
  std::uint32_t sequence = 1;
  auto state = [&](std::size_t k) {
    applyState(states[k], store, sequence, ipc::Clock::now());
    return store.snapshot();
  };
  RenderedFrame f;
  const Status none = c.finish(f);
  ASSERT_FALSE(none);
  EXPECT_NE(none.error().message.find("no frame begun"), std::string::npos) << none.error().message;
  ASSERT_TRUE(c.begin(*state(0), ipc::Clock::now(), true));
  ASSERT_TRUE(c.begin(*state(1), ipc::Clock::now(), true));
  EXPECT_EQ(c.inFlight(), 2u);
  const Status third = c.begin(*state(2), ipc::Clock::now(), true);
  ASSERT_FALSE(third);
  EXPECT_NE(third.error().message.find("two frames begun"), std::string::npos) << third.error().message;
  const Status whole = c.render(*state(2), ipc::Clock::now(), true, f);
  ASSERT_FALSE(whole);
  EXPECT_NE(whole.error().message.find("not finished"), std::string::npos) << whole.error().message;
  ASSERT_TRUE(c.finish(f));
  EXPECT_EQ(f.inputs.sim_time_s, 0.0);  // the oldest first
  ASSERT_TRUE(c.finish(f));
  EXPECT_EQ(f.inputs.sim_time_s, 0.25);
  EXPECT_EQ(c.inFlight(), 0u);
  ASSERT_TRUE(c.render(*state(2), ipc::Clock::now(), true, f));
  EXPECT_EQ(f.inputs.sim_time_s, 0.5);
}

TEST(FrameOverlap, OnWhereCoresAllowAndNeverWithHostViews) {
  ServiceConfig c = twoChannels({});
  EXPECT_EQ(c.overlap_frames, "auto");  // the default
  c.overlap_frames = "on";
  EXPECT_TRUE(overlapsFrames(c));
  c.overlap_frames = "off";
  EXPECT_FALSE(overlapsFrames(c));
  c.overlap_frames = "auto";
  c.threads = 1;
  EXPECT_FALSE(overlapsFrames(c));
  c.threads = 0;
  EXPECT_EQ(overlapsFrames(c), std::thread::hardware_concurrency() >= kOverlapMinCores);
  c.overlap_frames = "on";
  c.channels[1].depth_from = "host";
  EXPECT_FALSE(overlapsFrames(c));
  // The key: a choice, checked.
  auto bad = loadServiceConfig(kSmall, {"render.overlap_frames=\"yes\""});
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("overlap_frames"), std::string::npos) << bad.error().message;
  auto good = loadServiceConfig(kSmall, {"render.overlap_frames=\"off\""});
  ASSERT_TRUE(good) << good.error().message;
  EXPECT_EQ(good->overlap_frames, "off");
  EXPECT_NE(toToml(*good).find("overlap_frames = 'off'"), std::string::npos);
}

/// The newest frame of `channel` once its number is `frame`, polled; nullopt after `timeout`.
std::optional<std::vector<std::byte>> readFrame(const std::string& channel, std::uint64_t frame,
                                                std::chrono::milliseconds timeout) {
  auto reader = ipc::ShmReader::attach(channel);
  EXPECT_TRUE(reader) << (reader ? "" : reader.error().message);
  if (!reader) return std::nullopt;
  ipc::FrameMeta meta;
  std::vector<std::byte> pixels;
  if (!test::waitFor([&] { return (*reader)->latest(meta, pixels) == ipc::ReadStatus::Ok && meta.frame == frame; },
                     timeout))
    return std::nullopt;
  return pixels;
}

TEST(FrameOverlap, LockStepServeRepeatsByteForByte) {
  // A host that sends each frame's state and request and reads the frame before the next: lock-step
  // serve overlapped (twice) and in sequence gives the same frames; the fog changes at frame 5.
  const auto states = statesOf(8, 4);
  auto run = [&](const std::string& overlap) {
    static std::atomic<int> calls{0};
    ServiceConfig cfg = twoChannels({"timing.mode=\"lock-step\"", "render.table_adopt_frames=2",
                                     "render.overlap_frames=\"" + overlap + "\""});
    cfg.channels.pop_back();  // one channel: small.toml's main, 96×54 RGBA8
    cfg.channels[0].name = "test-ovl-" + std::to_string(::getpid()) + "-" + std::to_string(calls++);
    std::vector<std::vector<std::byte>> frames;
    auto created = Service::create(cfg);
    EXPECT_TRUE(created) << (created ? "" : created.error().message);
    if (!created) return frames;
    Service& service = **created;
    test::Running loop(service);
    test::LoopbackSender host(service.udpPort());
    std::uint32_t sequence = 1;
    for (std::size_t k = 0; k < states.size(); ++k) {
      for (const auto& d : encodeState(states[k], sequence)) host.raw(d);
      ipc::Message request;
      request.header.sequence = sequence++;
      request.payload = ipc::FrameRequest{k + 1};
      host.raw(ipc::encode(request));
      auto f = readFrame(service.config().channels[0].name, k + 1, 120'000ms);
      EXPECT_TRUE(f) << overlap << ": frame " << k + 1 << " never published";
      if (!f) break;
      frames.push_back(std::move(*f));
    }
    EXPECT_TRUE(loop.finish());
    return frames;
  };
  const auto on1 = run("on");
  const auto on2 = run("on");
  const auto off = run("off");
  ASSERT_EQ(on1.size(), states.size());
  EXPECT_TRUE(on1 == on2) << "two overlapped lock-step runs differ";
  EXPECT_TRUE(on1 == off) << "overlapped and sequential lock-step runs differ";
  EXPECT_NE(on1[0], on1[7]);
}

}  // namespace
}  // namespace fogbeam::plugin
