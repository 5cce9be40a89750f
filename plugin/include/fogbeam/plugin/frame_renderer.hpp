// fogbeam — one output view of the service: from a simulation state (ipc::SimSnapshot) to a
// packed frame and its metadata. Shared by `fogbeam serve` (frames to shared memory) and
// `fogbeam replay` (frames to files), so both render exactly the same way.
//
// Per frame: the ego pose places the driver's eye (ServiceConfig::eye_m + the channel's offset
// and orientation) and the ego rig; light bits switch rig lamps by role; live traffic objects get
// their class's rig; the world scene adds world lamps, planes and glTF. Surfaces (GL or CPU),
// airlight (the configured method; ego lamps through view tables), composite, pack.
//
// Issue 7 additions, each from the service config ([render] airlight, [glow], [glare]):
//  * airlight = "gpu": the GL surface pass computes the accurate airlight of every lit lamp in
//    the same draw as the surfaces (GlSurfacePass::setAirlight); no CPU tables, no table waits.
//  * glow and glare (LampEffects) of the lamps that are on, per frame, on the airlight's pool.
//  * rig lamps with an aperture become their point lamps once placed (expandRig, placeRigPoint).
//
// Tables that depend on the fog and on the ego lamps' bending angle (quantised to
// kBendingStepDeg) take seconds to build. With `wait` = false (free-running service) a change
// starts a build on a background thread and frames go on with the previous fog and bending until
// it is ready (RenderedFrame::pending says so); with `wait` = true (lock-step, replay) the frame
// waits, so that a run is deterministic.
//
// Thread-safety: one thread drives a ChannelRenderer; distinct renderers are independent.
#pragma once

#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/lamp_effects.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <memory>
#include <vector>

namespace fogbeam {
class GlSurfacePass;
}

namespace fogbeam::plugin {

/// Bending angles are applied in steps of this many degrees (each step has its own view tables).
inline constexpr double kBendingStepDeg = 1.0;

struct RenderedFrame {
  ipc::FrameMeta meta;             ///< everything but the frame numbers and publish time
  FrameLayers layers;              ///< linear layers (composite, airlight, surface, overlay, T, distance)
  std::vector<std::byte> packed;   ///< the channel's format, ready to publish
  std::size_t airlight_evaluated = 0;  ///< pixels evaluated (the rest interpolated)
  std::size_t traffic_evaluated = 0;   ///< pixels of the traffic layer evaluated (0: no traffic lamps)
  bool pending = false;            ///< a fog or bending change is still being tabulated
  double table_wait_ms = 0.0;      ///< time this frame waited for tables (wait = true)
  /// Glow and glare figures of the lamps that are on (LampEffectsReport: per lamp, eye
  /// illuminance in lx, veiling luminance at the image centre in cd/m², glow and glare
  /// seconds). Empty and 0 when [glow] and [glare] are both off.
  LampEffectsReport effects;
  double effects_ms = 0.0;         ///< wall time of glow + glare, ms (0 when both are off)
};

/// One point lamp of a rig lamp, in the vehicle frame: a rig lamp without an aperture is one
/// point, one with an aperture its expandSceneLamp points ("name [k/N]", colour × weight).
struct RigPoint {
  SceneLamp lamp;            ///< vehicle frame, aperture Point
  std::size_t rig_lamp = 0;  ///< the index in VehicleRig::lamps of the lamp it belongs to
};

/// Every lamp of `rig` as its point lamps, rig order (the points of a lamp consecutive).
[[nodiscard]] std::vector<RigPoint> expandRig(const VehicleRig& rig);

/// `point` (of rig lamp `lamp`) at a vehicle pose: world position origin_m + worldFromVehicle ·
/// p, orientation worldFromVehicle · worldFromLamp. `bend` (a rotation about the vehicle's z,
/// or null) swivels it about the vertical axis through its rig lamp's centre, as it swivels the
/// whole lamp, so that a lamp's face turns with it. The mount is left as the rig's (Vehicle).
[[nodiscard]] SceneLamp placeRigPoint(const RigPoint& point, const RigLamp& lamp, const Mat3& worldFromVehicle,
                                      const Vec3& origin_m, const Mat3* bend);

class ChannelRenderer {
 public:
  /// `world`: the world scene (its world lamps, planes, glTF; camera and vehicle lamps unused).
  /// `gl`: a surface pass to use (shared by the channels of one thread), or null for CPU planes.
  /// With [render] airlight = "gpu" the pass is required (an error without it) and its airlight
  /// stage is switched on here.
  [[nodiscard]] static Result<std::unique_ptr<ChannelRenderer>> create(const ServiceConfig& config, std::size_t channel,
                                                                       const Scene& world, GlSurfacePass* gl);
  ~ChannelRenderer();
  ChannelRenderer(const ChannelRenderer&) = delete;
  ChannelRenderer& operator=(const ChannelRenderer&) = delete;

  /// Renders `state` as of `now` (traffic liveness). Errors only for failures of the renderer
  /// itself (never for input values, which the decoders have checked).
  [[nodiscard]] Status render(const ipc::SimSnapshot& state, ipc::Clock::time_point now, bool wait, RenderedFrame& out);

  [[nodiscard]] const ChannelConfig& channel() const;
  [[nodiscard]] std::uint32_t shmFormat() const;

  struct Impl;

 private:
  explicit ChannelRenderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// The fog an environment message describes (fallback: phase, albedo … when a value is absent).
[[nodiscard]] Medium mediumFrom(const ipc::Environment& e);
/// The environment message that describes a medium.
[[nodiscard]] ipc::Environment environmentFrom(const Medium& m);

}  // namespace fogbeam::plugin
