// End to end through the simulator I/O: UDP datagrams in → state store → a rendered frame
// (CPU surfaces + accurate airlight, overlay RGBA16F) published to shared memory → read back by
// the C host SDK and by the Python reader, metadata checked against what was sent. Prints the
// input-to-publish latency over 30 frames and the shared-memory read cost at 1920×1080.
#include <fogbeam/fogbeam_host.h>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/udp_receiver.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/pixel_pack.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <thread>

namespace fogbeam::ipc {
namespace {

constexpr int kW = 96, kH = 54;

class UdpSender {
 public:
  explicit UdpSender(std::uint16_t port) : fd_(::socket(AF_INET, SOCK_DGRAM, 0)) {
    to_.sin_family = AF_INET;
    to_.sin_port = htons(port);
    inet_pton(AF_INET, "127.0.0.1", &to_.sin_addr);
  }
  ~UdpSender() { ::close(fd_); }
  void send(Payload p) {
    Message m;
    m.header.sequence = ++seq_;
    m.header.sim_time_s = 0.02 * seq_;
    m.payload = std::move(p);
    const auto b = encode(m);
    ::sendto(fd_, b.data(), b.size(), 0, reinterpret_cast<const sockaddr*>(&to_), sizeof to_);
  }
  std::uint32_t sequence() const { return seq_; }

 private:
  int fd_;
  sockaddr_in to_{};
  std::uint32_t seq_ = 0;
};

// The frame a minimal service would render from a snapshot: the driver's eye 1.2 m above the
// vehicle reference, two spot headlamps when the low beam is on, the fog from the environment.
Scene sceneFrom(const SimSnapshot& s) {
  Scene sc;
  const Environment& e = s.environment.value;
  sc.fog.extinction_per_m = e.visibility_m > 0.0f ? extinctionFromVisibility(static_cast<double>(e.visibility_m))
                                                  : static_cast<double>(e.extinction_per_m);
  sc.fog.albedo = static_cast<double>(e.albedo);
  sc.fog.phase = makeHenyeyGreenstein(static_cast<double>(e.g)).value();
  const Pose& p = s.ego.value.pose;
  const Mat3 R = worldFromYawPitchRoll(radians(static_cast<double>(p.yaw_deg)), radians(static_cast<double>(p.pitch_deg)),
                                       radians(static_cast<double>(p.roll_deg)));
  const Vec3 origin(p.position_m[0], p.position_m[1], p.position_m[2]);
  sc.camera.position_m = origin + R * Vec3(0.0, 0.37, 1.2);
  sc.camera.worldFromCamera = R;
  sc.camera.width = kW;
  sc.camera.height = kH;
  if (s.lamps.value.lights & light::kLowBeam) {
    for (double y : {0.7, -0.7}) {
      SceneLamp l;
      l.name = y > 0 ? "left" : "right";
      l.lamp.position_m = origin + R * Vec3(2.2, y, 0.65);
      l.lamp.worldFromLamp = R * worldFromYawPitchRoll(0.0, radians(1.0), 0.0);
      l.lamp.profile = makeProfile(SpotProfile{20000.0, radians(8.0), radians(20.0)}).value();
      sc.lamps.push_back(l);
    }
  }
  sc.planes.push_back(Plane{origin, R * Vec3(0, 0, 1), 0.15});
  return sc;
}

struct Rendered {
  std::vector<std::uint16_t> rgba16;
  std::vector<float> distance;
  double ms = 0.0;
};

Rendered render(const SimSnapshot& s) {
  const auto t0 = Clock::now();
  const Scene sc = sceneFrom(s);
  SurfaceBuffers surf;
  renderSurfacesCpu(sc, surf);
  AirlightImage air;
  air.width = kW;
  air.height = kH;
  air.rgb.assign(3 * kW * kH, 0.0f);
  if (!sc.lamps.empty()) {
    auto ev = AirlightImageEvaluator::build(sc, AirlightMethod::Accurate, {}, 1);
    ev->evaluate(sc, surf, SubsamplingOptions{}, air);
  }
  FrameLayers layers;
  compositeFrame(sc.fog, surf, air, layers);
  Rendered r;
  r.rgba16.resize(4 * kW * kH);
  packRgba16F(layers.overlay.data(), layers.transmittance.data(), 1.0f, kW * kH, r.rgba16.data());
  r.distance = layers.distance;
  r.ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  return r;
}

bool waitFor(const std::function<bool()>& done) {
  const auto end = Clock::now() + std::chrono::seconds(3);
  while (Clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  return done();
}

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

TEST(EndToEnd, UdpInStateFramePublishedReadByCAndPython) {
  StateStore store;
  UdpReceiverOptions udpOptions;
  udpOptions.port = 0;
  auto rx = UdpReceiver::start(udpOptions, store);
  ASSERT_TRUE(rx) << rx.error().message;
  const std::string ch = "test-e2e-" + std::to_string(::getpid());
  ShmChannelOptions o;
  o.channel = ch;
  o.width = kW;
  o.height = kH;
  o.format = FOGBEAM_FORMAT_RGBA16F_OVERLAY;
  o.distance = true;
  auto w = ShmWriter::create(o);
  ASSERT_TRUE(w) << w.error().message;
  fogbeam_reader* reader = nullptr;
  ASSERT_EQ(fogbeam_attach(ch.c_str(), &reader), FOGBEAM_OK) << fogbeam_last_error();

  UdpSender tx((*rx)->port());
  Environment env;
  env.visibility_m = 60.0f;
  env.g = 0.85f;
  tx.send(env);
  tx.send(LampState{light::kLowBeam, 0.0f});
  std::vector<double> latency, udp, renderMs;
  std::vector<std::uint16_t> pixels(4 * kW * kH);
  for (int f = 1; f <= 30; ++f) {
    EgoState ego;
    ego.pose.position_m = {10.0 * f, 2.0, 0.0};
    ego.pose.yaw_deg = static_cast<float>(f);
    ego.speed_m_s = 15.0f;
    const auto sent = Clock::now();
    tx.send(ego);
    const std::uint32_t egoSeq = tx.sequence();
    ASSERT_TRUE(waitFor([&] { return store.snapshot()->ego.stamp.sequence == egoSeq; })) << "frame " << f;
    const auto snap = store.snapshot();
    udp.push_back(std::chrono::duration<double, std::milli>(snap->ego.stamp.received - sent).count());
    const Rendered r = render(*snap);
    renderMs.push_back(r.ms);
    FrameMeta m;
    m.frame = static_cast<std::uint64_t>(f);
    m.sim_time_s = snap->ego.stamp.sim_time_s;
    m.position_m = snap->ego.value.pose.position_m;
    m.yaw_deg = snap->ego.value.pose.yaw_deg;
    m.lights = snap->lamps.value.lights;
    m.ego_sequence = snap->ego.stamp.sequence;
    m.lamp_sequence = snap->lamps.stamp.sequence;
    m.environment_sequence = snap->environment.stamp.sequence;
    m.total_ms = r.ms;
    const std::uint64_t now = monotonicNs();
    // Stamp.received is std::chrono::steady_clock, which is CLOCK_MONOTONIC on Linux.
    const auto received = static_cast<std::uint64_t>(
        std::chrono::duration_cast<std::chrono::nanoseconds>(snap->ego.stamp.received.time_since_epoch()).count());
    m.latency_ms = static_cast<double>(now - received) * 1e-6;
    (*w)->publish(m, std::as_bytes(std::span<const std::uint16_t>(r.rgba16)), r.distance);
    latency.push_back(m.latency_ms);

    fogbeam_frame_info info{};
    ASSERT_EQ(fogbeam_latest(reader, pixels.data(), pixels.size() * 2, &info), FOGBEAM_OK) << fogbeam_last_error();
    EXPECT_EQ(info.frame, static_cast<std::uint64_t>(f));
    EXPECT_EQ(info.ego_sequence, egoSeq);
    EXPECT_EQ(info.lamp_sequence, 2u);
    EXPECT_EQ(info.environment_sequence, 1u);
    EXPECT_EQ(info.lights, light::kLowBeam);
    EXPECT_EQ(info.position_m[0], 10.0 * f);
    EXPECT_EQ(info.yaw_deg, static_cast<float>(f));
    EXPECT_EQ(pixels, r.rgba16);
  }
  // The overlay has light in it: the low beams scatter in the fog (alpha = transmittance ≤ 1).
  double sumR = 0.0;
  for (std::size_t i = 0; i < pixels.size(); i += 4) sumR += static_cast<double>(halfToFloat(pixels[i]));
  EXPECT_GT(sumR, 0.0);
  std::printf("  UDP send -> state applied: median %.3f ms, p95 %.3f ms; render (96x54, CPU) median %.1f ms;\n"
              "  input received -> frame published: median %.2f ms, p95 %.2f ms (30 frames)\n",
              percentile(udp, 0.5), percentile(udp, 0.95), percentile(renderMs, 0.5), percentile(latency, 0.5),
              percentile(latency, 0.95));

  // The Python reader (standard library + numpy) sees the same last frame.
  const std::string cmd = std::string(FOGBEAM_PYTHON) + " " + FOGBEAM_PYTHON_READER + " " + ch + " --frames 1 --timeout 5";
  FILE* p = ::popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  char line[4096] = {};
  const bool got = std::fgets(line, sizeof line, p) != nullptr;
  const int rc = ::pclose(p);
  ASSERT_TRUE(got) << cmd;
  EXPECT_EQ(rc, 0) << cmd;
  const std::string out(line);
  EXPECT_NE(out.find("\"frame\": 30"), std::string::npos) << out;
  EXPECT_NE(out.find("\"lights\": 2"), std::string::npos) << out;
  EXPECT_NE(out.find("\"shape\": [54, 96, 4]"), std::string::npos) << out;
  EXPECT_NE(out.find("\"dtype\": \"float16\""), std::string::npos) << out;
  fogbeam_detach(reader);
}

TEST(EndToEnd, SharedMemoryReadCostAt1080p) {
  for (std::uint32_t format : {FOGBEAM_FORMAT_RGBA8_SRGB, FOGBEAM_FORMAT_RGBA16F_OVERLAY}) {
    const std::string ch = "test-cost-" + std::to_string(format) + "-" + std::to_string(::getpid());
    ShmChannelOptions o;
    o.channel = ch;
    o.width = 1920;
    o.height = 1080;
    o.format = format;
    auto w = ShmWriter::create(o);
    ASSERT_TRUE(w) << w.error().message;
    std::vector<std::byte> px(std::size_t{1920} * 1080 * bytesPerPixel(format), std::byte{7});
    std::vector<double> publishMs, readMs;
    auto r = ShmReader::attach(ch);
    ASSERT_TRUE(r);
    FrameMeta m;
    std::vector<std::byte> out;
    for (int i = 0; i < 20; ++i) {
      auto t0 = Clock::now();
      (*w)->publish(FrameMeta{static_cast<std::uint64_t>(i + 1)}, px);
      publishMs.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      t0 = Clock::now();
      ASSERT_EQ((*r)->latest(m, out), ReadStatus::Ok);
      readMs.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    }
    EXPECT_EQ(out, px);
    std::printf("  1920x1080 %s (%.1f MB): publish median %.2f ms, read (C++ reader, copy) median %.2f ms, p95 %.2f ms\n",
                format == FOGBEAM_FORMAT_RGBA8_SRGB ? "RGBA8 sRGB" : "RGBA16F overlay",
                static_cast<double>(px.size()) / 1e6, percentile(publishMs, 0.5), percentile(readMs, 0.5),
                percentile(readMs, 0.95));
  }
}

}  // namespace
}  // namespace fogbeam::ipc
