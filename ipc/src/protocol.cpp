// fogbeam — UDP protocol v1 codec (fogbeam/ipc/protocol.hpp, docs/protocol.md).
//
// Byte access is explicit little-endian assembly (not memcpy of structs): the layout is the
// document's, independent of the compiler's padding and the host's byte order.
#include <fogbeam/ipc/protocol.hpp>

#include <bit>
#include <cmath>
#include <cstring>
#include <utility>

namespace fogbeam::ipc {

std::string_view toString(DropReason r) {
  switch (r) {
    case DropReason::TooShort: return "too_short";
    case DropReason::BadMagic: return "bad_magic";
    case DropReason::BadVersion: return "bad_version";
    case DropReason::UnknownType: return "unknown_type";
    case DropReason::LengthMismatch: return "length_mismatch";
    case DropReason::BadCount: return "bad_count";
    case DropReason::NonFinite: return "non_finite";
    case DropReason::OutOfRange: return "out_of_range";
    case DropReason::SenderNotAllowed: return "sender_not_allowed";
    case DropReason::Duplicate: return "duplicate";
    case DropReason::OutOfOrder: return "out_of_order";
    case DropReason::TooManyObjects: return "too_many_objects";
    case DropReason::Count_: break;
  }
  return "?";
}

namespace {

// ---- little-endian reader over a bounded span: every read is checked by the caller's length
// validation first, so out-of-range offsets are programming errors, not input errors.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
  std::uint8_t u8(std::size_t o) const { return b_[o]; }
  std::uint16_t u16(std::size_t o) const {
    return static_cast<std::uint16_t>(b_[o] | (static_cast<unsigned>(b_[o + 1]) << 8));
  }
  std::uint32_t u32(std::size_t o) const {
    return static_cast<std::uint32_t>(b_[o]) | (static_cast<std::uint32_t>(b_[o + 1]) << 8) |
           (static_cast<std::uint32_t>(b_[o + 2]) << 16) | (static_cast<std::uint32_t>(b_[o + 3]) << 24);
  }
  std::uint64_t u64(std::size_t o) const {
    return static_cast<std::uint64_t>(u32(o)) | (static_cast<std::uint64_t>(u32(o + 4)) << 32);
  }
  float f32(std::size_t o) const { return std::bit_cast<float>(u32(o)); }
  double f64(std::size_t o) const { return std::bit_cast<double>(u64(o)); }

 private:
  std::span<const std::uint8_t> b_;
};

class Writer {
 public:
  explicit Writer(std::vector<std::uint8_t>& b) : b_(b) {}
  void u8(std::uint8_t v) { b_.push_back(v); }
  void u16(std::uint16_t v) {
    b_.push_back(static_cast<std::uint8_t>(v));
    b_.push_back(static_cast<std::uint8_t>(v >> 8));
  }
  void u32(std::uint32_t v) {
    for (int s = 0; s < 32; s += 8) b_.push_back(static_cast<std::uint8_t>(v >> s));
  }
  void u64(std::uint64_t v) {
    for (int s = 0; s < 64; s += 8) b_.push_back(static_cast<std::uint8_t>(v >> s));
  }
  void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
  void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }

 private:
  std::vector<std::uint8_t>& b_;
};

// A failed check: the reason and the field, for the caller's counters and rate-limited log.
struct Fail {
  DropReason reason;
  std::string_view field;
};

// Range limits (docs/protocol.md). Positions: a simulated world is at most 10 000 km across.
constexpr double kMaxPosition_m = 1e7;
constexpr float kMaxAngle_deg = 360.0f;
constexpr float kMaxSpeed_m_s = 200.0f;
constexpr float kMaxBending_deg = 45.0f;

bool finite(double v) { return std::isfinite(v); }
bool finite(float v) { return std::isfinite(v); }

// Checks a value: non-finite → NonFinite, outside [lo, hi] → OutOfRange.
template <class T>
const Fail* check(T v, T lo, T hi, std::string_view field, Fail& slot) {
  if (!finite(v)) {
    slot = {DropReason::NonFinite, field};
    return &slot;
  }
  if (v < lo || v > hi) {
    slot = {DropReason::OutOfRange, field};
    return &slot;
  }
  return nullptr;
}

const Fail* readPose(const Reader& r, std::size_t o, Pose& p, Fail& slot) {
  static constexpr std::string_view kPos[3] = {"position_m.x", "position_m.y", "position_m.z"};
  for (std::size_t k = 0; k < 3; ++k) {
    p.position_m[k] = r.f64(o + 8 * k);
    if (const Fail* f = check(p.position_m[k], -kMaxPosition_m, kMaxPosition_m, kPos[k], slot)) return f;
  }
  p.yaw_deg = r.f32(o + 24);
  p.pitch_deg = r.f32(o + 28);
  p.roll_deg = r.f32(o + 32);
  if (const Fail* f = check(p.yaw_deg, -kMaxAngle_deg, kMaxAngle_deg, "yaw_deg", slot)) return f;
  if (const Fail* f = check(p.pitch_deg, -kMaxAngle_deg, kMaxAngle_deg, "pitch_deg", slot)) return f;
  if (const Fail* f = check(p.roll_deg, -kMaxAngle_deg, kMaxAngle_deg, "roll_deg", slot)) return f;
  return nullptr;
}

void writePose(Writer& w, const Pose& p) {
  for (double v : p.position_m) w.f64(v);
  w.f32(p.yaw_deg);
  w.f32(p.pitch_deg);
  w.f32(p.roll_deg);
}

DecodeResult failed(DropReason r, std::string_view field) {
  DecodeResult d;
  d.ok = false;
  d.reason = r;
  d.field = field;
  return d;
}

DecodeResult failed(const Fail& f) { return failed(f.reason, f.field); }

}  // namespace

DecodeResult decode(std::span<const std::uint8_t> bytes) noexcept {
  if (bytes.size() < kHeaderSize) return failed(DropReason::TooShort, "header");
  const Reader r(bytes);
  if (r.u32(0) != kProtocolMagic) return failed(DropReason::BadMagic, "magic");
  if (r.u16(4) != kProtocolVersion) return failed(DropReason::BadVersion, "version");
  const std::uint16_t type = r.u16(6);
  DecodeResult out;
  Header& h = out.message.header;
  h.payload_length = r.u32(8);
  h.sequence = r.u32(12);
  h.sim_time_s = r.f64(16);
  if (h.payload_length != bytes.size() - kHeaderSize) return failed(DropReason::LengthMismatch, "payload_length");
  if (!std::isfinite(h.sim_time_s)) return failed(DropReason::NonFinite, "sim_time_s");
  if (h.sim_time_s < 0.0) return failed(DropReason::OutOfRange, "sim_time_s");
  const std::span<const std::uint8_t> payload = bytes.subspan(kHeaderSize);
  const Reader p(payload);
  Fail slot{};
  auto fixedSize = [&](std::size_t n) { return payload.size() == n; };

  switch (type) {
    case static_cast<std::uint16_t>(MessageType::EgoState): {
      h.type = MessageType::EgoState;
      if (!fixedSize(kEgoStateSize)) return failed(DropReason::LengthMismatch, "payload_length");
      EgoState e;
      if (const Fail* f = readPose(p, 0, e.pose, slot)) return failed(*f);
      e.speed_m_s = p.f32(36);
      if (const Fail* f = check(e.speed_m_s, -kMaxSpeed_m_s, kMaxSpeed_m_s, "speed_m_s", slot)) return failed(*f);
      out.message.payload = e;
      break;
    }
    case static_cast<std::uint16_t>(MessageType::LampState): {
      h.type = MessageType::LampState;
      if (!fixedSize(kLampStateSize)) return failed(DropReason::LengthMismatch, "payload_length");
      LampState l;
      l.lights = p.u32(0) & light::kKnown;  // other bits: lights fogbeam does not draw
      l.bending_deg = p.f32(4);
      if (const Fail* f = check(l.bending_deg, -kMaxBending_deg, kMaxBending_deg, "bending_deg", slot))
        return failed(*f);
      if (p.u32(8) != 0) return failed(DropReason::OutOfRange, "reserved");
      out.message.payload = l;
      break;
    }
    case static_cast<std::uint16_t>(MessageType::TrafficList): {
      h.type = MessageType::TrafficList;
      if (payload.size() < kTrafficHeaderSize) return failed(DropReason::LengthMismatch, "payload_length");
      const std::size_t count = p.u16(0);
      const std::uint16_t flags = p.u16(2);
      if (count > kMaxTrafficPerDatagram) return failed(DropReason::BadCount, "count");
      if (payload.size() != kTrafficHeaderSize + count * kTrafficObjectSize)
        return failed(DropReason::BadCount, "count");
      if ((flags & ~1u) != 0) return failed(DropReason::OutOfRange, "flags");
      TrafficList t;
      t.complete = (flags & 1u) != 0;
      t.objects.resize(count);
      for (std::size_t k = 0; k < count; ++k) {
        const std::size_t o = kTrafficHeaderSize + k * kTrafficObjectSize;
        TrafficObject& obj = t.objects[k];
        obj.id = p.u32(o);
        obj.vehicle_class = p.u16(o + 4);
        const std::uint16_t objFlags = p.u16(o + 6);
        if ((objFlags & ~1u) != 0) return failed(DropReason::OutOfRange, "object.flags");
        obj.removed = (objFlags & 1u) != 0;
        if (const Fail* f = readPose(p, o + 8, obj.pose, slot)) return failed(*f);
        obj.lights = p.u32(o + 44) & light::kKnown;
      }
      out.message.payload = std::move(t);
      break;
    }
    case static_cast<std::uint16_t>(MessageType::Environment): {
      h.type = MessageType::Environment;
      if (!fixedSize(kEnvironmentSize)) return failed(DropReason::LengthMismatch, "payload_length");
      Environment e;
      e.visibility_m = p.f32(0);
      e.extinction_per_m = p.f32(4);
      e.albedo = p.f32(8);
      const std::uint8_t phase = p.u8(12);
      e.g = p.f32(16);
      e.droplet_diameter_um = p.f32(20);
      e.ambient_cd_m2 = p.f32(24);
      const std::pair<std::string_view, float> numbers[] = {
          {"visibility_m", e.visibility_m}, {"extinction_per_m", e.extinction_per_m}, {"albedo", e.albedo},
          {"g", e.g}, {"droplet_diameter_um", e.droplet_diameter_um}, {"ambient_cd_m2", e.ambient_cd_m2}};
      for (const auto& [field, v] : numbers)
        if (!std::isfinite(v)) return failed(DropReason::NonFinite, field);
      if (e.visibility_m != 0.0f && (e.visibility_m < 1.0f || e.visibility_m > 1e5f))
        return failed(DropReason::OutOfRange, "visibility_m");
      if (e.visibility_m == 0.0f && !(e.extinction_per_m > 0.0f && e.extinction_per_m <= 10.0f))
        return failed(DropReason::OutOfRange, "extinction_per_m");
      if (e.albedo < 0.0f || e.albedo > 1.0f) return failed(DropReason::OutOfRange, "albedo");
      if (phase > 2) return failed(DropReason::OutOfRange, "phase");
      e.phase = static_cast<PhaseCode>(phase);
      if (p.u8(13) != 0 || p.u8(14) != 0 || p.u8(15) != 0) return failed(DropReason::OutOfRange, "reserved");
      if (e.phase == PhaseCode::HenyeyGreenstein && !(e.g > -1.0f && e.g < 1.0f))
        return failed(DropReason::OutOfRange, "g");
      if (e.phase == PhaseCode::FogMie && !(e.droplet_diameter_um >= 5.0f && e.droplet_diameter_um <= 50.0f))
        return failed(DropReason::OutOfRange, "droplet_diameter_um");
      if (e.ambient_cd_m2 < 0.0f || e.ambient_cd_m2 > 1e5f) return failed(DropReason::OutOfRange, "ambient_cd_m2");
      out.message.payload = e;
      break;
    }
    case static_cast<std::uint16_t>(MessageType::FrameRequest): {
      h.type = MessageType::FrameRequest;
      if (!fixedSize(kFrameRequestSize)) return failed(DropReason::LengthMismatch, "payload_length");
      out.message.payload = FrameRequest{p.u64(0)};
      break;
    }
    default:
      return failed(DropReason::UnknownType, "type");
  }
  out.ok = true;
  return out;
}

std::vector<std::uint8_t> encode(const Message& m) {
  std::vector<std::uint8_t> body;
  Writer w(body);
  MessageType type = MessageType::EgoState;
  if (const auto* e = std::get_if<EgoState>(&m.payload)) {
    type = MessageType::EgoState;
    writePose(w, e->pose);
    w.f32(e->speed_m_s);
  } else if (const auto* l = std::get_if<LampState>(&m.payload)) {
    type = MessageType::LampState;
    w.u32(l->lights);
    w.f32(l->bending_deg);
    w.u32(0);
  } else if (const auto* t = std::get_if<TrafficList>(&m.payload)) {
    type = MessageType::TrafficList;
    w.u16(static_cast<std::uint16_t>(t->objects.size()));
    w.u16(t->complete ? 1 : 0);
    for (const TrafficObject& o : t->objects) {
      w.u32(o.id);
      w.u16(o.vehicle_class);
      w.u16(o.removed ? 1 : 0);
      writePose(w, o.pose);
      w.u32(o.lights);
    }
  } else if (const auto* env = std::get_if<Environment>(&m.payload)) {
    type = MessageType::Environment;
    w.f32(env->visibility_m);
    w.f32(env->extinction_per_m);
    w.f32(env->albedo);
    w.u8(static_cast<std::uint8_t>(env->phase));
    w.u8(0);
    w.u8(0);
    w.u8(0);
    w.f32(env->g);
    w.f32(env->droplet_diameter_um);
    w.f32(env->ambient_cd_m2);
  } else if (const auto* fr = std::get_if<FrameRequest>(&m.payload)) {
    type = MessageType::FrameRequest;
    w.u64(fr->frame);
  }
  std::vector<std::uint8_t> out;
  out.reserve(kHeaderSize + body.size());
  Writer h(out);
  h.u32(kProtocolMagic);
  h.u16(kProtocolVersion);
  h.u16(static_cast<std::uint16_t>(type));
  h.u32(static_cast<std::uint32_t>(body.size()));
  h.u32(m.header.sequence);
  h.f64(m.header.sim_time_s);
  out.insert(out.end(), body.begin(), body.end());
  return out;
}

}  // namespace fogbeam::ipc
