// What docs/can.md, docs/protocol.md and docs/service.md promise about the inputs meeting in the
// state store (issue 16): the CAN mapping owns the bits it maps whatever a UDP lamp state says,
// repeated stalk frames refresh the lamps' stamp (input-to-publish latency counts from the
// newest input), CAN bits merge into the documented initial mask (low beam + position), a
// signal is not silent before its source has run for hold_s, a finished candump log is not a
// silent bus, a mapping signal the DBC lacks is reported at its line of the mapping file, and
// every UDP datagram is counted once (applied or dropped) when the traffic bound refuses objects.
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/ipc/udp_receiver.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <thread>

namespace fogbeam::ipc {
namespace {

using std::chrono::milliseconds;

const std::string kDbc = std::string(FOGBEAM_TEST_DATA_DIR) + "/can/vehicle.dbc";

// Low beam, high beam and front fog from LIGHT_STALK (tests/data/can/vehicle.dbc), hold 0.2 s,
// `fallback` for silent signals.
CanDecoder stalkDecoder(std::uint32_t fallback = 0) {
  CanMapping m;
  m.lamps[static_cast<std::size_t>(CanLamp::LowBeam)] = CanSignalRef{"LIGHT_STALK", "LOW_BEAM"};
  m.lamps[static_cast<std::size_t>(CanLamp::HighBeam)] = CanSignalRef{"LIGHT_STALK", "HIGH_BEAM"};
  m.lamps[static_cast<std::size_t>(CanLamp::FrontFog)] = CanSignalRef{"LIGHT_STALK", "FRONT_FOG"};
  m.hold_s = 0.2;
  m.fallback_lights = fallback;
  auto dbc = loadDbc(kDbc);
  EXPECT_TRUE(dbc) << dbc.error().message;
  auto d = CanDecoder::create(*dbc, m);
  EXPECT_TRUE(d) << d.error().message;
  return std::move(d).value();
}

// LIGHT_STALK (0x622), byte 3: LOW_BEAM 0x20, HIGH_BEAM 0x40, FRONT_FOG 0x08.
CanFrame stalk(std::uint8_t byte3) {
  CanFrame f;
  f.id = 0x622;
  f.len = 8;
  f.data[3] = byte3;
  return f;
}
constexpr std::uint8_t kStalkHigh = 0x40, kStalkLow = 0x20;

Stamp hostStamp(Clock::time_point t) {
  Stamp s;
  s.valid = true;
  s.received = t;
  s.sequence = 1;
  s.source = "udp test";
  return s;
}

bool waitFor(const std::function<bool()>& done) {
  const auto end = Clock::now() + std::chrono::seconds(3);
  while (Clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(milliseconds(2));
  }
  return done();
}

// ---- docs/can.md: "The CAN mapping owns the bits it maps" ---------------------------------------

// A UDP lamp state sets the bits the mapping does not map (DRL, position) and the bending angle,
// never the mapped ones, neither before nor after stalk frames that repeat the same value.
TEST(CanOwnership, UdpLampStatesNeverOverrideTheMappedBits) {
  CanDecoder d = stalkDecoder();
  StateStore store;
  const auto t0 = Clock::now();
  d.onFrame(stalk(kStalkHigh), t0);
  d.publish(store, t0, "can test");
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kHighBeam | light::kPosition);

  // The host says low beam on, high beam off, front fog on, DRL on: only DRL (and position,
  // which it leaves out: off) are the host's.
  store.setLamps(LampState{light::kLowBeam | light::kFrontFog | light::kDrl, 3.0f}, hostStamp(t0 + milliseconds(20)));
  auto s = store.snapshot();
  EXPECT_EQ(s->lamps.value.lights, light::kHighBeam | light::kDrl);
  EXPECT_EQ(s->lamps.value.bending_deg, 3.0f);

  // The same stalk value every 0.1 s (no change) keeps the bits the mapping's, and so does the
  // next host message.
  for (int k = 1; k <= 3; ++k) {
    const auto t = t0 + milliseconds(100 * k);
    d.onFrame(stalk(kStalkHigh), t);
    d.publish(store, t, "can test");
    EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kHighBeam | light::kDrl) << "repeat " << k;
    store.setLamps(LampState{light::kLowBeam | light::kDrl, 0.0f}, hostStamp(t + milliseconds(50)));
    EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kHighBeam | light::kDrl) << "host after repeat " << k;
  }
  // A stalk change is applied at once, the host's DRL kept.
  d.onFrame(stalk(kStalkLow), t0 + milliseconds(400));
  d.publish(store, t0 + milliseconds(400), "can test");
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kLowBeam | light::kDrl);
}

// The same through the real UDP receiver: a lamp datagram from a host cannot switch a mapped lamp.
TEST(CanOwnership, ThroughTheUdpReceiver) {
  StateStore store;
  CanDecoder d = stalkDecoder();
  const auto t0 = Clock::now();
  d.onFrame(stalk(kStalkHigh), t0);
  d.publish(store, t0, "can test");

  UdpReceiverOptions o;
  o.port = 0;
  auto rx = UdpReceiver::start(o, store);
  ASSERT_TRUE(rx) << rx.error().message;
  const UniqueFd fd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  ASSERT_TRUE(fd);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons((*rx)->port());
  inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
  Message m;
  m.header.sequence = 1;
  m.payload = LampState{light::kLowBeam | light::kPosition | light::kDrl, 0.0f};
  const auto bytes = encode(m);
  ASSERT_EQ(::sendto(fd.get(), bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to),
            static_cast<ssize_t>(bytes.size()));
  ASSERT_TRUE(waitFor([&] { return (*rx)->stats().applied == 1; }));
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kHighBeam | light::kPosition | light::kDrl);
  EXPECT_NE(store.snapshot()->lamps.stamp.source.find("udp"), std::string::npos);
}

// ---- docs/service.md: the mask starts as low beam + position --------------------------------------

TEST(CanOwnership, MappedBitsMergeIntoTheInitialMask) {
  StateStore store;
  EXPECT_FALSE(store.snapshot()->lamps.stamp.valid);
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kInitialEgo);
  EXPECT_EQ(light::kInitialEgo, light::kLowBeam | light::kPosition);
  CanDecoder d = stalkDecoder();
  const auto t0 = Clock::now();
  d.onFrame(stalk(kStalkHigh | 0x08), t0);  // high beam and front fog; low beam off
  d.publish(store, t0, "can test");
  const auto s = store.snapshot();
  EXPECT_TRUE(s->lamps.stamp.valid);
  EXPECT_EQ(s->lamps.value.lights, light::kPosition | light::kHighBeam | light::kFrontFog);
}

// ---- docs/shm.md: latency from the receipt of the newest input used -----------------------------

TEST(CanLatencyStamp, RepeatedFramesRefreshTheLampStampWithoutAChange) {
  CanDecoder d = stalkDecoder();
  StateStore store;
  const auto t0 = Clock::now();
  d.onFrame(stalk(kStalkHigh), t0);
  d.publish(store, t0 + milliseconds(10), "can test");  // the tick after the frame
  auto s = store.snapshot();
  EXPECT_EQ(s->lamps.stamp.received, t0) << "the frame's receipt, not the publish tick";
  const std::uint32_t firstSequence = s->lamps.stamp.sequence;

  // The same value 0.1 s later: the bits stay, the stamp is the repeat's.
  d.onFrame(stalk(kStalkHigh), t0 + milliseconds(100));
  d.publish(store, t0 + milliseconds(105), "can test");
  s = store.snapshot();
  EXPECT_EQ(s->lamps.value.lights, light::kHighBeam | light::kPosition);
  EXPECT_EQ(s->lamps.stamp.received, t0 + milliseconds(100));
  EXPECT_GT(s->lamps.stamp.sequence, firstSequence);

  // A tick without a new frame publishes nothing.
  const std::uint64_t version = s->version;
  d.publish(store, t0 + milliseconds(150), "can test");
  EXPECT_EQ(store.snapshot()->version, version);

  // A host lamp state after it, then the stalk falls silent: the fallback is published with the
  // host's (newer) receipt kept, since the mask still holds the host's bits.
  store.setLamps(LampState{light::kDrl, 0.0f}, hostStamp(t0 + milliseconds(200)));
  d.publish(store, t0 + milliseconds(400), "can test");  // > hold_s after the last frame
  s = store.snapshot();
  EXPECT_EQ(s->lamps.value.lights, light::kDrl);  // every mapped lamp fell back to off
  EXPECT_EQ(s->lamps.stamp.received, t0 + milliseconds(200));
  EXPECT_EQ(d.stats().fallbacks, 3u);
}

// ---- docs/can.md: silence counts from the source's start ----------------------------------------

TEST(CanSilence, NotSilentBeforeTheSourceHasRunForHoldS) {
  CanDecoder d = stalkDecoder(light::kLowBeam);
  StateStore store;
  const auto t0 = Clock::now();
  d.publish(store, t0, "can test");  // the source's first tick: nothing received yet
  d.publish(store, t0 + milliseconds(150), "can test");
  EXPECT_EQ(d.stats().fallbacks, 0u) << "no silence warning before hold_s has passed since the start";
  EXPECT_FALSE(store.snapshot()->lamps.stamp.valid) << "nothing known: the initial mask stays";
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kInitialEgo);
  // A host's lamp state meanwhile cannot set the mapped bits either: they are claimed.
  store.setLamps(LampState{light::kHighBeam | light::kDrl, 0.0f}, hostStamp(t0 + milliseconds(160)));
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kLowBeam | light::kDrl);

  d.publish(store, t0 + milliseconds(250), "can test");  // hold_s (0.2 s) passed without a frame
  EXPECT_EQ(d.stats().fallbacks, 3u);
  EXPECT_EQ(store.snapshot()->lamps.value.lights, light::kLowBeam | light::kDrl);  // fallback: low beam on
  EXPECT_NE(store.snapshot()->lamps.stamp.source.find("can"), std::string::npos);

  // A frame within hold_s of the start is never silent.
  CanDecoder early = stalkDecoder();
  StateStore other;
  early.publish(other, t0, "can test");
  early.onFrame(stalk(kStalkHigh), t0 + milliseconds(100));
  early.publish(other, t0 + milliseconds(100), "can test");
  early.publish(other, t0 + milliseconds(250), "can test");
  EXPECT_EQ(early.stats().fallbacks, 0u);
  EXPECT_EQ(other.snapshot()->lamps.value.lights, light::kHighBeam | light::kPosition);
}

// ---- docs/can.md: a finished candump log is not a silent bus --------------------------------------

TEST(CanCandumpEnd, AFinishedLogKeepsItsLastStateWithoutFallback) {
  const std::filesystem::path log =
      std::filesystem::temp_directory_path() / ("fogbeam-candump-end-" + std::to_string(::getpid()) + ".log");
  {
    std::ofstream out(log);
    out << "(1700000000.000000) vcan0 622#0000004000000000\n"   // high beam
           "(1700000000.010000) vcan0 622#0000004800000000\n";  // high beam + front fog
  }
  StateStore store;
  auto src = startCandumpReplay(log.string(), 0.0, stalkDecoder(light::kLowBeam), store);
  ASSERT_TRUE(src) << src.error().message;
  ASSERT_TRUE(waitFor([&] { return (*src)->finished(); }));
  const std::uint32_t expected = light::kHighBeam | light::kFrontFog | light::kPosition;
  EXPECT_EQ(store.snapshot()->lamps.value.lights, expected);
  // Well past hold_s (0.2 s): no fallback (low beam would come on), no silence counted.
  std::this_thread::sleep_for(milliseconds(500));
  EXPECT_EQ(store.snapshot()->lamps.value.lights, expected);
  EXPECT_EQ((*src)->stats().fallbacks, 0u);
  (*src)->stop();
  std::filesystem::remove(log);
}

// ---- docs/can.md: errors name the file and the line ---------------------------------------------

TEST(CanMappingErrors, ASignalTheDbcLacksIsReportedAtItsMappingLine) {
  const std::string dir = std::string(FOGBEAM_TEST_DATA_DIR) + "/can";
  auto err = [&](const std::string& text) {
    auto c = parseCanConfig(text, "map.toml", dir);
    if (!c) return "parse: " + c.error().message;
    auto d = makeDecoder(*c);
    return d ? std::string("(built)") : d.error().message;
  };
  const std::string lamp = err(
      "dbc = \"vehicle.dbc\"\n[lamps]\nlow_beam = { message = \"LIGHT_STALK\", signal = \"LOW_BEAM\" }\n"
      "high_beam = { message = \"LIGHT_STALK\", signal = \"MAIN_BEAM\" }\n");
  EXPECT_TRUE(lamp.starts_with("map.toml:4: [lamps] high_beam: ")) << lamp;
  EXPECT_NE(lamp.find("vehicle.dbc"), std::string::npos) << lamp;
  EXPECT_NE(lamp.find("MAIN_BEAM"), std::string::npos) << lamp;
  EXPECT_NE(lamp.find("LOW_BEAM"), std::string::npos) << "lists what the message has: " << lamp;

  const std::string message = err("dbc = \"vehicle.dbc\"\n\n[lamps]\nfront_fog = { message = \"FOG\", signal = \"FRONT_FOG\" }\n");
  EXPECT_TRUE(message.starts_with("map.toml:4: [lamps] front_fog: ")) << message;
  EXPECT_NE(message.find("LIGHT_STALK"), std::string::npos) << "lists the DBC's messages: " << message;

  const std::string speed = err("dbc = \"vehicle.dbc\"\nhold_s = 0.3\nspeed = { message = \"SPEED\", signal = \"KMH\" }\n");
  EXPECT_TRUE(speed.starts_with("map.toml:3: speed: ")) << speed;

  // The shipped test mapping still builds.
  auto ok = loadCanConfig(dir + "/mapping.toml");
  ASSERT_TRUE(ok) << ok.error().message;
  EXPECT_TRUE(makeDecoder(*ok)) << makeDecoder(*ok).error().message;
}

// ---- docs/protocol.md: max_traffic_objects, and every datagram counted once ------------------------

TEST(UdpTrafficBound, EveryDatagramIsCountedOnceWhenObjectsAreRefused) {
  StateStoreOptions so;
  so.max_traffic_objects = 2;
  StateStore store(so);
  UdpReceiverOptions o;
  o.port = 0;
  auto rx = UdpReceiver::start(o, store);
  ASSERT_TRUE(rx) << rx.error().message;
  const UniqueFd fd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  ASSERT_TRUE(fd);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons((*rx)->port());
  inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
  std::uint32_t seq = 0;
  auto send = [&](std::vector<std::uint32_t> ids) {
    TrafficList list;
    for (std::uint32_t id : ids) {
      TrafficObject obj;
      obj.id = id;
      obj.pose.position_m = {50.0, 0.0, 0.0};
      list.objects.push_back(obj);
    }
    Message m;
    m.header.sequence = ++seq;
    m.payload = list;
    const auto bytes = encode(m);
    ::sendto(fd.get(), bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  };
  send({1, 2, 3});  // two taken, one refused: applied
  send({4, 5});     // the store is full: nothing taken, a too_many_objects drop
  send({1, 6});     // object 1 updated, 6 refused: applied
  ASSERT_TRUE(waitFor([&] { return (*rx)->stats().datagrams == 3; }));
  const UdpStats st = (*rx)->stats();
  EXPECT_EQ(st.applied, 2u);
  EXPECT_EQ(st.dropped[static_cast<std::size_t>(DropReason::TooManyObjects)], 1u);
  EXPECT_EQ(st.datagrams, st.applied + st.droppedTotal());
  EXPECT_EQ(st.traffic_refused, 4u);  // 3, 4, 5 and 6
  EXPECT_EQ(store.snapshot()->traffic.size(), 2u);
}

}  // namespace
}  // namespace fogbeam::ipc
