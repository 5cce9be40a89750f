// fogbeam — the cannelloni CAN-over-UDP tunnel format (github.com/mguentner/cannelloni,
// doc/udp_format.md "cannelloni UDP/SCTP Format version 2"; parser.cpp, cannelloni.h).
//
// One datagram, everything big-endian (network byte order):
//   header   u8 version (2) | u8 op code (0 = DATA) | u8 sequence number | u16 frame count
//   frames   count × { u32 can_id | u8 len | [u8 flags] | data }
//     can_id  SocketCAN's canid_t: id | EFF 0x80000000 | RTR 0x40000000 | ERR 0x20000000
//     len     payload bytes; bit 0x80 set marks a CAN FD frame, whose `flags` byte (canfd_frame
//             flags: 0x01 BRS, 0x02 ESI, 0x04 FDF) follows; classic frames have no flags byte
//     data    len & 0x7F bytes, absent for remote (RTR) frames, where len is the requested
//             length
// A UDP datagram holds whole frames only; cannelloni itself packs frames until its buffer
// (MTU) is full, so count frames are always followed by exactly their bytes.
//
// Decoding checks all of it and fails with a message naming the first problem: a truncated
// header or frame, fewer or more bytes than `count` frames need, an unknown version or op
// code, a classic length > 8, a CAN FD length > 64, a remote CAN FD frame, a standard id with
// bits above 11 set. Error frames (ERR flag) carry bus diagnostics, not data: they are
// skipped and counted. Flag bits in the FD flags byte other than BRS and ESI are ignored.
// CAN FD lengths are taken as sent (0–64), as cannelloni forwards them, even where they are
// not one of the bus lengths (isValidCanFdLength): a virtual CAN interface passes such
// frames on. Frames carry no time: CanFrame::timestamp_s is 0 and the receiver stamps them.
//
// Thread-safety: pure functions.
#pragma once

#include <fogbeam/ipc/can_frame.hpp>
#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace fogbeam::ipc {

inline constexpr std::uint8_t kCannelloniVersion = 2;  ///< CANNELLONI_FRAME_VERSION
inline constexpr std::uint8_t kCannelloniOpData = 0;   ///< op code DATA (ACK = 1, NACK = 2 are not data)
inline constexpr std::size_t kCannelloniHeaderSize = 5;

struct CannelloniPacket {
  std::uint8_t sequence = 0;  ///< the sender's packet counter, wraps at 256
  /// Data and remote frames in packet order (timestamp_s = 0).
  std::vector<CanFrame> frames;
  /// Error frames (ERR flag) that were in the packet and skipped; decode only, ignored by encode.
  std::size_t error_frames = 0;
};

/// Decodes one datagram. Never reads outside `bytes`; never throws on bad input.
[[nodiscard]] Result<CannelloniPacket> decodeCannelloni(std::span<const std::uint8_t> bytes);

/// Encodes `packet` as cannelloni version 2 DATA, e.g. for tests and the host stand-in.
/// Preconditions (a violation is a bug and aborts with a message): at most 65535 frames; each
/// frame's id fits its format (11 or 29 bits); len ≤ 8 for classic and remote frames, ≤ 64
/// for CAN FD; CAN FD frames are not remote. The caller keeps the result under the path's MTU.
[[nodiscard]] std::vector<std::uint8_t> encodeCannelloni(const CannelloniPacket& packet);

}  // namespace fogbeam::ipc
