// fogbeam — one output view of the service: from a simulation state (ipc::SimSnapshot) to a
// packed frame and what the renderer knows about it (RenderedFrame: view, inputs used, stage
// times). Shared by `fogbeam serve` (frames to shared memory) and `fogbeam replay` (frames to
// files) through the frame pipeline (frame_pipeline.hpp), so both render exactly the same way;
// the service maps a frame to the wire metadata (wireMeta, service.hpp).
//
// Per frame, in stages (ChannelRenderer::render in frame_renderer.cpp):
//  1. tables: the fog and quantised bending the state wants; swap in, await or start a build;
//  2. scenes: the ego pose places the driver's eye (ServiceConfig::eye_m + the channel's offset
//     and orientation) and the ego rig; light bits switch rig lamps by role; the world scene adds
//     world lamps, planes and glTF; live traffic objects get their class's rig;
//  3. surfaces (GL or CPU planes);
//  4. airlight (the configured method; ego lamps through view tables, traffic per pixel; or the
//     GL pass's GPU airlight);
//  5. glow and glare of the lamps that are on;
//  6. composite and pack into the channel's format.
//
// Issue 7 additions, each from the service config ([render] airlight, [glow], [glare]):
//  * airlight = "gpu": the GL surface pass computes the accurate airlight of every lit lamp in
//    the same draw as the surfaces (GlSurfacePass::setAirlight); no CPU tables, no table waits.
//  * glow and glare (LampEffects) of the lamps that are on, per frame, on the airlight's pool.
//  * rig lamps with an aperture become their point lamps once placed (expandRig, placeRigPoint).
//
// The fog ladder ([render] fog_ladder_ratio): while the fog changes frame after frame, the ego
// lamps' view tables are built in the background at K_t = ratio^m per metre (rungs), one at a
// time, around the fog and ahead of it; a frame whose fog lies between two rungs (same fog
// otherwise, bending within the tolerance) reads both instead of going per pixel
// (RenderedFrame::fog_rungs), and is not pending.
//
// Tables that depend on the fog and on the ego lamps' bending angle (tables for one angle serve
// angles within [ego] bending_tolerance_deg of it) take seconds to build; a change starts a build on a background thread
// (RenderedFrame::pending while it is not in use). With [render] pending_tables = "per-pixel"
// (the default) frames meanwhile evaluate every lamp that is on per pixel, as moving lamps, in
// the wanted fog and bending, and nothing waits: free-running (`wait` = false) takes a build when
// it is done, lock-step and replay (`wait` = true) table_adopt_frames frames after it started,
// so that a run is deterministic. With "previous", free-running frames keep the previous fog and
// bending until the build is done, and `wait` = true (and the first frame) waits for it.
//
// render() is begin() (stages 1–3) then finish() (stages 4–6). Called apart, they let the surface
// pass of frame N+1 run on the GL thread while stages 4–6 of frame N run on another (frame
// overlap, FramePipeline; docs/service.md, "Overlapped frames"): each begun frame keeps its own
// scenes, surface buffers and decisions (one of two slots), and a table build taken by frame N+1
// replaces the evaluator only when N+1's stage 4 starts, after N's airlight has read the old one.
// The same calls in the same order on the same data: frames are byte for byte those of render().
//
// Thread-safety: one thread drives a ChannelRenderer (begin(), render() on the thread that owns
// the GL surface pass); finish() may run on a second thread, beside the begin() of the next
// frame, never beside another finish() or render(). Distinct renderers are independent.
#pragma once

#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/plugin/host_depth.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/lamp_effects.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace fogbeam {
class GlSurfacePass;
}

namespace fogbeam::plugin {

/// Where a frame was seen from and what it covers (the view fields of the shm metadata).
struct FrameView {
  Vec3 eye_m{0.0};  ///< the channel's eye in the world frame, m
  /// The ego's attitude, deg (the pose's yaw, pitch, roll; the channel's own rotation relative
  /// to the vehicle is not in it).
  float yaw_deg = 0.0f, pitch_deg = 0.0f, roll_deg = 0.0f;
  /// The whole horizontal and vertical extent, deg (off-axis views: left + right, up + down).
  float fov_x_deg = 0.0f, fov_y_deg = 0.0f;
  /// An off-axis view's half-angles left, right, up, down, deg; all 0 for a centred one.
  std::array<float, 4> frustum_deg{0.0f, 0.0f, 0.0f, 0.0f};
};

/// The inputs a frame was made of: the state snapshot's values and stamps it used.
struct FrameInputs {
  double sim_time_s = 0.0;   ///< the ego state's sender time, s (0 before the first ego state)
  /// ipc::light bits the ego's lamps were switched by (low beam + position until the first lamp
  /// state arrives).
  std::uint32_t lights = 0;
  /// Sender sequence numbers of the ego, lamp and environment messages used; 0 = none yet.
  std::uint32_t ego_sequence = 0, lamp_sequence = 0, environment_sequence = 0;
  std::uint32_t traffic_count = 0;  ///< live traffic objects (updated within the timeout), with or without a rig
};

/// Wall time of each stage of one render() call, ms.
struct FrameTimings {
  double table_wait_ms = 0.0;  ///< waited for fog/bending tables (wait = true, or the first frame)
  /// The surface pass. With the GPU airlight (one GL pass for both) the pass's wall time less
  /// its airlight draw's GPU time.
  double surface_ms = 0.0;
  double airlight_ms = 0.0;   ///< the airlight (GPU airlight: its draw's GPU time, GL timer query)
  double effects_ms = 0.0;    ///< glow + glare; 0 when both are off
  double composite_ms = 0.0;  ///< composite, glow and glare added, and packing into the channel's format
  double total_ms = 0.0;      ///< the whole frame, table wait included
};

/// One channel's frame and what the renderer knows about it. The frame loop's bookkeeping
/// (frame number, the request it answers, input-to-publish latency) is not in it: the service
/// adds that when it maps a frame to the wire (wireMeta in service.hpp).
struct RenderedFrame {
  FrameLayers layers;              ///< linear layers (composite, airlight, surface, overlay, T, distance)
  std::vector<std::byte> packed;   ///< the channel's format, ready to publish
  FrameView view;
  FrameInputs inputs;
  FrameTimings timings;
  std::size_t airlight_evaluated = 0;  ///< pixels evaluated (the rest interpolated)
  std::size_t traffic_evaluated = 0;   ///< pixels of the traffic layer evaluated (0: no traffic lamps)
  /// Lit traffic lamps left out of this frame by [render] max_moving_lamps (the dimmest by their bound).
  std::size_t traffic_lamps_dropped = 0;
  bool pending = false;            ///< a fog or bending change is still being tabulated
  /// Rungs of the fog ladder the ego lamps' tables were read from ([render] fog_ladder_ratio):
  /// 0 = the tables built for the frame's fog (or none: pending, GPU airlight), 1 = a rung at its
  /// K_t, 2 = the two around it.
  int fog_rungs = 0;
  /// Rungs of the bending ladder read per fog, each through its turn ([render]
  /// bending_ladder_step_deg): 0 = none, 2 = the two around the frame's bending angle.
  int bending_rungs = 0;
  /// The host depth frame the frame was rendered on (HostView::frame); 0 = the channel's own view.
  std::uint64_t host_frame = 0;
  /// rgba8-srgb: the EV the frame was packed at (the channel's exposure_ev, or its automatic
  /// exposure: ChannelConfig::autoExposure); 0 for the linear formats.
  double exposure_ev = 0.0;
  /// Glow and glare figures of the lamps that are on (LampEffectsReport: per lamp, eye
  /// illuminance in lx, veiling luminance at the image centre in cd/m², glow and glare
  /// seconds). Empty and 0 when [glow] and [glare] are both off.
  LampEffectsReport effects;
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

/// A host's view for a channel with depth_from (docs/service.md, "Host depth"): its camera and
/// distances replace the channel's camera and the surface pass. Both must outlive the render()
/// call; the surface's size is the view's and the channel's.
struct HostFrame {
  const HostView* view = nullptr;
  const SurfaceBuffers* surface = nullptr;  ///< distances (rgb zero)
};

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

  /// Renders `state` as of `now` (traffic liveness) into `out` (its buffers are reused: pass the
  /// same frame every time). `wait`: await table builds (lock-step, replay) instead of going on
  /// with the previous fog and bending (free-running). Errors only for failures of the renderer
  /// itself (never for input values, which the decoders have checked).
  /// `host` (channels with depth_from): render the host's view on its distances instead of the
  /// channel's own view and surface pass. The view is the host's camera; the ego's lamps hang
  /// from it (the vehicle pose that puts the channel's eye, eye_m + eye_offset_m and its
  /// rotation, at the host's camera), not from the state's ego pose; lamp bits, bending, fog and
  /// traffic come from the state. A host view of another size than the channel is an error
  /// (the service checks it first); one with other intrinsics (field of view, frustum) is
  /// followed, the view tables being rebuilt once.
  /// No frame may be begun and unfinished (begin() without finish()): an error otherwise.
  [[nodiscard]] Status render(const ipc::SimSnapshot& state, ipc::Clock::time_point now, bool wait, RenderedFrame& out,
                              const HostFrame* host = nullptr);

  /// The first half of render(), stages 1–3: the tables (a build started, taken or awaited, as
  /// render() does), the frame's scenes and the surface pass, kept for finish(). Arguments as
  /// render()'s; `state` is read during the call only, `host` (with its buffers) must stay valid
  /// until the frame's finish() returns. Calls GL: on the thread that owns the surface pass.
  /// At most two frames begun and not finished (errors: a third; a host view while a frame is
  /// in flight, since a host view changes the channel's camera). A begin() beside a finish()
  /// uses its own thread pool for CPU surfaces (a pool runs one loop at a time).
  [[nodiscard]] Status begin(const ipc::SimSnapshot& state, ipc::Clock::time_point now, bool wait,
                             const HostFrame* host = nullptr);
  /// The second half, stages 4–6 of the oldest begun frame (airlight, glow and glare, composite
  /// and pack) into `out`, and what the renderer knows about it (RenderedFrame). No GL call: may
  /// run on another thread than begin(), beside the next frame's begin(). Error: no frame begun.
  /// The frame is done with, failed or not. Its timings.total_ms is the time of its own stages
  /// (begin's and finish's calls), not the time it waited between them.
  [[nodiscard]] Status finish(RenderedFrame& out);
  /// Frames begun and not finished yet: 0, 1 or 2.
  [[nodiscard]] std::size_t inFlight() const;

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
