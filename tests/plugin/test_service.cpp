// The cab service as a library object (plugin/service.hpp) and the frame step it shares with
// `fogbeam replay` (plugin/frame_pipeline.hpp): a Service on tests/data/service/small.toml or
// timing.toml, UDP input and status on ports the system picks on 127.0.0.1, frames read back
// from its shared-memory channel. Every test stops its service itself (a limit or stop()).
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/status_server.hpp>
#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/plugin/frame_pipeline.hpp>
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/plugin/service.hpp>
#include <fogbeam/plugin/service_config.hpp>

#include <gtest/gtest.h>

#include "service_test_support.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <regex>
#include <string>
#include <thread>
#include <vector>

namespace fogbeam::plugin {
namespace {

using test::holdTheTestFogsTables;
using test::Running;
using test::waitFor;

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

const std::string kSmall = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/small.toml";
const std::string kTiming = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/timing.toml";
const std::string kScenario = std::string(FOGBEAM_TEST_DATA_DIR) + "/scenarios/timing.toml";

/// `file` with `settings`, its channels renamed to unique ones (this process, this call), so
/// that tests neither meet each other's segments nor a running service's.
/// The ego lamps' view tables at 4° instead of the configs' 1°: building them is most of a
/// Service's start-up (16× fewer directions here), and these tests check the Service's plumbing
/// and threads, not the tables' accuracy (tests/render has those). `settings` come after, so a
/// test may set its own step.
ServiceConfig configOf(const std::string& file, const std::vector<std::string>& settings = {}) {
  holdTheTestFogsTables();
  static std::atomic<int> calls{0};
  std::vector<std::string> layered{"render.view_table_step_deg=4.0"};
  layered.insert(layered.end(), settings.begin(), settings.end());
  auto c = loadServiceConfig(file, layered);
  EXPECT_TRUE(c) << (c ? "" : c.error().message);
  if (!c) return {};
  const std::string prefix = "test-svc-" + std::to_string(::getpid()) + "-" + std::to_string(calls++) + "-";
  for (ChannelConfig& ch : c->channels) ch.name = prefix + ch.name;
  return std::move(c).value();
}

/// Sends protocol messages to 127.0.0.1:port, sequence numbers from 1.
class UdpSender {
 public:
  explicit UdpSender(std::uint16_t port) : fd_(::socket(AF_INET, SOCK_DGRAM, 0)) {
    to_.sin_family = AF_INET;
    to_.sin_port = htons(port);
    ::inet_pton(AF_INET, "127.0.0.1", &to_.sin_addr);
  }
  ~UdpSender() { ::close(fd_); }
  UdpSender(const UdpSender&) = delete;
  UdpSender& operator=(const UdpSender&) = delete;

  /// Returns the message's sequence number.
  std::uint32_t send(ipc::Payload p) {
    ipc::Message m;
    m.header.sequence = seq_++;
    m.header.sim_time_s = 0.01 * m.header.sequence;
    m.payload = std::move(p);
    raw(ipc::encode(m));
    return m.header.sequence;
  }
  /// A scenario state as a host sends it (scenario.hpp, encodeState).
  void send(const ScenarioState& s) {
    for (const auto& d : encodeState(s, seq_)) raw(d);
  }
  void raw(const std::vector<std::uint8_t>& bytes) {
    ASSERT_EQ(::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to_), sizeof to_),
              static_cast<ssize_t>(bytes.size()));
  }
  [[nodiscard]] std::uint32_t last() const { return seq_ - 1; }

 private:
  int fd_;
  sockaddr_in to_{};
  std::uint32_t seq_ = 1;
};

/// The first frame builds the fog tables (seconds; more under sanitizers).
constexpr auto kFirstFrame = 120'000ms;

/// Threads of this process now (/proc/self/task).
std::size_t threadCount() {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator("/proc/self/task")) ++n;
  return n;
}

/// The newest frame of `channel` when its number is `frame` (else nullopt), polled.
struct ShmFrame {
  ipc::FrameMeta meta;
  std::vector<std::byte> pixels;
};
std::optional<ShmFrame> readFrame(const std::string& channel, std::uint64_t frame, std::chrono::milliseconds timeout) {
  auto reader = ipc::ShmReader::attach(channel);
  EXPECT_TRUE(reader) << (reader ? "" : reader.error().message);
  if (!reader) return std::nullopt;
  ShmFrame f;
  const bool got = waitFor(
      [&] { return (*reader)->latest(f.meta, f.pixels) == ipc::ReadStatus::Ok && f.meta.frame == frame; }, timeout);
  if (!got) return std::nullopt;
  return f;
}

/// A number field of a flat status JSON ("name": 12.5), or nullopt.
std::optional<double> jsonNumber(const std::string& json, const std::string& name) {
  std::smatch m;
  if (!std::regex_search(json, m, std::regex("\"" + name + "\": (-?[0-9.]+)"))) return std::nullopt;
  return std::stod(m[1].str());
}

TEST(WireMeta, CarriesTheRenderersFiguresAndTheLoopsBookkeeping) {
  RenderedFrame f;
  f.view.eye_m = Vec3(1.5, -2.0, 1.2);
  f.view.yaw_deg = 10.0f;
  f.view.pitch_deg = -1.0f;
  f.view.roll_deg = 0.5f;
  f.view.fov_x_deg = 60.0f;
  f.view.fov_y_deg = 35.0f;
  f.inputs.sim_time_s = 12.25;
  f.inputs.lights = ipc::light::kLowBeam | ipc::light::kPosition;
  f.inputs.ego_sequence = 7;
  f.inputs.lamp_sequence = 5;
  f.inputs.environment_sequence = 3;
  f.inputs.traffic_count = 2;
  f.timings = FrameTimings{1.0, 2.0, 3.0, 4.0, 5.0, 16.0};
  FrameBookkeeping book;
  book.frame = 101;
  book.frame_request = 101;
  book.latency_ms = 17.5;
  const ipc::FrameMeta m = wireMeta(f, book);
  EXPECT_EQ(m.frame, 101u);
  EXPECT_EQ(m.frame_request, 101u);
  EXPECT_EQ(m.latency_ms, 17.5);
  EXPECT_EQ(m.sim_time_s, 12.25);
  EXPECT_EQ(m.position_m, (std::array<double, 3>{1.5, -2.0, 1.2}));
  EXPECT_EQ(m.yaw_deg, 10.0f);
  EXPECT_EQ(m.pitch_deg, -1.0f);
  EXPECT_EQ(m.roll_deg, 0.5f);
  EXPECT_EQ(m.fov_x_deg, 60.0f);
  EXPECT_EQ(m.fov_y_deg, 35.0f);
  EXPECT_EQ(m.lights, ipc::light::kLowBeam | ipc::light::kPosition);
  EXPECT_EQ(m.ego_sequence, 7u);
  EXPECT_EQ(m.lamp_sequence, 5u);
  EXPECT_EQ(m.environment_sequence, 3u);
  EXPECT_EQ(m.traffic_count, 2u);
  // Stage times: the renderer's surface, airlight, composite (+ pack) and total; its table wait
  // and glow/glare have no field of their own (they are in total_ms).
  EXPECT_EQ(m.surface_ms, 2.0);
  EXPECT_EQ(m.airlight_ms, 3.0);
  EXPECT_EQ(m.composite_ms, 5.0);
  EXPECT_EQ(m.total_ms, 16.0);
  EXPECT_EQ(m.publish_ns, 0u);  // the writer's to stamp
  // A state without any input: latency 0 on the wire.
  book.latency_ms.reset();
  EXPECT_EQ(wireMeta(f, book).latency_ms, 0.0);
}

TEST(Service, LockStepPublishesOneFramePerRequestWithItsNumber) {
  auto created = Service::create(configOf(kSmall, {"timing.mode=\"lock-step\""}));
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  ASSERT_NE(service.udpPort(), 0);
  EXPECT_EQ(service.statusPort(), 0);  // small.toml: udp_port = 0 = off
  const std::string channel = service.config().channels.at(0).name;
  Running loop(service);

  UdpSender host(service.udpPort());
  ipc::Environment env;
  env.visibility_m = 60.0f;
  env.g = 0.85f;
  env.phase = ipc::PhaseCode::HenyeyGreenstein;
  const std::uint32_t envSeq = host.send(env);
  const std::uint32_t lampSeq = host.send(ipc::LampState{ipc::light::kLowBeam | ipc::light::kHighBeam, 0.0f});
  for (std::uint64_t k = 1; k <= 3; ++k) {
    ipc::EgoState ego;
    ego.pose.position_m = {5.0 * static_cast<double>(k), 0.0, 0.0};
    ego.pose.yaw_deg = 2.0f * static_cast<float>(k);
    const std::uint32_t egoSeq = host.send(ego);
    host.send(ipc::FrameRequest{100 + k});  // after the state on one socket: applied after it
    const auto f = readFrame(channel, 100 + k, kFirstFrame);
    ASSERT_TRUE(f) << "frame " << 100 + k << " never published";
    EXPECT_EQ(f->meta.frame_request, 100 + k);
    EXPECT_EQ(f->meta.ego_sequence, egoSeq);
    EXPECT_EQ(f->meta.lamp_sequence, lampSeq);
    EXPECT_EQ(f->meta.environment_sequence, envSeq);
    EXPECT_EQ(f->meta.lights, ipc::light::kLowBeam | ipc::light::kHighBeam);
    EXPECT_EQ(f->meta.yaw_deg, 2.0f * static_cast<float>(k));
    EXPECT_EQ(f->meta.traffic_count, 0u);
    EXPECT_NEAR(f->meta.fov_x_deg, 60.0f, 1e-4f);
    EXPECT_GT(f->meta.total_ms, 0.0);
    EXPECT_GT(f->meta.latency_ms, 0.0);  // from the request's arrival to the publish
    EXPECT_EQ(f->pixels.size(), std::size_t{160} * 90 * 8);  // RGBA16F overlay
    // frames() counts the frame once every channel has it (a moment after the reader may).
    EXPECT_TRUE(waitFor([&] { return service.frames() == k; }, 1000ms)) << service.frames();
  }
  // No request, no frame.
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(service.frames(), 3u);
  EXPECT_TRUE(loop.finish());
  EXPECT_EQ(service.udpStats().applied, host.last());  // every message applied
}

TEST(Service, FreeRunningKeepsItsRateWithoutBursts) {
  constexpr double kRateHz = 20.0;
  auto created = Service::create(configOf(kTiming, {"timing.rate_hz=20"}));
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  ASSERT_TRUE(waitFor([&] { return service.frames() >= 2; }, kFirstFrame)) << "no frames";
  const auto t0 = Clock::now();
  const std::uint64_t f0 = service.frames();
  std::this_thread::sleep_for(2s);
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  const double frames = static_cast<double>(service.frames() - f0);
  std::printf("  free-running at %.0f Hz: %.0f frames in %.2f s (%.1f Hz)\n", kRateHz, frames, seconds, frames / seconds);
  // Never faster than the rate (a late frame restarts the pace instead of bursting; +1 for the
  // frame in flight at either end). Not much slower either: 128x72 CPU frames take a few ms;
  // the bound leaves room for a loaded machine and sanitizers.
  EXPECT_LE(frames, kRateHz * seconds + 2.0);
  EXPECT_GE(frames, 0.25 * kRateHz * seconds);
  EXPECT_TRUE(loop.finish());
}

TEST(Service, StopIsPromptAtALowRate) {
  // 0.1 Hz: between frames the loop waits 10 s. (A first frame slower than a period, as it can
  // be on a loaded machine with its table build, is followed by a second one at once: the
  // figures are taken after both.)
  auto created = Service::create(configOf(kTiming, {"timing.rate_hz=0.1"}));
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  ASSERT_TRUE(waitFor([&] { return service.frames() >= 1; }, kFirstFrame));
  std::this_thread::sleep_for(500ms);  // into the wait
  const std::uint64_t frames = service.frames();
  const auto t0 = Clock::now();
  EXPECT_TRUE(loop.finish());
  const double stopS = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_LT(stopS, 1.0) << "stop waited for the next frame";
  EXPECT_EQ(service.frames(), frames);  // and rendered none after the request
}

TEST(Service, RunReturnsAtItsFrameLimitAndGoesOnWhenCalledAgain) {
  auto created = Service::create(configOf(kTiming));
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  RunLimits two;
  two.frames = 2;
  ASSERT_TRUE(service.run(two));
  EXPECT_EQ(service.frames(), 2u);
  ASSERT_TRUE(service.run(two));
  EXPECT_EQ(service.frames(), 4u);
  auto reader = ipc::ShmReader::attach(service.config().channels.at(0).name);
  ASSERT_TRUE(reader) << reader.error().message;
  ipc::FrameMeta meta;
  std::vector<std::byte> pixels;
  std::vector<float> distance;
  ASSERT_EQ((*reader)->latest(meta, pixels, &distance), ipc::ReadStatus::Ok);
  EXPECT_EQ(meta.frame, 4u);  // free-running: frames numbered from 1 across calls
  EXPECT_EQ(meta.frame_request, 0u);
  EXPECT_EQ(distance.size(), std::size_t{128} * 72);  // timing.toml's channel has the distance plane
  // A duration limit ends a loop that has nothing to do (lock-step, no request).
  auto idle = Service::create(configOf(kSmall, {"timing.mode=\"lock-step\""}));
  ASSERT_TRUE(idle) << idle.error().message;
  RunLimits shortly;
  shortly.duration_s = 0.2;
  const auto t0 = Clock::now();
  ASSERT_TRUE((*idle)->run(shortly));
  EXPECT_LT(Clock::now() - t0, 2s);
  EXPECT_EQ((*idle)->frames(), 0u);
}

TEST(Service, StatusPortAnswersWithTheFrameAndInputFigures) {
  ServiceOptions options;
  options.any_status_port = true;
  auto created = Service::create(configOf(kTiming, {"status.interval_s=0.2"}), options);
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  ASSERT_NE(service.statusPort(), 0);
  ASSERT_NE(service.statusPort(), service.udpPort());
  Running loop(service);
  UdpSender host(service.udpPort());
  host.send(ipc::LampState{ipc::light::kLowBeam, 0.0f});
  ipc::EgoState ego;
  ego.pose.position_m = {10.0, 0.0, 0.0};
  host.send(ego);
  // The figures are those of the last status interval: wait for one after frames came.
  ASSERT_TRUE(waitFor([&] { return jsonNumber(service.statusJson(), "frames").value_or(0) >= 3; }, kFirstFrame));
  auto reply = ipc::requestStatus("127.0.0.1", service.statusPort(), 2.0);
  ASSERT_TRUE(reply) << reply.error().message;
  const std::string& json = *reply;
  EXPECT_EQ(json.front(), '{');
  EXPECT_EQ(json.back(), '}');
  EXPECT_GE(jsonNumber(json, "frames").value_or(0), 3.0) << json;
  EXPECT_GT(jsonNumber(json, "fps").value_or(0), 0.0) << json;
  EXPECT_GT(jsonNumber(json, "frame_ms_p50").value_or(0), 0.0) << json;
  EXPECT_GE(jsonNumber(json, "ego_age_s").value_or(-1), 0.0) << json;
  EXPECT_EQ(jsonNumber(json, "environment_age_s").value_or(0), -1.0) << json;  // never sent
  EXPECT_NE(json.find("\"input\": \"udp 127.0.0.1:"), std::string::npos) << json;
  EXPECT_EQ(jsonNumber(json, "datagrams").value_or(0), 2.0) << json;
  EXPECT_EQ(jsonNumber(json, "applied").value_or(0), 2.0) << json;
  EXPECT_EQ(jsonNumber(json, "restarts").value_or(-1), 0.0) << json;
  EXPECT_NE(json.find("\"dropped\": {}"), std::string::npos) << json;
  EXPECT_TRUE(loop.finish());
}

TEST(Service, InputFromTheNetworkNeverStopsTheFrames) {
  ServiceOptions options;
  options.any_status_port = true;
  auto created = Service::create(configOf(kTiming, {"status.interval_s=0.2"}), options);
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  ASSERT_TRUE(waitFor([&] { return service.frames() >= 1; }, kFirstFrame));
  UdpSender host(service.udpPort());
  // Garbage of every kind a network can bring: empty, short, a wrong magic, a header whose
  // length disagrees, a valid header with non-finite values, random bytes; then a valid pose.
  host.raw({});
  host.raw({0x46, 0x47});
  host.raw(std::vector<std::uint8_t>(64, 0xAB));
  auto ego = ipc::encode(ipc::Message{ipc::Header{ipc::MessageType::EgoState, 0, 1000, 0.0}, ipc::EgoState{}});
  auto truncated = ego;
  truncated.resize(ego.size() - 5);
  host.raw(truncated);
  ipc::EgoState nan;
  nan.pose.position_m = {std::nan(""), 0.0, 0.0};
  host.send(nan);
  std::uint32_t x = 12345;
  for (int d = 0; d < 200; ++d) {
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(x % 1400));
    for (auto& b : bytes) b = static_cast<std::uint8_t>((x = x * 1664525u + 1013904223u) >> 24);
    host.raw(bytes);
  }
  ipc::EgoState good;
  good.pose.position_m = {3.0, 0.0, 0.0};
  host.send(good);
  ASSERT_TRUE(waitFor([&] { return service.udpStats().datagrams >= 206; }, 5000ms));
  const std::uint64_t before = service.frames();
  ASSERT_TRUE(waitFor([&] { return service.frames() >= before + 5; }, 10'000ms)) << "frames stopped";
  const ipc::UdpStats st = service.udpStats();
  EXPECT_EQ(st.applied, 1u);  // the good pose only
  EXPECT_EQ(st.droppedTotal(), st.datagrams - 1);
  EXPECT_GE(st.dropped[static_cast<std::size_t>(ipc::DropReason::NonFinite)], 1u);
  // The status reply lists the drops by reason.
  ASSERT_TRUE(waitFor([&] { return service.statusJson().find("\"non_finite\": 1") != std::string::npos; }, 5000ms))
      << service.statusJson();
  EXPECT_TRUE(loop.finish());
}

TEST(Service, StopJoinsEveryThreadAndUnlinksTheChannels) {
  const std::size_t baseline = threadCount();
  ServiceOptions options;
  options.any_status_port = true;
  auto created = Service::create(configOf(kTiming), options);
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  const std::string channel = service.config().channels.at(0).name;
  const std::uint16_t udpPort = service.udpPort(), statusPort = service.statusPort();
  std::thread loop([&] { EXPECT_TRUE(service.run()); });
  ASSERT_TRUE(waitFor([&] { return service.frames() >= 2; }, kFirstFrame));
  // UDP, status, heartbeat, the frame loop, the airlight workers.
  EXPECT_GE(threadCount(), baseline + 4);
  ASSERT_TRUE(ipc::requestStatus("127.0.0.1", statusPort, 2.0));

  const auto t0 = Clock::now();
  service.stop();
  const double stopS = std::chrono::duration<double>(Clock::now() - t0).count();
  loop.join();
  std::printf("  stop() took %.3f s\n", stopS);
  EXPECT_LT(stopS, 5.0);
  // A joined thread leaves /proc/self/task a moment after pthread_join returns.
  EXPECT_TRUE(waitFor([&] { return threadCount() == baseline; }, 1000ms)) << threadCount() << " vs " << baseline;
  EXPECT_FALSE(ipc::ShmReader::attach(channel)) << "segment not unlinked";
  EXPECT_FALSE(ipc::requestStatus("127.0.0.1", statusPort, 0.3)) << "status still answers";
  // The UDP port is free again.
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(udpPort);
  ::inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
  EXPECT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a), 0) << "UDP port still bound";
  ::close(fd);
  // Stopped is final: run() returns at once, the figures stay.
  const std::uint64_t frames = service.frames();
  EXPECT_TRUE(service.run());
  EXPECT_EQ(service.frames(), frames);
  service.stop();  // idempotent
}

TEST(Service, ABadChannelFailsCreateWithAClearErrorAndLeavesNothingRunning) {
  const std::size_t baseline = threadCount();
  // The configuration takes channel names of up to 200 characters, a segment name 48.
  ServiceConfig longName = configOf(kSmall);
  longName.channels.at(0).name = std::string(60, 'x');
  auto bad = Service::create(longName);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find(std::string(60, 'x') + "': expected 1–48 characters"), std::string::npos)
      << bad.error().message;
  EXPECT_TRUE(waitFor([&] { return threadCount() == baseline; }, 1000ms)) << threadCount() << " vs " << baseline;

  // A channel whose writer is alive (this process) is refused, naming the writer.
  ServiceConfig cfg = configOf(kSmall);
  auto first = Service::create(cfg);
  ASSERT_TRUE(first) << first.error().message;
  auto second = Service::create(cfg);
  ASSERT_FALSE(second);
  EXPECT_NE(second.error().message.find("in use by a running writer (pid " + std::to_string(::getpid()) + ")"),
            std::string::npos)
      << second.error().message;
  // The first one is unharmed: its channel is still there.
  EXPECT_TRUE(ipc::ShmReader::attach(cfg.channels.at(0).name));

  // A bad channel layout in a config layer is the config loader's error, before any service.
  auto layer = loadServiceConfig(kSmall, {"channel.width=640"});
  ASSERT_FALSE(layer);
  EXPECT_NE(layer.error().message.find("expected an array of tables [[channel]]"), std::string::npos)
      << layer.error().message;
}

/// Keeps each frame's packed pixels and metadata (what replay's sink gets, less the files).
class CaptureSink final : public FrameSink {
 public:
  Status consume(std::size_t channel, const RenderedFrame& frame, const FrameBookkeeping& book) override {
    EXPECT_EQ(channel, 0u);
    pixels.emplace_back(frame.packed);
    metas.push_back(wireMeta(frame, book));
    return Ok{};
  }
  std::vector<std::vector<std::byte>> pixels;
  std::vector<ipc::FrameMeta> metas;
};

TEST(Service, ReplaysStepGivesServesPixelsForTheSameStates) {
  auto scenario = loadScenario(kScenario);
  ASSERT_TRUE(scenario) << scenario.error().message;
  const ServiceConfig cfg = configOf(kSmall, {"timing.mode=\"lock-step\""});
  // Times on both sides of the scenario's light events (high beam from 2 s, low from 4 s).
  const std::vector<double> times{0.0, 1.5, 2.5, 4.5};

  // Serve: the states over UDP, one frame request after each; frames read from shared memory.
  std::vector<ShmFrame> served;
  {
    auto created = Service::create(cfg);
    ASSERT_TRUE(created) << created.error().message;
    Service& service = **created;
    Running loop(service);
    UdpSender host(service.udpPort());
    for (std::size_t k = 0; k < times.size(); ++k) {
      host.send(evaluate(*scenario, times[k]));
      host.send(ipc::FrameRequest{k + 1});
      auto f = readFrame(service.config().channels.at(0).name, k + 1, kFirstFrame);
      ASSERT_TRUE(f) << "frame " << k + 1;
      served.push_back(std::move(*f));
    }
    EXPECT_TRUE(loop.finish());
  }

  // Replay: the same states applied to a store, the pipeline's step into a sink.
  auto world = loadScene(cfg.scene_path);
  ASSERT_TRUE(world) << world.error().message;
  auto pipeline = FramePipeline::create(cfg, *world, nullptr, true);
  ASSERT_TRUE(pipeline) << pipeline.error().message;
  ipc::StateStore store;
  std::uint32_t sequence = 1;
  CaptureSink sink;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const auto now = Clock::now();
    applyState(evaluate(*scenario, times[k]), store, sequence, now);
    FrameBookkeeping book;
    book.frame = k + 1;
    ASSERT_TRUE((*pipeline)->step(*store.snapshot(), now, book, sink));
  }

  ASSERT_EQ(sink.pixels.size(), served.size());
  for (std::size_t k = 0; k < served.size(); ++k) {
    EXPECT_TRUE(sink.pixels[k] == served[k].pixels) << "t = " << times[k] << " s: pixels differ";
    const ipc::FrameMeta& a = sink.metas[k];
    const ipc::FrameMeta& b = served[k].meta;
    EXPECT_EQ(a.lights, b.lights) << k;
    EXPECT_EQ(a.traffic_count, b.traffic_count) << k;
    EXPECT_EQ(a.position_m, b.position_m) << k;
    EXPECT_EQ(a.yaw_deg, b.yaw_deg) << k;
  }
  // The frames are not all alike (the pose moves, the high beam comes and goes, the car nears).
  EXPECT_NE(sink.pixels[0], sink.pixels[1]);
  EXPECT_EQ(served[2].meta.lights & ipc::light::kHighBeam, ipc::light::kHighBeam);
  EXPECT_EQ(served[3].meta.lights & ipc::light::kHighBeam, 0u);
  EXPECT_EQ(served[0].meta.traffic_count, 1u);
}

// [glow] on: the pipeline makes the fog light's maps of the ego's and the traffic's lamps ahead
// of the frames (FogLightPrewarm), so the first frame with an oncoming car makes none (a map is
// ~1 s the first time a lamp file is ever seen). Table cache off: every map is made, none loaded.
TEST(Service, TheFogLightsMapsAreMadeBeforeTheFramesThatShowTheLamps) {
  auto scenario = loadScenario(kScenario);
  ASSERT_TRUE(scenario) << scenario.error().message;
  const ServiceConfig cfg =
      configOf(kSmall, {"timing.mode=\"lock-step\"", "glow.enabled=true", "render.table_cache=\"off\""});
  auto world = loadScene(cfg.scene_path);
  ASSERT_TRUE(world) << world.error().message;
  auto pipeline = FramePipeline::create(cfg, *world, nullptr, true);
  ASSERT_TRUE(pipeline) << pipeline.error().message;
  const FogLightPrewarm* prewarm = (*pipeline)->fogLightPrewarm();
  ASSERT_NE(prewarm, nullptr);
  // The ego's low beam (front only) and the car's low beam (all round): one file, two maps; the
  // ego's high beam a third.
  EXPECT_GE(prewarm->summary().maps.size(), 3u);
  EXPECT_EQ(prewarm->summary().loaded, 0u);
  const std::size_t made = AnnulusMeanMap::buildsSoFar();

  ipc::StateStore store;
  std::uint32_t sequence = 1;
  CaptureSink sink;
  for (double t : {0.0, 2.5, 4.5}) {  // the car in view; the ego's high beam on, then off
    const auto now = Clock::now();
    applyState(evaluate(*scenario, t), store, sequence, now);
    FrameBookkeeping book;
    book.frame = sink.pixels.size() + 1;
    ASSERT_TRUE((*pipeline)->step(*store.snapshot(), now, book, sink));
  }
  ASSERT_EQ(sink.metas.size(), 3u);
  EXPECT_EQ(sink.metas[0].traffic_count, 1u);
  EXPECT_EQ(AnnulusMeanMap::buildsSoFar(), made);

  // Glow off: no prewarm at all; nor where every channel takes the host's depth (no surfaces of
  // fogbeam's own for the fog light to light).
  auto off = FramePipeline::create(configOf(kSmall, {"timing.mode=\"lock-step\""}), *world, nullptr, true);
  ASSERT_TRUE(off) << off.error().message;
  EXPECT_EQ((*off)->fogLightPrewarm(), nullptr);
  ServiceConfig hostDepth = configOf(kSmall, {"timing.mode=\"lock-step\"", "glow.enabled=true"});
  for (ChannelConfig& c : hostDepth.channels) c.depth_from = "host";
  auto overlayOnly = FramePipeline::create(hostDepth, *world, nullptr, true);
  ASSERT_TRUE(overlayOnly) << overlayOnly.error().message;
  EXPECT_EQ((*overlayOnly)->fogLightPrewarm(), nullptr);
}

}  // namespace
}  // namespace fogbeam::plugin
