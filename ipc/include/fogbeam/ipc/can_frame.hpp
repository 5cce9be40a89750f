// fogbeam — one CAN or CAN FD frame, as the CAN input codecs (candump logs, the cannelloni UDP
// tunnel) deliver it and as the DBC decoder reads it.
//
// The fields follow SocketCAN's `struct canfd_frame` (<linux/can.h>), with the flag bits that
// SocketCAN packs into `can_id` (EFF 0x80000000, RTR 0x40000000) and into `flags` (BRS 0x01,
// ESI 0x02) given as plain booleans, so no OS header is needed here. Error frames
// (CAN_ERR_FLAG) are not data and are never represented by a CanFrame.
//
// Thread-safety: a value type.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

namespace fogbeam::ipc {

/// Largest payload of a classic CAN 2.0 frame, bytes.
inline constexpr std::size_t kCanMaxLen = 8;
/// Largest payload of a CAN FD frame, bytes.
inline constexpr std::size_t kCanFdMaxLen = 64;
/// Largest standard (11-bit) identifier.
inline constexpr std::uint32_t kCanMaxStandardId = 0x7FF;
/// Largest extended (29-bit) identifier.
inline constexpr std::uint32_t kCanMaxExtendedId = 0x1FFF'FFFF;

/// True for the payload lengths a CAN FD frame can have on the bus: 0–8, 12, 16, 20, 24, 32,
/// 48, 64 bytes (the lengths the 4-bit DLC codes 0–15 stand for, ISO 11898-1:2015).
[[nodiscard]] constexpr bool isValidCanFdLength(std::size_t len) noexcept {
  return len <= 8 || len == 12 || len == 16 || len == 20 || len == 24 || len == 32 || len == 48 || len == 64;
}

struct CanFrame {
  /// Identifier without flag bits: 0–0x7FF for a standard frame, 0–0x1FFFFFFF when `extended`.
  std::uint32_t id = 0;
  bool extended = false;  ///< 29-bit identifier (SocketCAN CAN_EFF_FLAG)
  bool remote = false;    ///< remote transmission request: no data, `len` is the requested length
  bool fd = false;        ///< CAN FD frame (never `remote`)
  bool brs = false;       ///< CAN FD bit rate switch (CANFD_BRS); false for classic frames
  bool esi = false;       ///< CAN FD error state indicator (CANFD_ESI); false for classic frames
  /// Data length in bytes: ≤ 8 for classic frames, ≤ 64 for CAN FD. For a remote frame the
  /// requested length, with `data` all zero.
  std::uint8_t len = 0;
  /// Payload; bytes at index ≥ len are zero.
  std::array<std::uint8_t, kCanFdMaxLen> data{};
  /// Time the frame was seen, seconds. For candump logs the recorded time (seconds since the
  /// Unix epoch as candump writes it); 0 where the source carries no time (cannelloni).
  double timestamp_s = 0.0;

  friend bool operator==(const CanFrame&, const CanFrame&) = default;
};

}  // namespace fogbeam::ipc
