// UDP protocol v1: every message round-trips, every documented byte offset holds, every drop
// reason is produced by the input it names, and garbage never crashes the decoder.
#include <fogbeam/ipc/protocol.hpp>

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

namespace fogbeam::ipc {
namespace {

Message msg(Payload p, std::uint32_t seq = 7, double t = 12.5) {
  Message m;
  m.header.sequence = seq;
  m.header.sim_time_s = t;
  m.payload = std::move(p);
  return m;
}

Pose pose(double x, double y, double z, float yaw) {
  Pose p;
  p.position_m = {x, y, z};
  p.yaw_deg = yaw;
  p.pitch_deg = -1.5f;
  p.roll_deg = 0.25f;
  return p;
}

TEST(Protocol, HeaderBytesAreAsDocumented) {
  const auto b = encode(msg(FrameRequest{0x0102030405060708ull}, 0xA1B2C3D4u, 1.0));
  ASSERT_EQ(b.size(), kHeaderSize + kFrameRequestSize);
  // magic "FGBM", version 1, type 5, payload length 8, sequence, time: all little-endian.
  const std::uint8_t expect[] = {'F', 'G', 'B', 'M', 1, 0, 5, 0, 8, 0, 0, 0, 0xD4, 0xC3, 0xB2, 0xA1};
  for (std::size_t i = 0; i < sizeof expect; ++i) EXPECT_EQ(b[i], expect[i]) << "byte " << i;
  double t = 0.0;
  std::memcpy(&t, b.data() + 16, 8);  // x86 is little-endian, as the wire
  EXPECT_EQ(t, 1.0);
  EXPECT_EQ(b[24], 0x08);  // frame number, least significant byte first
  EXPECT_EQ(b[31], 0x01);
}

TEST(Protocol, EveryMessageRoundTrips) {
  Environment env;
  env.visibility_m = 75.0f;
  env.albedo = 0.9f;
  env.phase = PhaseCode::FogMie;
  env.droplet_diameter_um = 12.0f;
  env.ambient_cd_m2 = 0.5f;
  TrafficList traffic;
  traffic.complete = true;
  for (std::uint32_t i = 0; i < 3; ++i) {
    TrafficObject o;
    o.id = 100 + i;
    o.vehicle_class = static_cast<std::uint16_t>(i);
    o.removed = i == 2;
    o.pose = pose(40.0 + i, 3.5, 0.0, 180.0f);
    o.lights = light::kLowBeam | light::kPosition;
    traffic.objects.push_back(o);
  }
  const std::vector<Payload> payloads{EgoState{pose(1.0, -2.0, 0.3, 45.0f), 13.9f},
                                      LampState{light::kLowBeam | light::kFrontFog, -12.5f}, traffic, env,
                                      FrameRequest{123456789}};
  for (const Payload& p : payloads) {
    const auto bytes = encode(msg(p));
    const DecodeResult d = decode(bytes);
    ASSERT_TRUE(d.ok) << toString(d.reason) << " " << d.field;
    EXPECT_EQ(d.message.header.sequence, 7u);
    EXPECT_EQ(d.message.header.sim_time_s, 12.5);
    EXPECT_EQ(d.message.header.payload_length, bytes.size() - kHeaderSize);
    EXPECT_EQ(encode(d.message), bytes) << "re-encoding differs for payload index " << p.index();
  }
  const auto d = decode(encode(msg(traffic)));
  const auto& t = std::get<TrafficList>(d.message.payload);
  ASSERT_EQ(t.objects.size(), 3u);
  EXPECT_TRUE(t.complete);
  EXPECT_TRUE(t.objects[2].removed);
  EXPECT_EQ(t.objects[1].pose.position_m[0], 41.0);
  EXPECT_EQ(t.objects[1].pose.yaw_deg, 180.0f);
}

TEST(Protocol, UnknownLightBitsAreIgnoredKnownOnesKept) {
  const auto d = decode(encode(msg(LampState{0xFFFFFFFFu, 0.0f})));
  ASSERT_TRUE(d.ok);
  EXPECT_EQ(std::get<LampState>(d.message.payload).lights, light::kKnown);
}

// Overwrites `n` bytes at `offset` of an encoded message.
template <class T>
std::vector<std::uint8_t> patched(std::vector<std::uint8_t> b, std::size_t offset, T value) {
  std::memcpy(b.data() + offset, &value, sizeof value);
  return b;
}

void expectDrop(const std::vector<std::uint8_t>& b, DropReason r, std::string_view field) {
  const DecodeResult d = decode(b);
  EXPECT_FALSE(d.ok);
  EXPECT_EQ(d.reason, r) << "got " << toString(d.reason) << " for field " << d.field;
  EXPECT_EQ(d.field, field);
}

TEST(Protocol, EachDropReasonNamesItsField) {
  const auto ego = encode(msg(EgoState{pose(1, 2, 3, 10.0f), 5.0f}));
  expectDrop(std::vector<std::uint8_t>(ego.begin(), ego.begin() + 10), DropReason::TooShort, "header");
  expectDrop(patched(ego, 0, std::uint32_t{0x12345678}), DropReason::BadMagic, "magic");
  expectDrop(patched(ego, 4, std::uint16_t{2}), DropReason::BadVersion, "version");
  expectDrop(patched(ego, 6, std::uint16_t{99}), DropReason::UnknownType, "type");
  expectDrop(patched(ego, 8, std::uint32_t{41}), DropReason::LengthMismatch, "payload_length");
  auto longer = ego;
  longer.push_back(0);
  longer[8] = 41;  // consistent header, but an ego payload is 40 bytes
  expectDrop(longer, DropReason::LengthMismatch, "payload_length");
  expectDrop(patched(ego, 16, std::numeric_limits<double>::quiet_NaN()), DropReason::NonFinite, "sim_time_s");
  expectDrop(patched(ego, 24 + 8, std::numeric_limits<double>::infinity()), DropReason::NonFinite, "position_m.y");
  expectDrop(patched(ego, 24 + 0, 2e7), DropReason::OutOfRange, "position_m.x");
  expectDrop(patched(ego, 24 + 28, 400.0f), DropReason::OutOfRange, "pitch_deg");
  expectDrop(patched(ego, 24 + 36, 250.0f), DropReason::OutOfRange, "speed_m_s");

  const auto lamps = encode(msg(LampState{light::kLowBeam, 0.0f}));
  expectDrop(patched(lamps, 24 + 4, 60.0f), DropReason::OutOfRange, "bending_deg");
  expectDrop(patched(lamps, 24 + 8, std::uint32_t{1}), DropReason::OutOfRange, "reserved");

  TrafficList t;
  t.objects.resize(2);
  const auto traffic = encode(msg(t));
  expectDrop(patched(traffic, 24, std::uint16_t{3}), DropReason::BadCount, "count");
  expectDrop(patched(traffic, 24, std::uint16_t{60000}), DropReason::BadCount, "count");
  expectDrop(patched(traffic, 26, std::uint16_t{2}), DropReason::OutOfRange, "flags");
  expectDrop(patched(traffic, 28 + 48 + 6, std::uint16_t{4}), DropReason::OutOfRange, "object.flags");
  expectDrop(patched(traffic, 28 + 48 + 8 + 16, std::numeric_limits<double>::quiet_NaN()), DropReason::NonFinite,
             "position_m.z");

  Environment e;
  const auto env = encode(msg(e));  // extinction 0 and visibility 0: no fog given
  expectDrop(env, DropReason::OutOfRange, "extinction_per_m");
  e.visibility_m = 100.0f;
  const auto okEnv = encode(msg(e));
  EXPECT_TRUE(decode(okEnv).ok);
  expectDrop(patched(okEnv, 24 + 0, 0.5f), DropReason::OutOfRange, "visibility_m");
  expectDrop(patched(okEnv, 24 + 8, 1.5f), DropReason::OutOfRange, "albedo");
  expectDrop(patched(okEnv, 24 + 12, std::uint8_t{7}), DropReason::OutOfRange, "phase");
  expectDrop(patched(okEnv, 24 + 16, 1.0f), DropReason::OutOfRange, "g");
  expectDrop(patched(okEnv, 24 + 24, std::numeric_limits<float>::infinity()), DropReason::NonFinite, "ambient_cd_m2");
}

// A bounded deterministic fuzz: random bytes, random truncations and random byte flips of valid
// messages. The decoder must return (ok or a reason) without crashing or reading out of bounds
// (the sanitizer build checks the latter); every accepted message must re-encode to itself.
TEST(Protocol, GarbageNeverCrashesAndAcceptedMessagesAreCanonical) {
  std::mt19937 rng(2024);
  std::uniform_int_distribution<int> byte(0, 255);
  TrafficList t;
  t.objects.resize(4);
  const std::vector<std::vector<std::uint8_t>> seeds{
      encode(msg(EgoState{pose(1, 2, 3, 10.0f), 5.0f})), encode(msg(LampState{light::kHighBeam, 3.0f})),
      encode(msg(t)), encode(msg(FrameRequest{42}))};
  std::size_t accepted = 0, tried = 0;
  for (int n = 0; n < 50000; ++n, ++tried) {
    std::vector<std::uint8_t> b;
    if (n % 3 == 0) {
      b.resize(static_cast<std::size_t>(byte(rng)) * 2);
      for (auto& x : b) x = static_cast<std::uint8_t>(byte(rng));
    } else {
      b = seeds[static_cast<std::size_t>(n) % seeds.size()];
      const int flips = 1 + byte(rng) % 3;
      for (int f = 0; f < flips; ++f) b[static_cast<std::size_t>(byte(rng)) % b.size()] ^= static_cast<std::uint8_t>(1 << (byte(rng) % 8));
      if (n % 5 == 0) b.resize(static_cast<std::size_t>(byte(rng)) % (b.size() + 1));
    }
    const DecodeResult d = decode(b);
    if (d.ok) {
      ++accepted;
      auto re = encode(d.message);
      // Unknown light bits are masked on decode; everything else is canonical.
      if (re != b) {
        const auto again = decode(re);
        ASSERT_TRUE(again.ok);
        EXPECT_EQ(encode(again.message), re);
      }
    }
  }
  std::printf("  %zu inputs, %zu accepted\n", tried, accepted);
  EXPECT_GT(accepted, 0u);
}

TEST(Protocol, TruncatedAndOversizedDatagramsAreDropped) {
  const auto ego = encode(msg(EgoState{pose(1, 2, 3, 10.0f), 5.0f}));
  for (std::size_t n = 0; n < ego.size(); ++n) {
    const DecodeResult d = decode(std::span<const std::uint8_t>(ego.data(), n));
    EXPECT_FALSE(d.ok) << n;
    EXPECT_EQ(d.reason, n < kHeaderSize ? DropReason::TooShort : DropReason::LengthMismatch) << n;
  }
  std::vector<std::uint8_t> huge(kMaxDatagram + 100, 0);
  std::copy(ego.begin(), ego.end(), huge.begin());
  EXPECT_EQ(decode(huge).reason, DropReason::LengthMismatch);
}

TEST(Protocol, SizesMatchTheDocument) {
  EXPECT_EQ(encode(msg(EgoState{})).size(), kHeaderSize + 40);
  EXPECT_EQ(encode(msg(LampState{})).size(), kHeaderSize + 12);
  EXPECT_EQ(encode(msg(Environment{})).size(), kHeaderSize + 28);
  EXPECT_EQ(encode(msg(FrameRequest{})).size(), kHeaderSize + 8);
  TrafficList t;
  t.objects.resize(kMaxTrafficPerDatagram);
  const auto b = encode(msg(t));
  EXPECT_LE(b.size(), kMaxDatagram);
  EXPECT_TRUE(decode(b).ok);
}

}  // namespace
}  // namespace fogbeam::ipc
