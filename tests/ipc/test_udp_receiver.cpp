// The UDP receiver end to end on loopback: datagrams in, state out, drops counted by reason,
// the allow-list, sequence handling, multicast (skipped where the kernel cannot loop it back).
// Every test binds port 0 (any free port) and stops by itself.
#include <fogbeam/ipc/udp_receiver.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <functional>
#include <thread>

namespace fogbeam::ipc {
namespace {

// A sending socket bound to `from` (any 127/8 address is local on Linux).
class Sender {
 public:
  explicit Sender(const char* from = "127.0.0.1") : fd_(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0)) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    inet_pton(AF_INET, from, &a.sin_addr);
    ok_ = fd_ && ::bind(fd_.get(), reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  }
  bool ok() const { return ok_; }
  void send(const std::vector<std::uint8_t>& b, std::uint16_t port, const char* to = "127.0.0.1") {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    inet_pton(AF_INET, to, &a.sin_addr);
    ::sendto(fd_.get(), b.data(), b.size(), 0, reinterpret_cast<sockaddr*>(&a), sizeof a);
  }
  int fd() const { return fd_.get(); }

 private:
  UniqueFd fd_;
  bool ok_ = false;
};

std::vector<std::uint8_t> datagram(Payload p, std::uint32_t seq) {
  Message m;
  m.header.sequence = seq;
  m.header.sim_time_s = 0.01 * seq;
  m.payload = std::move(p);
  return encode(m);
}

// Waits (at most 2 s) until `done` holds.
bool waitFor(const std::function<bool()>& done) {
  const auto end = Clock::now() + std::chrono::seconds(2);
  while (Clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return done();
}

UdpReceiverOptions loopback() {
  UdpReceiverOptions o;
  o.port = 0;
  return o;
}

TEST(UdpReceiver, AppliesEveryMessageTypeWithItsStamp) {
  StateStore store;
  auto rx = UdpReceiver::start(loopback(), store);
  ASSERT_TRUE(rx) << rx.error().message;
  Sender tx;
  ASSERT_TRUE(tx.ok());
  EgoState ego;
  ego.pose.position_m = {12.0, -3.0, 0.0};
  ego.speed_m_s = 20.0f;
  tx.send(datagram(ego, 1), (*rx)->port());
  tx.send(datagram(LampState{light::kHighBeam | light::kFrontFog, 5.0f}, 2), (*rx)->port());
  TrafficObject o;
  o.id = 9;
  o.pose.position_m = {60.0, 3.5, 0.0};
  o.lights = light::kLowBeam;
  tx.send(datagram(TrafficList{true, {o}}, 3), (*rx)->port());
  Environment env;
  env.visibility_m = 80.0f;
  tx.send(datagram(env, 4), (*rx)->port());
  tx.send(datagram(FrameRequest{77}, 5), (*rx)->port());
  ASSERT_TRUE(waitFor([&] { return (*rx)->stats().applied == 5; })) << "applied " << (*rx)->stats().applied;
  const auto s = store.snapshot();
  EXPECT_EQ(s->ego.value.pose.position_m[0], 12.0);
  EXPECT_EQ(s->ego.stamp.sequence, 1u);
  EXPECT_NE(s->ego.stamp.source.find("udp 127.0.0.1:"), std::string::npos);
  EXPECT_EQ(s->lamps.value.lights, light::kHighBeam | light::kFrontFog);
  ASSERT_EQ(s->traffic.size(), 1u);
  EXPECT_EQ(s->traffic[0].object.lights, light::kLowBeam);
  EXPECT_EQ(s->environment.value.visibility_m, 80.0f);
  EXPECT_EQ(s->frame_request.value.frame, 77u);
  EXPECT_EQ((*rx)->stats().droppedTotal(), 0u);
}

TEST(UdpReceiver, CountsDropsByReasonAndKeepsRunning) {
  StateStore store;
  auto rx = UdpReceiver::start(loopback(), store);
  ASSERT_TRUE(rx);
  Sender tx;
  const std::uint16_t port = (*rx)->port();
  tx.send({1, 2, 3}, port);                                   // too short
  auto bad = datagram(EgoState{}, 1);
  bad[0] ^= 0xFF;
  tx.send(bad, port);                                         // bad magic
  tx.send(datagram(LampState{light::kLowBeam, 0.0f}, 10), port);  // applied
  tx.send(datagram(LampState{light::kHighBeam, 0.0f}, 10), port);  // duplicate sequence
  tx.send(datagram(LampState{light::kHighBeam, 0.0f}, 9), port);   // older: out of order
  tx.send(datagram(LampState{light::kPosition, 0.0f}, 11), port);  // applied
  tx.send(datagram(LampState{light::kDrl, 0.0f}, 5000), port);     // applied
  tx.send(datagram(LampState{light::kFrontFog, 0.0f}, 3), port);   // 4997 back: sender restart, applied
  ASSERT_TRUE(waitFor([&] { return (*rx)->stats().datagrams == 8; }));
  const UdpStats st = (*rx)->stats();
  EXPECT_EQ(st.dropped[static_cast<std::size_t>(DropReason::TooShort)], 1u);
  EXPECT_EQ(st.dropped[static_cast<std::size_t>(DropReason::BadMagic)], 1u);
  EXPECT_EQ(st.dropped[static_cast<std::size_t>(DropReason::Duplicate)], 1u);
  EXPECT_EQ(st.dropped[static_cast<std::size_t>(DropReason::OutOfOrder)], 1u);
  EXPECT_EQ(st.restarts, 1u);
  EXPECT_EQ(st.applied, 4u);
  EXPECT_EQ(st.receive_errors, 0u);  // a drained socket (EAGAIN) is not an error
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kFrontFog);
}

// A sender whose sequence keeps jumping back by more than restart_window (random sequence
// numbers, or one alternating between two counters: found by a sweep of the service's input,
// 2026-11-29, when each such datagram logged a line) restarts again and again: each is applied
// and counted, the log line rate-limited to one a second. Alternating 0 and 2^31 + 5000, the
// jump to 2^31 + 5000 is 2^31 − 5000 behind in serial arithmetic (a restart), the jump back to 0
// as far ahead (in order).
TEST(UdpReceiver, EveryRestartIsCountedAndApplied) {
  StateStore store;
  auto rx = UdpReceiver::start(loopback(), store);
  ASSERT_TRUE(rx);
  Sender tx;
  const std::uint16_t port = (*rx)->port();
  constexpr std::uint32_t kFar = 0x80000000u + 5000u;  // 2^31 + 5000: "behind" in serial arithmetic
  for (std::uint32_t k = 0; k < 200; ++k)
    tx.send(datagram(LampState{k % 2 ? light::kLowBeam : light::kHighBeam, 0.0f}, k % 2 ? kFar : 0u), port);
  ASSERT_TRUE(waitFor([&] { return (*rx)->stats().datagrams == 200; }));
  const UdpStats st = (*rx)->stats();
  EXPECT_EQ(st.applied, 200u);
  EXPECT_EQ(st.restarts, 100u);
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kLowBeam);
}

TEST(UdpReceiver, AllowListRejectsOtherSenders) {
  StateStore store;
  UdpReceiverOptions o = loopback();
  o.allow = {"127.0.0.1"};
  auto rx = UdpReceiver::start(o, store);
  ASSERT_TRUE(rx);
  Sender stranger("127.0.0.2");
  if (!stranger.ok()) GTEST_SKIP() << "cannot bind a sender to 127.0.0.2 here";
  Sender friendly("127.0.0.1");
  stranger.send(datagram(FrameRequest{1}, 1), (*rx)->port());
  friendly.send(datagram(FrameRequest{2}, 1), (*rx)->port());
  ASSERT_TRUE(waitFor([&] { return (*rx)->stats().datagrams == 2; }));
  EXPECT_EQ((*rx)->stats().dropped[static_cast<std::size_t>(DropReason::SenderNotAllowed)], 1u);
  EXPECT_EQ(store.snapshot()->frame_request.value.frame, 2u);
}

TEST(UdpReceiver, StartErrorsNameTheAddress) {
  StateStore store;
  UdpReceiverOptions o = loopback();
  o.allow = {"not-an-address"};
  auto rx = UdpReceiver::start(o, store);
  ASSERT_FALSE(rx);
  EXPECT_NE(rx.error().message.find("'not-an-address' is not an IPv4 address"), std::string::npos);
  auto first = UdpReceiver::start(loopback(), store);
  ASSERT_TRUE(first);
  UdpReceiverOptions same = loopback();
  same.port = (*first)->port();
  // A unicast port is exclusive (no SO_REUSEADDR): a second instance fails and says where.
  auto second = UdpReceiver::start(same, store);
  ASSERT_FALSE(second);
  EXPECT_NE(second.error().message.find("bind 127.0.0.1:" + std::to_string(same.port)), std::string::npos)
      << second.error().message;
}

TEST(UdpReceiver, MulticastFeedsEveryMember) {
  StateStore a, b;
  UdpReceiverOptions o = loopback();
  o.multicast_group = "239.255.47.80";
  o.port = 0;
  auto rxA = UdpReceiver::start(o, a);
  if (!rxA) GTEST_SKIP() << "multicast join failed here: " << rxA.error().message;
  UdpReceiverOptions o2 = o;
  o2.port = (*rxA)->port();
  auto rxB = UdpReceiver::start(o2, b);
  if (!rxB) GTEST_SKIP() << "second member could not bind: " << rxB.error().message;
  Sender tx;
  in_addr iface{};
  inet_pton(AF_INET, "127.0.0.1", &iface);
  ::setsockopt(tx.fd(), IPPROTO_IP, IP_MULTICAST_IF, &iface, sizeof iface);
  const unsigned char loop = 1;
  ::setsockopt(tx.fd(), IPPROTO_IP, IP_MULTICAST_LOOP, &loop, sizeof loop);
  tx.send(datagram(FrameRequest{5}, 1), o2.port, "239.255.47.80");
  if (!waitFor([&] { return (*rxA)->stats().applied == 1 && (*rxB)->stats().applied == 1; }))
    GTEST_SKIP() << "no multicast loopback delivery on this machine (no multicast route on lo)";
  EXPECT_EQ(a.snapshot()->frame_request.value.frame, 5u);
  EXPECT_EQ(b.snapshot()->frame_request.value.frame, 5u);
}

TEST(UdpReceiver, SequenceDistanceWraps) {
  EXPECT_EQ(sequenceDistance(5, 3), 2);
  EXPECT_EQ(sequenceDistance(3, 5), -2);
  EXPECT_EQ(sequenceDistance(1, 0xFFFFFFFFu), 2);  // wrapped forward
  EXPECT_EQ(sequenceDistance(0xFFFFFFFEu, 1), -3);
}

}  // namespace
}  // namespace fogbeam::ipc
