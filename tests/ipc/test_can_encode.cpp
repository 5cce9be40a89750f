// The CAN output (host stand-in): CanEncoder frames decode with the CAN input's CanDecoder to
// the lamp bits and speed they were made from, for every lamp combination; multiplexed, CAN FD
// and extended messages; mapping and value errors; candump -L lines that candump's parser
// reads back; cannelloni datagrams that decode back to the same frames.
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/can_encode.hpp>
#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/ipc/candump.hpp>
#include <fogbeam/ipc/cannelloni.hpp>
#include <fogbeam/ipc/state_store.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace fogbeam::ipc {
namespace {

const std::string kCanData = std::string(FOGBEAM_TEST_DATA_DIR) + "/can";

CanConfig testConfig() {
  Result<CanConfig> c = loadCanConfig(kCanData + "/mapping.toml");
  EXPECT_TRUE(c) << c.error().message;
  return c ? *c : CanConfig{};
}

std::size_t lampIndex(CanLamp l) { return static_cast<std::size_t>(l); }

// The light:: bits a mapping maps.
std::uint32_t mappedBits(const CanMapping& m) {
  std::uint32_t bits = 0;
  for (std::size_t k = 0; k < kCanLampCount; ++k)
    if (m.lamps[k]) bits |= kCanLampBits[k];
  return bits;
}

// Every subset of `bits`, by counting through the set bits.
std::vector<std::uint32_t> subsetsOf(std::uint32_t bits) {
  std::vector<std::uint32_t> out;
  std::uint32_t s = 0;
  do {
    out.push_back(s);
    s = (s - bits) & bits;
  } while (s != 0);
  return out;
}

struct Decoded {
  std::uint32_t lights = 0;
  std::optional<float> speed_m_s;
};

// Feeds `frames` to a fresh decoder and reads what it publishes.
Decoded decodeWith(const DbcDatabase& dbc, const CanMapping& mapping, const std::vector<CanFrame>& frames) {
  Result<CanDecoder> d = CanDecoder::create(dbc, mapping);
  EXPECT_TRUE(d) << d.error().message;
  if (!d) return {};
  const auto now = Clock::now();
  for (const CanFrame& f : frames) EXPECT_TRUE(d->onFrame(f, now)) << "frame id " << f.id;
  EXPECT_EQ(d->stats().out_of_range, 0u);
  StateStore store;
  d->publish(store, now, "test", true);
  const auto snap = store.snapshot();
  Decoded out;
  out.lights = d->lights(now);
  // The mapped bits merge into the initial mask (low beam + position until the first lamp
  // state, docs/service.md); the bits the mapping leaves out keep their initial values.
  std::uint32_t owned = 0;
  for (std::size_t k = 0; k < kCanLampCount; ++k)
    if (mapping.lamps[k]) owned |= kCanLampBits[k];
  EXPECT_EQ(snap->lamps.value.lights, (light::kInitialEgo & ~owned) | out.lights);
  if (snap->vehicle_speed_m_s.stamp.valid) out.speed_m_s = snap->vehicle_speed_m_s.value;
  return out;
}

DbcDatabase load(const std::string& path) {
  Result<DbcDatabase> db = loadDbc(path);
  EXPECT_TRUE(db) << db.error().message;
  return db ? *db : DbcDatabase{};
}

TEST(CanEncode, TestMappingRoundTripsEveryLampCombinationAndSpeed) {
  const CanConfig config = testConfig();
  const DbcDatabase dbc = load(config.dbc_path);
  Result<CanEncoder> enc = makeEncoder(config);
  ASSERT_TRUE(enc) << enc.error().message;
  const std::uint32_t mapped = mappedBits(config.mapping);
  ASSERT_EQ(mapped, light::kLowBeam | light::kHighBeam | light::kFrontFog);
  // LIGHT_STALK first (the lamps come first in the mapping), then SPEED.
  EXPECT_EQ(enc->ids(), (std::vector<std::pair<std::uint32_t, bool>>{{1570, false}, {180, false}}));
  // SPEED has 0.01 km/h per count: half a count is 0.0014 m/s; the store keeps a float.
  const double tolerance = 0.005 / 3.6 + 1e-4;
  int combinations = 0;
  for (const std::uint32_t lamps : subsetsOf(mapped)) {
    for (const double speed : {0.0, 0.01, 13.89, 20.0, 300.0 / 3.6, -2.0 / 3.6}) {
      // Bits the mapping does not map (DRL, rear fog) are ignored, not an error.
      const std::uint32_t lights = lamps | light::kDrl | light::kRearFog;
      Result<std::vector<CanFrame>> frames = enc->encode(lights, speed);
      ASSERT_TRUE(frames) << frames.error().message;
      ASSERT_EQ(frames->size(), 2u);
      for (const CanFrame& f : *frames) {
        EXPECT_EQ(f.len, 8);
        EXPECT_FALSE(f.fd);
        EXPECT_FALSE(f.extended);
        EXPECT_FALSE(f.remote);
      }
      const Decoded d = decodeWith(dbc, config.mapping, *frames);
      EXPECT_EQ(d.lights, lamps) << "lamps 0x" << std::hex << lamps;
      ASSERT_TRUE(d.speed_m_s.has_value());
      EXPECT_NEAR(*d.speed_m_s, speed, tolerance) << speed;
      ++combinations;
    }
  }
  EXPECT_EQ(combinations, 8 * 6);
}

TEST(CanEncode, KnownBytesForTheTestMapping) {
  Result<CanEncoder> enc = makeEncoder(testConfig());
  ASSERT_TRUE(enc) << enc.error().message;
  // Low beam + front fog = byte 3 bits 5 and 3 (0x28); 20 m/s = 72 km/h = raw 7400 = 0x1CE8.
  Result<std::vector<CanFrame>> frames = enc->encode(light::kLowBeam | light::kFrontFog, 20.0);
  ASSERT_TRUE(frames) << frames.error().message;
  ASSERT_EQ(frames->size(), 2u);
  EXPECT_EQ((*frames)[0].id, 1570u);
  EXPECT_EQ((*frames)[0].data[3], 0x28);
  EXPECT_EQ((*frames)[1].id, 180u);
  EXPECT_EQ((*frames)[1].data[5], 0x1C);
  EXPECT_EQ((*frames)[1].data[6], 0xE8);
  EXPECT_EQ(formatCandumpLine(1700000000.123456, "can0", (*frames)[0]), "(1700000000.123456) can0 622#0000002800000000");
  EXPECT_EQ(formatCandumpLine(1700000000.123456, "can0", (*frames)[1]), "(1700000000.123456) can0 0B4#00000000001CE800");
}

TEST(CanEncode, WithoutASpeedTheSpeedOnlyMessageIsLeftOut) {
  const CanConfig config = testConfig();
  Result<CanEncoder> enc = makeEncoder(config);
  ASSERT_TRUE(enc) << enc.error().message;
  Result<std::vector<CanFrame>> frames = enc->encode(light::kHighBeam, std::nullopt);
  ASSERT_TRUE(frames) << frames.error().message;
  ASSERT_EQ(frames->size(), 1u);
  EXPECT_EQ((*frames)[0].id, 1570u);
  const Decoded d = decodeWith(load(config.dbc_path), config.mapping, *frames);
  EXPECT_EQ(d.lights, light::kHighBeam);
  EXPECT_FALSE(d.speed_m_s.has_value());
}

TEST(CanEncode, SpeedsTheDecoderWouldDropAreErrors) {
  Result<CanEncoder> enc = makeEncoder(testConfig());
  ASSERT_TRUE(enc) << enc.error().message;
  // The DBC range is −2 … 300 km/h: 100 m/s = 360 km/h is beyond it (and inside the field).
  Result<std::vector<CanFrame>> fast = enc->encode(0, 100.0);
  ASSERT_FALSE(fast);
  EXPECT_NE(fast.error().message.find("'SPEED'"), std::string::npos) << fast.error().message;
  EXPECT_NE(fast.error().message.find("360 km/h"), std::string::npos) << fast.error().message;
  EXPECT_NE(fast.error().message.find("outside the DBC range -2 to 300 km/h"), std::string::npos)
      << fast.error().message;
  EXPECT_FALSE(enc->encode(0, -1.0));  // −3.6 km/h
  EXPECT_FALSE(enc->encode(0, std::nan("")));
  EXPECT_TRUE(enc->encode(0, 300.0 / 3.6));
}

// A second DBC for what the vehicle DBC's mapping does not exercise: an extended-id CAN FD
// message with a multiplexor whose pages carry different lamps, signed and offset lamp
// signals, an Intel standard message, and a speed shared by every page.
constexpr const char* kFdDbc = R"(BO_ 300 BODY: 2 BCM
 SG_ LOW : 3|1@1+ (1,0) [0|1] "" FOGBEAM
 SG_ FOG : 12|1@0+ (1,0) [0|1] "" FOGBEAM
BO_ 2147484160 EXT_LAMPS: 12 BCM
 SG_ SEL M : 0|2@1+ (1,0) [0|3] "" FOGBEAM
 SG_ HIGH m0 : 19|4@0+ (0.5,-1) [-1|6.5] "" FOGBEAM
 SG_ REAR_FOG m1 : 8|1@1+ (1,0) [0|1] "" FOGBEAM
 SG_ IND_LEFT m2 : 8|1@1+ (1,0) [0|1] "" FOGBEAM
 SG_ IND_RIGHT m2 : 9|2@1- (1,0) [-1|0] "" FOGBEAM
 SG_ SPEED_FD : 43|21@1- (0.001,0) [-100|100] "m/s" FOGBEAM
)";

CanMapping fdMapping() {
  CanMapping m;
  m.lamps[lampIndex(CanLamp::LowBeam)] = CanSignalRef{"BODY", "LOW"};
  m.lamps[lampIndex(CanLamp::HighBeam)] = CanSignalRef{"EXT_LAMPS", "HIGH"};
  m.lamps[lampIndex(CanLamp::FrontFog)] = CanSignalRef{"BODY", "FOG"};
  m.lamps[lampIndex(CanLamp::RearFog)] = CanSignalRef{"EXT_LAMPS", "REAR_FOG"};
  m.lamps[lampIndex(CanLamp::IndicatorLeft)] = CanSignalRef{"EXT_LAMPS", "IND_LEFT"};
  m.lamps[lampIndex(CanLamp::IndicatorRight)] = CanSignalRef{"EXT_LAMPS", "IND_RIGHT"};
  m.speed = CanSignalRef{"EXT_LAMPS", "SPEED_FD"};
  return m;
}

TEST(CanEncode, MultiplexedFdExtendedMessagesRoundTrip) {
  Result<DbcDatabase> dbc = parseDbc(kFdDbc, "fd.dbc");
  ASSERT_TRUE(dbc) << dbc.error().message;
  const CanMapping mapping = fdMapping();
  Result<CanEncoder> enc = CanEncoder::create(*dbc, mapping);
  ASSERT_TRUE(enc) << enc.error().message;
  EXPECT_EQ(enc->ids(), (std::vector<std::pair<std::uint32_t, bool>>{{300, false}, {0x200, true}}));
  int combinations = 0;
  for (const std::uint32_t lamps : subsetsOf(mappedBits(mapping))) {
    for (const double speed : {-99.5, -0.001, 0.0, 12.345, 100.0}) {
      Result<std::vector<CanFrame>> frames = enc->encode(lamps, speed);
      ASSERT_TRUE(frames) << frames.error().message;
      // BODY, then EXT_LAMPS once per page in mapping order: 0 (HIGH), 1 (REAR_FOG), 2 (indicators).
      ASSERT_EQ(frames->size(), 4u);
      EXPECT_EQ((*frames)[0].len, 2);
      EXPECT_FALSE((*frames)[0].fd);
      for (std::size_t i = 1; i < 4; ++i) {
        const CanFrame& f = (*frames)[i];
        EXPECT_EQ(f.id, 0x200u);
        EXPECT_TRUE(f.extended);
        EXPECT_TRUE(f.fd);
        EXPECT_EQ(f.len, 12);
        EXPECT_EQ(f.data[0] & 0x3u, i - 1) << "page of frame " << i;
      }
      const Decoded d = decodeWith(*dbc, mapping, *frames);
      EXPECT_EQ(d.lights, lamps) << "lamps 0x" << std::hex << lamps;
      ASSERT_TRUE(d.speed_m_s.has_value());
      EXPECT_NEAR(*d.speed_m_s, speed, 0.0005 + 1e-5);
      ++combinations;
    }
  }
  EXPECT_EQ(combinations, 64 * 5);
  // The signed indicator's "on" is −1 (raw 0b11 in bits 9–10); the offset high beam's "off"
  // is raw 2 (physical 0 = 2 · 0.5 − 1).
  Result<std::vector<CanFrame>> frames = enc->encode(light::kIndicatorRight, 0.0);
  ASSERT_TRUE(frames);
  EXPECT_EQ((*frames)[3].data[1] & 0x06, 0x06);
  EXPECT_EQ(decodeSignal(*dbc->signal("EXT_LAMPS", "HIGH").value(), (*frames)[1]), 0.0);
  EXPECT_EQ(extractRaw(dbc->signal("EXT_LAMPS", "HIGH").value()->bits, (*frames)[1]), 2u);
}

TEST(CanEncode, LampsSharingASignalMustAgree) {
  const CanConfig config = testConfig();
  const DbcDatabase dbc = load(config.dbc_path);
  CanMapping m;
  m.lamps[lampIndex(CanLamp::LowBeam)] = CanSignalRef{"LIGHT_STALK", "LOW_BEAM"};
  m.lamps[lampIndex(CanLamp::HighBeam)] = CanSignalRef{"LIGHT_STALK", "LOW_BEAM"};
  Result<CanEncoder> enc = CanEncoder::create(dbc, m);
  ASSERT_TRUE(enc) << enc.error().message;
  for (const std::uint32_t both : {0u, light::kLowBeam | light::kHighBeam}) {
    Result<std::vector<CanFrame>> frames = enc->encode(both, std::nullopt);
    ASSERT_TRUE(frames) << frames.error().message;
    EXPECT_EQ(decodeWith(dbc, m, *frames).lights, both);
  }
  Result<std::vector<CanFrame>> conflict = enc->encode(light::kLowBeam, std::nullopt);
  ASSERT_FALSE(conflict);
  EXPECT_NE(conflict.error().message.find("LOW_BEAM"), std::string::npos) << conflict.error().message;
}

TEST(CanEncode, MappingErrorsNameTheProblem) {
  const DbcDatabase dbc = load(kCanData + "/vehicle.dbc");
  auto err = [](const DbcDatabase& db, const CanMapping& m) {
    Result<CanEncoder> e = CanEncoder::create(db, m);
    return e ? std::string("(created)") : e.error().message;
  };
  EXPECT_NE(err(dbc, CanMapping{}).find("names no signal"), std::string::npos);
  CanMapping missing;
  missing.lamps[0] = CanSignalRef{"LIGHT_STALK", "NOPE"};
  EXPECT_NE(err(dbc, missing).find("'NOPE'"), std::string::npos) << err(dbc, missing);
  CanMapping noMessage;
  noMessage.speed = CanSignalRef{"WHEELS", "SPEED"};
  EXPECT_NE(err(dbc, noMessage).find("'WHEELS'"), std::string::npos) << err(dbc, noMessage);
  CanMapping zeroScale;
  zeroScale.speed = CanSignalRef{"SPEED", "SPEED"};
  zeroScale.speed_to_m_s = 0.0;
  EXPECT_NE(err(dbc, zeroScale).find("to_m_s"), std::string::npos) << err(dbc, zeroScale);
  // A mapped multiplexor in a message whose mapped multiplexed signals set it themselves.
  CanMapping mux;
  mux.lamps[lampIndex(CanLamp::LowBeam)] = CanSignalRef{"LAMP_STATUS", "PAGE"};
  mux.lamps[lampIndex(CanLamp::HighBeam)] = CanSignalRef{"LAMP_STATUS", "LEFT_HIGH_CURRENT"};
  EXPECT_NE(err(dbc, mux).find("multiplexor"), std::string::npos) << err(dbc, mux);
  CanMapping speedAndLamp;
  speedAndLamp.lamps[0] = CanSignalRef{"SPEED", "SPEED"};
  speedAndLamp.speed = CanSignalRef{"SPEED", "SPEED"};
  EXPECT_NE(err(dbc, speedAndLamp).find("cannot carry both"), std::string::npos) << err(dbc, speedAndLamp);

  Result<DbcDatabase> odd = parseDbc("BO_ 5 ODD: 2 X\n"
                                     " SG_ A : 0|4@1+ (1,0) [0|15] \"\" X\n"
                                     " SG_ B : 3|2@1+ (1,0) [0|3] \"\" X\n"
                                     " SG_ C : 8|8@1+ (1,5) [5|10] \"\" X\n"
                                     " SG_ Z : 6|2@1+ (1,0) [0|0] \"\" X\n",
                                     "odd.dbc");
  ASSERT_TRUE(odd) << odd.error().message;
  CanMapping overlap;
  overlap.lamps[0] = CanSignalRef{"ODD", "A"};
  overlap.lamps[1] = CanSignalRef{"ODD", "B"};
  EXPECT_NE(err(*odd, overlap).find("'A' and 'B' of message 'ODD' share bits"), std::string::npos)
      << err(*odd, overlap);
  CanMapping noOff;
  noOff.lamps[0] = CanSignalRef{"ODD", "C"};  // physical 0 would be raw −5
  EXPECT_NE(err(*odd, noOff).find("cannot express off"), std::string::npos) << err(*odd, noOff);
  CanMapping fine;
  fine.lamps[0] = CanSignalRef{"ODD", "A"};
  fine.lamps[1] = CanSignalRef{"ODD", "Z"};
  EXPECT_EQ(err(*odd, fine), "(created)");

  CanConfig badPath;
  badPath.dbc_path = kCanData + "/no_such.dbc";
  badPath.mapping = testConfig().mapping;
  Result<CanEncoder> e = makeEncoder(badPath);
  ASSERT_FALSE(e);
  EXPECT_NE(e.error().message.find("no_such.dbc"), std::string::npos) << e.error().message;
}

// ---------------------------------------------------------------------------------------
// candump -L lines and cannelloni datagrams.

CanFrame parsedBack(const std::string& line) {
  Result<CandumpLine> r = parseCandumpLine(line);
  EXPECT_TRUE(r) << line << ": " << (r ? "" : r.error().message);
  return r ? r->frame : CanFrame{};
}

TEST(CanEncode, CandumpLinesInCanUtilsNotation) {
  CanFrame ext;
  ext.id = 0x1F334455;
  ext.extended = true;
  ext.len = 1;
  EXPECT_EQ(formatCandumpLine(0.5, "vcan0", ext), "(0000000000.500000) vcan0 1F334455#00");
  CanFrame remote;
  remote.id = 0x7FF;
  remote.remote = true;
  EXPECT_EQ(formatCandumpLine(12.0000004, "can1", remote), "(0000000012.000000) can1 7FF#R");
  remote.len = 4;
  EXPECT_EQ(formatCandumpLine(12.0000006, "can1", remote), "(0000000012.000001) can1 7FF#R4");
  CanFrame fd;
  fd.id = 0x123;
  fd.fd = true;
  fd.brs = true;
  fd.len = 12;
  for (std::size_t i = 0; i < 12; ++i) fd.data[i] = static_cast<std::uint8_t>(0x11 * i);
  EXPECT_EQ(formatCandumpLine(1.0, "can0", fd), "(0000000001.000000) can0 123##100112233445566778899AABB");
  fd.esi = true;
  fd.brs = false;
  EXPECT_EQ(formatCandumpLine(1.0, "can0", fd).substr(25, 6), "123##2");
  CanFrame empty;
  empty.id = 0x5;
  EXPECT_EQ(formatCandumpLine(-3.0, "can0", empty), "(0000000000.000000) can0 005#");
  // Each parses back to the frame it was made from.
  for (const CanFrame& f : {ext, remote, fd, empty}) EXPECT_EQ(parsedBack(formatCandumpLine(7.25, "can0", f)).id, f.id);
  CanFrame back = parsedBack(formatCandumpLine(7.25, "can0", fd));
  back.timestamp_s = 0.0;
  EXPECT_EQ(back, fd);
}

TEST(CanEncode, CandumpLinesParseBackForRandomFrames) {
  std::mt19937 rng(2024);  // 32-bit results: narrowed explicitly below
  constexpr std::size_t kFdLengths[] = {0, 1, 5, 8, 12, 16, 20, 24, 32, 48, 64};
  for (int trial = 0; trial < 1000; ++trial) {
    CanFrame f;
    f.extended = rng() % 2 == 0;
    f.id = static_cast<std::uint32_t>(f.extended ? rng() % (kCanMaxExtendedId + 1) : rng() % (kCanMaxStandardId + 1));
    const auto kind = static_cast<unsigned>(rng() % 3);  // classic, remote, FD
    if (kind == 1) {
      f.remote = true;
      f.len = static_cast<std::uint8_t>(rng() % 9);
    } else {
      f.fd = kind == 2;
      f.brs = f.fd && rng() % 2 == 0;
      f.esi = f.fd && rng() % 2 == 0;
      f.len = static_cast<std::uint8_t>(f.fd ? kFdLengths[rng() % std::size(kFdLengths)] : rng() % 9);
      for (std::size_t i = 0; i < f.len; ++i) f.data[i] = static_cast<std::uint8_t>(rng());
    }
    const double t = 1'700'000'000.0 + static_cast<double>(rng() % 100'000'000) * 1e-6;
    const std::string line = formatCandumpLine(t, "can0", f);
    Result<CandumpLine> r = parseCandumpLine(line);
    ASSERT_TRUE(r) << line << ": " << r.error().message;
    EXPECT_EQ(r->interface, "can0");
    EXPECT_NEAR(r->timestamp_s, t, 1e-6) << line;
    CanFrame back = r->frame;
    back.timestamp_s = 0.0;
    ASSERT_EQ(back, f) << line;
  }
}

TEST(CanEncode, EncodedFramesSurviveCannelloni) {
  Result<DbcDatabase> dbc = parseDbc(kFdDbc, "fd.dbc");
  ASSERT_TRUE(dbc) << dbc.error().message;
  Result<CanEncoder> enc = CanEncoder::create(*dbc, fdMapping());
  ASSERT_TRUE(enc) << enc.error().message;
  Result<std::vector<CanFrame>> frames = enc->encode(light::kLowBeam | light::kIndicatorLeft, 3.0);
  ASSERT_TRUE(frames) << frames.error().message;
  CannelloniPacket packet;
  packet.sequence = 7;
  packet.frames = *frames;
  Result<CannelloniPacket> back = decodeCannelloni(encodeCannelloni(packet));
  ASSERT_TRUE(back) << back.error().message;
  EXPECT_EQ(back->frames, *frames);
  const Decoded d = decodeWith(*dbc, fdMapping(), back->frames);
  EXPECT_EQ(d.lights, light::kLowBeam | light::kIndicatorLeft);
}

}  // namespace
}  // namespace fogbeam::ipc
