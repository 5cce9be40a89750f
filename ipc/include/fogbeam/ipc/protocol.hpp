// fogbeam — UDP protocol v1 between a simulator host and fogbeam (docs/protocol.md, byte by
// byte). Little-endian, fixed-size records, one message per datagram:
//
//   header (24 B) | payload (payload_length B)
//
// Messages: ego state, ego lamp state, traffic list, environment (fog), frame request
// (lock-step). Decoding validates everything (magic, version, type, lengths, counts, finite
// numbers, ranges) and reports the first failure as a DropReason; it never reads out of bounds
// and never throws. Encoding is provided for the host stand-in (`fogbeam send`) and tests.
//
// Thread-safety: pure functions.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <variant>
#include <vector>

namespace fogbeam::ipc {

inline constexpr std::uint32_t kProtocolMagic = 0x4D42'4746u;  ///< "FGBM" as little-endian bytes 46 47 42 4D
inline constexpr std::uint16_t kProtocolVersion = 1;
inline constexpr std::size_t kHeaderSize = 24;
/// Largest UDP payload over IPv4 (65535 − 20 − 8): no valid datagram is longer.
inline constexpr std::size_t kMaxDatagram = 65507;

enum class MessageType : std::uint16_t {
  EgoState = 1,
  LampState = 2,
  TrafficList = 3,
  Environment = 4,
  FrameRequest = 5,
};

/// Light state bits (docs/protocol.md). Park, low beam, high beam, front fog and DRL take the
/// positions of VIRES VTD's RDB lightMask (0x1, 0x2, 0x4, 0x100, 0x800); the others are
/// fogbeam's assignments, in positions VTD's mask leaves to other lights.
namespace light {
inline constexpr std::uint32_t kPosition = 0x1;
inline constexpr std::uint32_t kLowBeam = 0x2;
inline constexpr std::uint32_t kHighBeam = 0x4;
inline constexpr std::uint32_t kBrake = 0x8;
inline constexpr std::uint32_t kIndicatorLeft = 0x20;
inline constexpr std::uint32_t kIndicatorRight = 0x40;
inline constexpr std::uint32_t kFrontFog = 0x100;
inline constexpr std::uint32_t kRearFog = 0x200;
inline constexpr std::uint32_t kDrl = 0x800;
inline constexpr std::uint32_t kKnown =
    kPosition | kLowBeam | kHighBeam | kBrake | kIndicatorLeft | kIndicatorRight | kFrontFog | kRearFog | kDrl;
/// The ego's light mask until the first lamp state (docs/service.md, "How a frame is made",
/// step 3): low beam + position. The state store starts with it, so that bits a CAN input sets
/// before any lamp message merge into it.
inline constexpr std::uint32_t kInitialEgo = kLowBeam | kPosition;
}  // namespace light

struct Header {
  MessageType type = MessageType::EgoState;
  std::uint32_t payload_length = 0;  ///< bytes after the header
  std::uint32_t sequence = 0;        ///< per sender, +1 per datagram of any type (wraps)
  double sim_time_s = 0.0;           ///< the sender's simulation time, seconds
};

/// Pose in the simulator's world frame (docs/physics.md: x forward, y left, z up; yaw about z,
/// pitch about the new y with positive = nose down, roll about the new x).
struct Pose {
  std::array<double, 3> position_m{0.0, 0.0, 0.0};
  float yaw_deg = 0.0f, pitch_deg = 0.0f, roll_deg = 0.0f;
};

struct EgoState {
  Pose pose;            ///< the vehicle reference point (the eye offsets come from the rig config)
  float speed_m_s = 0.0f;
};

struct LampState {
  std::uint32_t lights = 0;       ///< light:: bits
  float bending_deg = 0.0f;       ///< adaptive front lighting swivel, + = to the left, |·| ≤ 45
};

struct TrafficObject {
  std::uint32_t id = 0;           ///< the host's object id, unique per sender
  std::uint16_t vehicle_class = 0;  ///< selects a lamp rig from the service config (0 = default)
  bool removed = false;           ///< the object is gone: drop it now
  Pose pose;
  std::uint32_t lights = 0;       ///< light:: bits
};

/// At most this many objects in one datagram (65507 − 24 − 4) / 48.
inline constexpr std::size_t kMaxTrafficPerDatagram = 1364;

struct TrafficList {
  bool complete = false;  ///< true: objects of this sender not listed are removed
  std::vector<TrafficObject> objects;
};

enum class PhaseCode : std::uint8_t { Isotropic = 0, HenyeyGreenstein = 1, FogMie = 2 };

struct Environment {
  float visibility_m = 0.0f;       ///< MOR; 0 = use extinction_per_m
  float extinction_per_m = 0.0f;   ///< used when visibility_m is 0
  float albedo = 0.95f;
  PhaseCode phase = PhaseCode::HenyeyGreenstein;
  float g = 0.85f;                 ///< Henyey–Greenstein only
  float droplet_diameter_um = 10.0f;  ///< fog-mie only
  float ambient_cd_m2 = 0.0f;
};

struct FrameRequest {
  std::uint64_t frame = 0;  ///< lock-step: render this frame number now
};

using Payload = std::variant<EgoState, LampState, TrafficList, Environment, FrameRequest>;

struct Message {
  Header header;
  Payload payload;
};

/// Why a datagram was dropped. Every value has a counter in the receiver's statistics.
enum class DropReason : std::uint8_t {
  TooShort,          ///< shorter than the header
  BadMagic,
  BadVersion,
  UnknownType,
  LengthMismatch,    ///< payload_length ≠ bytes received − header, or ≠ the type's size
  BadCount,          ///< traffic count too large or inconsistent with the length
  NonFinite,         ///< NaN or ±inf in a number
  OutOfRange,        ///< a value outside its documented range, or unknown bits/codes
  SenderNotAllowed,  ///< source address not on the allow-list (receiver)
  Duplicate,         ///< sequence number already seen (receiver)
  OutOfOrder,        ///< older than the newest seen from this sender (receiver)
  TooManyObjects,    ///< a traffic list none of whose objects fit the state store's bound (receiver)
  Count_
};
inline constexpr std::size_t kDropReasonCount = static_cast<std::size_t>(DropReason::Count_);
[[nodiscard]] std::string_view toString(DropReason r);

/// A decoded message, or the reason it was dropped and a short human-readable detail
/// (field name and value) for the rate-limited log.
struct DecodeResult {
  bool ok = false;
  Message message;
  DropReason reason = DropReason::TooShort;
  std::string_view field;  ///< the offending field (static string), empty when ok
};

/// Decodes one datagram. Never throws, never reads outside `bytes`.
[[nodiscard]] DecodeResult decode(std::span<const std::uint8_t> bytes) noexcept;

/// Encodes one message (header.type and payload_length are set from the payload).
[[nodiscard]] std::vector<std::uint8_t> encode(const Message& message);

/// Payload size in bytes of a fixed-size message type (traffic: of the count field plus one
/// object: 4 + 48 n).
inline constexpr std::size_t kEgoStateSize = 40;
inline constexpr std::size_t kLampStateSize = 12;
inline constexpr std::size_t kTrafficHeaderSize = 4;
inline constexpr std::size_t kTrafficObjectSize = 48;
inline constexpr std::size_t kEnvironmentSize = 28;
inline constexpr std::size_t kFrameRequestSize = 8;

/// Byte offsets of every field, as in docs/protocol.md's tables: the header's from the start of
/// the datagram, a payload's from the end of the header, a traffic object's from the object's
/// start, a pose's from the pose's start (at 0 in the ego state, at kObjectPose in an object).
/// decode() reads at these offsets; encode() writes the fields in this order, one after the
/// other, and protocol.cpp checks at compile time that each field starts where the one before it
/// ends and that the offsets are the documented ones. tests/ipc/test_layout_docs.cpp compares
/// them with the document's tables at run time.
namespace wire {
// Header (24 bytes).
inline constexpr std::size_t kHeaderMagic = 0;          // u32
inline constexpr std::size_t kHeaderVersion = 4;        // u16
inline constexpr std::size_t kHeaderType = 6;           // u16
inline constexpr std::size_t kHeaderPayloadLength = 8;  // u32
inline constexpr std::size_t kHeaderSequence = 12;      // u32
inline constexpr std::size_t kHeaderSimTime = 16;       // f64, s
// Pose (36 bytes), inside the ego state and a traffic object.
inline constexpr std::size_t kPoseX = 0;       // f64, m
inline constexpr std::size_t kPoseY = 8;       // f64, m
inline constexpr std::size_t kPoseZ = 16;      // f64, m
inline constexpr std::size_t kPoseYaw = 24;    // f32, deg
inline constexpr std::size_t kPosePitch = 28;  // f32, deg
inline constexpr std::size_t kPoseRoll = 32;   // f32, deg
inline constexpr std::size_t kPoseSize = 36;
// Ego state (type 1).
inline constexpr std::size_t kEgoPose = 0;    // pose
inline constexpr std::size_t kEgoSpeed = 36;  // f32, m/s
// Lamp state (type 2).
inline constexpr std::size_t kLampLights = 0;    // u32, light:: bits
inline constexpr std::size_t kLampBending = 4;   // f32, deg
inline constexpr std::size_t kLampReserved = 8;  // u32, 0
// Traffic list (type 3): count, flags, then count objects of kTrafficObjectSize.
inline constexpr std::size_t kTrafficCount = 0;    // u16
inline constexpr std::size_t kTrafficFlags = 2;    // u16
inline constexpr std::size_t kTrafficObjects = 4;  // object 0
// Traffic object.
inline constexpr std::size_t kObjectId = 0;            // u32
inline constexpr std::size_t kObjectVehicleClass = 4;  // u16
inline constexpr std::size_t kObjectFlags = 6;         // u16
inline constexpr std::size_t kObjectPose = 8;          // pose
inline constexpr std::size_t kObjectLights = 44;       // u32, light:: bits
// Environment (type 4).
inline constexpr std::size_t kEnvVisibility = 0;       // f32, m
inline constexpr std::size_t kEnvExtinction = 4;       // f32, 1/m
inline constexpr std::size_t kEnvAlbedo = 8;           // f32
inline constexpr std::size_t kEnvPhase = 12;           // u8, PhaseCode
inline constexpr std::size_t kEnvReserved = 13;        // u8 ×3, 0
inline constexpr std::size_t kEnvG = 16;               // f32
inline constexpr std::size_t kEnvDropletDiameter = 20; // f32, µm
inline constexpr std::size_t kEnvAmbient = 24;         // f32, cd/m²
// Frame request (type 5).
inline constexpr std::size_t kFrameNumber = 0;  // u64
}  // namespace wire

}  // namespace fogbeam::ipc
