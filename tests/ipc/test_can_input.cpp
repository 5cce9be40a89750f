// The CAN input end to end: DBC mapping → lamp bits and speed in the state store, hold and
// fallback of silent signals, and the three sources (candump replay, cannelloni over loopback
// UDP, SocketCAN where the kernel has it).
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/ipc/cannelloni.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <thread>

namespace fogbeam::ipc {
namespace {

const std::string kDbc = std::string(FOGBEAM_TEST_DATA_DIR) + "/can/vehicle.dbc";

CanMapping mapping() {
  CanMapping m;
  m.lamps[static_cast<std::size_t>(CanLamp::LowBeam)] = CanSignalRef{"LIGHT_STALK", "LOW_BEAM"};
  m.lamps[static_cast<std::size_t>(CanLamp::HighBeam)] = CanSignalRef{"LIGHT_STALK", "HIGH_BEAM"};
  m.lamps[static_cast<std::size_t>(CanLamp::FrontFog)] = CanSignalRef{"LIGHT_STALK", "FRONT_FOG"};
  m.speed = CanSignalRef{"SPEED", "SPEED"};
  m.speed_to_m_s = 1.0 / 3.6;
  m.hold_s = 0.2;
  return m;
}

CanDecoder decoder() {
  auto dbc = loadDbc(kDbc);
  EXPECT_TRUE(dbc) << dbc.error().message;
  auto d = CanDecoder::create(*dbc, mapping());
  EXPECT_TRUE(d) << d.error().message;
  return std::move(d).value();
}

// LIGHT_STALK (0x622): LOW_BEAM is Motorola bit 29 = byte 3, bit 5 (0x20); FRONT_FOG bit 27 =
// byte 3, bit 3 (0x08); HIGH_BEAM bit 30 = byte 3, bit 6 (0x40).
CanFrame stalk(std::uint8_t byte3) {
  CanFrame f;
  f.id = 0x622;
  f.len = 8;
  f.data[3] = byte3;
  return f;
}

// SPEED (0xB4): 16 bits Motorola from bit 47 (bytes 5–6, big-endian), 0.01 km/h, offset −2.
CanFrame speed(double kmh) {
  CanFrame f;
  f.id = 0xB4;
  f.len = 8;
  const auto raw = static_cast<std::uint16_t>(std::lround((kmh + 2.0) / 0.01));
  f.data[5] = static_cast<std::uint8_t>(raw >> 8);
  f.data[6] = static_cast<std::uint8_t>(raw);
  return f;
}

TEST(CanInput, DecodesLampsAndSpeedIntoTheStore) {
  CanDecoder d = decoder();
  StateStore store;
  store.setLamps(LampState{light::kDrl, 0.0f}, Stamp{});  // a bit the CAN mapping does not own
  const auto t0 = Clock::now();
  EXPECT_TRUE(d.onFrame(stalk(0x28), t0));
  EXPECT_TRUE(d.onFrame(speed(72.0), t0));
  CanFrame other;
  other.id = 0x123;
  EXPECT_FALSE(d.onFrame(other, t0));
  d.publish(store, t0, "test");
  const auto s = store.snapshot();
  EXPECT_EQ(s->lamps.value.lights, light::kLowBeam | light::kFrontFog | light::kDrl);
  EXPECT_EQ(s->lamps.stamp.source, "test");
  EXPECT_NEAR(s->vehicle_speed_m_s.value, 20.0f, 1e-4f);
  EXPECT_EQ(d.stats().matched, 2u);
  const auto ids = d.ids();
  EXPECT_EQ(ids.size(), 2u);
}

TEST(CanInput, SilentLampSignalsAreHeldThenFallBack) {
  CanMapping m = mapping();
  m.fallback_lights = light::kLowBeam;  // a cab that must never go dark: low beam on when silent
  auto dbc = loadDbc(kDbc);
  ASSERT_TRUE(dbc);
  auto d = CanDecoder::create(*dbc, m);
  ASSERT_TRUE(d);
  StateStore store;  // position stays on: the initial mask's, not mapped (docs/service.md)
  const auto t0 = Clock::now();
  d->onFrame(stalk(0x40), t0);  // high beam only
  d->publish(store, t0, "test");
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kHighBeam | light::kPosition);
  d->publish(store, t0 + std::chrono::milliseconds(150), "test");  // within hold: unchanged
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kHighBeam | light::kPosition);
  d->publish(store, t0 + std::chrono::milliseconds(300), "test");  // silent: fallback
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kLowBeam | light::kPosition);
  EXPECT_EQ(d->stats().fallbacks, 3u);  // low, high, front fog each went silent once
  d->publish(store, t0 + std::chrono::milliseconds(400), "test");
  EXPECT_EQ(d->stats().fallbacks, 3u);  // logged once per transition
  d->onFrame(stalk(0x20), t0 + std::chrono::milliseconds(500));
  d->publish(store, t0 + std::chrono::milliseconds(500), "test");
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kLowBeam | light::kPosition);
}

TEST(CanInput, MappingErrorsNameWhatIsMissing) {
  auto dbc = loadDbc(kDbc);
  ASSERT_TRUE(dbc);
  CanMapping m;
  m.lamps[0] = CanSignalRef{"LIGHT_STALK", "DIPPED"};
  auto d = CanDecoder::create(*dbc, m);
  ASSERT_FALSE(d);
  EXPECT_NE(d.error().message.find("DIPPED"), std::string::npos) << d.error().message;
  EXPECT_NE(d.error().message.find("LOW_BEAM"), std::string::npos) << "should list what exists: " << d.error().message;
  m.lamps[0] = CanSignalRef{"HEADLIGHTS", "LOW_BEAM"};
  d = CanDecoder::create(*dbc, m);
  ASSERT_FALSE(d);
  EXPECT_NE(d.error().message.find("HEADLIGHTS"), std::string::npos) << d.error().message;
  EXPECT_FALSE(CanDecoder::create(*dbc, CanMapping{}));
}

bool waitFor(const std::function<bool()>& done) {
  const auto end = Clock::now() + std::chrono::seconds(3);
  while (Clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return done();
}

TEST(CanInput, CandumpReplayFeedsTheStore) {
  StateStore store;
  auto src = startCandumpReplay(std::string(FOGBEAM_TEST_DATA_DIR) + "/can/drive.log", 0.0, decoder(), store);
  ASSERT_TRUE(src) << src.error().message;
  ASSERT_TRUE(waitFor([&] { return (*src)->finished(); }));
  const auto s = store.snapshot();
  EXPECT_TRUE(s->lamps.stamp.valid);
  EXPECT_NE(s->lamps.stamp.source.find("candump"), std::string::npos);
  EXPECT_GT((*src)->stats().matched, 0u);
  EXPECT_TRUE(s->vehicle_speed_m_s.stamp.valid);
}

TEST(CanInput, CannelloniOverLoopbackFeedsTheStoreAndSurvivesGarbage) {
  StateStore store;
  std::uint16_t port = 0;
  auto src = startCannelloni("127.0.0.1", 0, decoder(), store, &port);
  ASSERT_TRUE(src) << src.error().message;
  ASSERT_NE(port, 0);
  const UniqueFd fd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  ASSERT_TRUE(fd);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(port);
  inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
  const std::uint8_t garbage[] = {9, 9, 9};
  ::sendto(fd.get(), garbage, sizeof garbage, 0, reinterpret_cast<sockaddr*>(&to), sizeof to);
  CannelloniPacket p;
  p.frames = {stalk(0x40), speed(36.0)};
  const auto bytes = encodeCannelloni(p);
  ::sendto(fd.get(), bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to);
  ASSERT_TRUE(waitFor([&] { return store.snapshot()->lamps.value.lights == (light::kHighBeam | light::kPosition); }))
      << "lights " << store.snapshot()->lamps.value.lights;
  EXPECT_NEAR(store.snapshot()->vehicle_speed_m_s.value, 10.0f, 1e-4f);
  EXPECT_EQ((*src)->stats().matched, 2u);
  EXPECT_EQ((*src)->stats().receive_errors, 0u);  // a drained socket (EAGAIN) is not an error
}

TEST(CanInput, SocketCanWhereTheKernelHasIt) {
  StateStore store;
  auto src = startSocketCan("vcan0", decoder(), store);
  if (!src) {
    const std::string& why = src.error().message;
    if (why.rfind("SocketCAN unavailable", 0) == 0 || why.find("No such device") != std::string::npos)
      GTEST_SKIP() << why << " (the same decoder is tested through candump and cannelloni above)";
    FAIL() << why;
  }
  (*src)->stop();
  SUCCEED() << "SocketCAN socket opened and bound on vcan0";
}

}  // namespace
}  // namespace fogbeam::ipc

namespace fogbeam::ipc {
namespace {

TEST(CanConfig, MappingFileNamesTheDbcAndSignals) {
  auto c = loadCanConfig(std::string(FOGBEAM_TEST_DATA_DIR) + "/can/mapping.toml");
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_NE(c->dbc_path.find("tests/data/can/vehicle.dbc"), std::string::npos) << c->dbc_path;
  EXPECT_EQ(c->mapping.hold_s, 0.25);
  EXPECT_EQ(c->mapping.fallback_lights, light::kLowBeam);
  EXPECT_NEAR(c->mapping.speed_to_m_s, 1.0 / 3.6, 1e-12);
  ASSERT_TRUE(c->mapping.lamps[static_cast<std::size_t>(CanLamp::FrontFog)]);
  EXPECT_EQ(c->mapping.lamps[static_cast<std::size_t>(CanLamp::FrontFog)]->signal, "FRONT_FOG");
  auto d = makeDecoder(*c);
  ASSERT_TRUE(d) << d.error().message;
  EXPECT_EQ(d->ids().size(), 2u);
}

TEST(CanConfig, ErrorsNameFileLineAndWhatWasExpected) {
  auto err = [](const std::string& text) {
    auto c = parseCanConfig(text, "map.toml", "/tmp");
    return c ? std::string("(parsed)") : c.error().message;
  };
  // The messages of every configuration format (util/toml_section.hpp, docs/can.md).
  EXPECT_EQ(err("dbc = \"x.dbc\"\nholds = 1\n"), "map.toml:2: unknown top-level key 'holds' (did you mean 'hold_s'?)");
  EXPECT_EQ(err("hold_s = 1\n"), "map.toml:1: dbc: missing (expected the path of a DBC file)");
  EXPECT_EQ(err("dbc = \"\"\n"), "map.toml:1: dbc: expected the path of a DBC file, found \"\"");
  EXPECT_EQ(err("dbc = \"x.dbc\"\nhold_s = -1\n"), "map.toml:2: hold_s: expected a number in (0, 3600], found -1");
  EXPECT_EQ(err("dbc = \"x.dbc\"\n[lamps]\ndipped = { message = \"A\", signal = \"B\" }\n"),
            "map.toml:3: [lamps]: unknown key 'dipped'");
  EXPECT_EQ(err("dbc = \"x.dbc\"\n[lamps]\nlow_bean = { message = \"A\", signal = \"B\" }\n"),
            "map.toml:3: [lamps]: unknown key 'low_bean' (did you mean 'low_beam'?)");
  EXPECT_EQ(err("dbc = \"x.dbc\"\n[lamps]\nlow_beam = { message = \"A\" }\n"),
            "map.toml:3: [lamps.low_beam] signal: missing (expected a signal name of the DBC)");
  EXPECT_EQ(err("dbc = \"x.dbc\"\n[lamps]\nlow_beam = 1\n"),
            "map.toml:3: [lamps] low_beam: expected a table [low_beam], found 1");
  EXPECT_EQ(err("dbc = \"x.dbc\"\nspeed = { message = \"S\", signal = \"V\", to_ms = 1 }\n"),
            "map.toml:2: [speed]: unknown key 'to_ms' (did you mean 'to_m_s'?)");
  EXPECT_EQ(err("dbc = \"x.dbc\"\nspeed = { message = \"S\", signal = \"V\", to_m_s = 0 }\n"),
            "map.toml:2: [speed] to_m_s: expected a number > 0, found 0");
  EXPECT_EQ(err("dbc = \"x.dbc\"\nfallback = [\"low_beam\", \"fog\"]\n"),
            "map.toml:2: fallback[1]: expected a lamp name, \"low_beam\", \"high_beam\", \"front_fog\", \"rear_fog\", "
            "\"indicator_left\" or \"indicator_right\", found \"fog\"");
  EXPECT_TRUE(err("dbc = \n").starts_with("map.toml:1:")) << err("dbc = \n");  // TOML syntax: line and column
  CanConfig bad;
  bad.dbc_path = std::string(FOGBEAM_TEST_DATA_DIR) + "/can/vehicle.dbc";
  bad.mapping.lamps[0] = CanSignalRef{"LIGHT_STALK", "NOPE"};
  auto d = makeDecoder(bad);
  ASSERT_FALSE(d);
  EXPECT_NE(d.error().message.find("vehicle.dbc"), std::string::npos) << d.error().message;
}

}  // namespace
}  // namespace fogbeam::ipc
