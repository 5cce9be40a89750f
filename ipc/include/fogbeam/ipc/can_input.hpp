// fogbeam — the CAN input: vehicle-bus frames → the ego vehicle's lamp state and speed, through a
// DBC mapping. One decoder (CanDecoder) serves every source, so the path tested from candump logs
// and the cannelloni UDP tunnel here is the path a SocketCAN bus takes in a cab:
//
//   SocketCAN (CAN_RAW, kernel filters for the mapped ids, classic and FD frames)
//   cannelloni over UDP (a CAN-to-Ethernet gateway, or `cannelloni` on another machine)
//   candump -L log files, replayed at recorded speed or as fast as possible
//
// Lamp signals are read as booleans (physical value ≠ 0 = on). A lamp signal that has not been
// seen for `hold_s` keeps its last value until then and then falls back to the configured
// default (off unless set in `fallback_lights`); the transition to and from "silent" is logged.
// A signal not seen yet is silent once `hold_s` has passed since the decoder's first publish
// (its source's start); until then it is unknown and its bit is left as the store has it (the
// documented initial mask, or a host's lamp state).
//
// The CAN mapping owns the bits it maps (StateStore::setBusLights): a UDP lamp state does not
// change them. The lamps' stamp carries the receipt of the newest frame that carried a mapped
// lamp signal, so a stalk frame that repeats the same value refreshes it (input-to-publish
// latency counts from the newest input) without changing a bit.
//
// A candump replay that reaches the end of its log stops there: its last values are kept, with
// no fallback and no silence line (a finished log is not a silent bus); the end is logged once.
//
// Thread-safety: a CanDecoder is used by one thread (its source's); sources are started and
// stopped from one thread.
#pragma once

#include <fogbeam/ipc/can_frame.hpp>
#include <fogbeam/ipc/candump.hpp>
#include <fogbeam/ipc/dbc.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace fogbeam::ipc {

/// A DBC message and signal, by name.
struct CanSignalRef {
  std::string message;
  std::string signal;
};

/// Lamp functions the CAN input can drive, in light:: bit order of `kCanLampBits`.
enum class CanLamp : std::uint8_t { LowBeam, HighBeam, FrontFog, RearFog, IndicatorLeft, IndicatorRight, Count_ };
inline constexpr std::size_t kCanLampCount = static_cast<std::size_t>(CanLamp::Count_);
inline constexpr std::array<std::uint32_t, kCanLampCount> kCanLampBits{
    light::kLowBeam, light::kHighBeam, light::kFrontFog, light::kRearFog, light::kIndicatorLeft, light::kIndicatorRight};

struct CanMapping {
  std::array<std::optional<CanSignalRef>, kCanLampCount> lamps;  ///< by CanLamp
  std::optional<CanSignalRef> speed;
  double speed_to_m_s = 1.0;       ///< multiplies the speed signal's physical value (1/3.6 for km/h)
  double hold_s = 0.5;             ///< a silent lamp signal keeps its value this long (s)
  std::uint32_t fallback_lights = 0;  ///< light:: bits for silent signals (default: off)
};

struct CanStats {
  std::uint64_t frames = 0;        ///< frames offered to the decoder
  std::uint64_t matched = 0;       ///< frames of a mapped message
  std::uint64_t out_of_range = 0;  ///< mapped signals outside their DBC [min, max] (ignored)
  std::uint64_t fallbacks = 0;     ///< lamp signals that went silent and fell back
  std::uint64_t published = 0;     ///< state-store updates
  /// Socket sources: poll/read/recv failures other than "nothing to read" or a signal (logged at
  /// most once per second); the source goes on. Filled by CanSource::stats(), 0 in a CanDecoder's.
  std::uint64_t receive_errors = 0;
};

class CanDecoder {
 public:
  /// Resolves every mapped signal in `dbc`; errors name the missing message or signal and what
  /// the DBC has.
  [[nodiscard]] static Result<CanDecoder> create(const DbcDatabase& dbc, const CanMapping& mapping);

  /// Decodes one frame received at `now`; true when it carried a mapped signal.
  bool onFrame(const CanFrame& frame, Clock::time_point now);
  /// Publishes the lamp state (held values, fallbacks for silent signals) and the speed to the
  /// store when they changed, the lamps also when a frame carried a lamp signal since the last
  /// call (a newer stamp, the same bits), and both every call with `force`; `source` goes into
  /// the stamps. The first call starts the silence clock of the signals not seen yet.
  void publish(StateStore& store, Clock::time_point now, const std::string& source, bool force = false);

  /// The CAN ids (and extended flags) the mapping needs: for kernel filters.
  [[nodiscard]] std::vector<std::pair<std::uint32_t, bool>> ids() const;
  [[nodiscard]] const CanStats& stats() const noexcept { return stats_; }
  /// The lamp bits as of `now` (for tests and status); a lamp not known yet (never seen, and
  /// `hold_s` not passed since the first publish) is off here.
  [[nodiscard]] std::uint32_t lights(Clock::time_point now) const;

 private:
  struct Bound {
    DbcSignal signal;  ///< a copy: the decoder outlives the DbcDatabase it was built from
    std::uint32_t id = 0;  ///< the signal's message
    bool extended = false;
    bool present = false;
    double value = 0.0;
    Clock::time_point seen{};
    bool silentLogged = false;
  };
  /// A lamp signal's state as of `now`: seen within hold_s, silent (fallback), or not known yet.
  enum class SignalState : std::uint8_t { Fresh, Silent, Unknown };
  [[nodiscard]] SignalState stateOf(const Bound& b, Clock::time_point now) const;

  CanMapping mapping_;
  std::vector<std::pair<std::uint32_t, bool>> ids_;  // (id, extended) of the mapped messages
  std::array<Bound, kCanLampCount> lamps_{};
  Bound speed_{};
  CanStats stats_;
  Clock::time_point started_{};      ///< the first publish: silence of unseen signals counts from here
  std::uint32_t lastLights_ = 0xFFFFFFFFu;  ///< the known bits last published
  std::uint32_t lastKnown_ = 0;      ///< which bits were known then
  Clock::time_point lastLampSeen_{};  ///< the newest lamp signal's receipt last published
  double lastSpeed_ = -1.0;
  std::uint32_t sequence_ = 0;
};

/// A running CAN source feeding a StateStore through a CanDecoder. Stops on destruction.
class CanSource {
 public:
  virtual ~CanSource() = default;
  virtual void stop() = 0;
  [[nodiscard]] virtual CanStats stats() const = 0;
  [[nodiscard]] virtual bool finished() const = 0;  ///< a replay reached its end
};

/// SocketCAN on `interface` (e.g. "can0", "vcan0"), CAN_RAW with FD frames and kernel filters.
/// Fails with the system's reason where AF_CAN is unavailable ("SocketCAN unavailable: …").
[[nodiscard]] Result<std::unique_ptr<CanSource>> startSocketCan(const std::string& interface, CanDecoder decoder,
                                                                StateStore& store);
/// cannelloni datagrams on `bind_address:port` (0 = any free port; see port()).
[[nodiscard]] Result<std::unique_ptr<CanSource>> startCannelloni(const std::string& bind_address, std::uint16_t port,
                                                                 CanDecoder decoder, StateStore& store,
                                                                 std::uint16_t* boundPort = nullptr);
/// Replays a candump log: `speed` 1 = recorded speed, 0 = as fast as possible.
[[nodiscard]] Result<std::unique_ptr<CanSource>> startCandumpReplay(const std::string& path, double speed,
                                                                    CanDecoder decoder, StateStore& store);

}  // namespace fogbeam::ipc
