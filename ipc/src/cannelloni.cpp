// fogbeam — cannelloni UDP format v2 decoder and encoder (layout and choices in
// cannelloni.hpp). Bytes are read one by one with explicit big-endian assembly and a length
// check before every read; nothing is cast to a struct.
#include <fogbeam/ipc/cannelloni.hpp>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace fogbeam::ipc {

namespace {

// SocketCAN can_id flag bits (<linux/can.h>).
constexpr std::uint32_t kEffFlag = 0x8000'0000u;
constexpr std::uint32_t kRtrFlag = 0x4000'0000u;
constexpr std::uint32_t kErrFlag = 0x2000'0000u;
// cannelloni marks a CAN FD frame with the top bit of `len` (CANFD_FRAME).
constexpr std::uint8_t kFdLenFlag = 0x80;
constexpr std::uint8_t kFdBrs = 0x01;  // CANFD_BRS
constexpr std::uint8_t kFdEsi = 0x02;  // CANFD_ESI
constexpr std::size_t kFrameBaseSize = 5;  // can_id + len

// Reads big-endian fields from a span; every read checks the length first.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> bytes) noexcept : bytes_(bytes) {}

  [[nodiscard]] std::size_t offset() const noexcept { return pos_; }
  [[nodiscard]] std::size_t remaining() const noexcept { return bytes_.size() - pos_; }

  std::uint8_t u8() noexcept { return bytes_[pos_++]; }
  std::uint16_t u16() noexcept {
    const auto v = static_cast<std::uint16_t>(bytes_[pos_] << 8 | bytes_[pos_ + 1]);
    pos_ += 2;
    return v;
  }
  std::uint32_t u32() noexcept {
    const std::uint32_t v = std::uint32_t{bytes_[pos_]} << 24 | std::uint32_t{bytes_[pos_ + 1]} << 16 |
                            std::uint32_t{bytes_[pos_ + 2]} << 8 | std::uint32_t{bytes_[pos_ + 3]};
    pos_ += 4;
    return v;
  }

 private:
  std::span<const std::uint8_t> bytes_;
  std::size_t pos_ = 0;
};

std::string hex32(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08X", static_cast<unsigned>(v));
  return buf;
}

Error bad(std::size_t frameIndex, std::size_t offset, const std::string& what) {
  return Error{"cannelloni frame " + std::to_string(frameIndex) + " at byte " + std::to_string(offset) + ": " + what};
}

[[noreturn]] void preconditionFailed(const char* what) {
  std::fprintf(stderr, "fogbeam: encodeCannelloni: %s\n", what);
  std::abort();
}

void put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  out.push_back(static_cast<std::uint8_t>(v >> 24));
  out.push_back(static_cast<std::uint8_t>(v >> 16));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
  out.push_back(static_cast<std::uint8_t>(v));
}

}  // namespace

Result<CannelloniPacket> decodeCannelloni(std::span<const std::uint8_t> bytes) {
  Reader r(bytes);
  if (r.remaining() < kCannelloniHeaderSize) {
    return Error{"cannelloni packet: expected a header of " + std::to_string(kCannelloniHeaderSize) +
                 " bytes, found " + std::to_string(bytes.size()) + " bytes"};
  }
  const std::uint8_t version = r.u8();
  const std::uint8_t opCode = r.u8();
  CannelloniPacket packet;
  packet.sequence = r.u8();
  const std::uint16_t count = r.u16();
  if (version != kCannelloniVersion) {
    return Error{"cannelloni packet: expected version " + std::to_string(kCannelloniVersion) + ", found version " +
                 std::to_string(version)};
  }
  if (opCode != kCannelloniOpData) {
    return Error{"cannelloni packet: expected op code 0 (DATA), found " + std::to_string(opCode) +
                 (opCode == 1 ? " (ACK)" : opCode == 2 ? " (NACK)" : "")};
  }
  // Each frame takes at least 5 bytes: a count that cannot fit is rejected before allocating.
  if (std::size_t{count} * kFrameBaseSize > r.remaining()) {
    return Error{"cannelloni packet: expected at least " + std::to_string(std::size_t{count} * kFrameBaseSize) +
                 " bytes for " + std::to_string(count) + " frames, found " + std::to_string(r.remaining())};
  }
  packet.frames.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t at = r.offset();
    if (r.remaining() < kFrameBaseSize) {
      return bad(i, at, "expected a frame header (can_id, len) of 5 bytes, found " + std::to_string(r.remaining()) +
                            " bytes (packet truncated)");
    }
    const std::uint32_t canId = r.u32();
    const std::uint8_t lenByte = r.u8();
    CanFrame f;
    f.fd = (lenByte & kFdLenFlag) != 0;
    const auto len = static_cast<std::uint8_t>(lenByte & ~kFdLenFlag);
    f.len = len;
    f.extended = (canId & kEffFlag) != 0;
    f.remote = (canId & kRtrFlag) != 0;
    const bool error = (canId & kErrFlag) != 0;
    f.id = canId & (f.extended ? kCanMaxExtendedId : ~(kEffFlag | kRtrFlag | kErrFlag));
    if (f.fd) {
      if (r.remaining() < 1) return bad(i, at, "expected the CAN FD flags byte, found the end of the packet");
      const std::uint8_t flags = r.u8();
      f.brs = (flags & kFdBrs) != 0;
      f.esi = (flags & kFdEsi) != 0;
      if (len > kCanFdMaxLen)
        return bad(i, at, "expected a CAN FD length of at most 64 bytes, found " + std::to_string(len));
      if (f.remote) return bad(i, at, "expected no RTR flag on a CAN FD frame (CAN FD has no remote frames)");
    } else if (len > kCanMaxLen) {
      return bad(i, at, "expected a classic CAN length of at most 8 bytes, found " + std::to_string(len));
    }
    if (!error && !f.extended && f.id > kCanMaxStandardId) {
      return bad(i, at, "expected a standard id of at most 0x7FF (or the EFF flag), found can_id " + hex32(canId));
    }
    // Remote frames carry no data section (cannelloni parser.cpp): len is the requested length.
    if (!f.remote) {
      if (r.remaining() < len) {
        return bad(i, at, "expected " + std::to_string(len) + " data bytes, found " + std::to_string(r.remaining()) +
                              " (packet truncated)");
      }
      for (std::size_t k = 0; k < len; ++k) f.data[k] = r.u8();
    }
    if (error) {
      ++packet.error_frames;
      continue;
    }
    packet.frames.push_back(f);
  }
  if (r.remaining() != 0) {
    return Error{"cannelloni packet: expected " + std::to_string(count) + " frames ending at byte " +
                 std::to_string(r.offset()) + ", found " + std::to_string(r.remaining()) +
                 " more bytes (frame count does not match the packet)"};
  }
  return packet;
}

std::vector<std::uint8_t> encodeCannelloni(const CannelloniPacket& packet) {
  if (packet.frames.size() > 0xFFFF) preconditionFailed("more than 65535 frames");
  std::vector<std::uint8_t> out;
  out.reserve(kCannelloniHeaderSize + packet.frames.size() * (kFrameBaseSize + 1 + kCanMaxLen));
  out.push_back(kCannelloniVersion);
  out.push_back(kCannelloniOpData);
  out.push_back(packet.sequence);
  out.push_back(static_cast<std::uint8_t>(packet.frames.size() >> 8));
  out.push_back(static_cast<std::uint8_t>(packet.frames.size()));
  for (const CanFrame& f : packet.frames) {
    if (f.id > (f.extended ? kCanMaxExtendedId : kCanMaxStandardId)) preconditionFailed("id too large for its format");
    if (f.len > (f.fd ? kCanFdMaxLen : kCanMaxLen)) preconditionFailed("frame length too large");
    if (f.fd && f.remote) preconditionFailed("remote CAN FD frame");
    put32(out, f.id | (f.extended ? kEffFlag : 0u) | (f.remote ? kRtrFlag : 0u));
    out.push_back(static_cast<std::uint8_t>(f.len | (f.fd ? kFdLenFlag : 0u)));
    if (f.fd) out.push_back(static_cast<std::uint8_t>((f.brs ? kFdBrs : 0u) | (f.esi ? kFdEsi : 0u)));
    if (!f.remote) out.insert(out.end(), f.data.begin(), f.data.begin() + f.len);
  }
  return out;
}

}  // namespace fogbeam::ipc
