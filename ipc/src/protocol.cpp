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

// ---- The documented layout (docs/protocol.md), checked at compile time. decode() reads at the
// wire:: offsets; encode() appends the fields in the tables' order (Writer below), so the two agree
// only while every field starts where the one before it ends (`follows`). Both that and the
// documented numbers themselves are asserted: an edit that breaks the document fails to compile.
// tests/ipc/test_layout_docs.cpp checks the document's tables against these constants.
constexpr bool follows(std::size_t next, std::size_t field, std::size_t fieldBytes) { return next == field + fieldBytes; }

// Transport and header: "FGBM" little-endian, version 1, 24 bytes; at most 65 507 bytes, the
// largest UDP payload over IPv4 (65 535 − 20 IP − 8 UDP).
static_assert(kProtocolMagic == 0x4D424746u);
static_assert(kProtocolMagic == (std::uint32_t{'F'} | std::uint32_t{'G'} << 8 | std::uint32_t{'B'} << 16 |
                                 std::uint32_t{'M'} << 24));
static_assert(kProtocolVersion == 1);
static_assert(kMaxDatagram == 65507 && kMaxDatagram == 65535 - 20 - 8);
static_assert(wire::kHeaderMagic == 0);
static_assert(wire::kHeaderVersion == 4 && follows(wire::kHeaderVersion, wire::kHeaderMagic, 4));
static_assert(wire::kHeaderType == 6 && follows(wire::kHeaderType, wire::kHeaderVersion, 2));
static_assert(wire::kHeaderPayloadLength == 8 && follows(wire::kHeaderPayloadLength, wire::kHeaderType, 2));
static_assert(wire::kHeaderSequence == 12 && follows(wire::kHeaderSequence, wire::kHeaderPayloadLength, 4));
static_assert(wire::kHeaderSimTime == 16 && follows(wire::kHeaderSimTime, wire::kHeaderSequence, 4));
static_assert(kHeaderSize == 24 && follows(kHeaderSize, wire::kHeaderSimTime, 8));
// Header "type": 1 ego state, 2 lamp state, 3 traffic list, 4 environment, 5 frame request.
static_assert(static_cast<int>(MessageType::EgoState) == 1 && static_cast<int>(MessageType::LampState) == 2 &&
              static_cast<int>(MessageType::TrafficList) == 3 && static_cast<int>(MessageType::Environment) == 4 &&
              static_cast<int>(MessageType::FrameRequest) == 5);

// Pose: f64 x, y, z (m), f32 yaw, pitch, roll (deg); 36 bytes.
static_assert(wire::kPoseX == 0);
static_assert(wire::kPoseY == 8 && follows(wire::kPoseY, wire::kPoseX, 8));
static_assert(wire::kPoseZ == 16 && follows(wire::kPoseZ, wire::kPoseY, 8));
static_assert(wire::kPoseYaw == 24 && follows(wire::kPoseYaw, wire::kPoseZ, 8));
static_assert(wire::kPosePitch == 28 && follows(wire::kPosePitch, wire::kPoseYaw, 4));
static_assert(wire::kPoseRoll == 32 && follows(wire::kPoseRoll, wire::kPosePitch, 4));
static_assert(wire::kPoseSize == 36 && follows(wire::kPoseSize, wire::kPoseRoll, 4));

// Ego state (type 1, 40 bytes): x 0, y 8, z 16, yaw 24, pitch 28, roll 32, speed 36.
static_assert(wire::kEgoPose == 0);
static_assert(wire::kEgoPose + wire::kPoseY == 8 && wire::kEgoPose + wire::kPoseZ == 16);
static_assert(wire::kEgoPose + wire::kPoseYaw == 24 && wire::kEgoPose + wire::kPosePitch == 28 &&
              wire::kEgoPose + wire::kPoseRoll == 32);
static_assert(wire::kEgoSpeed == 36 && follows(wire::kEgoSpeed, wire::kEgoPose, wire::kPoseSize));
static_assert(kEgoStateSize == 40 && follows(kEgoStateSize, wire::kEgoSpeed, 4));

// Lamp state (type 2, 12 bytes): lights 0, bending 4, reserved 8.
static_assert(wire::kLampLights == 0);
static_assert(wire::kLampBending == 4 && follows(wire::kLampBending, wire::kLampLights, 4));
static_assert(wire::kLampReserved == 8 && follows(wire::kLampReserved, wire::kLampBending, 4));
static_assert(kLampStateSize == 12 && follows(kLampStateSize, wire::kLampReserved, 4));
// Light bits: VTD RDB's positions for park, low, high, front fog and DRL; fogbeam's for the rest.
static_assert(light::kPosition == 0x001 && light::kLowBeam == 0x002 && light::kHighBeam == 0x004 &&
              light::kBrake == 0x008 && light::kIndicatorLeft == 0x020 && light::kIndicatorRight == 0x040 &&
              light::kFrontFog == 0x100 && light::kRearFog == 0x200 && light::kDrl == 0x800);

// Traffic list (type 3, 4 + 48·n bytes): count 0, flags 2, object k at 4 + 48 k; at most 1 364
// objects, as many as fit in one datagram.
static_assert(wire::kTrafficCount == 0);
static_assert(wire::kTrafficFlags == 2 && follows(wire::kTrafficFlags, wire::kTrafficCount, 2));
static_assert(wire::kTrafficObjects == 4 && follows(wire::kTrafficObjects, wire::kTrafficFlags, 2));
static_assert(kTrafficHeaderSize == 4 && kTrafficHeaderSize == wire::kTrafficObjects);
static_assert(kMaxTrafficPerDatagram == 1364 &&
              kMaxTrafficPerDatagram == (kMaxDatagram - kHeaderSize - kTrafficHeaderSize) / kTrafficObjectSize);
// Traffic object (48 bytes): id 0, class 4, flags 6, x y z 8, yaw pitch roll 32, lights 44.
static_assert(wire::kObjectId == 0);
static_assert(wire::kObjectVehicleClass == 4 && follows(wire::kObjectVehicleClass, wire::kObjectId, 4));
static_assert(wire::kObjectFlags == 6 && follows(wire::kObjectFlags, wire::kObjectVehicleClass, 2));
static_assert(wire::kObjectPose == 8 && follows(wire::kObjectPose, wire::kObjectFlags, 2));
static_assert(wire::kObjectPose + wire::kPoseYaw == 32);
static_assert(wire::kObjectLights == 44 && follows(wire::kObjectLights, wire::kObjectPose, wire::kPoseSize));
static_assert(kTrafficObjectSize == 48 && follows(kTrafficObjectSize, wire::kObjectLights, 4));

// Environment (type 4, 28 bytes): visibility 0, extinction 4, albedo 8, phase 12, reserved 13–15,
// g 16, droplet diameter 20, ambient 24.
static_assert(wire::kEnvVisibility == 0);
static_assert(wire::kEnvExtinction == 4 && follows(wire::kEnvExtinction, wire::kEnvVisibility, 4));
static_assert(wire::kEnvAlbedo == 8 && follows(wire::kEnvAlbedo, wire::kEnvExtinction, 4));
static_assert(wire::kEnvPhase == 12 && follows(wire::kEnvPhase, wire::kEnvAlbedo, 4));
static_assert(wire::kEnvReserved == 13 && follows(wire::kEnvReserved, wire::kEnvPhase, 1));
static_assert(wire::kEnvG == 16 && follows(wire::kEnvG, wire::kEnvReserved, 3));
static_assert(wire::kEnvDropletDiameter == 20 && follows(wire::kEnvDropletDiameter, wire::kEnvG, 4));
static_assert(wire::kEnvAmbient == 24 && follows(wire::kEnvAmbient, wire::kEnvDropletDiameter, 4));
static_assert(kEnvironmentSize == 28 && follows(kEnvironmentSize, wire::kEnvAmbient, 4));
static_assert(static_cast<int>(PhaseCode::Isotropic) == 0 && static_cast<int>(PhaseCode::HenyeyGreenstein) == 1 &&
              static_cast<int>(PhaseCode::FogMie) == 2);

// Frame request (type 5, 8 bytes): the frame number at 0.
static_assert(wire::kFrameNumber == 0);
static_assert(kFrameRequestSize == 8 && follows(kFrameRequestSize, wire::kFrameNumber, 8));

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
  static constexpr std::size_t kPosOffset[3] = {wire::kPoseX, wire::kPoseY, wire::kPoseZ};
  for (std::size_t k = 0; k < 3; ++k) {
    p.position_m[k] = r.f64(o + kPosOffset[k]);
    if (const Fail* f = check(p.position_m[k], -kMaxPosition_m, kMaxPosition_m, kPos[k], slot)) return f;
  }
  p.yaw_deg = r.f32(o + wire::kPoseYaw);
  p.pitch_deg = r.f32(o + wire::kPosePitch);
  p.roll_deg = r.f32(o + wire::kPoseRoll);
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
  if (r.u32(wire::kHeaderMagic) != kProtocolMagic) return failed(DropReason::BadMagic, "magic");
  if (r.u16(wire::kHeaderVersion) != kProtocolVersion) return failed(DropReason::BadVersion, "version");
  const std::uint16_t type = r.u16(wire::kHeaderType);
  DecodeResult out;
  Header& h = out.message.header;
  h.payload_length = r.u32(wire::kHeaderPayloadLength);
  h.sequence = r.u32(wire::kHeaderSequence);
  h.sim_time_s = r.f64(wire::kHeaderSimTime);
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
      if (const Fail* f = readPose(p, wire::kEgoPose, e.pose, slot)) return failed(*f);
      e.speed_m_s = p.f32(wire::kEgoSpeed);
      if (const Fail* f = check(e.speed_m_s, -kMaxSpeed_m_s, kMaxSpeed_m_s, "speed_m_s", slot)) return failed(*f);
      out.message.payload = e;
      break;
    }
    case static_cast<std::uint16_t>(MessageType::LampState): {
      h.type = MessageType::LampState;
      if (!fixedSize(kLampStateSize)) return failed(DropReason::LengthMismatch, "payload_length");
      LampState l;
      l.lights = p.u32(wire::kLampLights) & light::kKnown;  // other bits: lights fogbeam does not draw
      l.bending_deg = p.f32(wire::kLampBending);
      if (const Fail* f = check(l.bending_deg, -kMaxBending_deg, kMaxBending_deg, "bending_deg", slot))
        return failed(*f);
      if (p.u32(wire::kLampReserved) != 0) return failed(DropReason::OutOfRange, "reserved");
      out.message.payload = l;
      break;
    }
    case static_cast<std::uint16_t>(MessageType::TrafficList): {
      h.type = MessageType::TrafficList;
      if (payload.size() < kTrafficHeaderSize) return failed(DropReason::LengthMismatch, "payload_length");
      const std::size_t count = p.u16(wire::kTrafficCount);
      const std::uint16_t flags = p.u16(wire::kTrafficFlags);
      if (count > kMaxTrafficPerDatagram) return failed(DropReason::BadCount, "count");
      if (payload.size() != kTrafficHeaderSize + count * kTrafficObjectSize)
        return failed(DropReason::BadCount, "count");
      if ((flags & ~1u) != 0) return failed(DropReason::OutOfRange, "flags");
      TrafficList t;
      t.complete = (flags & 1u) != 0;
      t.objects.resize(count);
      for (std::size_t k = 0; k < count; ++k) {
        const std::size_t o = wire::kTrafficObjects + k * kTrafficObjectSize;
        TrafficObject& obj = t.objects[k];
        obj.id = p.u32(o + wire::kObjectId);
        obj.vehicle_class = p.u16(o + wire::kObjectVehicleClass);
        const std::uint16_t objFlags = p.u16(o + wire::kObjectFlags);
        if ((objFlags & ~1u) != 0) return failed(DropReason::OutOfRange, "object.flags");
        obj.removed = (objFlags & 1u) != 0;
        if (const Fail* f = readPose(p, o + wire::kObjectPose, obj.pose, slot)) return failed(*f);
        obj.lights = p.u32(o + wire::kObjectLights) & light::kKnown;
      }
      out.message.payload = std::move(t);
      break;
    }
    case static_cast<std::uint16_t>(MessageType::Environment): {
      h.type = MessageType::Environment;
      if (!fixedSize(kEnvironmentSize)) return failed(DropReason::LengthMismatch, "payload_length");
      Environment e;
      e.visibility_m = p.f32(wire::kEnvVisibility);
      e.extinction_per_m = p.f32(wire::kEnvExtinction);
      e.albedo = p.f32(wire::kEnvAlbedo);
      const std::uint8_t phase = p.u8(wire::kEnvPhase);
      e.g = p.f32(wire::kEnvG);
      e.droplet_diameter_um = p.f32(wire::kEnvDropletDiameter);
      e.ambient_cd_m2 = p.f32(wire::kEnvAmbient);
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
      if (p.u8(wire::kEnvReserved) != 0 || p.u8(wire::kEnvReserved + 1) != 0 || p.u8(wire::kEnvReserved + 2) != 0)
        return failed(DropReason::OutOfRange, "reserved");
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
      out.message.payload = FrameRequest{p.u64(wire::kFrameNumber)};
      break;
    }
    default:
      return failed(DropReason::UnknownType, "type");
  }
  out.ok = true;
  return out;
}

// Appends each record's fields in their wire:: order, one after the other: the compile-time checks
// at the top of this file make that the documented layout.
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
