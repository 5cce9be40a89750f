// fogbeam — CAN output: lamp states and speed → frames (fogbeam/ipc/can_encode.hpp).
//
// The encoder is the mirror of CanDecoder (can_input.cpp): it resolves the same mapping in the
// same DBC and writes each mapped signal so that decodeSignalValue reads back what was meant.
// Everything that can be checked once (names, on/off values, overlaps) is checked in create(),
// so that encode() only fails on values the caller passes.
#include <fogbeam/ipc/can_encode.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <string_view>
#include <system_error>

namespace fogbeam::ipc {

namespace {

// The mapping's keys (can_config.hpp), by CanLamp, for messages.
constexpr std::array<const char*, kCanLampCount> kLampKeys{"low_beam",  "high_beam",      "front_fog",
                                                           "rear_fog",  "indicator_left", "indicator_right"};

std::string numberText(double v) {
  std::array<char, 32> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  if (ec != std::errc{}) return "?";
  return std::string(buf.data(), end);
}

std::string hexText(std::uint32_t v) {
  std::array<char, 16> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v, 16);
  if (ec != std::errc{}) return "?";
  return std::string(buf.data(), end);
}

std::string withUnit(double v, const std::string& unit) {
  return numberText(v) + (unit.empty() ? std::string() : " " + unit);
}

// The physical value `physical` reads back as after a trip through a frame, or nullopt when it
// cannot be encoded or the decoder would drop it (out of the DBC range).
std::optional<double> roundTrip(const DbcSignal& signal, double physical) {
  CanFrame f;
  f.len = static_cast<std::uint8_t>(kCanFdMaxLen);  // every field fits 64 bytes (parseDbc checks)
  if (!encodeSignal(signal, physical, f)) return std::nullopt;
  const std::optional<DbcValue> v = decodeSignalValue(signal, f);
  if (!v || v->out_of_range) return std::nullopt;
  return v->physical;
}

// A 64-byte frame with exactly the field's bits set: for overlap checks.
CanFrame fieldMask(const DbcBitField& bits) {
  CanFrame f;
  f.len = static_cast<std::uint8_t>(kCanFdMaxLen);
  (void)insertRaw(bits, ~std::uint64_t{0}, f);  // cannot fail: len 64 holds every DBC field
  return f;
}

bool overlaps(const CanFrame& a, const CanFrame& b) noexcept {
  for (std::size_t i = 0; i < kCanFdMaxLen; ++i)
    if ((a.data[i] & b.data[i]) != 0) return true;
  return false;
}

// A mapped signal before grouping into frames.
struct Ref {
  const DbcMessage* message = nullptr;
  const DbcSignal* signal = nullptr;
  bool is_speed = false;
  std::uint32_t lamp_bits = 0;
  std::string role;  // "low_beam", "speed": for messages
};

}  // namespace

Result<CanEncoder> CanEncoder::create(const DbcDatabase& dbc, const CanMapping& mapping) {
  CanEncoder e;
  e.speed_to_m_s_ = mapping.speed_to_m_s;
  if (mapping.speed && (!std::isfinite(mapping.speed_to_m_s) || mapping.speed_to_m_s == 0.0))
    return Error{"CAN mapping: speed to_m_s must be finite and non-zero, found " + numberText(mapping.speed_to_m_s)};

  // Resolve names the way CanDecoder::create does (same errors), merging lamps that share a
  // signal: they can only be encoded together.
  std::vector<Ref> refs;
  auto add = [&](const std::optional<CanSignalRef>& ref, bool isSpeed, std::uint32_t lampBit,
                 const std::string& role) -> Status {
    if (!ref) return Ok{};
    const Result<const DbcMessage*> msg = dbc.message(ref->message);
    if (!msg) return msg.error();
    const Result<const DbcSignal*> sig = dbc.signal(ref->message, ref->signal);
    if (!sig) return sig.error();
    for (Ref& r : refs) {
      if (r.signal != *sig) continue;
      if (r.is_speed || isSpeed)
        return Error{"CAN mapping: signal '" + ref->signal + "' of message '" + ref->message + "' is mapped as " +
                     r.role + " and as " + role + "; one signal cannot carry both"};
      r.lamp_bits |= lampBit;
      r.role += "+" + role;
      return Ok{};
    }
    refs.push_back(Ref{*msg, *sig, isSpeed, lampBit, role});
    return Ok{};
  };
  for (std::size_t k = 0; k < kCanLampCount; ++k)
    if (Status s = add(mapping.lamps[k], false, kCanLampBits[k], kLampKeys[k]); !s) return s.error();
  if (Status s = add(mapping.speed, true, 0, "speed"); !s) return s.error();
  if (refs.empty()) return Error{"CAN mapping names no signal (lamps or speed)"};

  // Messages in the order the mapping first names them.
  std::vector<const DbcMessage*> messages;
  for (const Ref& r : refs)
    if (std::find(messages.begin(), messages.end(), r.message) == messages.end()) messages.push_back(r.message);

  for (const DbcMessage* m : messages) {
    std::vector<Slot> always;  // not multiplexed: in every frame of the message
    std::vector<std::uint64_t> muxValues;
    std::vector<std::pair<std::uint64_t, Slot>> multiplexed;
    const Ref* mappedMultiplexor = nullptr;
    for (const Ref& r : refs) {
      if (r.message != m) continue;
      Slot slot;
      slot.signal = *r.signal;
      slot.is_speed = r.is_speed;
      slot.lamp_bits = r.lamp_bits;
      if (!r.is_speed) {
        // The decoder reads "on" as physical ≠ 0: 1 where the signal can say so, else raw 1
        // (physical = factor + offset, e.g. a 1-bit signal with factor 2), else the ends of
        // the DBC range.
        const std::string sigText = "CAN mapping: " + r.role + " signal '" + r.signal->name + "'";
        const std::optional<double> off = roundTrip(slot.signal, 0.0);
        if (!off || *off != 0.0)
          return Error{sigText + " cannot express off (physical 0 does not decode back to 0 within its DBC range)"};
        bool found = false;
        std::vector<double> candidates{1.0, r.signal->factor + r.signal->offset};
        if (r.signal->hasRange()) {  // e.g. a signed bit whose only non-zero value is −1
          candidates.push_back(r.signal->maximum);
          candidates.push_back(r.signal->minimum);
        }
        for (const double candidate : candidates) {
          const std::optional<double> on = roundTrip(slot.signal, candidate);
          if (on && *on != 0.0) {
            slot.on = candidate;
            found = true;
            break;
          }
        }
        if (!found)
          return Error{sigText +
                       " cannot express on (neither physical 1, raw 1 nor the DBC range's ends decode to a non-zero "
                       "value within the range)"};
      }
      if (r.signal->mux_role == DbcMuxRole::Multiplexed) {
        if (std::find(muxValues.begin(), muxValues.end(), r.signal->mux_value) == muxValues.end())
          muxValues.push_back(r.signal->mux_value);
        multiplexed.emplace_back(r.signal->mux_value, std::move(slot));
      } else {
        if (r.signal->mux_role == DbcMuxRole::Multiplexor) mappedMultiplexor = &r;
        always.push_back(std::move(slot));
      }
    }
    if (mappedMultiplexor != nullptr && !muxValues.empty())
      return Error{"CAN mapping: " + mappedMultiplexor->role + " signal '" + mappedMultiplexor->signal->name +
                   "' is the multiplexor of message '" + m->name +
                   "', which the mapped multiplexed signals of that message set themselves"};

    FrameSpec base;
    base.id = m->id;
    base.extended = m->extended;
    base.message = m->name;
    // Classic frames up to 8 bytes; longer messages are CAN FD, whose lengths come in steps.
    std::size_t len = m->size;
    if (len > kCanMaxLen) {
      base.fd = true;
      while (!isValidCanFdLength(len)) ++len;
    }
    base.len = static_cast<std::uint8_t>(len);

    std::vector<FrameSpec> specs;
    if (muxValues.empty()) {
      specs.push_back(base);
      specs.back().slots = always;
    } else {
      for (const std::uint64_t v : muxValues) {
        specs.push_back(base);
        specs.back().slots = always;
        for (const auto& [value, slot] : multiplexed)
          if (value == v) specs.back().slots.push_back(slot);
      }
    }

    // Overlapping fields would overwrite each other: refuse the mapping rather than send
    // frames that decode to something else. The multiplexor field counts as a field too.
    for (const FrameSpec& spec : specs) {
      std::vector<std::pair<std::string, CanFrame>> fields;
      for (const Slot& s : spec.slots) {
        fields.emplace_back(s.signal.name, fieldMask(s.signal.bits));
        if (s.signal.mux_role == DbcMuxRole::Multiplexed &&
            std::none_of(fields.begin(), fields.end(), [](const auto& f) { return f.first == "(multiplexor)"; }))
          fields.emplace_back("(multiplexor)", fieldMask(s.signal.multiplexor));
      }
      for (std::size_t i = 0; i < fields.size(); ++i)
        for (std::size_t j = i + 1; j < fields.size(); ++j)
          if (overlaps(fields[i].second, fields[j].second))
            return Error{"CAN mapping: signals '" + fields[i].first + "' and '" + fields[j].first + "' of message '" +
                         m->name + "' share bits; they cannot be encoded together"};
    }
    for (FrameSpec& spec : specs) e.frames_.push_back(std::move(spec));
  }
  return e;
}

Result<std::vector<CanFrame>> CanEncoder::encode(std::uint32_t lights, std::optional<double> speed_m_s) const {
  std::vector<CanFrame> out;
  out.reserve(frames_.size());
  for (const FrameSpec& spec : frames_) {
    CanFrame f;
    f.id = spec.id;
    f.extended = spec.extended;
    f.fd = spec.fd;
    f.len = spec.len;
    bool any = false;
    for (const Slot& slot : spec.slots) {
      if (slot.is_speed) {
        if (!speed_m_s) continue;
        const double physical = *speed_m_s / speed_to_m_s_;
        const std::string what = "speed " + numberText(*speed_m_s) + " m/s (" + withUnit(physical, slot.signal.unit) +
                                 " in signal '" + slot.signal.name + "' of message '" + spec.message + "')";
        if (isOutOfRange(slot.signal, physical))
          return Error{what + " is outside the DBC range " + numberText(slot.signal.minimum) + " to " +
                       withUnit(slot.signal.maximum, slot.signal.unit) + "; a decoder would ignore it"};
        if (Status s = encodeSignal(slot.signal, physical, f); !s) return Error{what + ": " + s.error().message};
      } else {
        const std::uint32_t on = lights & slot.lamp_bits;
        if (on != 0 && on != slot.lamp_bits)
          return Error{"lamps mapped to the one signal '" + slot.signal.name + "' of message '" + spec.message +
                       "' cannot be on and off at once (light bits 0x" + hexText(lights) + ")"};
        if (Status s = encodeSignal(slot.signal, on != 0 ? slot.on : slot.off, f); !s) return s.error();
      }
      any = true;
    }
    if (any) out.push_back(f);
  }
  return out;
}

std::vector<std::pair<std::uint32_t, bool>> CanEncoder::ids() const {
  std::vector<std::pair<std::uint32_t, bool>> out;
  for (const FrameSpec& spec : frames_) {
    const std::pair<std::uint32_t, bool> key{spec.id, spec.extended};
    if (std::find(out.begin(), out.end(), key) == out.end()) out.push_back(key);
  }
  return out;
}

Result<CanEncoder> makeEncoder(const CanConfig& config) {
  const Result<DbcDatabase> dbc = loadDbc(config.dbc_path);
  if (!dbc) return dbc.error();
  Result<CanEncoder> e = CanEncoder::create(*dbc, config.mapping);
  if (!e) return Error{"CAN mapping against " + config.dbc_path + ": " + e.error().message};
  return e;
}

std::string formatCandumpLine(double time_s, const std::string& interface, const CanFrame& frame) {
  constexpr std::string_view kHex = "0123456789ABCDEF";
  // candump prints "(%010lu.%06lu)" from a timeval: whole microseconds. Rounding here (not
  // truncating) keeps a time that came from parseCandumpLine's double the same on the way back.
  long long micros = 0;
  if (std::isfinite(time_s) && time_s > 0.0) micros = std::llround(std::min(time_s, 9.0e12) * 1e6);
  std::array<char, 48> stamp{};
  const int n = std::snprintf(stamp.data(), stamp.size(), "(%010lld.%06lld) ", micros / 1'000'000, micros % 1'000'000);
  std::string out(stamp.data(), n > 0 ? static_cast<std::size_t>(n) : 0u);
  out += interface;
  out += ' ';
  const int idDigits = frame.extended ? 8 : 3;
  for (int d = idDigits - 1; d >= 0; --d) out += kHex[(frame.id >> (4 * d)) & 0xFu];
  out += '#';
  const std::size_t len = std::min<std::size_t>(frame.len, kCanFdMaxLen);
  if (frame.remote) {
    // can-utils writes "R" and, when non-zero, the requested length as one digit.
    out += 'R';
    if (len > 0 && len <= kCanMaxLen) out += kHex[len];
    return out;
  }
  if (frame.fd) {
    out += '#';
    out += kHex[(frame.brs ? 1u : 0u) | (frame.esi ? 2u : 0u)];
  }
  for (std::size_t i = 0; i < len; ++i) {
    out += kHex[unsigned{frame.data[i]} >> 4];
    out += kHex[unsigned{frame.data[i]} & 0xFu];
  }
  return out;
}

}  // namespace fogbeam::ipc
