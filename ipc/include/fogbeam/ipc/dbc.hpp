// fogbeam — DBC (Vector CANdb++ database) reader, signal decoder and encoder, for mapping vehicle CAN
// signals (light stalk, speed) onto fogbeam's lamp and ego state.
//
// What is read (Vector "DBC File Format Documentation" v01/2007, §8 messages and signals):
//   BO_ <id> <name>: <size> <transmitter>
//       id: decimal; bit 31 set marks an extended 29-bit identifier (id = value − 0x80000000).
//       size: payload bytes, ≤ 64 (CAN FD).
//   SG_ <name> [M|m<N>] : <start>|<length>@<order><sign> (<factor>,<offset>) [<min>|<max>]
//       "<unit>" <receiver>[,<receiver>…]
//       order 1 = Intel (little-endian): start is the least significant bit, numbered
//         byte·8 + bit with bit 0 the LSB of each byte; the signal runs upward from there.
//       order 0 = Motorola (big-endian): start is the MOST significant bit, in the same
//         "sawtooth" numbering (byte 0 holds bits 7…0, byte 1 bits 15…8); the signal runs from
//         there towards less significant bits, continuing at bit 7 of the next byte. (Some web
//         pages say start is the LSB for Motorola; Vector's tools, cantools and opendbc all
//         write the MSB, as the DBC documentation does.)
//       sign '+' unsigned, '-' two's complement. physical = raw · factor + offset.
//       M marks the message's multiplexor; m<N> a signal present only when the multiplexor's
//       raw value is N.
//   SIG_VALTYPE_ <id> <signal> : 1|2;   the signal's raw bits are an IEEE float (32 bits) or
//       double (64 bits) instead of an integer.
// Every other statement (VERSION, NS_ with its indented list, BS_, BU_, CM_, BA_DEF_, BA_,
// VAL_, VAL_TABLE_, …, including strings that span several lines) is skipped. Extended
// multiplexing (SG_MUL_VAL_, m<N>M signals, more than one multiplexor per message) is rejected
// with a message saying so. Vector's pseudo-message VECTOR__INDEPENDENT_SIG_MSG (id
// 0xC0000000, signals not assigned to any frame) is skipped with its signals.
//
// Thread-safety: the parser is reentrant; a DbcDatabase is a value, safe to read from several
// threads.
#pragma once

#include <fogbeam/ipc/can_frame.hpp>
#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::ipc {

/// Largest DBC message, bytes (a CAN FD frame).
inline constexpr std::size_t kDbcMaxMessageSize = 64;

enum class DbcByteOrder {
  Intel,     ///< "@1": little-endian, start bit = least significant bit
  Motorola,  ///< "@0": big-endian, start bit = most significant bit (sawtooth numbering)
};

/// How a signal's raw bits are interpreted.
enum class DbcValueType {
  Integer,  ///< the default: unsigned or two's complement by `is_signed`
  Float32,  ///< SIG_VALTYPE_ 1: IEEE 754 single precision, length 32
  Float64,  ///< SIG_VALTYPE_ 2: IEEE 754 double precision, length 64
};

/// Where a signal's bits are in the payload.
struct DbcBitField {
  std::uint16_t start_bit = 0;  ///< as written in the DBC: LSB (Intel) or MSB (Motorola), 0–511
  std::uint8_t length = 1;      ///< bits, 1–64
  DbcByteOrder order = DbcByteOrder::Intel;
  bool is_signed = false;  ///< '-' in the DBC: two's complement
};

enum class DbcMuxRole {
  None,         ///< always present
  Multiplexor,  ///< "M": selects which multiplexed signals the frame carries
  Multiplexed,  ///< "m<N>": present only when the multiplexor's raw value equals `mux_value`
};

struct DbcSignal {
  std::string name;
  DbcBitField bits;
  DbcValueType value_type = DbcValueType::Integer;
  double factor = 1.0;   ///< physical units per raw count
  double offset = 0.0;   ///< physical units
  double minimum = 0.0;  ///< physical units; with maximum == minimum == 0 no range is given
  double maximum = 0.0;  ///< physical units
  std::string unit;      ///< as written in the DBC ("km/h"); may be empty
  std::vector<std::string> receivers;
  DbcMuxRole mux_role = DbcMuxRole::None;
  std::uint64_t mux_value = 0;  ///< Multiplexed: the multiplexor raw value that selects this signal
  /// Multiplexed: a copy of the message's multiplexor field, so that decodeSignal can check
  /// the selection from the signal alone.
  DbcBitField multiplexor;

  /// True when the DBC gives a range, i.e. min and max are not both 0.
  [[nodiscard]] bool hasRange() const noexcept { return minimum != 0.0 || maximum != 0.0; }
};

struct DbcMessage {
  std::uint32_t id = 0;  ///< without the DBC's bit 31: 0–0x7FF standard, 0–0x1FFFFFFF extended
  bool extended = false;
  std::string name;
  std::uint8_t size = 0;  ///< payload bytes, 0–64
  std::string transmitter;
  std::vector<DbcSignal> signals;  ///< in file order
};

struct DbcDatabase {
  std::string file_name;  ///< as given to parseDbc, for messages
  /// Sorted by (extended, id); parseDbc keeps it so and findMessage relies on it.
  std::vector<DbcMessage> messages;

  /// The message with this identifier, or nullptr. `id` without flag bits.
  [[nodiscard]] const DbcMessage* findMessage(std::uint32_t id, bool extended) const noexcept;
  /// The message called `name`, or an error listing the messages that exist.
  [[nodiscard]] Result<const DbcMessage*> message(std::string_view name) const;
  /// Signal `signalName` of message `messageName`, or an error naming what is missing and listing the
  /// messages (or that message's signals) that exist.
  [[nodiscard]] Result<const DbcSignal*> signal(std::string_view messageName, std::string_view signalName) const;
};

/// Parses DBC text. `fileName` is used in messages ("lights.dbc:12: expected …, found …").
/// Never returns a half-parsed database.
[[nodiscard]] Result<DbcDatabase> parseDbc(std::string_view text, const std::string& fileName);
/// Reads and parses a DBC file; errors name `path`.
[[nodiscard]] Result<DbcDatabase> loadDbc(const std::string& path);

/// A decoded signal value.
struct DbcValue {
  std::uint64_t raw = 0;      ///< the signal's bits, right-aligned (not sign-extended)
  double physical = 0.0;      ///< raw (sign-extended or as float) · factor + offset
  bool out_of_range = false;  ///< the signal has a range and physical lies outside [min, max]
};

/// The signal's raw bits from `frame`, or nullopt when frame.len is too short to hold them.
/// The caller has matched the frame's id with the signal's message.
[[nodiscard]] std::optional<std::uint64_t> extractRaw(const DbcBitField& bits, const CanFrame& frame) noexcept;

/// Decodes `signal` from `frame`, or nullopt when the frame is too short for the signal (or
/// for its multiplexor) or, for a multiplexed signal, the multiplexor selects another value.
/// The caller has matched the frame's id with the signal's message (DbcDatabase::findMessage).
[[nodiscard]] std::optional<DbcValue> decodeSignalValue(const DbcSignal& signal, const CanFrame& frame) noexcept;

/// decodeSignalValue's physical value: raw · factor + offset.
[[nodiscard]] std::optional<double> decodeSignal(const DbcSignal& signal, const CanFrame& frame) noexcept;

/// True when the signal has a range (hasRange) and `physical` lies outside [minimum, maximum].
[[nodiscard]] bool isOutOfRange(const DbcSignal& signal, double physical) noexcept;

// ---------------------------------------------------------------------------------------
// Encoding: the inverse of the decoding above, for tools that put signals on a bus (the host
// stand-in `fogbeam send`, tests). Pure functions, safe from several threads on distinct frames.

/// Writes the low `bits.length` bits of `raw` into `frame` where extractRaw reads them (the
/// same bit numbering: Intel from the LSB upward, Motorola from the MSB in sawtooth order), so
/// that extractRaw(bits, frame) == raw & mask afterwards. Bits of `raw` above the field are
/// ignored; every other bit of the frame is left as it was. Returns false, with the frame
/// untouched, when frame.len is too short for the field or bits.length is not 1–64 (the same
/// cases in which extractRaw gives nullopt). frame.len is not changed: the caller sizes it.
[[nodiscard]] bool insertRaw(const DbcBitField& bits, std::uint64_t raw, CanFrame& frame) noexcept;

/// The raw bits (right-aligned, not sign-extended, masked to the field's length) that
/// decodeSignalValue decodes to `physical`, in the signal's physical unit:
///   integer signals: (physical − offset) / factor rounded to the nearest integer (halves away
///     from zero), which must fit the field: 0 … 2^length − 1 unsigned, −2^(length−1) …
///     2^(length−1) − 1 signed (two's complement);
///   Float32 / Float64 signals: the IEEE bit pattern of (physical − offset) / factor, which
///     must be finite (and within float's range for Float32).
/// Errors name the signal, the value and, for integers, the physical range the field can hold.
/// Also errors: a non-finite `physical`, a factor of 0. The DBC's [minimum, maximum] is NOT
/// checked here (isOutOfRange does that; a decoder flags such values but they are encodable).
[[nodiscard]] Result<std::uint64_t> encodeSignalValue(const DbcSignal& signal, double physical);

/// encodeSignalValue + insertRaw: writes `physical` into `frame` and, for a multiplexed signal,
/// also writes the multiplexor field with the signal's mux_value, so that decodeSignal finds
/// the signal. Errors (frame unchanged): encodeSignalValue's, and a frame.len too short for
/// the signal or its multiplexor (naming the signal and both lengths). The caller has set the
/// frame's id, extended flag and len for the signal's message.
[[nodiscard]] Status encodeSignal(const DbcSignal& signal, double physical, CanFrame& frame);

}  // namespace fogbeam::ipc
