// fogbeam — the CAN output of the host stand-in (`fogbeam send`): lamp states and speed → CAN
// frames through the same DBC mapping the CAN input reads (can_input.hpp, can_config.hpp), so
// that frames made here decode with CanDecoder to the lamp bits and speed they were made from.
// The frames go out as cannelloni datagrams (cannelloni.hpp, encodeCannelloni) or as a
// candump -L log (formatCandumpLine below; read back by candump.hpp's parseCandumpLine).
//
// How the decoder reads the mapping, and what the encoder therefore writes:
//   lamp signal: physical ≠ 0 = on. On is written as physical 1 or, where 1 does not decode
//     to a non-zero value inside the DBC range, as raw 1 (physical factor + offset), else as
//     the range's maximum or minimum; off as physical 0. create() checks that both decode back
//     as intended and fails otherwise.
//   speed signal: physical · speed_to_m_s = m/s, so physical = speed / speed_to_m_s. A speed
//     outside the DBC's [minimum, maximum] is an error, because the decoder would drop it.
//   multiplexed signals: the frame's multiplexor is set to the signal's m<N> value; mapped
//     signals of one message with different m<N> values go into one frame each.
// hold_s and fallback_lights only matter on the receiving side and are not used here.
//
// Thread-safety: a CanEncoder is immutable after create(); encode() is const and may be
// called from several threads at once. formatCandumpLine is a pure function.
#pragma once

#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/can_frame.hpp>
#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/ipc/dbc.hpp>
#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace fogbeam::ipc {

class CanEncoder {
 public:
  /// Resolves every mapped signal in `dbc` (the inputs CanDecoder::create takes). Errors name
  /// what is missing (as CanDecoder::create does), a mapping that names no signal, a lamp
  /// signal whose on/off values do not survive a round trip, a speed_to_m_s that is 0 or not
  /// finite, mapped signals whose bits overlap, and a mapped multiplexor in a message whose
  /// mapped multiplexed signals need it set otherwise. The encoder keeps copies: `dbc` may go.
  [[nodiscard]] static Result<CanEncoder> create(const DbcDatabase& dbc, const CanMapping& mapping);

  /// Frames carrying the state: one per mapped message (one per message and multiplexor value
  /// for multiplexed signals), in the order the mapping first names them, each with every
  /// mapped signal it holds set and every other bit 0. id, extended and len come from the DBC
  /// message (len > 8 makes a CAN FD frame, rounded up to a valid CAN FD length); timestamp_s
  /// is 0.
  /// @param lights     light:: bits (protocol.hpp); bits of lamps the mapping does not map
  ///                   (DRL, brake, …) are ignored.
  /// @param speed_m_s  vehicle speed, m/s; nullopt leaves the speed signal out: a message that
  ///                   carries only the speed is not sent, one that also carries lamps has the
  ///                   speed bits 0. Ignored when the mapping has no speed.
  /// Errors: a speed that the signal cannot hold or that lies outside the DBC range (the
  /// message names the signal and the value); two lamps mapped to one signal but asked to be
  /// on and off at once.
  [[nodiscard]] Result<std::vector<CanFrame>> encode(std::uint32_t lights, std::optional<double> speed_m_s) const;

  /// The (id, extended) of the messages encode() can produce, in frame order, without repeats.
  [[nodiscard]] std::vector<std::pair<std::uint32_t, bool>> ids() const;

 private:
  struct Slot {
    DbcSignal signal;            // a copy: the encoder outlives the DbcDatabase
    bool is_speed = false;
    std::uint32_t lamp_bits = 0;  // light:: bits of every lamp mapped to this signal
    double on = 1.0;              // physical values written for a lamp
    double off = 0.0;
  };
  struct FrameSpec {
    std::uint32_t id = 0;
    bool extended = false;
    std::uint8_t len = 0;
    bool fd = false;
    std::string message;  // for errors
    std::vector<Slot> slots;
  };
  std::vector<FrameSpec> frames_;
  double speed_to_m_s_ = 1.0;
};

/// Loads the DBC a configuration names and builds the encoder (errors name the DBC file), the
/// counterpart of makeDecoder.
[[nodiscard]] Result<CanEncoder> makeEncoder(const CanConfig& config);

/// One candump -L log line for `frame`, without a line end, as can-utils' candump writes it:
///   "(1700000000.123456) can0 123#DEADBEEF"   (3 hex digits for an 11-bit id, 8 for 29 bits,
///   upper-case hex; "123#R" / "123#R4" for remote frames; "123##1<data>" for CAN FD, the digit
///   after "##" being the flags, 1 = BRS, 2 = ESI).
/// @param time_s     seconds (since the Unix epoch for a live-looking log), written to the
///                   microsecond; negative or non-finite times are written as 0.
/// @param interface  e.g. "can0"; must be non-empty and without blanks or '#' for
///                   parseCandumpLine to read the line back.
/// @param frame      a valid frame (id fits its format, len ≤ 8 classic/remote, a valid CAN FD
///                   length for FD); bytes beyond len (at most 64) are not written.
[[nodiscard]] std::string formatCandumpLine(double time_s, const std::string& interface, const CanFrame& frame);

}  // namespace fogbeam::ipc
