// DBC reader, signal decoder and encoder: every byte order against hand-computed values, sign
// extension, factor/offset, multiplexing, ranges, look-ups, every parse error, and encoding as
// the decoder's inverse.
#include <fogbeam/ipc/dbc.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <iterator>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace fogbeam::ipc {
namespace {

const std::string kCanData = std::string(FOGBEAM_TEST_DATA_DIR) + "/can";

CanFrame frameOf(std::uint32_t id, std::initializer_list<std::uint8_t> bytes, bool extended = false) {
  CanFrame f;
  f.id = id;
  f.extended = extended;
  std::size_t i = 0;
  for (const std::uint8_t b : bytes) f.data[i++] = b;
  f.len = static_cast<std::uint8_t>(bytes.size());
  return f;
}

DbcDatabase loadVehicle() {
  Result<DbcDatabase> db = loadDbc(kCanData + "/vehicle.dbc");
  EXPECT_TRUE(db.has_value()) << (db ? "" : db.error().message);
  return db ? *db : DbcDatabase{};
}

const DbcSignal& signalOf(const DbcDatabase& db, const std::string& message, const std::string& name) {
  const Result<const DbcSignal*> s = db.signal(message, name);
  if (!s) {
    ADD_FAILURE() << s.error().message;
    static const DbcSignal kNone;
    return kNone;
  }
  return **s;
}

// One-message database from a single SG_ line, for the bit-layout tests.
DbcSignal oneSignal(const std::string& sg, int size = 8) {
  const std::string text = "BO_ 100 M: " + std::to_string(size) + " X\n SG_ " + sg + "\n";
  Result<DbcDatabase> db = parseDbc(text, "inline.dbc");
  EXPECT_TRUE(db.has_value()) << (db ? "" : db.error().message);
  if (!db || db->messages.empty() || db->messages[0].signals.empty()) return {};
  return db->messages[0].signals[0];
}

std::string parseError(const std::string& text) {
  Result<DbcDatabase> db = parseDbc(text, "bad.dbc");
  EXPECT_FALSE(db.has_value()) << "parsed without error:\n" << text;
  return db ? std::string() : db.error().message;
}

// ---------------------------------------------------------------------------------------
// The fixture file.

TEST(DbcFile, ReadsMessagesSignalsAndSkipsOtherStatements) {
  const DbcDatabase db = loadVehicle();
  EXPECT_EQ(db.file_name, kCanData + "/vehicle.dbc");
  // LIGHT_STALK, SPEED, STEER, LAMP_STATUS, HEADLAMP_LEVELING, CABIN; the Vector pseudo-message
  // VECTOR__INDEPENDENT_SIG_MSG and the "signal" inside the multi-line CM_ string are skipped.
  ASSERT_EQ(db.messages.size(), 6u);
  const DbcMessage* stalk = db.findMessage(1570, false);
  ASSERT_NE(stalk, nullptr);
  EXPECT_EQ(stalk->name, "LIGHT_STALK");
  EXPECT_EQ(stalk->size, 8);
  EXPECT_EQ(stalk->transmitter, "SCM");
  ASSERT_EQ(stalk->signals.size(), 5u);
  EXPECT_EQ(stalk->signals[1].name, "FRONT_FOG");
  const DbcMessage* speed = db.findMessage(180, false);
  ASSERT_NE(speed, nullptr);
  ASSERT_EQ(speed->signals.size(), 2u);
  const DbcSignal& s = speed->signals[1];
  EXPECT_EQ(s.name, "SPEED");
  EXPECT_EQ(s.bits.start_bit, 47);
  EXPECT_EQ(s.bits.length, 16);
  EXPECT_EQ(s.bits.order, DbcByteOrder::Motorola);
  EXPECT_FALSE(s.bits.is_signed);
  EXPECT_DOUBLE_EQ(s.factor, 0.01);
  EXPECT_DOUBLE_EQ(s.offset, -2.0);
  EXPECT_DOUBLE_EQ(s.minimum, -2.0);
  EXPECT_DOUBLE_EQ(s.maximum, 300.0);
  EXPECT_EQ(s.unit, "km/h");
  ASSERT_EQ(s.receivers.size(), 2u);
  EXPECT_EQ(s.receivers[1], "EPS");
  EXPECT_EQ(db.findMessage(0, false), nullptr);
  EXPECT_EQ(db.findMessage(1570, true), nullptr);  // same number, other id format
}

TEST(DbcFile, ExtendedIdHasBit31Removed) {
  const DbcDatabase db = loadVehicle();
  // 2566844705 = 0x98FEF121 = 0x80000000 (extended marker) + 0x18FEF121.
  const DbcMessage* m = db.findMessage(0x18FEF121, true);
  ASSERT_NE(m, nullptr);
  EXPECT_EQ(m->name, "HEADLAMP_LEVELING");
  EXPECT_TRUE(m->extended);
  EXPECT_EQ(db.findMessage(0x18FEF121, false), nullptr);
  // LEVEL 0|8@1- (0.5,0): byte 0 = 0xF6 = 246 → 246 − 256 = −10 → −10 · 0.5 = −5 deg.
  EXPECT_EQ(decodeSignal(signalOf(db, "HEADLAMP_LEVELING", "LEVEL"), frameOf(0x18FEF121, {0xF6, 0, 0, 0, 0, 0, 0, 0}, true)),
            -5.0);
}

TEST(DbcDecode, LightStalkBits) {
  const DbcDatabase db = loadVehicle();
  // 1-bit Motorola signals: the start bit is the bit itself, byte = bit / 8, bit in byte =
  // bit % 8. FRONT_FOG 27 → byte 3 0x08, PARKING_LIGHT 28 → 0x10, LOW_BEAM 29 → 0x20,
  // HIGH_BEAM 30 → 0x40, AUTO_HIGH_BEAM 37 → byte 4 0x20. Byte 3 = 0x28 = low beam + front fog.
  const CanFrame f = frameOf(1570, {0, 0, 0, 0x28, 0, 0, 0, 0});
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "LOW_BEAM"), f), 1.0);
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "FRONT_FOG"), f), 1.0);
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "HIGH_BEAM"), f), 0.0);
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "PARKING_LIGHT"), f), 0.0);
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "AUTO_HIGH_BEAM"), f), 0.0);
  const CanFrame high = frameOf(1570, {0, 0, 0, 0x40, 0x20, 0, 0, 0});
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "HIGH_BEAM"), high), 1.0);
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "AUTO_HIGH_BEAM"), high), 1.0);
  EXPECT_EQ(decodeSignal(signalOf(db, "LIGHT_STALK", "LOW_BEAM"), high), 0.0);
}

TEST(DbcDecode, MotorolaSpeedWithFactorAndOffset) {
  const DbcDatabase db = loadVehicle();
  // SPEED 47|16@0+ (0.01,-2): MSB = bit 47 = byte 5 bit 7; 16 bits run through byte 5 and
  // byte 6, so raw = byte5 · 256 + byte6 = 0x12 · 256 + 0x34 = 4660 → 4660 · 0.01 − 2 = 44.6.
  // (Reading 47 as the LSB instead would take byte 5 and byte 4 and give 0x0012 · … — wrong.)
  const CanFrame f = frameOf(180, {0xAF, 0x9C, 0, 0, 0, 0x12, 0x34, 0});
  const std::optional<DbcValue> v = decodeSignalValue(signalOf(db, "SPEED", "SPEED"), f);
  ASSERT_TRUE(v.has_value());
  EXPECT_EQ(v->raw, 0x1234u);
  EXPECT_NEAR(v->physical, 44.6, 1e-9);
  EXPECT_FALSE(v->out_of_range);
}

TEST(DbcDecode, MotorolaSignedAcrossBytes) {
  const DbcDatabase db = loadVehicle();
  // ACCEL_X 3|12@0- (0.001,0): MSB = byte 0 bit 3; the 12 bits are byte 0 bits 3…0 then byte 1
  // bits 7…0: raw = (0xAF & 0x0F) · 256 + 0x9C = 0xF9C = 3996 (the 0xA0 above belongs to no
  // signal). Top bit set → 3996 − 4096 = −100 → −100 · 0.001 = −0.1 g.
  const CanFrame f = frameOf(180, {0xAF, 0x9C, 0, 0, 0, 0x12, 0x34, 0});
  const std::optional<DbcValue> v = decodeSignalValue(signalOf(db, "SPEED", "ACCEL_X"), f);
  ASSERT_TRUE(v.has_value());
  EXPECT_EQ(v->raw, 0xF9Cu);
  EXPECT_NEAR(v->physical, -0.1, 1e-12);
  // 0x07FF: the largest positive value, 2047 · 0.001.
  EXPECT_NEAR(*decodeSignal(signalOf(db, "SPEED", "ACCEL_X"), frameOf(180, {0x07, 0xFF, 0, 0, 0, 0, 0, 0})), 2.047,
              1e-12);
}

TEST(DbcDecode, IntelSignedAndUnsignedAcrossBytes) {
  const DbcDatabase db = loadVehicle();
  // STEER frame D0 B7 BF 00 …
  // STEER_ANGLE 0|12@1+ (1.5,-1500): bits 0…11 = byte 0 (low 8 bits) + byte 1 bits 0…3 (high 4):
  //   raw = 0x7 · 256 + 0xD0 = 0x7D0 = 2000 → 2000 · 1.5 − 1500 = 1500 deg (the range's max).
  // YAW_RATE 12|10@1- (0.1,0): bits 12…21 = byte 1 bits 4…7 (value bits 0…3) + byte 2 bits 0…5
  //   (value bits 4…9): raw = (0xBF & 0x3F) · 16 + (0xB7 >> 4) = 0x3F0 + 0xB = 0x3FB = 1019;
  //   top bit set → 1019 − 1024 = −5 → −0.5 deg/s.
  const CanFrame f = frameOf(37, {0xD0, 0xB7, 0xBF, 0, 0, 0, 0, 0});
  const std::optional<DbcValue> angle = decodeSignalValue(signalOf(db, "STEER", "STEER_ANGLE"), f);
  ASSERT_TRUE(angle.has_value());
  EXPECT_EQ(angle->raw, 2000u);
  EXPECT_DOUBLE_EQ(angle->physical, 1500.0);
  EXPECT_FALSE(angle->out_of_range);
  const std::optional<DbcValue> yaw = decodeSignalValue(signalOf(db, "STEER", "YAW_RATE"), f);
  ASSERT_TRUE(yaw.has_value());
  EXPECT_EQ(yaw->raw, 0x3FBu);
  EXPECT_NEAR(yaw->physical, -0.5, 1e-12);
}

TEST(DbcDecode, OutOfRangeIsReportedWhenARangeIsGiven) {
  const DbcDatabase db = loadVehicle();
  const DbcSignal& angle = signalOf(db, "STEER", "STEER_ANGLE");
  // raw 2001 (byte 0 = 0xD1) → 1501.5 deg > max 1500.
  const std::optional<DbcValue> v = decodeSignalValue(angle, frameOf(37, {0xD1, 0x07, 0, 0, 0, 0, 0, 0}));
  ASSERT_TRUE(v.has_value());
  EXPECT_DOUBLE_EQ(v->physical, 1501.5);
  EXPECT_TRUE(v->out_of_range);
  EXPECT_TRUE(isOutOfRange(angle, -1500.1));
  EXPECT_FALSE(isOutOfRange(angle, -1500.0));
  // SPEED's max 300 is raw 30200 · 0.01 − 2, computed with rounding: still inside.
  const DbcSignal& speed = signalOf(db, "SPEED", "SPEED");
  EXPECT_FALSE(decodeSignalValue(speed, frameOf(180, {0, 0, 0, 0, 0, 0x75, 0xF8, 0}))->out_of_range);  // 30200
  EXPECT_TRUE(decodeSignalValue(speed, frameOf(180, {0, 0, 0, 0, 0, 0x75, 0xF9, 0}))->out_of_range);   // 30201
  // AMBIENT_LIGHT has [0|0]: no range, never out of range.
  const DbcSignal& ambient = signalOf(db, "LAMP_STATUS", "AMBIENT_LIGHT");
  EXPECT_FALSE(ambient.hasRange());
  EXPECT_FALSE(isOutOfRange(ambient, 1e9));
}

TEST(DbcDecode, MultiplexedSignalsDecodeOnlyForTheirPage) {
  const DbcDatabase db = loadVehicle();
  const DbcSignal& page = signalOf(db, "LAMP_STATUS", "PAGE");
  const DbcSignal& leftLow = signalOf(db, "LAMP_STATUS", "LEFT_LOW_CURRENT");
  const DbcSignal& rightLow = signalOf(db, "LAMP_STATUS", "RIGHT_LOW_CURRENT");
  const DbcSignal& leftHigh = signalOf(db, "LAMP_STATUS", "LEFT_HIGH_CURRENT");
  const DbcSignal& ambient = signalOf(db, "LAMP_STATUS", "AMBIENT_LIGHT");
  EXPECT_EQ(page.mux_role, DbcMuxRole::Multiplexor);
  EXPECT_EQ(leftHigh.mux_role, DbcMuxRole::Multiplexed);
  EXPECT_EQ(leftHigh.mux_value, 1u);
  // PAGE 0|4@1+ = byte 0 low nibble. Page 0: LEFT_LOW 8|16@1+ = bytes 1–2 little-endian
  // 0x03E8 = 1000 → 1.000 A; RIGHT_LOW 24|16@1+ = bytes 3–4 0x07D0 = 2000 → 2.000 A;
  // AMBIENT 56|8 = byte 7 = 5 → 500 lx. The 0xF0 in byte 0 is outside PAGE and ignored.
  const CanFrame page0 = frameOf(1024, {0xF0, 0xE8, 0x03, 0xD0, 0x07, 0, 0, 0x05});
  EXPECT_EQ(decodeSignal(page, page0), 0.0);
  EXPECT_NEAR(*decodeSignal(leftLow, page0), 1.0, 1e-12);
  EXPECT_NEAR(*decodeSignal(rightLow, page0), 2.0, 1e-12);
  EXPECT_EQ(decodeSignal(leftHigh, page0), std::nullopt);
  EXPECT_EQ(decodeSignal(ambient, page0), 500.0);
  // Page 1: the same bytes 1–2 are LEFT_HIGH_CURRENT.
  const CanFrame page1 = frameOf(1024, {0x01, 0xE8, 0x03, 0xD0, 0x07, 0, 0, 0x05});
  EXPECT_EQ(decodeSignal(leftLow, page1), std::nullopt);
  EXPECT_EQ(decodeSignal(rightLow, page1), std::nullopt);
  EXPECT_NEAR(*decodeSignal(leftHigh, page1), 1.0, 1e-12);
  EXPECT_EQ(decodeSignal(ambient, page1), 500.0);
  // Page 2 selects none of them.
  const CanFrame page2 = frameOf(1024, {0x02, 0xE8, 0x03, 0xD0, 0x07, 0, 0, 0x05});
  EXPECT_EQ(decodeSignal(leftLow, page2), std::nullopt);
  EXPECT_EQ(decodeSignal(leftHigh, page2), std::nullopt);
}

TEST(DbcDecode, FloatSignalFromSigValtype) {
  const DbcDatabase db = loadVehicle();
  const DbcSignal& t = signalOf(db, "CABIN", "TEMPERATURE");
  EXPECT_EQ(t.value_type, DbcValueType::Float32);
  // 21.5f = 0x41AC0000 (sign 0, exponent 131 → 2^4, mantissa 1.34375: 16 · 1.34375 = 21.5),
  // little-endian bytes 00 00 AC 41.
  EXPECT_EQ(decodeSignal(t, frameOf(1025, {0x00, 0x00, 0xAC, 0x41, 0, 0, 0, 0})), 21.5);
  // −40.0f = 0xC2200000 (sign 1, exponent 132 → 2^5, mantissa 1.25).
  EXPECT_EQ(decodeSignal(t, frameOf(1025, {0x00, 0x00, 0x20, 0xC2, 0, 0, 0, 0})), -40.0);
}

TEST(DbcDecode, ShortFrameGivesNothing) {
  const DbcDatabase db = loadVehicle();
  // SPEED needs bytes 5 and 6 (7 bytes); ACCEL_X bytes 0 and 1.
  const CanFrame f = frameOf(180, {0xAF, 0x9C, 0, 0, 0, 0x12});
  EXPECT_EQ(decodeSignal(signalOf(db, "SPEED", "SPEED"), f), std::nullopt);
  EXPECT_TRUE(decodeSignal(signalOf(db, "SPEED", "ACCEL_X"), f).has_value());
  EXPECT_EQ(decodeSignal(signalOf(db, "SPEED", "ACCEL_X"), frameOf(180, {0xAF})), std::nullopt);
  // A multiplexed signal in a frame too short for its multiplexor.
  EXPECT_EQ(decodeSignal(signalOf(db, "LAMP_STATUS", "LEFT_LOW_CURRENT"), frameOf(1024, {})), std::nullopt);
}

// ---------------------------------------------------------------------------------------
// Bit layouts on inline signals.

TEST(DbcDecode, SixtyFourBitSignalsInBothOrders) {
  const CanFrame f = frameOf(100, {0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08});
  // Intel 0|64: byte 0 is the least significant → 0x0807060504030201.
  EXPECT_EQ(extractRaw(oneSignal("A : 0|64@1+ (1,0) [0|0] \"\" X").bits, f), 0x0807060504030201u);
  // Motorola 7|64: MSB = byte 0 bit 7 → byte 0 is the most significant → 0x0102030405060708.
  EXPECT_EQ(extractRaw(oneSignal("A : 7|64@0+ (1,0) [0|0] \"\" X").bits, f), 0x0102030405060708u);
  // Signed 64-bit all ones = −1; unsigned = 2^64 − 1.
  const CanFrame ones = frameOf(100, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF});
  EXPECT_EQ(decodeSignal(oneSignal("A : 0|64@1- (1,0) [0|0] \"\" X"), ones), -1.0);
  EXPECT_EQ(decodeSignal(oneSignal("A : 0|64@1+ (1,0) [0|0] \"\" X"), ones), 18446744073709551615.0);
}

TEST(DbcDecode, MotorolaOddStartCrossesIntoNextByte) {
  // 12|10@0+: MSB = byte 1 bit 4; value bits 9…5 = byte 1 bits 4…0, bits 4…0 = byte 2 bits 7…3.
  // Byte 1 = 0b0001'0110 → bits 4…0 = 10110; byte 2 = 0b1100'1111 → bits 7…3 = 11001:
  // raw = 0b10110'11001 = 729.
  const DbcSignal s = oneSignal("A : 12|10@0+ (1,0) [0|0] \"\" X");
  EXPECT_EQ(extractRaw(s.bits, frameOf(100, {0xFF, 0x16, 0xCF, 0, 0, 0, 0, 0})), 729u);
  // The same bits as signed: top bit (bit 9) set → 729 − 1024 = −295.
  const DbcSignal sSigned = oneSignal("A : 12|10@0- (1,0) [0|0] \"\" X");
  EXPECT_EQ(decodeSignal(sSigned, frameOf(100, {0xFF, 0x16, 0xCF, 0, 0, 0, 0, 0})), -295.0);
}

TEST(DbcDecode, SignExtensionAtEveryLength) {
  // A signed Intel field of length n holding all ones is −1, holding only its top bit is −2^(n−1).
  for (int n = 1; n <= 64; ++n) {
    const DbcSignal s = oneSignal("A : 0|" + std::to_string(n) + "@1- (1,0) [0|0] \"\" X");
    CanFrame allOnes = frameOf(100, {0, 0, 0, 0, 0, 0, 0, 0});
    CanFrame topOnly = allOnes;
    for (int b = 0; b < n; ++b) allOnes.data[static_cast<std::size_t>(b / 8)] |= static_cast<std::uint8_t>(1u << (b % 8));
    topOnly.data[static_cast<std::size_t>((n - 1) / 8)] |= static_cast<std::uint8_t>(1u << ((n - 1) % 8));
    EXPECT_EQ(decodeSignal(s, allOnes), -1.0) << "length " << n;
    EXPECT_EQ(decodeSignal(s, topOnly), -std::ldexp(1.0, n - 1)) << "length " << n;
  }
}

// Reference for the Motorola layout written the other way round: walk the sawtooth
// numbering from the MSB (bit b, then b−1, and from bit 0 of a byte to bit 7 of the next).
std::uint64_t motorolaBySawtooth(const CanFrame& f, int start, int length) {
  std::uint64_t raw = 0;
  int b = start;
  for (int i = 0; i < length; ++i) {
    raw = raw << 1 | ((unsigned{f.data[static_cast<std::size_t>(b / 8)]} >> (b % 8)) & 1u);
    b = b % 8 == 0 ? b + 15 : b - 1;
  }
  return raw;
}

TEST(DbcDecode, MotorolaMatchesSawtoothWalkOnRandomLayouts) {
  std::mt19937 rng(4242);
  for (int trial = 0; trial < 2000; ++trial) {
    CanFrame f = frameOf(100, {});
    f.len = 64;
    for (auto& byte : f.data) byte = static_cast<std::uint8_t>(rng());
    const int length = static_cast<int>(rng() % 64) + 1;
    const int start = static_cast<int>(rng() % 512);
    // Keep only layouts that end inside 64 bytes.
    const int msbLinear = start / 8 * 8 + 7 - start % 8;
    if (msbLinear + length > 512) continue;
    DbcBitField bits;
    bits.start_bit = static_cast<std::uint16_t>(start);
    bits.length = static_cast<std::uint8_t>(length);
    bits.order = DbcByteOrder::Motorola;
    EXPECT_EQ(extractRaw(bits, f), motorolaBySawtooth(f, start, length)) << start << "|" << length;
  }
}

TEST(DbcParse, IntelAndMotorolaSignalsFitSixtyFourByteMessages) {
  // The last bit of a 64-byte message: Intel 504|8 (byte 63), Motorola 511|8 (byte 63 MSB).
  const DbcSignal intel = oneSignal("A : 504|8@1+ (1,0) [0|0] \"\" X", 64);
  const DbcSignal motorola = oneSignal("A : 511|8@0+ (1,0) [0|0] \"\" X", 64);
  CanFrame f = frameOf(100, {});
  f.len = 64;
  f.fd = true;
  f.data[63] = 0x5A;
  EXPECT_EQ(decodeSignal(intel, f), 90.0);
  EXPECT_EQ(decodeSignal(motorola, f), 90.0);
  f.len = 48;
  EXPECT_EQ(decodeSignal(intel, f), std::nullopt);
}

TEST(DbcParse, AcceptsLooseSpacingAndNumberForms) {
  const std::string text =
      "BO_ 100 M : 8 X\n"
      " SG_ SEL M : 0|8@1+ (1,0) [0|0] \"\" X\n"
      "  SG_   SPD   m3  :  8|16@1- ( 1E-002 , +5 ) [ -10 | 1.5e2 ] \"km/h\"  A, B ,C\n";
  Result<DbcDatabase> db = parseDbc(text, "loose.dbc");
  ASSERT_TRUE(db.has_value()) << db.error().message;
  const DbcSignal& s = db->messages[0].signals[1];
  EXPECT_EQ(s.name, "SPD");
  EXPECT_EQ(s.mux_role, DbcMuxRole::Multiplexed);
  EXPECT_EQ(s.mux_value, 3u);
  EXPECT_EQ(s.multiplexor.start_bit, 0);
  EXPECT_EQ(s.multiplexor.length, 8);
  EXPECT_TRUE(s.bits.is_signed);
  EXPECT_DOUBLE_EQ(s.factor, 0.01);
  EXPECT_DOUBLE_EQ(s.offset, 5.0);
  EXPECT_DOUBLE_EQ(s.minimum, -10.0);
  EXPECT_DOUBLE_EQ(s.maximum, 150.0);
  ASSERT_EQ(s.receivers.size(), 3u);
  EXPECT_EQ(s.receivers[2], "C");
  // Selector 3, raw 0xFFFE = −2 → −2 · 0.01 + 5 = 4.98.
  EXPECT_NEAR(*decodeSignal(s, frameOf(100, {3, 0xFE, 0xFF})), 4.98, 1e-12);
}

TEST(DbcParse, AcceptsCrLfBomAndNoReceivers) {
  const std::string text =
      "\xEF\xBB\xBFVERSION \"1\"\r\n\r\nBO_ 200 A: 2 X\r\n SG_ S : 0|16@1+ (0.5,1) [0|0] \"\"\r\n";
  Result<DbcDatabase> db = parseDbc(text, "crlf.dbc");
  ASSERT_TRUE(db.has_value()) << db.error().message;
  ASSERT_EQ(db->messages.size(), 1u);
  const DbcSignal& s = db->messages[0].signals[0];
  EXPECT_TRUE(s.receivers.empty());
  EXPECT_EQ(decodeSignal(s, frameOf(200, {0x04, 0x00})), 3.0);  // 4 · 0.5 + 1
}

TEST(DbcParse, ReadsTheShapesGeneratorsWrite) {
  // Written in the style of opendbc's and CANdb++'s output: a CM_ before VERSION, value
  // tables, a message without signals, two blanks before the receiver, BO_TX_BU_, BA_DEF_
  // with two blanks, and a last VAL_ without its ';'.
  const std::string text =
      "CM_ \"IMPORT common.dbc\";\n"
      "VERSION \"\"\n\n\nNS_ :\n\tNS_DESC_\n\tCM_\n\tSG_MUL_VAL_\n\nBS_:\n\n"
      "BU_: BCM ECM NEO\n"
      "VAL_TABLE_ Beam 1 \"On\" 0 \"Off\" ;\n\n\n"
      "BO_ 320 BCMLights: 3 BCM\n"
      " SG_ HighBeam : 7|1@0+ (1,0) [0|1] \"\"  NEO\n"
      " SG_ Position : 5|1@0+ (1,0) [0|0] \"\"  NEO\n\n"
      "BO_ 328 EMPTY_148: 1 BCM\n\n"
      "BO_ 532 BRAKE: 6 XXX\n"
      " SG_ Pressure : 0|9@0+ (1,0) [0|511] \"\" XXX\n\n"
      "BO_TX_BU_ 320 : BCM,NEO;\n\n"
      "CM_ BU_ BCM \"Body Control Module\";\n"
      "BA_DEF_  \"BusType\" STRING ;\n"
      "BA_DEF_DEF_  \"BusType\" \"\";\n"
      "VAL_ 320 HighBeam 1 \"On\" 0 \"Off\"\n";
  Result<DbcDatabase> db = parseDbc(text, "style.dbc");
  ASSERT_TRUE(db.has_value()) << db.error().message;
  ASSERT_EQ(db->messages.size(), 3u);
  EXPECT_TRUE(db->findMessage(328, false)->signals.empty());
  // Pressure 0|9@0+: MSB = byte 0 bit 0, then byte 1 bits 7…0: raw = 1 · 256 + 0x2C = 300.
  const Result<const DbcSignal*> pressure = db->signal("BRAKE", "Pressure");
  ASSERT_TRUE(pressure.has_value());
  EXPECT_EQ(decodeSignal(**pressure, frameOf(532, {0x01, 0x2C, 0, 0, 0, 0})), 300.0);
  // HighBeam 7|1 = byte 0 bit 7.
  EXPECT_EQ(decodeSignal(**db->signal("BCMLights", "HighBeam"), frameOf(320, {0x80, 0, 0})), 1.0);
}

// ---------------------------------------------------------------------------------------
// Look-ups.

TEST(DbcLookup, MissingMessageListsMessages) {
  const DbcDatabase db = loadVehicle();
  const Result<const DbcSignal*> s = db.signal("LIGHTS", "LOW_BEAM");
  ASSERT_FALSE(s.has_value());
  EXPECT_EQ(s.error().message, kCanData +
                                   "/vehicle.dbc: no message 'LIGHTS'; messages: CABIN, HEADLAMP_LEVELING, "
                                   "LAMP_STATUS, LIGHT_STALK, SPEED, STEER");
}

TEST(DbcLookup, MissingSignalListsTheMessagesSignals) {
  const DbcDatabase db = loadVehicle();
  const Result<const DbcSignal*> s = db.signal("LIGHT_STALK", "FOG");
  ASSERT_FALSE(s.has_value());
  EXPECT_EQ(s.error().message, kCanData +
                                   "/vehicle.dbc: no signal 'FOG' in message 'LIGHT_STALK'; its signals: "
                                   "AUTO_HIGH_BEAM, FRONT_FOG, PARKING_LIGHT, LOW_BEAM, HIGH_BEAM");
  const Result<const DbcMessage*> m = db.message("SPEED");
  ASSERT_TRUE(m.has_value());
  EXPECT_EQ((*m)->id, 180u);
}

// ---------------------------------------------------------------------------------------
// Errors: file, line, what was expected, what was found.

TEST(DbcErrors, FixtureFilesNameFileAndLine) {
  struct Case {
    const char* file;
    const char* message;
  };
  const Case cases[] = {
      {"bad_byte_order.dbc",
       ":9: expected the byte order '1' (Intel, little-endian) or '0' (Motorola, big-endian), found '2+'"},
      {"bad_two_multiplexors.dbc",
       ":5: expected at most one multiplexor (M) in message 'LAMP_STATUS', found 'SUBPAGE' after 'PAGE' (line 4); "
       "several multiplexors (extended multiplexing) are not supported"},
      {"bad_extended_mux.dbc",
       ":7: extended multiplexing (SG_MUL_VAL_) is not supported; expected at most one multiplexor (M) per message "
       "with signals selected by m<N>"},
      {"bad_unterminated_comment.dbc",
       ":6: expected the closing '\"' of the string opened on this line, found the end of the file"},
  };
  for (const Case& c : cases) {
    const std::string path = kCanData + "/" + c.file;
    const Result<DbcDatabase> db = loadDbc(path);
    ASSERT_FALSE(db.has_value()) << c.file;
    EXPECT_EQ(db.error().message, path + c.message);
  }
}

TEST(DbcErrors, MissingFileNamesThePath) {
  const Result<DbcDatabase> db = loadDbc(kCanData + "/no_such.dbc");
  ASSERT_FALSE(db.has_value());
  EXPECT_EQ(db.error().message.rfind(kCanData + "/no_such.dbc: cannot open", 0), 0u) << db.error().message;
}

TEST(DbcErrors, MessageLines) {
  EXPECT_EQ(parseError("\nBO_ x A: 8 X\n"), "bad.dbc:2: expected a message id (an integer from 0 to 4294967295), found 'x'");
  EXPECT_EQ(parseError("BO_ 100 : 8 X\n"), "bad.dbc:1: expected a message name, found ':'");
  EXPECT_EQ(parseError("BO_ 100 A 8 X\n"), "bad.dbc:1: expected ':' after the message name, found '8'");
  EXPECT_EQ(parseError("BO_ 100 A: 65 X\n"),
            "bad.dbc:1: expected the message size in bytes (an integer from 0 to 64), found '65'");
  EXPECT_EQ(parseError("BO_ 100 A: 8\n"),
            "bad.dbc:1: expected the transmitting node (Vector__XXX for none), found the end of the line");
  EXPECT_EQ(parseError("BO_ 100 A: 8 X Y\n"), "bad.dbc:1: expected the end of the BO_ line, found 'Y'");
  EXPECT_EQ(parseError("BO_ 2048 A: 8 X\n"),
            "bad.dbc:1: expected a standard id ≤ 2047 (an extended id is written with bit 31 set, i.e. 2147483648 + "
            "id), found 2048");
  EXPECT_EQ(parseError("BO_ 3221225473 A: 8 X\n"),
            "bad.dbc:1: expected an extended id (bit 31 set) of at most 29 bits (≤ 2147483648 + 536870911), found "
            "3221225473");
  EXPECT_EQ(parseError("BO_ 1 A: 8 X\nBO_ 2 A: 8 X\n"),
            "bad.dbc:2: expected a unique message name, found 'A' again (first defined on line 1)");
  EXPECT_EQ(parseError("BO_ 1 A: 8 X\nBO_ 1 B: 8 X\n"),
            "bad.dbc:2: expected a unique message id, found 1 again (first defined on line 1 as 'A')");
}

TEST(DbcErrors, SignalLines) {
  const std::string bo = "BO_ 100 M: 8 X\n";
  const auto err = [&](const std::string& sg) { return parseError(bo + " SG_ " + sg + "\n"); };
  EXPECT_EQ(err(": 0|8@1+ (1,0) [0|0] \"\" X"), "bad.dbc:2: expected a signal name, found ':'");
  EXPECT_EQ(err("S 0|8@1+ (1,0) [0|0] \"\" X"), "bad.dbc:2: expected ':' after the signal name, found '0'");
  EXPECT_EQ(err("S x : 0|8@1+ (1,0) [0|0] \"\" X"),
            "bad.dbc:2: expected ':' or a multiplexer indicator 'M' or 'm<N>' after the signal name, found 'x'");
  EXPECT_EQ(err("S m1M : 0|8@1+ (1,0) [0|0] \"\" X"),
            "bad.dbc:2: extended multiplexing (signal 'S' is multiplexed and a multiplexor, 'm1M') is not "
            "supported; expected 'M' or 'm<N>'");
  EXPECT_EQ(err("S m1x : 0|8@1+ (1,0) [0|0] \"\" X"),
            "bad.dbc:2: expected a multiplexer indicator 'M' or 'm<N>' (N a decimal integer), found 'm1x'");
  EXPECT_EQ(err("S : 512|8@1+ (1,0) [0|0] \"\" X"),
            "bad.dbc:2: expected the start bit (an integer from 0 to 511), found '512'");
  EXPECT_EQ(err("S : 0 8@1+ (1,0) [0|0] \"\" X"), "bad.dbc:2: expected '|' between start bit and length, found '8'");
  EXPECT_EQ(err("S : 0|0@1+ (1,0) [0|0] \"\" X"), "bad.dbc:2: expected a signal length from 1 to 64 bits, found 0");
  EXPECT_EQ(err("S : 0|65@1+ (1,0) [0|0] \"\" X"),
            "bad.dbc:2: expected the signal length in bits (an integer from 0 to 64), found '65'");
  EXPECT_EQ(err("S : 0|8 1+ (1,0) [0|0] \"\" X"), "bad.dbc:2: expected '@' before the byte order, found '1+'");
  EXPECT_EQ(err("S : 0|8@1 (1,0) [0|0] \"\" X"),
            "bad.dbc:2: expected the value type '+' (unsigned) or '-' (signed), found '('");
  EXPECT_EQ(err("S : 0|8@1+ 1,0) [0|0] \"\" X"), "bad.dbc:2: expected '(' before the factor, found '1'");
  EXPECT_EQ(err("S : 0|8@1+ (abc,0) [0|0] \"\" X"), "bad.dbc:2: expected the factor (a finite number), found 'abc'");
  EXPECT_EQ(err("S : 0|8@1+ (1 0) [0|0] \"\" X"), "bad.dbc:2: expected ',' between factor and offset, found '0'");
  EXPECT_EQ(err("S : 0|8@1+ (1,inf) [0|0] \"\" X"), "bad.dbc:2: expected the offset (a finite number), found 'inf'");
  EXPECT_EQ(err("S : 0|8@1+ (1,0 [0|0] \"\" X"), "bad.dbc:2: expected ')' after the offset, found '['");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) 0|0] \"\" X"), "bad.dbc:2: expected '[' before the minimum, found '0'");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) [|0] \"\" X"), "bad.dbc:2: expected the minimum (a finite number), found '|'");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) [0,0] \"\" X"), "bad.dbc:2: expected '|' between minimum and maximum, found ','");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) [0|] \"\" X"), "bad.dbc:2: expected the maximum (a finite number), found ']'");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) [0|0 \"\" X"), "bad.dbc:2: expected ']' after the maximum, found '\"'");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) [0|0] km X"), "bad.dbc:2: expected the unit (a quoted string), found 'km'");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) [0|0] \"km X"), "bad.dbc:2: expected the closing '\"' of the unit, found the end of the line");
  EXPECT_EQ(err("S : 0|8@1+ (1,0) [0|0] \"\" X,,"), "bad.dbc:2: expected a receiving node name, found ','");
}

TEST(DbcErrors, SignalMustFitItsMessage) {
  EXPECT_EQ(parseError("BO_ 100 M: 2 X\n SG_ S : 8|16@1+ (1,0) [0|0] \"\" X\n"),
            "bad.dbc:2: expected signal 'S' (8|16@1) to fit in message 'M' of 2 bytes, found it needs 3 bytes");
  // Motorola 7|16 uses bytes 0 and 1; 0|16 runs from byte 0 bit 0 into byte 1 and byte 2.
  EXPECT_EQ(parseError("BO_ 100 M: 2 X\n SG_ S : 0|16@0+ (1,0) [0|0] \"\" X\n"),
            "bad.dbc:2: expected signal 'S' (0|16@0) to fit in message 'M' of 2 bytes, found it needs 3 bytes");
  EXPECT_EQ(parseError("BO_ 100 M: 64 X\n SG_ S : 500|16@1+ (1,0) [0|0] \"\" X\n"),
            "bad.dbc:2: expected start bit + length ≤ 512 (64 bytes), found 500 + 16");
  EXPECT_EQ(parseError("BO_ 100 M: 64 X\n SG_ S : 505|16@0+ (1,0) [0|0] \"\" X\n"),
            "bad.dbc:2: expected a Motorola signal that ends within 64 bytes, found start bit 505 (MSB) with length 16");
}

TEST(DbcErrors, StructureAndMultiplexing) {
  EXPECT_EQ(parseError("VERSION \"\"\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n"),
            "bad.dbc:2: expected SG_ to follow a BO_ line or another SG_ line of its message, found it after other "
            "statements");
  EXPECT_EQ(parseError("BO_ 100 M: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ S : 8|8@1+ (1,0) [0|0] \"\" X\n"),
            "bad.dbc:3: expected a unique signal name in message 'M', found 'S' again (first defined on line 2)");
  EXPECT_EQ(parseError("BO_ 100 M: 8 X\n SG_ A m2 : 0|8@1+ (1,0) [0|0] \"\" X\n\nCM_ \"x\";\n"),
            "bad.dbc:2: expected a multiplexor signal (M) in message 'M' for the multiplexed signal 'A', found none");
  EXPECT_EQ(parseError("BO_ 100 M: 8 X\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" X\nSIG_VALTYPE_ 100 B : 1;\n"),
            "bad.dbc:3: expected SIG_VALTYPE_ to name a signal defined by BO_/SG_, found message id 100 signal 'B'");
  EXPECT_EQ(parseError("BO_ 100 M: 8 X\n SG_ A : 0|16@1+ (1,0) [0|0] \"\" X\nSIG_VALTYPE_ 100 A : 2;\n"),
            "bad.dbc:3: expected signal 'A' to be 64 bits long for SIG_VALTYPE_ 2 (double), found 16 bits");
  EXPECT_EQ(parseError("SIG_VALTYPE_ 100 A : 3;\n"),
            "bad.dbc:1: expected the value type 0 (integer), 1 (float) or 2 (double) (an integer from 0 to 2), found "
            "'3'");
  EXPECT_EQ(parseError("CM_ \"unterminated\n\n"),
            "bad.dbc:1: expected the closing '\"' of the string opened on this line, found the end of the file");
}

TEST(DbcErrors, GarbageNeverCrashes) {
  // Random text built from DBC's own vocabulary: parsing must fail or succeed cleanly, and a
  // database that parses must decode any frame without reading out of bounds.
  const char* pieces[] = {"BO_ ", "SG_ ", " M ", " m1 ", "m", ":", "|", "@", "0", "1", "+", "-", "(", ")", ",",
                          "[", "]", "\"", "\n", " ", "7", "64", "511", "8", "A", "B", "NS_ :\n", "CM_ ", ";",
                          "2147483648", "SIG_VALTYPE_ ", "\\", "\t", "3221225472", "1E5"};
  std::mt19937 rng(20240601);
  CanFrame f = frameOf(0, {});
  f.len = 64;
  for (auto& b : f.data) b = static_cast<std::uint8_t>(rng());
  int parsed = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    std::string text;
    const std::size_t n = rng() % 40;
    for (std::size_t i = 0; i < n; ++i) text += pieces[rng() % std::size(pieces)];
    const Result<DbcDatabase> db = parseDbc(text, "fuzz.dbc");
    if (!db) {
      EXPECT_EQ(db.error().message.rfind("fuzz.dbc:", 0), 0u) << db.error().message;
      continue;
    }
    ++parsed;
    for (const DbcMessage& m : db->messages)
      for (const DbcSignal& s : m.signals) (void)decodeSignalValue(s, f);
  }
  EXPECT_GT(parsed, 0);
}

// ---------------------------------------------------------------------------------------
// Encoding: insertRaw / encodeSignalValue / encodeSignal, checked against hand-worked bytes,
// an independent bit walk and the decoder.

// The (byte, bit) positions of a field, most significant value bit first, walked the way the
// DBC documentation describes it (Intel: start is the LSB, upward; Motorola: start is the MSB,
// sawtooth downward) — independent of extractRaw's linear-index arithmetic.
std::vector<std::pair<std::size_t, unsigned>> fieldPositionsMsbFirst(const DbcBitField& bits) {
  std::vector<std::pair<std::size_t, unsigned>> out;
  int b = bits.start_bit;
  for (int i = 0; i < bits.length; ++i) {
    out.emplace_back(static_cast<std::size_t>(b / 8), static_cast<unsigned>(b % 8));
    if (bits.order == DbcByteOrder::Intel)
      ++b;
    else
      b = b % 8 == 0 ? b + 15 : b - 1;
  }
  if (bits.order == DbcByteOrder::Intel) std::reverse(out.begin(), out.end());
  return out;
}

TEST(DbcEncode, InsertRawHandWorkedBytes) {
  const DbcDatabase db = loadVehicle();
  // LOW_BEAM 29|1@0+ = byte 3 bit 5; HIGH_BEAM 30 = byte 3 bit 6.
  CanFrame stalk = frameOf(1570, {0, 0, 0, 0, 0, 0, 0, 0});
  ASSERT_TRUE(insertRaw(signalOf(db, "LIGHT_STALK", "LOW_BEAM").bits, 1, stalk));
  ASSERT_TRUE(insertRaw(signalOf(db, "LIGHT_STALK", "HIGH_BEAM").bits, 1, stalk));
  EXPECT_EQ(stalk, frameOf(1570, {0, 0, 0, 0x60, 0, 0, 0, 0}));
  ASSERT_TRUE(insertRaw(signalOf(db, "LIGHT_STALK", "LOW_BEAM").bits, 0, stalk));  // clears only its bit
  EXPECT_EQ(stalk, frameOf(1570, {0, 0, 0, 0x40, 0, 0, 0, 0}));
  // SPEED 47|16@0+: 72 km/h → (72 + 2) / 0.01 = 7400 = 0x1CE8, big-endian in bytes 5–6.
  CanFrame speed = frameOf(180, {0, 0, 0, 0, 0, 0, 0, 0});
  const Result<std::uint64_t> raw = encodeSignalValue(signalOf(db, "SPEED", "SPEED"), 72.0);
  ASSERT_TRUE(raw) << raw.error().message;
  EXPECT_EQ(*raw, 7400u);
  ASSERT_TRUE(insertRaw(signalOf(db, "SPEED", "SPEED").bits, *raw, speed));
  EXPECT_EQ(speed, frameOf(180, {0, 0, 0, 0, 0, 0x1C, 0xE8, 0}));
  // Motorola 12|10 = 729 = 0b10110'11001: byte 1 bits 4…0 = 10110, byte 2 bits 7…3 = 11001;
  // the other bits of bytes 1 and 2 (all ones here) are kept.
  CanFrame odd = frameOf(100, {0xFF, 0xFF, 0xFF, 0, 0, 0, 0, 0});
  ASSERT_TRUE(insertRaw(oneSignal("A : 12|10@0+ (1,0) [0|0] \"\" X").bits, 729, odd));
  EXPECT_EQ(odd, frameOf(100, {0xFF, 0xF6, 0xCF, 0, 0, 0, 0, 0}));
  // Intel 12|10 = 0x2D9: bits 12–15 of byte 1 = 0x9 (low nibble of value), byte 2 = 0x2D.
  CanFrame intel = frameOf(100, {0, 0, 0, 0, 0, 0, 0, 0});
  ASSERT_TRUE(insertRaw(oneSignal("A : 12|10@1+ (1,0) [0|0] \"\" X").bits, 0x2D9, intel));
  EXPECT_EQ(intel, frameOf(100, {0, 0x90, 0x2D, 0, 0, 0, 0, 0}));
  // Bits of raw above the field are ignored.
  CanFrame masked = frameOf(100, {0, 0});
  ASSERT_TRUE(insertRaw(oneSignal("A : 4|4@1+ (1,0) [0|0] \"\" X").bits, 0xFFA, masked));
  EXPECT_EQ(masked, frameOf(100, {0xA0, 0}));
}

TEST(DbcEncode, InsertRawRefusesFramesTooShortAndLeavesThemAlone) {
  const DbcDatabase db = loadVehicle();
  CanFrame f = frameOf(180, {1, 2, 3, 4, 5, 6});  // SPEED needs 7 bytes
  const CanFrame before = f;
  EXPECT_FALSE(insertRaw(signalOf(db, "SPEED", "SPEED").bits, 0xFFFF, f));
  EXPECT_EQ(f, before);
  DbcBitField zero;
  zero.length = 0;
  EXPECT_FALSE(insertRaw(zero, 1, f));
  EXPECT_EQ(f, before);
  // The frame is not lengthened either.
  const Status s = encodeSignal(signalOf(db, "SPEED", "SPEED"), 10.0, f);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("SPEED"), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("7 bytes"), std::string::npos) << s.error().message;
  EXPECT_EQ(f, before);
}

TEST(DbcEncode, InsertRawInvertsExtractRawOnRandomLayouts) {
  std::mt19937_64 rng(777);
  int checked = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    CanFrame f = frameOf(100, {});
    f.len = 64;
    for (auto& byte : f.data) byte = static_cast<std::uint8_t>(rng());
    DbcBitField bits;
    bits.length = static_cast<std::uint8_t>(rng() % 64 + 1);
    bits.start_bit = static_cast<std::uint16_t>(rng() % 512);
    bits.order = rng() % 2 == 0 ? DbcByteOrder::Intel : DbcByteOrder::Motorola;
    const int start = bits.start_bit;
    const int lastLinear = bits.order == DbcByteOrder::Intel ? start + bits.length - 1
                                                             : start / 8 * 8 + 7 - start % 8 + bits.length - 1;
    if (lastLinear >= 512) continue;
    const std::uint64_t raw = rng();
    const std::uint64_t mask = bits.length == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << bits.length) - 1;
    const CanFrame before = f;
    ASSERT_TRUE(insertRaw(bits, raw, f)) << start << "|" << int{bits.length};
    EXPECT_EQ(extractRaw(bits, f), raw & mask) << start << "|" << int{bits.length};
    // Each field bit holds its value bit; every other bit of the frame is as before.
    CanFrame expected = before;
    const auto positions = fieldPositionsMsbFirst(bits);
    for (std::size_t i = 0; i < positions.size(); ++i) {
      const auto [byte, bit] = positions[i];
      const auto m = static_cast<std::uint8_t>(1u << bit);
      if (((raw >> (positions.size() - 1 - i)) & 1u) != 0)
        expected.data[byte] = static_cast<std::uint8_t>(expected.data[byte] | m);
      else
        expected.data[byte] = static_cast<std::uint8_t>(expected.data[byte] & ~m);
    }
    ASSERT_EQ(f, expected) << (bits.order == DbcByteOrder::Intel ? "Intel " : "Motorola ") << start << "|"
                           << int{bits.length};
    ++checked;
  }
  EXPECT_GT(checked, 1000);
}

TEST(DbcEncode, PhysicalValuesRoundTripThroughTheDecoder) {
  // Both orders, signed and unsigned, odd starts and lengths crossing bytes, factors (also
  // negative and fractional) and offsets, 1 and 64 bits.
  const std::vector<std::string> layouts{
      "A : 0|1@1+ (1,0) [0|0] \"\" X",           "A : 7|1@0+ (1,0) [0|0] \"\" X",
      "A : 3|12@0- (0.001,0) [0|0] \"g\" X",     "A : 47|16@0+ (0.01,-2) [0|0] \"km/h\" X",
      "A : 12|10@1- (0.1,0) [0|0] \"\" X",       "A : 13|11@0+ (0.5,-100) [0|0] \"\" X",
      "A : 5|19@1- (0.25,3) [0|0] \"\" X",       "A : 29|23@0- (-2,1) [0|0] \"\" X",
      "A : 0|64@1- (1,0) [0|0] \"\" X",          "A : 7|64@0+ (1,0) [0|0] \"\" X",
      "A : 9|33@1+ (1e-3,-5) [0|0] \"\" X",      "A : 60|3@0- (1,0) [0|0] \"\" X"};
  std::mt19937_64 rng(99);
  for (const std::string& sg : layouts) {
    const DbcSignal s = oneSignal(sg);
    const int n = s.bits.length;
    const std::uint64_t mask = n == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << n) - 1;
    // Extremes and random raws; each decodes to a physical value that must encode back to it.
    std::vector<std::uint64_t> raws{0, 1, mask, mask >> 1, (mask >> 1) + 1};
    for (int i = 0; i < 200; ++i) raws.push_back(rng() & mask);
    for (const std::uint64_t r : raws) {
      CanFrame src = frameOf(100, {0, 0, 0, 0, 0, 0, 0, 0});
      ASSERT_TRUE(insertRaw(s.bits, r, src));
      const std::optional<double> physical = decodeSignal(s, src);
      ASSERT_TRUE(physical.has_value());
      // Above 2^53 a double cannot hold every integer: compare the decoded values instead.
      CanFrame out = frameOf(100, {0xA5, 0xA5, 0xA5, 0xA5, 0xA5, 0xA5, 0xA5, 0xA5});
      const Status st = encodeSignal(s, *physical, out);
      ASSERT_TRUE(st) << sg << " raw " << r << ": " << st.error().message;
      EXPECT_EQ(decodeSignal(s, out), physical) << sg << " raw " << r;
      if (n <= 52) {
        EXPECT_EQ(extractRaw(s.bits, out), r) << sg;
        EXPECT_EQ(encodeSignalValue(s, *physical).value(), r) << sg;
      }
    }
  }
}

TEST(DbcEncode, RoundsToTheNearestRawCount) {
  const DbcSignal s = oneSignal("A : 0|8@1+ (0.5,0) [0|0] \"\" X");
  EXPECT_EQ(encodeSignalValue(s, 10.2).value(), 20u);   // 20.4 → 20
  EXPECT_EQ(encodeSignalValue(s, 10.3).value(), 21u);   // 20.6 → 21
  EXPECT_EQ(encodeSignalValue(s, 10.25).value(), 21u);  // 20.5: halves away from zero
  const DbcSignal sig = oneSignal("A : 0|8@1- (1,0) [0|0] \"\" X");
  EXPECT_EQ(encodeSignalValue(sig, -1.4).value(), 0xFFu);  // −1, two's complement in 8 bits
  EXPECT_EQ(encodeSignalValue(sig, -2.5).value(), 0xFDu);  // −3
}

TEST(DbcEncode, ValuesTheFieldCannotHoldAreErrors) {
  auto fails = [](const DbcSignal& s, double v) {
    const Result<std::uint64_t> r = encodeSignalValue(s, v);
    EXPECT_FALSE(r.has_value()) << s.name << " " << v << " gave " << (r ? *r : 0);
    return r ? std::string() : r.error().message;
  };
  const DbcSignal u8 = oneSignal("U8 : 0|8@1+ (1,0) [0|0] \"\" X");
  EXPECT_EQ(encodeSignalValue(u8, 255.0).value(), 255u);
  EXPECT_EQ(encodeSignalValue(u8, 0.0).value(), 0u);
  EXPECT_EQ(encodeSignalValue(u8, -0.4).value(), 0u);
  const std::string big = fails(u8, 256.0);
  EXPECT_NE(big.find("U8"), std::string::npos) << big;
  EXPECT_NE(big.find("256"), std::string::npos) << big;
  EXPECT_NE(big.find("0 to 255"), std::string::npos) << big;
  fails(u8, 255.5);  // rounds to 256
  fails(u8, -1.0);
  fails(u8, -0.5);  // rounds to −1
  const DbcSignal s8 = oneSignal("S8 : 0|8@1- (1,0) [0|0] \"\" X");
  EXPECT_EQ(encodeSignalValue(s8, 127.0).value(), 0x7Fu);
  EXPECT_EQ(encodeSignalValue(s8, -128.0).value(), 0x80u);
  fails(s8, 128.0);
  const std::string neg = fails(s8, -129.0);
  EXPECT_NE(neg.find("-128 to 127"), std::string::npos) << neg;
  const DbcSignal one = oneSignal("B : 5|1@0- (1,0) [0|0] \"\" X");  // a signed bit: −1 or 0
  EXPECT_EQ(encodeSignalValue(one, -1.0).value(), 1u);
  fails(one, 1.0);
  // 64 bits: 2^64 − 1 is not a double and decodes as 2^64, which therefore encodes as the
  // largest value; the next double above is out. Signed likewise at 2^63.
  const DbcSignal u64 = oneSignal("U64 : 0|64@1+ (1,0) [0|0] \"\" X");
  EXPECT_EQ(encodeSignalValue(u64, std::ldexp(1.0, 63)).value(), std::uint64_t{1} << 63);
  EXPECT_EQ(encodeSignalValue(u64, std::ldexp(1.0, 64)).value(), ~std::uint64_t{0});
  fails(u64, std::nextafter(std::ldexp(1.0, 64), INFINITY));
  const DbcSignal s64 = oneSignal("S64 : 0|64@1- (1,0) [0|0] \"\" X");
  EXPECT_EQ(encodeSignalValue(s64, -std::ldexp(1.0, 63)).value(), std::uint64_t{1} << 63);
  EXPECT_EQ(encodeSignalValue(s64, std::ldexp(1.0, 63)).value(), ~std::uint64_t{0} >> 1);
  fails(s64, std::nextafter(std::ldexp(1.0, 63), INFINITY));
  fails(s64, std::nextafter(-std::ldexp(1.0, 63), -INFINITY));
  // Factor and offset apply before the check; the message gives the physical range and unit.
  const DbcDatabase db = loadVehicle();
  const std::string fast = fails(signalOf(db, "SPEED", "SPEED"), 700.0);
  EXPECT_NE(fast.find("'SPEED'"), std::string::npos) << fast;
  EXPECT_NE(fast.find("700 km/h"), std::string::npos) << fast;
  EXPECT_NE(fast.find("-2 to 653.35 km/h"), std::string::npos) << fast;
  fails(signalOf(db, "SPEED", "SPEED"), -2.01);
  // Not numbers, and a factor no raw value scales to.
  fails(u8, std::nan(""));
  fails(u8, INFINITY);
  fails(oneSignal("Z : 0|8@1+ (0,1) [0|0] \"\" X"), 1.0);
  // The DBC range is not the encoder's business (the decoder flags it): 20 A fits 16 bits.
  EXPECT_TRUE(encodeSignalValue(signalOf(db, "LAMP_STATUS", "LEFT_LOW_CURRENT"), 20.0).has_value());
}

TEST(DbcEncode, FloatSignalsByBitPattern) {
  const DbcDatabase db = loadVehicle();
  const DbcSignal& t = signalOf(db, "CABIN", "TEMPERATURE");
  EXPECT_EQ(encodeSignalValue(t, 21.5).value(), 0x41AC0000u);
  EXPECT_EQ(encodeSignalValue(t, -40.0).value(), 0xC2200000u);
  CanFrame f = frameOf(1025, {0, 0, 0, 0, 0, 0, 0, 0});
  ASSERT_TRUE(encodeSignal(t, 21.5, f));
  EXPECT_EQ(f, frameOf(1025, {0x00, 0x00, 0xAC, 0x41, 0, 0, 0, 0}));
  for (const double v : {0.0, -0.0, 1e-30, 3.25, -1234.5, 1e30}) {
    ASSERT_TRUE(encodeSignal(t, v, f));
    EXPECT_EQ(decodeSignal(t, f), static_cast<double>(static_cast<float>(v))) << v;
  }
  EXPECT_FALSE(encodeSignalValue(t, 1e39).has_value());  // beyond FLT_MAX
  EXPECT_FALSE(encodeSignalValue(t, std::nan("")).has_value());

  // A double, Motorola, with factor and offset: exact for values the scaling keeps exact.
  const std::string text =
      "BO_ 100 M: 8 X\n SG_ D : 7|64@0- (2,1) [0|0] \"\" X\nSIG_VALTYPE_ 100 D : 2;\n";
  const Result<DbcDatabase> d = parseDbc(text, "double.dbc");
  ASSERT_TRUE(d) << d.error().message;
  const DbcSignal& dbl = d->messages[0].signals[0];
  ASSERT_EQ(dbl.value_type, DbcValueType::Float64);
  // (3 − 1) / 2 = 1.0 = 0x3FF0000000000000, big-endian from byte 0.
  EXPECT_EQ(encodeSignalValue(dbl, 3.0).value(), 0x3FF0000000000000u);
  for (const double v : {3.0, -1e300, 0.1 * 2 + 1, 123456.789}) {
    CanFrame g = frameOf(100, {0, 0, 0, 0, 0, 0, 0, 0});
    ASSERT_TRUE(encodeSignal(dbl, v, g));
    EXPECT_DOUBLE_EQ(*decodeSignal(dbl, g), v);
  }
}

TEST(DbcEncode, MultiplexedSignalsSetTheirMultiplexor) {
  const DbcDatabase db = loadVehicle();
  const DbcSignal& page = signalOf(db, "LAMP_STATUS", "PAGE");
  const DbcSignal& leftLow = signalOf(db, "LAMP_STATUS", "LEFT_LOW_CURRENT");
  const DbcSignal& leftHigh = signalOf(db, "LAMP_STATUS", "LEFT_HIGH_CURRENT");
  const DbcSignal& ambient = signalOf(db, "LAMP_STATUS", "AMBIENT_LIGHT");
  // Start from page 0 with a high nibble in byte 0 that is not PAGE's and must survive.
  CanFrame f = frameOf(1024, {0xF0, 0, 0, 0, 0, 0, 0, 0});
  ASSERT_TRUE(encodeSignal(leftHigh, 1.5, f));
  EXPECT_EQ(f.data[0], 0xF1);  // PAGE = 1
  EXPECT_EQ(decodeSignal(page, f), 1.0);
  EXPECT_NEAR(*decodeSignal(leftHigh, f), 1.5, 1e-12);
  EXPECT_EQ(decodeSignal(leftLow, f), std::nullopt);
  ASSERT_TRUE(encodeSignal(ambient, 700.0, f));  // not multiplexed: PAGE unchanged
  EXPECT_EQ(decodeSignal(page, f), 1.0);
  EXPECT_EQ(decodeSignal(ambient, f), 700.0);
  ASSERT_TRUE(encodeSignal(leftLow, 2.25, f));  // back to page 0
  EXPECT_EQ(f.data[0], 0xF0);
  EXPECT_NEAR(*decodeSignal(leftLow, f), 2.25, 1e-12);
  EXPECT_EQ(decodeSignal(leftHigh, f), std::nullopt);
  // Setting the multiplexor directly works too; encoding a value it cannot hold does not
  // touch the frame.
  ASSERT_TRUE(encodeSignal(page, 1.0, f));
  EXPECT_EQ(decodeSignal(page, f), 1.0);
  const CanFrame before = f;
  EXPECT_FALSE(encodeSignal(leftLow, 70.0, f));  // 70000 counts > 16 bits
  EXPECT_EQ(f, before);
}

}  // namespace
}  // namespace fogbeam::ipc
