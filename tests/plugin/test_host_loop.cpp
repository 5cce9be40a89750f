// The cab loop (docs/service.md, "Host depth"): a host publishes its depth and camera through the
// C SDK, a Service with a depth_from channel answers with the overlay for exactly that view.
// Checked against the same service's own view of the same plane scene, for a host whose depth
// lags its state, for a host that stops and restarts, and for the configuration rules.
#include <fogbeam/fogbeam_host.h>
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/plugin/service.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/render/pixel_pack.hpp>

#include <gtest/gtest.h>

#include "service_test_support.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
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

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

const std::string kSmall = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/small.toml";
constexpr auto kFirstFrame = 120'000ms;  // the first frame may build tables (more under sanitizers)

/// small.toml (one 160×90 overlay channel "own", fogbeam's own view) plus a channel "host" of
/// the same view fed by host depth channel `depth`; unique names per process and call.
struct LoopConfig {
  ServiceConfig config;
  std::string own, host, depth;
};
LoopConfig loopConfig(const std::vector<std::string>& settings) {
  holdTheTestFogsTables();
  static std::atomic<int> calls{0};
  std::vector<std::string> layered{"render.view_table_step_deg=4.0"};
  layered.insert(layered.end(), settings.begin(), settings.end());
  auto c = loadServiceConfig(kSmall, layered);
  EXPECT_TRUE(c) << (c ? "" : c.error().message);
  LoopConfig lc;
  if (!c) return lc;
  const std::string prefix = "test-loop-" + std::to_string(::getpid()) + "-" + std::to_string(calls++) + "-";
  lc.own = prefix + "own";
  lc.host = prefix + "host";
  lc.depth = prefix + "depth";
  ChannelConfig own = c->channels.at(0);
  own.name = lc.own;
  ChannelConfig host = own;
  host.name = lc.host;
  host.depth_from = lc.depth;
  c->channels = {own, host};
  EXPECT_TRUE(validate(*c));
  lc.config = std::move(c).value();
  return lc;
}

/// A host stand-in: the road plane z = 0 seen from `camera`, distances along each pixel's ray
/// computed from the camera model (Camera::rayDirection), +inf above the horizon.
std::vector<float> planeDepth(const Camera& camera) {
  std::vector<float> d(static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height));
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const Vec3 dir = camera.rayDirection(x + 0.5, y + 0.5);
      const double t = dir.z < 0.0 ? -camera.position_m.z / dir.z : std::numeric_limits<double>::infinity();
      d[static_cast<std::size_t>(y) * static_cast<std::size_t>(camera.width) + static_cast<std::size_t>(x)] =
          static_cast<float>(t);
    }
  }
  return d;
}

/// The channel's camera at the ego pose `origin` (yaw 0): what the own channel renders.
Camera ownCamera(const ServiceConfig& c, const Vec3& origin) {
  Camera cam = channelCamera(c, c.channels.at(0));
  cam.position_m += origin;
  return cam;
}

fogbeam_camera sdkCamera(const Camera& cam, std::uint64_t frame, double simTime) {
  fogbeam_camera fc{};
  fc.frame = frame;
  fc.sim_time_s = simTime;
  for (int k = 0; k < 3; ++k) fc.position_m[k] = cam.position_m[k];
  fc.fov_x_deg = static_cast<float>(cam.fov_x * 180.0 / kPi);
  return fc;
}

struct Overlay {
  ipc::FrameMeta meta;
  std::vector<float> rgba;  ///< linear, 4 per pixel
};

/// The newest frame of `channel` that satisfies `want`, polled.
std::optional<Overlay> readOverlay(const std::string& channel, const std::function<bool(const ipc::FrameMeta&)>& want,
                                   std::chrono::milliseconds timeout) {
  std::unique_ptr<ipc::ShmReader> reader;
  if (!waitFor(
          [&] {
            auto r = ipc::ShmReader::attach(channel);
            if (r) reader = std::move(r).value();
            return reader != nullptr;
          },
          5000ms))
    return std::nullopt;
  Overlay o;
  std::vector<std::byte> px;
  if (!waitFor([&] { return reader->latest(o.meta, px) == ipc::ReadStatus::Ok && want(o.meta); }, timeout))
    return std::nullopt;
  const auto* h = reinterpret_cast<const std::uint16_t*>(px.data());
  o.rgba.resize(px.size() / 2);
  for (std::size_t i = 0; i < o.rgba.size(); ++i) o.rgba[i] = halfToFloat(h[i]);
  return o;
}

/// p95 of |a − b| / b over pixels whose in-scattered luminance (G) exceeds 1 % of the 99.5th
/// percentile of b's; and the largest transmittance difference.
struct Agreement {
  double p95 = 0.0, maxT = 0.0;
  std::size_t pixels = 0;
};
Agreement agreement(const Overlay& a, const Overlay& b) {
  std::vector<double> g;
  for (std::size_t i = 1; i < b.rgba.size(); i += 4) g.push_back(static_cast<double>(b.rgba[i]));
  std::sort(g.begin(), g.end());
  const double floor = 0.01 * g[static_cast<std::size_t>(0.995 * static_cast<double>(g.size() - 1))];
  std::vector<double> rel;
  Agreement r;
  for (std::size_t i = 0; i < b.rgba.size(); i += 4) {
    r.maxT = std::max(r.maxT, std::abs(static_cast<double>(a.rgba[i + 3] - b.rgba[i + 3])));
    for (std::size_t c = 0; c < 3; ++c) {
      const double ref = b.rgba[i + c];
      if (ref > floor) rel.push_back(std::abs(static_cast<double>(a.rgba[i + c]) - ref) / ref);
    }
  }
  std::sort(rel.begin(), rel.end());
  r.pixels = rel.size() / 3;
  r.p95 = rel.empty() ? 1.0 : rel[static_cast<std::size_t>(0.95 * static_cast<double>(rel.size() - 1))];
  return r;
}

struct DepthWriter {
  fogbeam_depth_writer* w = nullptr;
  DepthWriter(const std::string& name, int width, int height) {
    EXPECT_EQ(fogbeam_depth_create(name.c_str(), static_cast<std::uint32_t>(width), static_cast<std::uint32_t>(height), &w),
              FOGBEAM_OK)
        << fogbeam_last_error();
  }
  ~DepthWriter() { fogbeam_depth_destroy(w); }
  DepthWriter(const DepthWriter&) = delete;
  DepthWriter& operator=(const DepthWriter&) = delete;
  void publish(const std::vector<float>& d, const fogbeam_camera& c) {
    ASSERT_EQ(fogbeam_depth_publish(w, d.data(), &c), FOGBEAM_OK) << fogbeam_last_error();
  }
};

TEST(HostLoop, OverlayOfAHostsPlaneDepthEqualsTheServicesOwnViewOfThePlane) {
  // Lock-step on the host's depth frames: each step renders the own channel (CPU road plane,
  // ego at the origin: no ego message) and the host channel (the host's plane depth, the same
  // camera), from one state. No bonnet: the host's plane depth has none.
  LoopConfig lc = loopConfig({"timing.mode=\"lock-step\"", "ego.bonnet.enabled=false"});
  auto created = Service::create(lc.config);
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  const Camera cam = ownCamera(service.config(), Vec3(0.0));
  DepthWriter host(lc.depth, cam.width, cam.height);
  host.publish(planeDepth(cam), sdkCamera(cam, 7, 3.25));

  const auto ownFrame = readOverlay(lc.own, [](const ipc::FrameMeta& m) { return m.frame == 7; }, kFirstFrame);
  const auto hostFrame = readOverlay(lc.host, [](const ipc::FrameMeta& m) { return m.host_frame == 7; }, kFirstFrame);
  ASSERT_TRUE(ownFrame && hostFrame) << "no frame 7 on both channels";
  // The host's frame echoed: number, simulation time, view.
  EXPECT_EQ(hostFrame->meta.frame, 7u);  // lock-step on depth: the frame number is the host's
  EXPECT_EQ(hostFrame->meta.frame_request, 7u);
  EXPECT_EQ(hostFrame->meta.sim_time_s, 3.25);
  EXPECT_EQ(hostFrame->meta.position_m[1], cam.position_m.y);
  EXPECT_NEAR(hostFrame->meta.fov_x_deg, 60.0f, 1e-4f);
  EXPECT_EQ(ownFrame->meta.host_frame, 0u);
  EXPECT_GT(hostFrame->meta.latency_ms, 0.0);  // from the host's publish
  // The overlay itself: the same airlight and transmittance as fogbeam's own view of the plane.
  const Agreement a = agreement(*hostFrame, *ownFrame);
  EXPECT_GT(a.pixels, 1000u);
  EXPECT_LE(a.p95, 0.01) << "over " << a.pixels << " pixels";
  EXPECT_LE(a.maxT, 2e-3);
  std::printf("host plane vs own view: p95 %.2e over %zu pixels, max |dT| %.2e\n", a.p95, a.pixels, a.maxT);
  EXPECT_TRUE(loop.finish());
}

TEST(HostLoop, AHostWhoseDepthLagsItsStateByAFrameGetsTheOverlayOfItsDepthsView) {
  // The host's camera wins for the view and for the ego's lamps (they hang from the host's eye):
  // an ego state one frame ahead of the depth (the vehicle 1.5 m further on) changes nothing of
  // the host channel's overlay, while fogbeam's own channel, which follows the state, moves.
  LoopConfig lc = loopConfig({"timing.mode=\"lock-step\""});
  auto created = Service::create(lc.config);
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  test::LoopbackSender state(service.udpPort());
  const Camera cam = ownCamera(service.config(), Vec3(10.0, 0.0, 0.0));
  const std::vector<float> depth = planeDepth(cam);
  DepthWriter host(lc.depth, cam.width, cam.height);

  ipc::EgoState ego;
  ego.pose.position_m = {10.0, 0.0, 0.0};
  state.send(ego);
  // Frame 1: state and depth agree. Wait until the state is applied before publishing the depth.
  std::this_thread::sleep_for(200ms);
  host.publish(depth, sdkCamera(cam, 1, 1.0));
  const auto host1 = readOverlay(lc.host, [](const ipc::FrameMeta& m) { return m.host_frame == 1; }, kFirstFrame);
  const auto own1 = readOverlay(lc.own, [](const ipc::FrameMeta& m) { return m.frame == 1; }, kFirstFrame);
  ASSERT_TRUE(host1 && own1);
  // Frame 2: the state is a frame ahead of the depth (the host sent its next pose first).
  ego.pose.position_m = {11.5, 0.0, 0.0};
  state.send(ego);
  std::this_thread::sleep_for(200ms);
  host.publish(depth, sdkCamera(cam, 2, 1.0));
  const auto host2 = readOverlay(lc.host, [](const ipc::FrameMeta& m) { return m.host_frame == 2; }, kFirstFrame);
  const auto own2 = readOverlay(lc.own, [](const ipc::FrameMeta& m) { return m.frame == 2; }, kFirstFrame);
  ASSERT_TRUE(host2 && own2);
  EXPECT_EQ(host2->meta.position_m, host1->meta.position_m);
  EXPECT_NE(own2->meta.position_m, own1->meta.position_m);
  EXPECT_EQ(host2->rgba, host1->rgba) << "the host channel's overlay followed the state instead of the host's view";
  EXPECT_NE(own2->rgba, own1->rgba);  // the check above can fail: the state does move the own view
  EXPECT_TRUE(loop.finish());
}

TEST(HostLoop, FreeRunningGoesOnWithTheLastHostFrameAndReattachesARestartedHost) {
  LoopConfig lc = loopConfig({"timing.rate_hz=50", "status.interval_s=0.1"});
  auto created = Service::create(lc.config, ServiceOptions{true});
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  const Camera cam = ownCamera(service.config(), Vec3(0.0));
  const std::vector<float> depth = planeDepth(cam);
  auto status = [&] { return service.statusJson(); };
  auto field = [&](const std::string& json, const std::string& name) -> std::optional<double> {
    std::smatch m;
    if (!std::regex_search(json, m, std::regex("\"" + name + "\": (-?[0-9.]+)"))) return std::nullopt;
    return std::stod(m[1].str());
  };
  {
    DepthWriter host(lc.depth, cam.width, cam.height);
    host.publish(depth, sdkCamera(cam, 1, 0.0));
    ASSERT_TRUE(readOverlay(lc.host, [](const ipc::FrameMeta& m) { return m.host_frame == 1; }, kFirstFrame));
    // The host stops publishing: frames go on with host frame 1, the link reports it stale.
    // Waited for, not slept for: under a sanitizer on two cores a frame takes ~100 ms while the
    // tables build, so a fixed sleep counts machine speed, not whether the frames go on.
    const std::uint64_t before = service.frames();
    EXPECT_TRUE(waitFor([&] { return service.frames() > before + 12; }, 20'000ms))
        << service.frames() - before << " frames since the host stopped; " << status();
    EXPECT_TRUE(waitFor([&] { return status().find("\"stale\": true") != std::string::npos; }, 3000ms)) << status();
    EXPECT_GT(field(status(), "repeated").value_or(0), 10.0) << status();
  }  // the host exits (channel closed)
  EXPECT_TRUE(waitFor([&] { return status().find("\"connected\": false") != std::string::npos; }, 5000ms)) << status();
  // The host starts again (a new writer generation): attached again, its frames used.
  DepthWriter again(lc.depth, cam.width, cam.height);
  again.publish(depth, sdkCamera(cam, 100, 0.0));
  const auto f = readOverlay(lc.host, [](const ipc::FrameMeta& m) { return m.host_frame == 100; }, 10'000ms);
  ASSERT_TRUE(f) << status();
  EXPECT_TRUE(waitFor([&] { return field(status(), "attached").value_or(0) == 2.0; }, 3000ms)) << status();
  EXPECT_EQ(field(status(), "lost").value_or(0), 1.0) << status();
  EXPECT_TRUE(loop.finish());
}

TEST(HostLoop, AHostDepthOfTheWrongSizeOrWithNaNsIsRefusedAndNothingStops) {
  LoopConfig lc = loopConfig({"timing.rate_hz=50", "status.interval_s=0.1"});
  auto created = Service::create(lc.config, ServiceOptions{true});
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  const Camera cam = ownCamera(service.config(), Vec3(0.0));
  {
    DepthWriter wrong(lc.depth, cam.width + 1, cam.height);
    std::vector<float> d(static_cast<std::size_t>(cam.width + 1) * static_cast<std::size_t>(cam.height), 10.0f);
    wrong.publish(d, sdkCamera(cam, 1, 0.0));
    EXPECT_TRUE(waitFor([&] { return service.statusJson().find("\"refused\": 1") != std::string::npos; }, 10'000ms))
        << service.statusJson();
  }
  DepthWriter host(lc.depth, cam.width, cam.height);
  std::vector<float> d = planeDepth(cam);
  d[5] = std::numeric_limits<float>::quiet_NaN();
  host.publish(d, sdkCamera(cam, 1, 0.0));
  EXPECT_TRUE(waitFor([&] { return service.statusJson().find("\"refused\": 2") != std::string::npos; }, 10'000ms))
      << service.statusJson();
  d[5] = 3.0f;
  host.publish(d, sdkCamera(cam, 2, 0.0));
  EXPECT_TRUE(readOverlay(lc.host, [](const ipc::FrameMeta& m) { return m.host_frame == 2; }, kFirstFrame));
  const std::uint64_t frames = service.frames();
  EXPECT_TRUE(waitFor([&] { return service.frames() > frames + 5; }, 5000ms));  // the own channel never stopped
  EXPECT_TRUE(loop.finish());
}

TEST(HostLoop, ACompositeChannelShowsTheHostsColourThroughTheFogPlusTheOverlay) {
  // Three channels on one host channel with colour (RGBA16F linear): the overlay, the composite
  // fogbeam makes of the host's image, and fogbeam's own view. composite = host·T + overlay RGB.
  LoopConfig lc = loopConfig({"timing.mode=\"lock-step\""});
  ChannelConfig comp = lc.config.channels[1];
  comp.name = lc.host + "-comp";
  comp.format = "rgba16f-linear";
  lc.config.channels.push_back(comp);
  ASSERT_TRUE(validate(lc.config));
  auto created = Service::create(lc.config);
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  const Camera cam = ownCamera(service.config(), Vec3(0.0));
  const std::vector<float> depth = planeDepth(cam);
  fogbeam_depth_writer* w = nullptr;
  ASSERT_EQ(fogbeam_depth_create_colour(lc.depth.c_str(), static_cast<std::uint32_t>(cam.width),
                                        static_cast<std::uint32_t>(cam.height), FOGBEAM_FORMAT_RGBA16F_LINEAR, &w),
            FOGBEAM_OK)
      << fogbeam_last_error();
  // The host's image: 2 cd/m² on the road's left half, 0.5 on its right, 0.1 sky (as halves).
  std::vector<std::uint16_t> colour(depth.size() * 4);
  std::vector<float> hostL(depth.size());
  for (std::size_t i = 0; i < depth.size(); ++i) {
    hostL[i] = std::isinf(depth[i]) ? 0.1f : (i % static_cast<std::size_t>(cam.width)) < 80 ? 2.0f : 0.5f;
    std::uint16_t h[4];
    const float v[3] = {hostL[i], hostL[i], hostL[i]};
    packRgba16F(v, nullptr, 1.0f, 1, h);
    for (std::size_t c = 0; c < 4; ++c) colour[4 * i + c] = h[c];
  }
  fogbeam_camera fc = sdkCamera(cam, 4, 0.0);
  ASSERT_EQ(fogbeam_depth_publish_colour(w, depth.data(), colour.data(), &fc), FOGBEAM_OK) << fogbeam_last_error();
  const auto overlay = readOverlay(lc.host, [](const ipc::FrameMeta& m) { return m.host_frame == 4; }, kFirstFrame);
  const auto composite = readOverlay(comp.name, [](const ipc::FrameMeta& m) { return m.host_frame == 4; }, kFirstFrame);
  ASSERT_TRUE(overlay && composite);
  double worst = 0.0;
  for (std::size_t i = 0; i < depth.size(); ++i) {
    const double want = static_cast<double>(hostL[i]) * static_cast<double>(overlay->rgba[4 * i + 3]) +
                        static_cast<double>(overlay->rgba[4 * i]);
    worst = std::max(worst, std::abs(static_cast<double>(composite->rgba[4 * i]) - want) / std::max(want, 1e-3));
  }
  EXPECT_LE(worst, 2e-3);  // two half-float roundings
  EXPECT_TRUE(loop.finish());
  fogbeam_depth_destroy(w);
}

TEST(HostLoop, ACompositeChannelRefusesAHostWithoutColour) {
  LoopConfig lc = loopConfig({"timing.rate_hz=50", "status.interval_s=0.1"});
  lc.config.channels[1].format = "rgba16f-linear";
  auto created = Service::create(lc.config);
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  const Camera cam = ownCamera(service.config(), Vec3(0.0));
  DepthWriter host(lc.depth, cam.width, cam.height);
  host.publish(planeDepth(cam), sdkCamera(cam, 1, 0.0));
  EXPECT_TRUE(waitFor([&] { return service.statusJson().find("\"refused\": 1") != std::string::npos; }, 10'000ms))
      << service.statusJson();
  EXPECT_NE(service.statusJson().find("\"connected\": false"), std::string::npos);
  EXPECT_TRUE(loop.finish());
}

TEST(HostLoop, DepthFromNamesAHostChannelNotOneOfFogbeams) {
  LoopConfig lc = loopConfig({});
  ServiceConfig c = lc.config;
  c.channels[1].depth_from = c.channels[0].name;
  auto s = validate(c);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("names one of fogbeam's own output channels"), std::string::npos) << s.error().message;
  // From a file: the key, its line, the name rule.
  auto bad = loadServiceConfig(kSmall, {"render.surface=\"cpu\""});
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->channels.at(0).depth_from, "");
}

TEST(HostLoop, SdkRefusesHostFrameZero) {
  const std::string ch = "test-loop-zero-" + std::to_string(::getpid());
  DepthWriter host(ch, 4, 2);
  std::vector<float> d(8, 1.0f);
  fogbeam_camera c{};
  c.fov_x_deg = 60.0f;
  EXPECT_EQ(fogbeam_depth_publish(host.w, d.data(), &c), FOGBEAM_ERROR);
  EXPECT_NE(std::string(fogbeam_last_error()).find("start at 1"), std::string::npos);
}

}  // namespace
}  // namespace fogbeam::plugin
