// cannelloni UDP format v2: hand-built packets, round trips, every error, and garbage input.
#include <fogbeam/ipc/cannelloni.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace fogbeam::ipc {
namespace {

using Bytes = std::vector<std::uint8_t>;

std::string decodeError(const Bytes& bytes) {
  const Result<CannelloniPacket> p = decodeCannelloni(bytes);
  EXPECT_FALSE(p.has_value());
  return p ? std::string() : p.error().message;
}

TEST(CannelloniDecode, HandBuiltPacketWithEveryFrameKind) {
  // Header: version 2, op DATA (0), sequence 7, count 0x0004 (big-endian).
  // 1. classic 0x123, 3 bytes:      00 00 01 23 | 03 | AA BB CC
  // 2. extended 0x18FEF121, FD 12 B, BRS:  98 FE F1 21 (EFF 0x80000000 | id) | 8C (0x80 | 12) | 01 | 12 bytes
  // 3. remote 0x0B4, requested 4:   40 00 00 B4 (RTR 0x40000000 | id) | 04 | no data
  // 4. FD 0x400, 0 bytes, ESI:      00 00 04 00 | 80 | 02
  const Bytes bytes = {0x02, 0x00, 0x07, 0x00, 0x04,                                         //
                       0x00, 0x00, 0x01, 0x23, 0x03, 0xAA, 0xBB, 0xCC,                       //
                       0x98, 0xFE, 0xF1, 0x21, 0x8C, 0x01, 1,    2,    3, 4, 5, 6, 7, 8, 9, 10, 11, 12,  //
                       0x40, 0x00, 0x00, 0xB4, 0x04,                                         //
                       0x00, 0x00, 0x04, 0x00, 0x80, 0x02};
  const Result<CannelloniPacket> p = decodeCannelloni(bytes);
  ASSERT_TRUE(p.has_value()) << p.error().message;
  EXPECT_EQ(p->sequence, 7);
  EXPECT_EQ(p->error_frames, 0u);
  ASSERT_EQ(p->frames.size(), 4u);

  const CanFrame& a = p->frames[0];
  EXPECT_EQ(a.id, 0x123u);
  EXPECT_FALSE(a.extended || a.remote || a.fd);
  ASSERT_EQ(a.len, 3);
  EXPECT_EQ(a.data[0], 0xAA);
  EXPECT_EQ(a.data[2], 0xCC);
  EXPECT_EQ(a.data[3], 0);

  const CanFrame& b = p->frames[1];
  EXPECT_EQ(b.id, 0x18FEF121u);
  EXPECT_TRUE(b.extended);
  EXPECT_TRUE(b.fd);
  EXPECT_TRUE(b.brs);
  EXPECT_FALSE(b.esi);
  ASSERT_EQ(b.len, 12);
  EXPECT_EQ(b.data[0], 1);
  EXPECT_EQ(b.data[11], 12);

  const CanFrame& c = p->frames[2];
  EXPECT_EQ(c.id, 0xB4u);
  EXPECT_TRUE(c.remote);
  EXPECT_EQ(c.len, 4);
  EXPECT_EQ(c.data[0], 0);

  const CanFrame& d = p->frames[3];
  EXPECT_EQ(d.id, 0x400u);
  EXPECT_TRUE(d.fd);
  EXPECT_TRUE(d.esi);
  EXPECT_FALSE(d.brs);
  EXPECT_EQ(d.len, 0);
  EXPECT_EQ(d.timestamp_s, 0.0);

  // The encoder writes exactly these bytes back.
  EXPECT_EQ(encodeCannelloni(*p), bytes);
}

TEST(CannelloniDecode, EmptyPacketAndErrorFramesCounted) {
  const Result<CannelloniPacket> empty = decodeCannelloni(Bytes{0x02, 0x00, 0xFF, 0x00, 0x00});
  ASSERT_TRUE(empty.has_value()) << empty.error().message;
  EXPECT_EQ(empty->sequence, 0xFF);
  EXPECT_TRUE(empty->frames.empty());
  // An error frame (ERR 0x20000000, CAN_ERR_CRTL 0x004, 8 bytes) then a data frame: the error
  // frame is counted, not returned.
  const Bytes bytes = {0x02, 0x00, 0x01, 0x00, 0x02,                                           //
                       0x20, 0x00, 0x00, 0x04, 0x08, 0, 0, 0x08, 0, 0, 0, 0, 0,                //
                       0x00, 0x00, 0x06, 0x22, 0x01, 0x28};
  const Result<CannelloniPacket> p = decodeCannelloni(bytes);
  ASSERT_TRUE(p.has_value()) << p.error().message;
  EXPECT_EQ(p->error_frames, 1u);
  ASSERT_EQ(p->frames.size(), 1u);
  EXPECT_EQ(p->frames[0].id, 0x622u);
  EXPECT_EQ(p->frames[0].data[0], 0x28);
}

TEST(CannelloniDecode, FdFlagsByteIgnoresFdfAndUnknownBits) {
  // flags 0x07 = BRS | ESI | FDF (set by newer kernels); 0xF0 are not defined.
  const Result<CannelloniPacket> p =
      decodeCannelloni(Bytes{0x02, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x01, 0x23, 0x81, 0xF7, 0x55});
  ASSERT_TRUE(p.has_value()) << p.error().message;
  EXPECT_TRUE(p->frames[0].brs);
  EXPECT_TRUE(p->frames[0].esi);
  EXPECT_EQ(p->frames[0].len, 1);
}

TEST(CannelloniEncode, RoundTripsRandomPackets) {
  std::mt19937 rng(99);
  for (int trial = 0; trial < 500; ++trial) {
    CannelloniPacket packet;
    packet.sequence = static_cast<std::uint8_t>(rng());
    const std::size_t n = rng() % 20;
    for (std::size_t i = 0; i < n; ++i) {
      CanFrame f;
      f.extended = rng() % 2 == 0;
      f.id = static_cast<std::uint32_t>(rng()) & (f.extended ? kCanMaxExtendedId : kCanMaxStandardId);
      const auto kind = rng() % 3;  // classic, remote, FD
      f.remote = kind == 1;
      f.fd = kind == 2;
      if (f.fd) {
        f.brs = rng() % 2 == 0;
        f.esi = rng() % 2 == 0;
      }
      f.len = static_cast<std::uint8_t>(rng() % ((f.fd ? kCanFdMaxLen : kCanMaxLen) + 1));
      if (!f.remote)
        for (std::size_t k = 0; k < f.len; ++k) f.data[k] = static_cast<std::uint8_t>(rng());
      packet.frames.push_back(f);
    }
    const Bytes bytes = encodeCannelloni(packet);
    const Result<CannelloniPacket> back = decodeCannelloni(bytes);
    ASSERT_TRUE(back.has_value()) << back.error().message;
    EXPECT_EQ(back->sequence, packet.sequence);
    EXPECT_EQ(back->frames, packet.frames);
  }
}

TEST(CannelloniErrors, EveryMessage) {
  EXPECT_EQ(decodeError({}), "cannelloni packet: expected a header of 5 bytes, found 0 bytes");
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00}), "cannelloni packet: expected a header of 5 bytes, found 4 bytes");
  EXPECT_EQ(decodeError({0x01, 0x00, 0x00, 0x00, 0x00}), "cannelloni packet: expected version 2, found version 1");
  EXPECT_EQ(decodeError({0x02, 0x01, 0x00, 0x00, 0x00}), "cannelloni packet: expected op code 0 (DATA), found 1 (ACK)");
  EXPECT_EQ(decodeError({0x02, 0x02, 0x00, 0x00, 0x00}), "cannelloni packet: expected op code 0 (DATA), found 2 (NACK)");
  EXPECT_EQ(decodeError({0x02, 0x09, 0x00, 0x00, 0x00}), "cannelloni packet: expected op code 0 (DATA), found 9");
  // Count 0x0101 = 257 frames need at least 1285 bytes.
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x01, 0x01, 0, 0, 0, 0, 0}),
            "cannelloni packet: expected at least 1285 bytes for 257 frames, found 5");
  // Two frames counted, the second truncated inside its header (5 + 4 bytes present + 5 + 2).
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x02, 0, 0, 1, 0x23, 0x01, 0xAA, 0, 0, 1, 0x23}),
            "cannelloni frame 1 at byte 11: expected a frame header (can_id, len) of 5 bytes, found 4 bytes (packet "
            "truncated)");
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x01, 0, 0, 1, 0x23, 0x04, 0xAA, 0xBB}),
            "cannelloni frame 0 at byte 5: expected 4 data bytes, found 2 (packet truncated)");
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x01, 0, 0, 1, 0x23, 0x80}),
            "cannelloni frame 0 at byte 5: expected the CAN FD flags byte, found the end of the packet");
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x01, 0, 0, 1, 0x23, 0x09, 0, 0, 0, 0, 0, 0, 0, 0, 0}),
            "cannelloni frame 0 at byte 5: expected a classic CAN length of at most 8 bytes, found 9");
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x01, 0, 0, 1, 0x23, 0xC1, 0x00}),
            "cannelloni frame 0 at byte 5: expected a CAN FD length of at most 64 bytes, found 65");
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x01, 0x40, 0, 1, 0x23, 0x81, 0x00}),
            "cannelloni frame 0 at byte 5: expected no RTR flag on a CAN FD frame (CAN FD has no remote frames)");
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x01, 0, 0, 0x08, 0x00, 0x00}),
            "cannelloni frame 0 at byte 5: expected a standard id of at most 0x7FF (or the EFF flag), found can_id "
            "0x00000800");
  // One frame counted, but bytes for more follow.
  EXPECT_EQ(decodeError({0x02, 0x00, 0x00, 0x00, 0x01, 0, 0, 1, 0x23, 0x00, 0, 0, 1, 0x23, 0x00}),
            "cannelloni packet: expected 1 frames ending at byte 10, found 5 more bytes (frame count does not match "
            "the packet)");
}

TEST(CannelloniErrors, GarbageNeverCrashes) {
  // 20 000 inputs from a fixed seed: random bytes (with a valid header half the time, so the
  // frame parser is reached) and random byte edits of a valid packet. Every result is either a
  // clean error or a packet whose frames respect the format's limits.
  CannelloniPacket valid;
  valid.sequence = 3;
  CanFrame a;
  a.id = 0x123;
  a.len = 8;
  CanFrame b;
  b.id = 0x18FEF121;
  b.extended = true;
  b.fd = true;
  b.len = 20;
  valid.frames = {a, b, a};
  const Bytes base = encodeCannelloni(valid);
  std::mt19937 rng(12345);
  int accepted = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    Bytes bytes;
    if (trial % 2 == 0) {
      bytes.resize(rng() % 200);
      for (auto& x : bytes) x = static_cast<std::uint8_t>(rng());
      if (bytes.size() >= 5 && trial % 4 == 0) {
        bytes[0] = 2;
        bytes[1] = 0;
        bytes[3] = 0;
        bytes[4] = static_cast<std::uint8_t>(rng() % 8);
      }
    } else {
      bytes = base;
      const std::size_t edits = 1 + rng() % 4;
      for (std::size_t e = 0; e < edits; ++e) {
        switch (rng() % 3) {
          case 0: bytes[rng() % bytes.size()] = static_cast<std::uint8_t>(rng()); break;
          case 1: bytes.resize(rng() % (bytes.size() + 1)); break;
          default: bytes.push_back(static_cast<std::uint8_t>(rng())); break;
        }
        if (bytes.empty()) break;
      }
    }
    const Result<CannelloniPacket> p = decodeCannelloni(bytes);
    if (!p) {
      EXPECT_EQ(p.error().message.rfind("cannelloni ", 0), 0u) << p.error().message;
      continue;
    }
    ++accepted;
    for (const CanFrame& f : p->frames) {
      EXPECT_LE(f.id, f.extended ? kCanMaxExtendedId : kCanMaxStandardId);
      EXPECT_LE(f.len, f.fd ? kCanFdMaxLen : kCanMaxLen);
      EXPECT_FALSE(f.fd && f.remote);
    }
  }
  EXPECT_GT(accepted, 10);
}

}  // namespace
}  // namespace fogbeam::ipc
