// fogbeam — the UDP input (protocol v1, docs/protocol.md): one thread that receives datagrams
// (unicast, or multicast so that one host feeds several image-generator machines), checks the
// sender against an optional allow-list, decodes and validates every datagram, drops stale and
// duplicate sequence numbers, and applies the rest to a StateStore.
//
// Every dropped datagram is counted by reason (UdpStats) and logged at most once per second per
// reason (spdlog, with the count since the last line); nothing from the network can stop or
// crash the thread. Memory per sender is bounded (at most kMaxSenders tracked).
//
// Sequence numbers: tracked per (sender, message type). A datagram whose number equals the
// newest one applied for its type is a Duplicate; an older one is OutOfOrder (a newer state of
// the same kind is already applied) unless it is more than `restart_window` behind, which means
// the sender restarted: it is applied and counted as a restart. Comparison is serial-number
// arithmetic (RFC 1982), so the 32-bit counter may wrap.
//
// Thread-safety: start() / stop() from one thread; stats() and port() from any thread.
#pragma once

#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam::ipc {

struct UdpReceiverOptions {
  std::string bind_address = "127.0.0.1";  ///< IPv4 address to bind; loopback by default
  std::uint16_t port = 47800;              ///< 0 = any free port (see UdpReceiver::port())
  std::string multicast_group;             ///< e.g. "239.255.47.80"; empty = unicast only
  std::string multicast_interface = "127.0.0.1";  ///< local address of the interface to join on
  std::vector<std::string> allow;          ///< sender IPv4 addresses; empty = any sender
  std::uint32_t restart_window = 1000;     ///< see the header comment
  int receive_buffer_bytes = 1 << 20;      ///< SO_RCVBUF request
};

/// Every datagram counts once: datagrams = applied + the sum of dropped, in every snapshot
/// (a datagram is counted together with its outcome, once it has been applied or dropped).
struct UdpStats {
  std::uint64_t datagrams = 0;  ///< received and handled (applied or dropped), valid or not
  /// decoded and applied to the state store (a traffic list also when the store refused some
  /// of its objects, not when it refused all: that is a too_many_objects drop)
  std::uint64_t applied = 0;
  std::array<std::uint64_t, 6> applied_by_type{};  ///< index = MessageType value
  std::array<std::uint64_t, kDropReasonCount> dropped{};  ///< index = DropReason
  std::uint64_t restarts = 0;   ///< sender restarts detected from sequence numbers
  std::uint64_t traffic_refused = 0;  ///< objects refused by a full state store (max_traffic_objects)
  /// poll/recvfrom failures other than "nothing to read" or a signal (logged at most once per
  /// second, like drops); the receiver goes on.
  std::uint64_t receive_errors = 0;
  [[nodiscard]] std::uint64_t droppedTotal() const noexcept;
};

class UdpReceiver {
 public:
  /// Opens and binds the socket (and joins the group), then starts the thread.
  /// Errors name the address and the system error ("bind 127.0.0.1:47800: Address already in use").
  [[nodiscard]] static Result<std::unique_ptr<UdpReceiver>> start(const UdpReceiverOptions& options, StateStore& store);
  ~UdpReceiver();  ///< stop()s
  UdpReceiver(const UdpReceiver&) = delete;
  UdpReceiver& operator=(const UdpReceiver&) = delete;

  /// Stops and joins the thread (idempotent; returns within ~0.1 s).
  void stop();
  [[nodiscard]] UdpStats stats() const;
  [[nodiscard]] std::uint16_t port() const noexcept { return port_; }

  struct Impl;

 private:
  explicit UdpReceiver(std::unique_ptr<Impl> impl, std::uint16_t port);
  std::unique_ptr<Impl> impl_;
  std::uint16_t port_ = 0;
};

/// Serial-number comparison (RFC 1982) of 32-bit sequence numbers: a − b as a signed distance.
[[nodiscard]] constexpr std::int64_t sequenceDistance(std::uint32_t a, std::uint32_t b) noexcept {
  return static_cast<std::int64_t>(static_cast<std::int32_t>(a - b));
}

}  // namespace fogbeam::ipc
