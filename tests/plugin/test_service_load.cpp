// The Service with every one of its threads busy at once (what scripts/tsan.sh runs under
// ThreadSanitizer, and the plain and ASan suites run too): free-running at the test cab's 60 Hz,
// a host sending the soak scenario's states over UDP at 60 Hz (traffic coming and going, lamps
// switching, fog changing, so fog and bending tables build in the background), the light stalk
// over CAN as cannelloni datagrams at 50 Hz, a status request every 100 ms, and a reader taking
// every frame from shared memory. Every datagram must be applied, the CAN mapping's lamp bits
// must reach the frames (it owns the bits it maps: docs/can.md), status must answer throughout,
// and stop() must end it all.
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/can_encode.hpp>
#include <fogbeam/ipc/cannelloni.hpp>
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/status_server.hpp>
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/plugin/service.hpp>
#include <fogbeam/plugin/service_config.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <thread>
#include <variant>
#include <vector>

namespace fogbeam::plugin {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

const std::string kData = FOGBEAM_TEST_DATA_DIR;

/// A UDP socket that sends datagrams to 127.0.0.1:port.
class Sender {
 public:
  explicit Sender(std::uint16_t port) : fd_(::socket(AF_INET, SOCK_DGRAM, 0)) {
    to_.sin_family = AF_INET;
    to_.sin_port = htons(port);
    ::inet_pton(AF_INET, "127.0.0.1", &to_.sin_addr);
  }
  ~Sender() { ::close(fd_); }
  Sender(const Sender&) = delete;
  Sender& operator=(const Sender&) = delete;
  bool send(const std::vector<std::uint8_t>& bytes) {
    return ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to_), sizeof to_) ==
           static_cast<ssize_t>(bytes.size());
  }

 private:
  int fd_;
  sockaddr_in to_{};
};

/// A UDP port that was free a moment ago on 127.0.0.1 (the cannelloni port must be given).
std::uint16_t freePort() {
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  ::inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
  socklen_t len = sizeof a;
  const bool ok = ::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0 &&
                  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0;
  ::close(fd);
  return ok ? ntohs(a.sin_port) : 0;
}

TEST(ServiceUnderLoad, EveryThreadBusyAtOnceAndStopEndsThem) {
  constexpr double kSeconds = 5.0;
  const std::uint16_t canPort = freePort();
  ASSERT_NE(canPort, 0);
  const std::string mapping = kData + "/can/mapping.toml";
  auto cfg = loadServiceConfig(kData + "/service/timing.toml",
                               {"input.can.source=\"cannelloni\"", "input.can.cannelloni_port=" + std::to_string(canPort),
                                "input.can.mapping=\"" + mapping + "\"", "status.interval_s=0.5"});
  ASSERT_TRUE(cfg) << cfg.error().message;
  for (ChannelConfig& ch : cfg->channels) ch.name = "test-load-" + std::to_string(::getpid()) + "-" + ch.name;
  const std::string channel = cfg->channels.at(0).name;
  ServiceOptions so;
  so.any_status_port = true;
  auto service = Service::create(std::move(cfg).value(), so);
  ASSERT_TRUE(service) << service.error().message;
  Service& s = **service;

  auto scenario = loadScenario(kData + "/scenarios/soak.toml");
  ASSERT_TRUE(scenario) << scenario.error().message;
  auto canConfig = ipc::loadCanConfig(mapping);
  ASSERT_TRUE(canConfig) << canConfig.error().message;
  auto encoder = ipc::makeEncoder(*canConfig);
  ASSERT_TRUE(encoder) << encoder.error().message;

  auto reader = ipc::ShmReader::attach(channel);  // the segment exists from create() on
  ASSERT_TRUE(reader) << reader.error().message;

  std::thread loop([&] { EXPECT_TRUE(s.run()); });
  // The first frame builds the fog's tables (about a second here, over half a minute under
  // ThreadSanitizer); the load starts once it is out, as a host's would after start-up.
  ipc::FrameMeta meta;
  std::vector<std::byte> pixels;
  const auto firstDeadline = Clock::now() + 300s;
  while ((*reader)->latest(meta, pixels) != ipc::ReadStatus::Ok && Clock::now() < firstDeadline)
    std::this_thread::sleep_for(10ms);
  if (meta.frame == 0) {
    s.stop();
    loop.join();
    FAIL() << "no first frame within 300 s";
  }

  // The host: the scenario's states at 60 Hz over UDP but for their lamp messages, and the light
  // stalk over CAN at 50 Hz with the high beam on: the lamp bits come from CAN alone, so the frames
  // must show its high beam. (A UDP lamp message could not take them over either: the CAN
  // mapping owns the bits it maps, docs/can.md; tests/ipc/test_input_promises.cpp.)
  std::atomic<bool> sending{true};
  std::atomic<std::uint64_t> datagrams{0}, canPackets{0};
  std::thread host([&] {
    Sender udp(s.udpPort()), can(canPort);
    std::uint32_t sequence = 1;
    std::uint8_t canSequence = 0;
    const auto start = Clock::now();
    auto nextCan = start;
    for (int k = 0; sending.load(); ++k) {
      const double t = std::chrono::duration<double>(Clock::now() - start).count();
      for (const auto& d : encodeState(evaluate(*scenario, t), sequence)) {
        const ipc::DecodeResult m = ipc::decode(d);
        if (m.ok && std::holds_alternative<ipc::LampState>(m.message.payload)) continue;
        if (udp.send(d)) ++datagrams;
      }
      if (Clock::now() >= nextCan) {
        auto frames = encoder->encode(ipc::light::kLowBeam | ipc::light::kHighBeam, 20.0);
        if (frames) {
          ipc::CannelloniPacket p;
          p.sequence = canSequence++;
          p.frames = std::move(frames).value();
          if (can.send(ipc::encodeCannelloni(p))) ++canPackets;
        }
        nextCan += 20ms;
      }
      std::this_thread::sleep_until(start + (k + 1) * std::chrono::microseconds(16'667));
    }
  });

  // The reader and the status requests, on this thread.
  std::uint64_t frames = 0, lastFrame = meta.frame, withCanBit = 0, statuses = 0;
  const auto end = Clock::now() + std::chrono::duration<double>(kSeconds);
  auto nextStatus = Clock::now();
  while (Clock::now() < end) {
    if ((*reader)->latest(meta, pixels) == ipc::ReadStatus::Ok && meta.frame != lastFrame) {
      lastFrame = meta.frame;
      ++frames;
      if (meta.lights & ipc::light::kHighBeam) ++withCanBit;
    }
    if (Clock::now() >= nextStatus) {
      if (ipc::requestStatus("127.0.0.1", s.statusPort(), 5.0)) ++statuses;
      nextStatus += 100ms;
    }
    std::this_thread::sleep_for(2ms);
  }
  sending = false;
  host.join();
  // Every datagram that left the host is in the receiver's count before stop() returns.
  const auto sent = datagrams.load();
  const auto settle = Clock::now() + 2s;
  while (s.udpStats().datagrams < sent && Clock::now() < settle) std::this_thread::sleep_for(5ms);
  const auto t0 = Clock::now();
  s.stop();
  loop.join();
  const double stopS = std::chrono::duration<double>(Clock::now() - t0).count();
  const ipc::UdpStats udp = s.udpStats();
  std::printf("  %.0f s: %llu frames read (%llu with the CAN's high beam), %llu status replies, %llu datagrams sent, "
              "%llu applied, %llu dropped, %llu cannelloni packets; stop() took %.3f s\n",
              kSeconds, static_cast<unsigned long long>(frames), static_cast<unsigned long long>(withCanBit),
              static_cast<unsigned long long>(statuses), static_cast<unsigned long long>(sent),
              static_cast<unsigned long long>(udp.applied), static_cast<unsigned long long>(udp.droppedTotal()),
              static_cast<unsigned long long>(canPackets.load()), stopS);
  EXPECT_GT(frames, 0u);
  EXPECT_GT(withCanBit, 0u) << "the CAN mapping's high beam never reached a frame";
  EXPECT_GE(statuses, static_cast<std::uint64_t>(kSeconds * 10 / 2)) << "status answered too rarely";
  EXPECT_EQ(udp.datagrams, sent);
  EXPECT_EQ(udp.droppedTotal(), 0u);
  EXPECT_GT(canPackets.load(), 0u);
}

}  // namespace
}  // namespace fogbeam::plugin
