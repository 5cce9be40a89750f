// fogbeam — one output view of the service (frame_renderer.hpp).
#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/exposure.hpp>
#include <fogbeam/render/pixel_pack.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/render/surface_shading.hpp>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <future>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <utility>

namespace fogbeam::plugin {

namespace {

using Clock = std::chrono::steady_clock;

double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

/// The gate of a rate-limited log line: true at most once every `seconds` per gate, whichever
/// thread asks (a compare-exchange, so two threads never both log in the same window). A gate
/// is a function-local static: one per kind of message, shared by every channel.
bool gateOpens(std::atomic<std::int64_t>& gate, std::int64_t seconds) {
  const std::int64_t now = std::chrono::duration_cast<std::chrono::seconds>(Clock::now().time_since_epoch()).count();
  std::int64_t last = gate.load();
  return now - last >= seconds && gate.compare_exchange_strong(last, now);
}

Mat3 rotation(const ipc::Pose& p) {
  return worldFromYawPitchRoll(radians(static_cast<double>(p.yaw_deg)), radians(static_cast<double>(p.pitch_deg)),
                               radians(static_cast<double>(p.roll_deg)));
}

Vec3 position(const ipc::Pose& p) { return Vec3(p.position_m[0], p.position_m[1], p.position_m[2]); }

/// Where the vehicle is: the ego lamps and the channel's eye hang from it.
struct VehiclePose {
  Mat3 R{1.0};     ///< worldFromVehicle
  Vec3 O{0.0};     ///< the vehicle origin in the world, m
};

VehiclePose poseOf(const ipc::EgoState& ego) { return {rotation(ego.pose), position(ego.pose)}; }

/// The vehicle pose that puts the channel's eye (`vehicleCamera`, vehicle frame) exactly where
/// the host's camera is: worldFromVehicle = worldFromHostCamera · (worldFromCamera_vehicle)ᵀ,
/// origin = host eye − worldFromVehicle · eye_vehicle. The ego lamps then keep their place
/// relative to the eye, whatever the UDP/CAN ego pose says (docs/service.md, "Host depth").
VehiclePose poseOf(const Camera& host, const Camera& vehicleCamera) {
  VehiclePose v;
  v.R = host.worldFromCamera * glm::transpose(vehicleCamera.worldFromCamera);
  v.O = host.position_m - v.R * vehicleCamera.position_m;
  return v;
}

/// The extinction coefficient an environment message describes, 1/m.
double ktOf(const ipc::Environment& e) {
  return e.visibility_m > 0.0f ? extinctionFromVisibility(static_cast<double>(e.visibility_m))
                               : static_cast<double>(e.extinction_per_m);
}

/// What the tables depend on besides the rig: the fog and the ego's bending angle. Fogs compare
/// by the medium they describe (a visibility and the equivalent extinction are equal); tables
/// for one angle serve angles within [ego] bending_tolerance_deg of it (serves()).
struct TableKey {
  ipc::Environment fog;
  double bendingDeg = 0.0;

  bool operator==(const TableKey& o) const { return bendingDeg == o.bendingDeg && sameFog(o); }
  [[nodiscard]] bool sameFog(const TableKey& o) const {
    const ipc::Environment& a = fog;
    const ipc::Environment& b = o.fog;
    auto kt = [](const ipc::Environment& e) { return ktOf(e); };
    const bool phaseSame = a.phase == b.phase && (a.phase != ipc::PhaseCode::HenyeyGreenstein || a.g == b.g) &&
                           (a.phase != ipc::PhaseCode::FogMie || a.droplet_diameter_um == b.droplet_diameter_um);
    // Relative 1e-6 in K_t: the float of a message and the double of a config file agree.
    return std::abs(kt(a) - kt(b)) <= 1e-6 * kt(a) && a.albedo == b.albedo && a.ambient_cd_m2 == b.ambient_cd_m2 &&
           phaseSame;
  }
  /// Tables made for this key serve a frame that wants `o`: the same fog, the bending angle
  /// within `toleranceDeg`.
  [[nodiscard]] bool serves(const TableKey& o, double toleranceDeg) const {
    return sameFog(o) && std::abs(bendingDeg - o.bendingDeg) <= toleranceDeg;
  }
};

/// Frames a want must hold before its exact tables are built while a ladder serves it (half a
/// second at 30 frames/s): updateTables.
constexpr int kLadderHoldFrames = 15;

/// The fog ladder's base of a key: its fog with K_t set to 1 /m (what the rungs share besides
/// their K_t) and its bending.
TableKey ladderBase(const TableKey& k) {
  TableKey b = k;
  b.fog.visibility_m = 0.0f;
  b.fog.extinction_per_m = 1.0f;
  return b;
}

std::uint32_t formatCode(const std::string& f) {
  if (f == "rgba16f-linear") return FOGBEAM_FORMAT_RGBA16F_LINEAR;
  if (f == "rgba16f-overlay") return FOGBEAM_FORMAT_RGBA16F_OVERLAY;
  return FOGBEAM_FORMAT_RGBA8_SRGB;
}

}  // namespace

Medium mediumFrom(const ipc::Environment& e) {
  Medium m;
  m.extinction_per_m = e.visibility_m > 0.0f ? extinctionFromVisibility(static_cast<double>(e.visibility_m))
                                             : static_cast<double>(e.extinction_per_m);
  m.albedo = static_cast<double>(e.albedo);
  m.ambient_cd_m2 = static_cast<double>(e.ambient_cd_m2);
  switch (e.phase) {
    case ipc::PhaseCode::Isotropic: m.phase = IsotropicPhase{}; break;
    case ipc::PhaseCode::HenyeyGreenstein: m.phase = makeHenyeyGreenstein(static_cast<double>(e.g)).value(); break;
    case ipc::PhaseCode::FogMie: m.phase = makeFogMie(static_cast<double>(e.droplet_diameter_um)).value(); break;
  }
  return m;
}

ipc::Environment environmentFrom(const Medium& m) {
  ipc::Environment e;
  e.visibility_m = 0.0f;
  e.extinction_per_m = static_cast<float>(m.extinction_per_m);
  e.albedo = static_cast<float>(m.albedo);
  e.ambient_cd_m2 = static_cast<float>(m.ambient_cd_m2);
  if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&m.phase)) {
    e.phase = ipc::PhaseCode::HenyeyGreenstein;
    e.g = static_cast<float>(hg->g);
  } else if (const auto* mie = std::get_if<FogMiePhase>(&m.phase)) {
    e.phase = ipc::PhaseCode::FogMie;
    e.droplet_diameter_um = static_cast<float>(mie->diameter_um);
  } else {
    e.phase = ipc::PhaseCode::Isotropic;
  }
  return e;
}

std::vector<RigPoint> expandRig(const VehicleRig& rig) {
  std::vector<RigPoint> points;
  for (std::size_t i = 0; i < rig.lamps.size(); ++i) {
    for (SceneLamp& p : expandSceneLamp(rig.lamps[i].lamp)) points.push_back(RigPoint{std::move(p), i});
  }
  return points;
}

SceneLamp placeRigPoint(const RigPoint& point, const RigLamp& lamp, const Mat3& worldFromVehicle, const Vec3& origin_m,
                        const Mat3* bend) {
  SceneLamp l = point.lamp;
  Vec3 p = point.lamp.lamp.position_m;
  Mat3 orientation = point.lamp.lamp.worldFromLamp;
  if (bend) {
    // About the vertical axis through the rig lamp's centre (its position), not through each
    // point: the face turns as one piece.
    const Vec3 centre = lamp.lamp.lamp.position_m;
    p = centre + *bend * (p - centre);
    orientation = *bend * orientation;
  }
  l.lamp.position_m = origin_m + worldFromVehicle * p;
  l.lamp.worldFromLamp = worldFromVehicle * orientation;
  return l;
}

struct ChannelRenderer::Impl {
  const ServiceConfig* config = nullptr;
  ChannelConfig channel;
  Scene world;             ///< the world scene: world lamps only
  GlSurfacePass* gl = nullptr;
  AirlightMethod method = AirlightMethod::Accurate;
  FastPathOptions fast;
  SubsamplingOptions subsampling;
  std::uint32_t format = FOGBEAM_FORMAT_RGBA8_SRGB;
  Camera vehicleCamera;  ///< the channel's camera in the vehicle frame
  /// The ego rig's point lamps (expandRig), and each traffic rig's (by rig, as rigFor gives it).
  std::vector<RigPoint> egoPoints;
  std::map<const VehicleRig*, std::vector<RigPoint>> trafficPoints;

  /// [render] airlight = "gpu": the GL pass computes the airlight; no CPU evaluator, no tables.
  bool gpuAirlight = false;
  /// Glow, glare and the per-frame airlight evaluators of pending frames (below) run on it; the
  /// tables' evaluator has its own (a build makes a new one, possibly on another thread).
  std::shared_ptr<ThreadPool> framePool;
  SurfaceShader cpuSurfaces;             ///< the CPU surface pass (no GL, or a failed GL frame)
  kernels::ShadeFrame cpuShadeFrame;     ///< its per-frame lamps and planes, kept
  /// The CPU surface pass's pool while another frame's finish() runs on framePool (a pool runs
  /// one loop at a time): made the first time a begin() overlaps a finish().
  std::unique_ptr<ThreadPool> surfacePool;

  /// [render] pending_tables = "per-pixel": while the tables for the wanted fog and bending are
  /// not in use, a frame evaluates the ego lamps (with every other lamp that is on) through the
  /// moving-lamp path in that fog and bending instead of showing the previous ones or waiting.
  bool perPixelPending = true;
  /// Frames rendered so far (render() calls), and the frame at which the running build started:
  /// with `wait` (lock-step, replay) and per-pixel pending frames, a build is taken at frame
  /// buildStart + config->table_adopt_frames whatever the machine's speed, so runs repeat.
  std::int64_t frameIndex = 0;
  std::int64_t buildStart = 0;
  /// The key the previous frame wanted, and for how many frames in a row it has been wanted: a
  /// per-pixel build starts only once a key has held for two frames, so that a fog ramp (a new
  /// key every frame) does not spend the cores on tables that are stale before they are done.
  TableKey lastWant;
  int wantHeld = 0;
  /// An evaluator with tables exists or has been taken by a begun frame (which installs it in
  /// `eval` at its finish()): what stage 1 asks of `eval` without reading it, since the previous
  /// frame's airlight may be reading it on another thread.
  bool tablesBuilt = false;

  /// Glow and glare ([glow], [glare]), evaluated on each frame's lit scene (its lamp list changes
  /// with traffic and light bits, which LampEffects follows). LampEffects::build takes the fog's
  /// phase (its single-scattering table) from the scene it is given, so it is rebuilt when the
  /// frame's key (fog, hence phase) changes. It runs on framePool. A rebuild costs a 512-entry
  /// CIE table, µs.
  std::optional<LampEffects> effects;
  TableKey effectsKey;
  const ThreadPool* effectsPool = nullptr;
  std::vector<float> glow, glare;
  /// The automatic exposure (rgba8-srgb channels with exposure_ev = "auto") and the previous
  /// frame's times it adapts over.
  ExposureAdaptation exposure;
  bool exposureClockSet = false;
  double exposureSimTime = 0.0;
  ipc::Clock::time_point exposureWallTime{};

  std::unique_ptr<AirlightImageEvaluator> eval;  ///< tables for `current`
  /// Pending frames' evaluator of the world and ego lamps (every one treated as moving: per
  /// pixel), kept from frame to frame: each frame gives it the frame's fog (setFog, while the
  /// phase function stays) and poses. Its pencils keep the spokes of lamps whose pose relative
  /// to the eye holds (the ego's lamps while they do not bend), which are most of a per-pixel
  /// frame's cost; rebuilt when the phase function changes.
  std::unique_ptr<AirlightImageEvaluator> pendingEval;
  /// The traffic lamps' evaluator, kept from frame to frame while the traffic's lamps are the
  /// same (profile, colour and mount, in order) and its pool too: each frame gives it the fog
  /// and the poses (a kept evaluator shows moving lamps as a new one does:
  /// AirlightImage.AFogChangeKeepsTheSpokesOfLampsFixedToTheEye). Building one per frame
  /// (per-lamp evaluators, pencils, per-thread memory of ~0.8 MB a thread) cost 13–19 % of a
  /// table frame's airlight at 1280×720 (docs/service.md). Rebuilt when a vehicle comes or goes,
  /// switches a lamp or the phase function changes.
  std::unique_ptr<AirlightImageEvaluator> trafficEval;
  struct TrafficLampKey {
    const Profile* profile = nullptr;
    glm::dvec3 color{0.0};
    LampMount mount = LampMount::World;
  };
  std::vector<TrafficLampKey> trafficKeys;  ///< trafficEval's lamps, scene order
  const ThreadPool* trafficPool = nullptr;   ///< the pool trafficEval runs on
  TableKey current;
  std::future<Result<AirlightImageEvaluator>> building;  ///< tables for `next`, off the frame thread
  TableKey next;

  /// The fog ladder ([render] fog_ladder_ratio; docs/service.md, "The fog ladder"): rungs of the
  /// ego lamps' view tables at K_t = ladderRatio^m per metre (by m) for the fog (its K_t aside)
  /// and bending of rungBase, built one at a time in the background (rungBuilding: rung
  /// rungBuildIndex for rungBuildBase, started at frame rungStart) and taken as table builds
  /// are. rungsVersion counts changes of the set; finish() gives the evaluator a new set
  /// (evalRungsVersion: the one it has).
  double ladderRatio = 0.0;
  std::map<int, std::shared_ptr<const FogTables>> rungs;
  TableKey rungBase;
  bool rungBaseSet = false;
  std::future<Result<std::shared_ptr<const FogTables>>> rungBuilding;
  int rungBuildIndex = 0;
  TableKey rungBuildBase;
  std::int64_t rungStart = 0;
  std::uint64_t rungsVersion = 0, evalRungsVersion = ~std::uint64_t{0};
  /// Frames in a row whose K_t differs from the previous frame's, and its direction (+1, −1):
  /// rungs are built only while the fog keeps changing, ahead in its direction.
  int fogChanging = 0, fogTrend = 0;
  double lastKt = 0.0;
  double lastRungFrames = 1.0;  ///< frames the last rung took from its start to being taken
  /// The ego lamps' light bits (egoLightBits: every rig lamp's) the rungs were made for (the
  /// lamps they tabulate), and those of the rung being built.
  std::uint32_t egoLightBits = 0, rungLights = 0, rungBuildLights = 0;
  /// The bending ladder ([render] bending_ladder_step_deg; docs/service.md, "The bending
  /// ladder"): rungs of the ego lamps' view tables at bending j · bendStep (by j) for the exact
  /// fog of bendBase, built in the fog ladder's background slot (rungBuildBending says which
  /// kind is building) and taken as fog rungs are. Only for a rig with bending lamps.
  double bendStep = 0.0;
  std::map<int, std::shared_ptr<const FogTables>> bendRungs;
  TableKey bendBase;
  bool bendBaseSet = false;
  std::uint32_t bendLights = 0;
  bool rungBuildBending = false;
  /// Changes of the bending angle in one direction (holds of up to kLadderHoldFrames between
  /// them allowed), that direction and the rate over the last (deg a frame): rungs are built
  /// ahead of a wheel that keeps turning.
  int bendChanging = 0, bendTrend = 0;
  double lastBend = 0.0, bendStepPerFrame = 0.0;
  std::int64_t lastBendChange = 0;  ///< frameIndex of the last change of angle
  std::uint64_t ladderMisses = 0;  ///< ladder frames the evaluator could not serve (per pixel instead)
  std::uint64_t droppedLamps = 0;  ///< traffic lamps left out by [render] max_moving_lamps, summed over frames

  AirlightImage air;

  /// A frame between begin() and finish(): what stages 1–3 decided and made, for stages 4–6.
  /// Two slots, so that frame N+1 can be begun while frame N is finished on another thread.
  struct Begun {
    TableKey key;             ///< the fog and bending the frame shows
    bool useTables = false;   ///< the tables' evaluator serves the world and ego lamps
    /// The tables' evaluator reads two rungs of the fog ladder (`rungs`, set `rungsVersion`)
    /// for the ego lamps (useTables is then true).
    bool ladder = false;
    /// The rungs read are the bending ladder's (the frame shows its own bending angle), not the
    /// fog ladder's (the rungs' angle, within bending_tolerance_deg).
    bool bendingLadder = false;
    std::vector<std::shared_ptr<const FogTables>> rungs;
    std::uint64_t rungsVersion = 0;
    bool trafficLive = false;  ///< live traffic objects with a rig (their lamps go per pixel)
    bool pending = false;     ///< RenderedFrame::pending
    /// A table build this frame took (stage 1): it replaces `eval` when the frame's finish()
    /// starts, after the previous frame's airlight has read the old tables.
    std::unique_ptr<AirlightImageEvaluator> adopt;
    /// `scene`: world lamps + the whole ego rig; `lit`: the lamps that are on (world, ego,
    /// traffic); `traffic`: the traffic lamps that are on (render(), stage 2).
    Scene scene, lit, traffic;
    std::vector<char> lampOn;  ///< per lamp of `scene`: switched on
    std::uint32_t lights = 0;
    SurfaceBuffers surface;    ///< the surface pass's output (own views)
    /// The frame's surfaces: `surface`, or a host's distances (depth_from; rgb zero).
    const SurfaceBuffers* surf = nullptr;
    std::vector<float> gpuAir;  ///< the GL pass's airlight, 3 per pixel ([render] airlight = "gpu")
    const HostFrame* host = nullptr;
    bool wait = false;
    ipc::Clock::time_point now{};
    double simTime = 0.0;      ///< s: the automatic exposure's clock when `wait`
    FrameView view;
    FrameInputs inputs;
    std::uint64_t hostFrame = 0;
    /// ms: stage 1's wait, the surface pass (the GL pass's wall time, its airlight draw's GPU
    /// time in gpuAirlightMs), begin()'s whole call.
    double tableWaitMs = 0.0, surfaceMs = 0.0, gpuAirlightMs = 0.0, beginMs = 0.0;
  };
  std::array<Begun, 2> slots;
  /// The begun frames are slots[head], slots[(head + 1) % 2], `queued` of them. Guarded by
  /// `ring`: begin() and finish() of two frames may run on two threads at once; each touches
  /// only its own slot's contents.
  mutable std::mutex ring;
  std::size_t head = 0, queued = 0;

  /// The frame's scene: world lamps, then the ego rig (in config order), for the ego pose, the
  /// key's fog and bending.
  Scene sceneFor(const VehiclePose& pose, const TableKey& key) const {
    Scene s = world;
    s.effects = config->effects;  // the service's [glow] (its `surfaces`: the surface pass's fog light), [glare], [render]
    s.fog = mediumFrom(key.fog);
    const Mat3& R = pose.R;
    const Vec3& O = pose.O;
    s.camera = vehicleCamera;
    s.camera.position_m = O + R * vehicleCamera.position_m;
    s.camera.worldFromCamera = R * vehicleCamera.worldFromCamera;
    if (config->bonnet) s.body.push_back(config->bonnet->quad(R, O));  // hangs from the vehicle like the lamps
    const Mat3 bend = worldFromYawPitchRoll(radians(key.bendingDeg), 0.0, 0.0);
    for (const RigPoint& p : egoPoints) {
      // Bending swivels the lamp about the vehicle's vertical axis through the lamp.
      const RigLamp& r = config->ego.lamps[p.rig_lamp];
      SceneLamp l = placeRigPoint(p, r, R, O, r.bending ? &bend : nullptr);
      l.mount = LampMount::Vehicle;
      s.lamps.push_back(std::move(l));
    }
    return s;
  }

  // The stages of render(), in order (defined below, each with what it does).
  [[nodiscard]] TableKey wantedTables(const ipc::SimSnapshot& state) const;
  [[nodiscard]] Status updateTables(const VehiclePose& pose, const TableKey& want, bool wait, Begun& b);
  [[nodiscard]] Status updateLadder(const VehiclePose& pose, const TableKey& want, bool wait, bool served, Begun& b);
  void startRung(const VehiclePose& pose, int index);
  void startBendRung(const VehiclePose& pose, int index);
  /// Starts the background build of one rung of either ladder: the tables for `key`, recorded
  /// as rung `index` of the ladder whose base is `base` (lamps `lights` on).
  void startRungBuild(const VehiclePose& pose, const TableKey& key, const TableKey& base, std::uint32_t lights,
                      int index, bool bending);
  /// The bending ladder's part of updateLadder: takes nothing, starts at most one rung (when
  /// `mayStart`), sets b.ladder / b.bendingLadder when its rungs serve the frame.
  /// `idleRungs`: while frames are cheap, build up to that many rungs nearest the angle.
  void updateBendingLadder(const VehiclePose& pose, const TableKey& want, bool served, bool wait, bool mayStart,
                           int idleRungs, std::uint32_t lights, Begun& b);
  void litLamps(std::uint32_t lights, Begun& b);
  /// Per lamp of sceneFor()'s scenes (`count` of them): on (1) or off by the light bits.
  [[nodiscard]] std::vector<char> lampsOn(std::uint32_t lights, std::size_t count) const;
  [[nodiscard]] Status setEvaluatorLamps(const Begun& b);
  void startBuild(const VehiclePose& pose, const TableKey& want);
  void adoptHostIntrinsics(const Camera& host);
  [[nodiscard]] std::uint32_t trafficLamps(const ipc::SimSnapshot& state, ipc::Clock::time_point now, Scene& traffic,
                                           Scene& lit) const;
  [[nodiscard]] Status renderSurfaces(Begun& b, bool overlapped);
  [[nodiscard]] Status renderAirlight(Begun& b, RenderedFrame& out);
  [[nodiscard]] Status renderEffects(const Begun& b, RenderedFrame& out, EffectLayers& layers);
  void compositeAndPack(const Begun& b, const EffectLayers& layers, double adaptSeconds, RenderedFrame& out);
  [[nodiscard]] Status beginFrame(const ipc::SimSnapshot& state, ipc::Clock::time_point now, bool wait,
                                  const HostFrame* host, Begun& b, bool overlapped);
  [[nodiscard]] Status finishFrame(Begun& b, RenderedFrame& out);
  /// The rgba8-srgb exposure of this frame (ChannelConfig::autoExposure: adapted, else fixed).
  double exposureFor(const FrameLayers& l, double adaptSeconds);

  Result<AirlightImageEvaluator> buildFor(const Scene& scene) const {
    auto e = AirlightImageEvaluator::build(scene, method, {}, config->threads, fast);
    if (!e) return e;
    // Build the view tables now (they are built on first use): one throwaway frame over sky.
    SurfaceBuffers sky;
    sky.resize(scene.camera.width, scene.camera.height);
    std::fill(sky.distance.begin(), sky.distance.end(), std::numeric_limits<float>::infinity());
    AirlightImage scratch;
    e->evaluate(scene, sky, subsampling, scratch);
    if (!scratch.table_cache_error.empty()) {
      // The next start builds these tables again; nothing else is lost. At most every 10 s: a
      // fog ramp builds tables one after the other.
      static std::atomic<std::int64_t> lastLog{0};
      if (gateOpens(lastLog, 10))
        spdlog::warn("render: view tables not cached ({}): the next start builds them again", scratch.table_cache_error);
    }
    return e;
  }
};

ChannelRenderer::ChannelRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ChannelRenderer::~ChannelRenderer() {
  if (impl_ && impl_->building.valid()) impl_->building.wait();
  if (impl_ && impl_->rungBuilding.valid()) impl_->rungBuilding.wait();
}

const ChannelConfig& ChannelRenderer::channel() const { return impl_->channel; }
std::uint32_t ChannelRenderer::shmFormat() const { return impl_->format; }

Result<std::unique_ptr<ChannelRenderer>> ChannelRenderer::create(const ServiceConfig& config, std::size_t channel,
                                                                 const Scene& world, GlSurfacePass* gl) {
  if (channel >= config.channels.size()) return Error{"no channel #" + std::to_string(channel)};
  auto impl = std::make_unique<Impl>();
  impl->config = &config;
  impl->channel = config.channels[channel];
  impl->world = world;
  impl->world.lamps.clear();
  for (const SceneLamp& l : world.lamps)
    if (l.mount == LampMount::World) impl->world.lamps.push_back(l);
  impl->gl = gl;
  auto m = parseAirlightMethod(config.method);
  if (!m) return m.error();
  impl->method = *m;
  impl->fast.view_table_step_deg = config.view_table_step_deg;
  impl->fast.table_cache_dir = tableCacheDirFor(config.table_cache);
  impl->cpuSurfaces.setTableCacheDir(impl->fast.table_cache_dir);  // the fog light's table and annulus maps
  impl->fast.moving_lamps = parseMovingLampPath(config.moving_lamps).value_or(MovingLampPath::Pencil);
  // Halved: a frame's airlight comes from two evaluators (world and ego lamps, then traffic), each
  // leaving out lamps worth up to its cutoff, and the key bounds what a pixel loses in all.
  impl->fast.moving_lamp_cutoff_cd_m2 = 0.5 * config.moving_lamp_cutoff_cd_m2;
  impl->fast.max_moving_lamps = config.max_moving_lamps;
  impl->subsampling.full = !config.subsampling;
  impl->format = formatCode(impl->channel.format);
  impl->vehicleCamera = channelCamera(config, impl->channel);
  impl->egoPoints = expandRig(config.ego);
  for (const auto& [cls, rig] : config.traffic) impl->trafficPoints.emplace(&rig, expandRig(rig));
  impl->perPixelPending = config.pending_tables == "per-pixel";
  impl->ladderRatio = impl->perPixelPending ? config.fog_ladder_ratio : 0.0;
  const bool bends = std::any_of(config.ego.lamps.begin(), config.ego.lamps.end(), [](const RigLamp& l) { return l.bending; });
  impl->bendStep = impl->perPixelPending && bends ? config.bending_ladder_step_deg : 0.0;
  for (const RigLamp& l : config.ego.lamps) impl->egoLightBits |= l.light_bit;
  impl->framePool = std::make_shared<ThreadPool>(config.threads);
  if (config.effects.render.airlight == AirlightDevice::Gpu) {
    if (!gl) {
      return Error{"[render] airlight = \"gpu\" needs the GL surface pass, and there is none (surface = \"" +
                   config.surface + "\", or no EGL/OpenGL here): use airlight = \"cpu\""};
    }
    GpuAirlightOptions gpu;
    gpu.pieces = config.effects.render.gpu_pieces;
    if (Status s = gl->setAirlight(gpu); !s) return Error{"[render] airlight = \"gpu\": " + s.error().message};
    impl->gpuAirlight = true;
  }
  return std::unique_ptr<ChannelRenderer>(new ChannelRenderer(std::move(impl)));
}

// ---- render(), stage by stage ---------------------------------------------------------------
// Each stage reads and writes the renderer's buffers (surface, air, glow, glare) and fills its
// part of the RenderedFrame. The order of operations within and across stages is that of the
// frames published so far (the surface pass before the airlight, which reads its distances; the
// evaluator's lamp poses before its enable bits): frames stay byte for byte what they were.

TableKey ChannelRenderer::Impl::wantedTables(const ipc::SimSnapshot& state) const {
  // The environment message's fog, or the configuration's until one arrives. The bending angle
  // matters only when an ego lamp bends; it is clamped to the configured limit (tables for one
  // angle serve angles within bending_tolerance_deg of it: serves()).
  TableKey want;
  want.fog = state.environment.stamp.valid ? state.environment.value : environmentFrom(config->fog);
  const double bend = std::clamp(static_cast<double>(state.lamps.value.bending_deg), -config->bending_max_deg,
                                 config->bending_max_deg);
  const bool anyBending =
      std::any_of(config->ego.lamps.begin(), config->ego.lamps.end(), [](const RigLamp& r) { return r.bending; });
  want.bendingDeg = anyBending ? bend : 0.0;
  return want;
}

void ChannelRenderer::Impl::startBuild(const VehiclePose& pose, const TableKey& want) {
  next = want;
  buildStart = frameIndex;
  building = std::async(std::launch::async, [this, scene = sceneFor(pose, want)] { return buildFor(scene); });
}

void ChannelRenderer::Impl::adoptHostIntrinsics(const Camera& host) {
  // The view tables are made for the camera's frustum (ViewKey): a host view with other
  // intrinsics than the channel's makes the evaluator rebuild them at its next frame (seconds,
  // once). The eye's place and orientation in the vehicle stay the channel's.
  Camera& v = vehicleCamera;
  if (v.width == host.width && v.height == host.height && v.fov_x == host.fov_x &&
      v.principalPoint() == host.principalPoint())
    return;
  spdlog::info("serve: channel {}: the host view is {}x{}, {:.3f}° wide{}: the channel follows it (tables rebuilt once)",
               channel.name, host.width, host.height, (host.frustum().left + host.frustum().right) * 180.0 / kPi,
               host.isCentred() ? "" : ", off-axis");
  v.width = host.width;
  v.height = host.height;
  v.fov_x = host.fov_x;
  v.principal_px = host.principal_px;
}

Status ChannelRenderer::Impl::updateTables(const VehiclePose& pose, const TableKey& want, bool wait, Begun& b) {
  // A build taken here goes to b.adopt, not to `eval`: the previous frame's airlight may still be
  // reading `eval` on another thread (finish()); finishFrame installs it.
  ++frameIndex;
  b.adopt.reset();
  b.useTables = false;
  if (gpuAirlight) {
    // Nothing is tabulated on the CPU: every frame renders its own fog and bending at once.
    current = want;
    return Ok{};
  }
  if (perPixelPending) {
    // No frame waits for a build and none shows another fog or bending: until the tables for
    // `want` are in use, render() evaluates the lamps per pixel. One build at a time, in the
    // background. Free-running takes a build as soon as it is done; lock-step and replay at a
    // fixed number of frames after it started (waiting there for what is left of it), so that
    // which frames use tables does not depend on the machine.
    if (building.valid()) {
      const bool take = wait ? frameIndex >= buildStart + config->table_adopt_frames
                             : building.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
      if (take) {
        auto built = building.get();
        if (!built) return built.error();
        b.adopt = std::make_unique<AirlightImageEvaluator>(std::move(built).value());
        tablesBuilt = true;
        current = next;
      }
    }
    // A want holds while its fog stays and its angle stays within the tolerance of the last
    // frame's (a jittering bending signal holds).
    const double tol = config->bending_tolerance_deg;
    wantHeld = frameIndex > 1 && lastWant.serves(want, tol) ? wantHeld + 1 : 1;
    lastWant = want;
    b.useTables = tablesBuilt && current.serves(want, tol);
    if (Status s = updateLadder(pose, want, wait, b.useTables, b); !s) return s;
    // The exact build for a want that holds: after two frames when frames go per pixel; after
    // kLadderHoldFrames when a ladder serves them (a wheel that moves in steps holds each angle
    // a few frames, and a build started then would keep the slot from the rungs ahead of it,
    // only to be taken after the angle has moved on; a build is a rung's work).
    const int hold = b.ladder ? kLadderHoldFrames : 2;
    if (!b.useTables && !building.valid() && wantHeld >= hold) startBuild(pose, want);
    if (b.ladder) b.useTables = true;
    return Ok{};
  }
  // pending_tables = "previous". A finished background build replaces the tables in use
  // (awaited when `wait`).
  if (building.valid() && (wait || building.wait_for(std::chrono::seconds(0)) == std::future_status::ready)) {
    auto built = building.get();
    if (!built) return built.error();
    b.adopt = std::make_unique<AirlightImageEvaluator>(std::move(built).value());
    tablesBuilt = true;
    current = next;
  }
  if (!tablesBuilt || !current.serves(want, config->bending_tolerance_deg)) {
    if (wait || !tablesBuilt) {
      // Lock-step, replay, and the very first frame: build here, the frame waits.
      auto built = buildFor(sceneFor(pose, want));
      if (!built) return built.error();
      b.adopt = std::make_unique<AirlightImageEvaluator>(std::move(built).value());
      tablesBuilt = true;
      current = want;
    } else if (!building.valid()) {
      // Free-running: one build at a time in the background; frames keep `current` meanwhile.
      startBuild(pose, want);
    }
  }
  b.useTables = true;
  return Ok{};
}

Status ChannelRenderer::Impl::updateLadder(const VehiclePose& pose, const TableKey& want, bool wait, bool served,
                                           Begun& b) {
  // A frame whose fog the tables do not serve reads the two rungs around its K_t when both
  // exist for its fog's other fields and bending. Rungs are built one at a time in the
  // background, when frames are cheap: while tables serve the fog and no traffic is live, the
  // rungs nearest it on both sides, up to fog_ladder_rungs; while the fog keeps changing on the ladder (two frames in a
  // row or more: a ramp, not a step, which the exact build after it serves), around where it
  // is heading. Frames off the ladder (per pixel) need the cores: no rung is started then. A
  // rung is taken as table builds are, free-running when done, lock-step and replay
  // fog_ladder_adopt_frames after it started (so that runs repeat). Rungs hold the ego lamps the
  // frame's light bits switch on: other bits, another ladder. The bending ladder
  // (updateBendingLadder) shares the build slot: a frame whose bending angle the tables do not
  // serve, in the fog of its rungs, reads the two rungs around its angle.
  b.ladder = false;
  b.bendingLadder = false;
  if (ladderRatio <= 1.0 && bendStep <= 0.0) return Ok{};
  if (rungBuilding.valid()) {
    const bool take = wait ? frameIndex >= rungStart + config->fog_ladder_adopt_frames
                           : rungBuilding.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    if (take) {
      lastRungFrames = static_cast<double>(frameIndex - rungStart);
      auto built = rungBuilding.get();
      if (!built) return built.error();
      if (rungBuildBending) {
        if (bendBaseSet && rungBuildBase == bendBase && rungBuildLights == bendLights) {
          bendRungs[rungBuildIndex] = std::move(built).value();
          ++rungsVersion;
        }
      } else if (rungBaseSet && rungBuildBase == rungBase && rungBuildLights == rungLights) {
        rungs[rungBuildIndex] = std::move(built).value();
        ++rungsVersion;
      }
    }
  }
  const std::uint32_t lights = b.lights & egoLightBits;
  const bool idle = served && !b.trafficLive;
  if (bendStep > 0.0) {
    // The wheel's turns in one direction, and its rate (deg a frame) over the last: a bending
    // signal that moves in steps holds each angle a few frames between them, so a hold shorter
    // than kLadderHoldFrames does not end the turn.
    const double bend = want.bendingDeg;
    if (frameIndex > 1 && std::abs(bend - lastBend) > 1e-9) {
      const int trend = bend > lastBend ? 1 : -1;
      const std::int64_t since = frameIndex - lastBendChange;
      bendChanging = trend == bendTrend && bendChanging > 0 ? bendChanging + 1 : 1;
      bendTrend = trend;
      bendStepPerFrame = (bend - lastBend) / static_cast<double>(std::max<std::int64_t>(1, since));
      lastBendChange = frameIndex;
      lastBend = bend;
    } else if (frameIndex - lastBendChange > kLadderHoldFrames) {
      bendChanging = 0;
    }
    if (frameIndex <= 1) lastBend = bend;
  }
  bool onLadder = false;
  if (ladderRatio > 1.0) {
    // Another fog (its K_t aside), a bending angle beyond the tolerance or other ego lamps on: a
    // new ladder.
    const TableKey base = ladderBase(want);
    if (!rungBaseSet || !rungBase.serves(base, config->bending_tolerance_deg) || lights != rungLights) {
      if (!rungs.empty()) ++rungsVersion;
      rungs.clear();
      rungBase = base;
      rungLights = lights;
      rungBaseSet = true;
    }
    const double kt = ktOf(want.fog);
    // ln K_t's change over the last frame, while it changes the same way.
    double step = 0.0;
    if (lastKt > 0.0 && std::abs(kt - lastKt) > 1e-6 * kt) {
      const int trend = kt > lastKt ? 1 : -1;
      fogChanging = trend == fogTrend ? fogChanging + 1 : 1;
      fogTrend = trend;
      step = std::log(kt / lastKt);
    } else {
      fogChanging = 0;
    }
    lastKt = kt;
    const double lr = std::log(ladderRatio);
    const int m = static_cast<int>(std::floor(std::log(kt) / lr));
    onLadder = rungs.count(m) != 0 && rungs.count(m + 1) != 0;
    if (!served && onLadder && fogChanging >= 2 && !rungBuilding.valid() && !building.valid()) {
      // Where the fog will be when this build is taken, at its present rate: fog_ladder_adopt_frames
      // ahead (lock-step, replay), or as many frames as the last rung took (free-running). The
      // rungs around that fog first (nearer first), the next one beyond it, then those around the
      // fog now.
      const double lead = wait ? static_cast<double>(config->fog_ladder_adopt_frames) : std::max(1.0, lastRungFrames);
      const double ahead = std::log(kt) + lead * step;
      const int a = static_cast<int>(std::floor(ahead / lr));
      const bool upperFirst = ahead - a * lr > 0.5 * lr;
      const std::array<int, 5> order{upperFirst ? a + 1 : a, upperFirst ? a : a + 1, fogTrend > 0 ? a + 2 : a - 1, m,
                                     m + 1};
      for (int c : order)
        if (rungs.count(c) == 0) {
          startRung(pose, c);
          break;
        }
    }
    // While frames are cheap (the tables serve the fog, no traffic lamp goes per pixel): the
    // idle cores build the rungs nearest the fog, on both sides, so that the next change of fog
    // starts on the ladder; `count`: among that many nearest (at most fog_ladder_rungs: those
    // kept). First the fog's three nearest (the two around it and the next: a fog that starts
    // to change off its last rung reads from the first frame on), then the bending ladder's two
    // (a wheel that starts to turn needs them at once), then the rest of each.
    auto fogIdle = [&](int count) {
      if (!idle || rungBuilding.valid() || building.valid() ||
          rungs.size() >= static_cast<std::size_t>(config->fog_ladder_rungs))
        return;
      const double x = std::log(kt) / lr;  // the fog in rung units
      int best = m;
      double bestDistance = std::numeric_limits<double>::infinity();
      for (int c = m - count; c <= m + 1 + count; ++c) {
        const double d = std::abs(static_cast<double>(c) - x);
        if (rungs.count(c) == 0 && d < bestDistance) {
          best = c;
          bestDistance = d;
        }
      }
      // Only within the `count` nearest rungs (a farther one would be dropped at once).
      std::size_t nearer = 0;
      for (const auto& [index, rung] : rungs) nearer += std::abs(static_cast<double>(index) - x) < bestDistance ? 1u : 0u;
      if (nearer < static_cast<std::size_t>(count)) startRung(pose, best);
    };
    fogIdle(std::min(3, config->fog_ladder_rungs));
    if (idle && !rungBuilding.valid() && !building.valid())
      updateBendingLadder(pose, want, served, wait, true, 2, lights, b);
    fogIdle(config->fog_ladder_rungs);
    // At most fog_ladder_rungs, those furthest from the fog dropped.
    while (rungs.size() > static_cast<std::size_t>(config->fog_ladder_rungs)) {
      const auto lowest = rungs.begin();
      const auto highest = std::prev(rungs.end());
      rungs.erase(m - lowest->first > highest->first - m ? lowest : highest);
      ++rungsVersion;
    }
  }
  // The bending ladder: a rung started when the fog ladder started none; at most
  // bending_ladder_rungs kept, those furthest from the angle dropped.
  updateBendingLadder(pose, want, served, wait, !rungBuilding.valid() && !building.valid(),
                      config->bending_ladder_rungs, lights, b);
  if (bendStep > 0.0)
    while (bendRungs.size() > static_cast<std::size_t>(config->bending_ladder_rungs)) {
      // From the middle of the angle's interval [j, j + 1], as the idle order counts them.
      const double x = std::floor(want.bendingDeg / bendStep) + 0.5;
      const auto lowest = bendRungs.begin();
      const auto highest = std::prev(bendRungs.end());
      bendRungs.erase(x - lowest->first > highest->first - x ? lowest : highest);
      ++rungsVersion;
    }
  if (served) return Ok{};
  if (onLadder) {
    b.bendingLadder = false;  // the fog ladder first: its rungs are the frame's own bending
  } else if (!b.bendingLadder) {
    return Ok{};
  }
  b.ladder = true;
  // The slot keeps its copy of the set while the set is the same (a copy per change, not per
  // frame): every change of `rungs` or `bendRungs` counts rungsVersion up. Both ladders' rungs:
  // the evaluator reads those that serve the frame.
  if (b.rungs.empty() || b.rungsVersion != rungsVersion) {
    b.rungs.clear();
    for (const auto& [index, rung] : rungs) b.rungs.push_back(rung);
    for (const auto& [index, rung] : bendRungs) b.rungs.push_back(rung);
    b.rungsVersion = rungsVersion;
  }
  if (!tablesBuilt) {
    // No tables' evaluator yet (the fog has changed since the start): one without tables of its
    // own, which reads the rungs (its lamps and pool; cheap).
    auto e = AirlightImageEvaluator::build(sceneFor(pose, want), method, {}, config->threads, fast);
    if (!e) return e.error();
    b.adopt = std::make_unique<AirlightImageEvaluator>(std::move(e).value());
    tablesBuilt = true;
  }
  return Ok{};
}

void ChannelRenderer::Impl::updateBendingLadder(const VehiclePose& pose, const TableKey& want, bool served,
                                                bool wait, bool mayStart, int idleRungs, std::uint32_t lights,
                                                Begun& b) {
  // Rungs at bending j · bendStep for the fog as it is (exactly: a fog that changes takes the fog
  // ladder, and bending rungs of another fog are dropped), within ±bending_max_deg (the angles a
  // frame can have) and a step. Built like fog rungs: while tables serve the angle and frames
  // are cheap, the two around it, then the nearest on both sides up to bending_ladder_rungs;
  // while the wheel keeps turning (bendChanging ≥ 2), around where it heads. A frame between two
  // rungs reads both, each through its turn (AirlightImageEvaluator::setFogLadder's
  // maxBendingDeg; docs/airlight.md, "Bending on the ladder"), and shows its own angle.
  if (bendStep <= 0.0) return;
  TableKey base = want;
  base.bendingDeg = 0.0;
  if (!bendBaseSet || !bendBase.sameFog(base) || lights != bendLights) {
    if (!bendRungs.empty()) ++rungsVersion;
    bendRungs.clear();
    bendBase = base;
    bendLights = lights;
    bendBaseSet = true;
  }
  const double bend = want.bendingDeg;
  const double x = bend / bendStep;  // the angle in rung units
  const int j = static_cast<int>(std::floor(x));
  const bool exact = std::abs(x - j) < 1e-9;
  const bool onBend = bendRungs.count(j) != 0 && (exact || bendRungs.count(j + 1) != 0);
  const double reach = config->bending_max_deg + bendStep;
  auto useful = [&](int c) { return bendRungs.count(c) == 0 && std::abs(bendStep * c) <= reach; };
  if (mayStart && !rungBuilding.valid() && !building.valid()) {
    if (!served && bendChanging >= 2) {
      // Where the wheel will be when this build is taken, at its present rate (as fog rungs).
      // Also while frames go per pixel (unlike the fog ladder): the wheel sweeps a few degrees
      // back and forth, so the rungs it heads for are read again on its way back.
      const double lead = wait ? static_cast<double>(config->fog_ladder_adopt_frames) : std::max(1.0, lastRungFrames);
      const double ahead = (bend + lead * bendStepPerFrame) / bendStep;
      const int a = static_cast<int>(std::floor(ahead));
      const std::array<int, 4> order{a, a + 1, bendTrend > 0 ? a + 2 : a - 1, j};
      for (int c : order)
        if (useful(c)) {
          startBendRung(pose, c);
          break;
        }
    } else if (served && !b.trafficLive) {
      // Idle: the first missing of j, j + 1, j − 1, j + 2, j − 2, … (the two around the angle,
      // then outwards on both sides), among the first idleRungs of them (at most
      // bending_ladder_rungs: those the eviction keeps).
      for (int n = 0; n < std::min(idleRungs, config->bending_ladder_rungs); ++n) {
        const int c = n % 2 == 0 ? j - n / 2 : j + (n + 1) / 2;
        if (useful(c)) {
          startBendRung(pose, c);
          break;
        }
      }
    }
  }
  b.bendingLadder = !served && onBend;
}

void ChannelRenderer::Impl::startBendRung(const VehiclePose& pose, int index) {
  TableKey key = bendBase;
  key.bendingDeg = bendStep * index;
  startRungBuild(pose, key, bendBase, bendLights, index, true);
}

void ChannelRenderer::Impl::startRung(const VehiclePose& pose, int index) {
  TableKey key = rungBase;
  key.fog.extinction_per_m = static_cast<float>(std::pow(ladderRatio, index));
  startRungBuild(pose, key, rungBase, rungLights, index, false);
}

void ChannelRenderer::Impl::startRungBuild(const VehiclePose& pose, const TableKey& key, const TableKey& base,
                                           std::uint32_t lights, int index, bool bending) {
  rungBuildIndex = index;
  rungBuildBending = bending;
  rungBuildBase = base;
  rungBuildLights = lights;
  rungStart = frameIndex;
  Scene scene = sceneFor(pose, key);
  std::vector<char> on = lampsOn(lights, scene.lamps.size());
  rungBuilding = std::async(std::launch::async, [this, scene = std::move(scene), on = std::move(on)] {
    return AirlightImageEvaluator::buildFogTables(scene, fast, std::make_shared<ThreadPool>(config->threads), on);
  });
}

void ChannelRenderer::Impl::litLamps(std::uint32_t lights, Begun& b) {
  // b.scene holds every world lamp and every ego point lamp, the evaluator's view tables being
  // per lamp: those that are on go to b.lit (world lamps always are), and b.lampOn says which
  // they are for the evaluator (setEvaluatorLamps, at the frame's airlight).
  const Scene& scene = b.scene;
  b.lampOn = lampsOn(lights, scene.lamps.size());
  for (std::size_t i = 0; i < scene.lamps.size(); ++i)
    if (b.lampOn[i]) b.lit.lamps.push_back(scene.lamps[i]);
}

std::vector<char> ChannelRenderer::Impl::lampsOn(std::uint32_t lights, std::size_t count) const {
  const std::size_t worldCount = world.lamps.size();
  std::vector<char> on(count, 0);
  for (std::size_t i = 0; i < count; ++i) {
    // All points of an aperture lamp switch together: by their rig lamp's light bit.
    const std::uint32_t bit = i < worldCount ? 0u : config->ego.lamps[egoPoints[i - worldCount].rig_lamp].light_bit;
    on[i] = bit == 0 || (lights & bit) != 0 ? 1 : 0;
  }
  return on;
}

Status ChannelRenderer::Impl::setEvaluatorLamps(const Begun& b) {
  // The tables' evaluator gets the frame's poses of all its lamps, then those that are off are
  // switched off in it, not removed (this order: poses before enable bits). A frame without
  // tables (pending) leaves it as it is: its tables are for another key.
  if (!b.useTables) return Ok{};
  // The ladder's rungs (a new set), and the frame's fog: the tables' own, or between two rungs.
  if (b.ladder && b.rungsVersion != evalRungsVersion) {
    // Rungs' K_t are floats (ipc::Environment): a little slack on the ratio.
    eval->setFogLadder(b.rungs, ladderRatio * (1.0 + 1e-6), bendStep * (1.0 + 1e-6));
    evalRungsVersion = b.rungsVersion;
  }
  if (Status s = eval->setFog(b.scene.fog); !s) return s;
  if (Status s = eval->setLampPoses(b.scene); !s) return s;
  for (std::size_t i = 0; i < b.lampOn.size(); ++i) eval->setLampEnabled(i, b.lampOn[i] != 0);
  return Ok{};
}

std::uint32_t ChannelRenderer::Impl::trafficLamps(const ipc::SimSnapshot& state, ipc::Clock::time_point now,
                                                  Scene& traffic, Scene& lit) const {
  // Each live object's rig lamps that its light bits switch on, at its pose. Returns the live
  // objects, with or without a rig.
  std::uint32_t count = 0;
  for (const ipc::TrafficEntry& e : state.traffic) {
    if (!state.live(e, now)) continue;
    ++count;
    const VehicleRig* rig = config->rigFor(e.object.vehicle_class);
    if (!rig) continue;
    const Mat3 R = rotation(e.object.pose);
    const Vec3 O = position(e.object.pose);
    for (const RigPoint& p : trafficPoints.at(rig)) {
      const RigLamp& r = rig->lamps[p.rig_lamp];
      if (r.light_bit != 0 && (e.object.lights & r.light_bit) == 0) continue;
      SceneLamp w = placeRigPoint(p, r, R, O, nullptr);
      w.mount = LampMount::World;
      traffic.lamps.push_back(w);
      lit.lamps.push_back(std::move(w));
    }
  }
  return count;
}

Status ChannelRenderer::Impl::renderSurfaces(Begun& b, bool overlapped) {
  b.gpuAirlightMs = 0.0;
  if (gpuAirlight) {
    // Surfaces and the airlight of every lit lamp (world, ego, traffic) in one GL pass.
    if (Status s = gl->render(b.lit, b.surface, b.gpuAir); !s) return Error{"GL surface pass: " + s.error().message};
    b.gpuAirlightMs = gl->stats().airlight_ms;
  } else if (!gl || !gl->render(b.lit, b.surface)) {
    // CPU planes and body (the bonnet): no GL pass, or it failed this frame (then they stand in
    // for it). SurfaceShader's SIMD path; renderSurfacesCpu is its double-precision oracle.
    // Beside another frame's finish() (on framePool) on a pool of its own; rows are independent,
    // so the pool does not change a pixel.
    if (overlapped && !surfacePool) surfacePool = std::make_unique<ThreadPool>(config->threads);
    cpuSurfaces.render(b.lit, cpuShadeFrame, b.surface, overlapped ? surfacePool.get() : framePool.get());
  }
  // A fog-light table or annulus map that could not be stored in the table cache: the next
  // start builds it again, nothing else is lost. Logged at most every 10 s.
  std::string cacheError = cpuSurfaces.takeTableCacheError();
  if (gl && cacheError.empty()) cacheError = gl->takeTableCacheError();
  if (!cacheError.empty()) {
    static std::atomic<std::int64_t> lastLog{0};
    if (gateOpens(lastLog, 10))
      spdlog::warn("render: fog-light table or map not cached ({}): the next start builds it again", cacheError);
  }
  return Ok{};
}

Status ChannelRenderer::Impl::renderAirlight(Begun& b, RenderedFrame& out) {
  const Scene& scene = b.scene;
  const Scene& traffic = b.traffic;
  const SurfaceBuffers* surf = b.surf;
  out.traffic_evaluated = 0;
  out.traffic_lamps_dropped = 0;
  if (gpuAirlight) {
    air.width = surf->width;
    air.height = surf->height;
    air.rgb.swap(b.gpuAir);  // no copy; the GL pass refills the slot's buffer at its next frame
    air.evaluated = static_cast<std::size_t>(surf->width) * static_cast<std::size_t>(surf->height);
    out.airlight_evaluated = air.evaluated;
    return Ok{};
  }
  bool perPixel = !b.useTables;
  if (b.ladder && !eval->viewTablesReady(scene.camera)) {
    // The rungs do not fit this frame (which updateLadder's choice should exclude): per pixel,
    // never a build in the frame. Counted; logged at most every 10 s.
    perPixel = true;
    ++ladderMisses;
    static std::atomic<std::int64_t> lastLog{0};
    if (gateOpens(lastLog, 10))
      spdlog::warn("render: the fog ladder's rungs did not fit {} frame(s); those went per pixel", ladderMisses);
  }
  out.fog_rungs = 0;
  out.bending_rungs = 0;
  if (perPixel) {
    // Tables pending ([render] pending_tables = "per-pixel"): the world and ego lamps that are
    // on, the ego's as lamps that move relative to the eye (the pencil, maps or per ray:
    // [render] moving_lamps), in this frame's fog and bending; traffic below, as in frames
    // with tables. Per-lamp tables (profiles, F and G tables) come from the evaluators' caches;
    // nothing here depends on the view tables.
    Scene all = scene;
    for (SceneLamp& l : all.lamps) l.mount = LampMount::World;
    const bool kept = pendingEval && pendingEval->setFog(all.fog) && pendingEval->setLampPoses(all);
    if (!kept) {
      auto fe = AirlightImageEvaluator::build(all, method, AirlightOptions{}, framePool, fast);
      if (!fe) return fe.error();
      pendingEval = std::make_unique<AirlightImageEvaluator>(std::move(fe).value());
    }
    for (std::size_t i = 0; i < all.lamps.size(); ++i) pendingEval->setLampEnabled(i, b.lampOn[i] != 0);
    pendingEval->evaluate(all, *surf, subsampling, air);
  } else {
    // World and ego lamps through the tables (lamps that are off switched off in the evaluator).
    eval->evaluate(scene, *surf, subsampling, air);
    out.fog_rungs = air.fog_rungs;
    out.bending_rungs = air.bending_rungs;
  }
  out.airlight_evaluated = air.evaluated;
  if (!traffic.lamps.empty()) {
    // Traffic lamps move relative to the eye: no view tables, so measured profiles go per pixel
    // through the pencil integrator or per ray ([render] moving_lamps, docs/airlight.md);
    // per-lamp tables come from the evaluators' caches, the pool is the frame's.
    const std::shared_ptr<ThreadPool>& pool = b.useTables ? eval->pool() : framePool;
    bool kept = trafficEval && trafficPool == pool.get() && trafficKeys.size() == traffic.lamps.size();
    for (std::size_t i = 0; kept && i < traffic.lamps.size(); ++i) {
      const SceneLamp& l = traffic.lamps[i];
      const TrafficLampKey& k = trafficKeys[i];
      kept = k.profile == l.lamp.profile.get() && k.color == l.lamp.color && k.mount == l.mount;
    }
    kept = kept && trafficEval->setFog(traffic.fog) && trafficEval->setLampPoses(traffic);
    if (!kept) {
      auto te = AirlightImageEvaluator::build(traffic, method, AirlightOptions{}, pool, fast);
      if (!te) return te.error();
      trafficEval = std::make_unique<AirlightImageEvaluator>(std::move(te).value());
      trafficPool = pool.get();
      trafficKeys.clear();
      for (const SceneLamp& l : traffic.lamps) trafficKeys.push_back({l.lamp.profile.get(), l.lamp.color, l.mount});
    }
    // Added onto the world and ego lamps' image as its tiles are written: no second image, and
    // no pass to sum two (2.8 M floats at 1280×720).
    trafficEval->evaluate(traffic, *surf, subsampling, air, AirlightImageEvaluator::Write::Add);
    out.traffic_evaluated = air.evaluated;
    out.traffic_lamps_dropped = air.moving_dropped;
    if (air.moving_dropped > 0) {
      // Over the budget ([render] max_moving_lamps): the dimmest traffic lamps were left out of
      // this frame. Counted; logged at most every 10 s.
      droppedLamps += air.moving_dropped;
      static std::atomic<std::int64_t> lastLog{0};
      if (gateOpens(lastLog, 10))
        spdlog::warn("render: more lit traffic lamps than [render] max_moving_lamps = {}: {} lamp-frame(s) so far left "
                     "out, the dimmest each frame",
                     config->max_moving_lamps, droppedLamps);
    }
  }
  return Ok{};
}

Status ChannelRenderer::Impl::renderEffects(const Begun& b, RenderedFrame& out, EffectLayers& layers) {
  const Scene& lit = b.lit;
  const TableKey& key = b.key;
  // Glow and glare of the lamps that are on, seen from this frame's eye through its fog, with
  // the surfaces' distances (a lamp behind a surface has neither). The lit scene holds only the
  // lamps that are on; LampEffects leaves the ego's own (vehicle-mounted) lamps out itself.
  out.effects = LampEffectsReport{};
  const SceneEffects& fx = config->effects;
  if (!fx.glow.enabled && !fx.glare.enabled) return Ok{};
  const std::shared_ptr<ThreadPool>& pool = framePool;
  if (!effects || !(effectsKey == key) || effectsPool != pool.get()) {
    // The old instance lives until the new one is built, so its single-scattering table
    // (cached while someone holds it) is reused when the phase has not changed.
    auto built = LampEffects::build(lit, fx.glow, fx.glare, pool);
    if (!built) return built.error();
    effects = std::move(built).value();
    effectsKey = key;
    effectsPool = pool.get();
  }
  effects->evaluate(lit, *b.surf, glow, glare, out.effects);
  layers.glow = &glow;
  layers.glare = &glare;
  return Ok{};
}

double ChannelRenderer::Impl::exposureFor(const FrameLayers& l, double adaptSeconds) {
  if (!channel.autoExposure()) return channel.exposure_ev;
  // The first frame takes its own EV; a clock that went back (a scenario loop, a new host) starts
  // the adaptation again.
  if (exposure.started() && !(adaptSeconds >= 0.0)) exposure.reset();
  return exposure.update(autoExposureEv(l.composite, l.width, l.height), adaptSeconds);
}

void ChannelRenderer::Impl::compositeAndPack(const Begun& b, const EffectLayers& layers, double adaptSeconds,
                                             RenderedFrame& out) {
  // Composite (surface · T + airlight, glow and glare added), then the channel's wire format:
  // tone-mapped sRGB at the channel's exposure, linear cd/m², or the overlay (A = T).
  compositeFrame(b.scene.fog, *b.surf, air, out.layers, layers, framePool.get());
  const std::size_t n = static_cast<std::size_t>(channel.width) * static_cast<std::size_t>(channel.height);
  out.packed.resize(n * ipc::bytesPerPixel(format));
  if (format == FOGBEAM_FORMAT_RGBA8_SRGB) {
    out.exposure_ev = exposureFor(out.layers, adaptSeconds);
    packRgba8Srgb(out.layers.composite.data(), n, out.exposure_ev, reinterpret_cast<std::uint8_t*>(out.packed.data()));
  } else if (format == FOGBEAM_FORMAT_RGBA16F_LINEAR) {
    out.exposure_ev = 0.0;
    packRgba16F(out.layers.composite.data(), nullptr, 1.0f, n, reinterpret_cast<std::uint16_t*>(out.packed.data()));
  } else {
    out.exposure_ev = 0.0;
    packRgba16F(out.layers.overlay.data(), out.layers.transmittance.data(), 1.0f, n,
                reinterpret_cast<std::uint16_t*>(out.packed.data()));
  }
}

Status ChannelRenderer::Impl::beginFrame(const ipc::SimSnapshot& state, ipc::Clock::time_point now, bool wait,
                                          const HostFrame* host, Begun& b, bool overlapped) {
  const auto t0 = Clock::now();
  const ipc::EgoState& ego = state.ego.value;
  if (host) {
    const Camera& hc = host->view->camera;
    if (hc.width != channel.width || hc.height != channel.height || host->surface->width != hc.width ||
        host->surface->height != hc.height)
      return Error{"host view " + std::to_string(hc.width) + "x" + std::to_string(hc.height) + " for a " +
                   std::to_string(channel.width) + "x" + std::to_string(channel.height) + " channel"};
    adoptHostIntrinsics(hc);
  }
  b.host = host;
  b.wait = wait;
  b.now = now;
  // The vehicle: the ego pose, or for a host view the pose that puts the channel's eye at the
  // host's camera (the host's view wins; docs/service.md, "Host depth").
  const VehiclePose pose = host ? poseOf(host->view->camera, vehicleCamera) : poseOf(ego);
  // Until the first lamp state the ego drives with low beams and position lamps.
  b.lights = state.lamps.stamp.valid ? state.lamps.value.lights : ipc::light::kInitialEgo;
  // Live traffic with a rig: its lamps go per pixel, so the frame is not a cheap one (the fog
  // ladder starts no rung around a steady fog then).
  b.trafficLive = std::any_of(state.traffic.begin(), state.traffic.end(), [&](const ipc::TrafficEntry& e) {
    return state.live(e, now) && config->rigFor(e.object.vehicle_class) != nullptr;
  });

  // 1. Tables for the wanted fog and bending (built, awaited or still building).
  const TableKey want = wantedTables(state);
  const auto tw = Clock::now();
  if (Status s = updateTables(pose, want, wait, b); !s) return s;
  b.tableWaitMs = ms(tw, Clock::now());
  const bool served = current.serves(want, config->bending_tolerance_deg);
  b.pending = gpuAirlight ? false : perPixelPending ? !b.useTables : !served;
  // The fog and bending this frame shows: the wanted ones, unless pending_tables = "previous"
  // keeps the tables' until their build is done.
  // (Tables serve it when its bending angle is within bending_tolerance_deg of theirs: then the
  // frame shows theirs, the evaluator's lamps keeping the poses its tables were built for.)
  b.key = gpuAirlight || (perPixelPending && !b.useTables) ? want : current;
  if (b.ladder) {
    // Between two rungs: the wanted fog, and the fog rungs' bending (within the tolerance of the
    // wanted) or, between two bending rungs, the wanted bending.
    b.key = want;
    if (!b.bendingLadder) b.key.bendingDeg = rungBase.bendingDeg;
  }

  // 2. The frame's scenes: `scene` = world lamps + the whole ego rig for the tables' fog and
  // bending; `lit` = the lamps that are on (world, ego by light bits, traffic), for the surface
  // pass, the GPU airlight, glow and glare; `traffic` = the traffic lamps that are on. (The
  // tables' evaluator gets the poses and switches at the airlight: setEvaluatorLamps.)
  b.scene = sceneFor(pose, b.key);
  if (host) b.scene.camera = host->view->camera;  // exactly the host's (sceneFor's differs by rounding)
  b.lit = b.scene;
  b.lit.lamps.clear();
  b.traffic = b.scene;
  b.traffic.lamps.clear();
  litLamps(b.lights, b);
  const std::uint32_t trafficCount = trafficLamps(state, now, b.traffic, b.lit);

  // 3. Surfaces.
  const auto tS = Clock::now();
  b.gpuAirlightMs = 0.0;
  b.surf = host ? host->surface : &b.surface;  // a host view: its distances, no surface pass
  if (!host) {
    if (Status s = renderSurfaces(b, overlapped); !s) return s;
  } else if (host->view->colour && format != FOGBEAM_FORMAT_RGBA16F_OVERLAY) {
    // A composite of the host's own image: its surfaces seen through this frame's fog, as the
    // surface pass gives fogbeam's own (L·T + ambient·(1 − T), T = exp(−K_t d), 0 for sky), so
    // that composite = host·T + overlay.
    const SurfaceBuffers& hs = *host->surface;
    b.surface.resize(hs.width, hs.height);
    const double kt = b.scene.fog.extinction_per_m;
    const auto ia = static_cast<float>(b.scene.fog.ambient_cd_m2);
    for (std::size_t k = 0; k < hs.distance.size(); ++k) {
      const float d = hs.distance[k];
      const float t = std::isinf(d) ? 0.0f : static_cast<float>(std::exp(-kt * static_cast<double>(d)));
      b.surface.distance[k] = d;
      for (std::size_t c = 0; c < 3; ++c) b.surface.rgb[3 * k + c] = hs.rgb[3 * k + c] * t + ia * (1.0f - t);
    }
    b.surf = &b.surface;
  }
  const auto tE = Clock::now();
  b.surfaceMs = ms(tS, tE);

  // What the renderer knows of the frame (the state is not kept: finish() may run after the
  // caller's next snapshot).
  b.view.eye_m = b.scene.camera.position_m;
  const FrustumAngles f = vehicleCamera.frustum();
  b.view.fov_x_deg = static_cast<float>((f.left + f.right) * 180.0 / kPi);
  b.view.fov_y_deg = static_cast<float>((f.up + f.down) * 180.0 / kPi);
  b.hostFrame = host ? host->view->frame : 0;
  if (host) {
    // The host's view echoed as it was published, so that the host pairs the overlay with its frame.
    const HostView& hv = *host->view;
    b.view.yaw_deg = hv.yaw_deg;
    b.view.pitch_deg = hv.pitch_deg;
    b.view.roll_deg = hv.roll_deg;
    b.view.frustum_deg = hv.frustum_deg;
    b.inputs.sim_time_s = hv.sim_time_s;
  } else {
    b.view.yaw_deg = ego.pose.yaw_deg;
    b.view.pitch_deg = ego.pose.pitch_deg;
    b.view.roll_deg = ego.pose.roll_deg;
    b.view.frustum_deg = {0.0f, 0.0f, 0.0f, 0.0f};
    if (channel.frustum_deg)
      for (std::size_t k = 0; k < 4; ++k) b.view.frustum_deg[k] = static_cast<float>((*channel.frustum_deg)[k]);
    b.inputs.sim_time_s = state.ego.stamp.sim_time_s;
  }
  // The automatic exposure's simulation clock (finishFrame).
  b.simTime = host ? host->view->sim_time_s : state.ego.stamp.sim_time_s;
  b.inputs.lights = b.lights;
  b.inputs.ego_sequence = state.ego.stamp.sequence;
  b.inputs.lamp_sequence = state.lamps.stamp.sequence;
  b.inputs.environment_sequence = state.environment.stamp.sequence;
  b.inputs.traffic_count = trafficCount;
  b.beginMs = ms(t0, Clock::now());
  return Ok{};
}

Status ChannelRenderer::Impl::finishFrame(Begun& b, RenderedFrame& out) {
  const auto t0 = Clock::now();
  // A build the frame took in stage 1 replaces the tables now: the frame before it is done.
  if (b.adopt) {
    eval = std::move(b.adopt);
    evalRungsVersion = ~std::uint64_t{0};
  }
  out.timings.table_wait_ms = b.tableWaitMs;
  out.pending = b.pending;

  // 4. Airlight (the tables' evaluator given the frame's lamp poses and switches first).
  const auto tA = Clock::now();
  if (Status s = setEvaluatorLamps(b); !s) return s;
  if (Status s = renderAirlight(b, out); !s) return s;

  // 5. Glow and glare.
  const auto tF = Clock::now();
  EffectLayers layers;
  if (Status s = renderEffects(b, out, layers); !s) return s;

  // 6. Composite and pack.
  const auto tC = Clock::now();
  // The automatic exposure adapts over the time between frames: the states' simulation time when
  // frames wait for their inputs (lock-step, replay: the same states give the same frames), the
  // wall clock when free-running (what the cab's driver sees).
  double adaptSeconds = 0.0;
  if (exposureClockSet)
    adaptSeconds = b.wait ? b.simTime - exposureSimTime : std::chrono::duration<double>(b.now - exposureWallTime).count();
  exposureSimTime = b.simTime;
  exposureWallTime = b.now;
  exposureClockSet = true;
  compositeAndPack(b, layers, adaptSeconds, out);
  const auto tE = Clock::now();

  // What the renderer knows of the frame; the service adds its bookkeeping (wireMeta).
  out.view = b.view;
  out.inputs = b.inputs;
  out.host_frame = b.hostFrame;
  // With the GPU airlight, surfaces and airlight are one GL pass: its airlight draw's GPU time
  // (timer query) is the airlight, the rest of the pass's wall time the surface.
  out.timings.surface_ms = std::max(0.0, b.surfaceMs - b.gpuAirlightMs);
  out.timings.airlight_ms = ms(tA, tF) + b.gpuAirlightMs;
  out.timings.effects_ms = config->effects.glow.enabled || config->effects.glare.enabled ? ms(tF, tC) : 0.0;
  out.timings.composite_ms = ms(tC, tE);
  out.timings.total_ms = b.beginMs + ms(t0, tE);
  // The frame's scenes are rebuilt by its slot's next begin(); the host's buffers are the host's.
  b.host = nullptr;
  return Ok{};
}

Status ChannelRenderer::begin(const ipc::SimSnapshot& state, ipc::Clock::time_point now, bool wait,
                              const HostFrame* host) {
  Impl& m = *impl_;
  std::size_t slot = 0;
  bool overlapped = false;
  {
    std::lock_guard lock(m.ring);
    if (m.queued >= m.slots.size())
      return Error{"ChannelRenderer::begin: two frames begun and not finished (finish() one first)"};
    if (host && m.queued != 0)
      return Error{"ChannelRenderer::begin: a host view's frame cannot be begun beside another (finish it first)"};
    if (m.queued == 0) m.head = 0;  // frames in sequence always use slot 0 (one set of buffers)
    slot = (m.head + m.queued) % m.slots.size();
    overlapped = m.queued != 0;  // the frame in flight may be in finish() on another thread
  }
  // Only this thread touches slots[slot] until it is queued below.
  if (Status s = m.beginFrame(state, now, wait, host, m.slots[slot], overlapped); !s) return s;
  std::lock_guard lock(m.ring);
  ++m.queued;
  return Ok{};
}

Status ChannelRenderer::finish(RenderedFrame& out) {
  Impl& m = *impl_;
  std::size_t slot = 0;
  {
    std::lock_guard lock(m.ring);
    if (m.queued == 0) return Error{"ChannelRenderer::finish: no frame begun"};
    slot = m.head;
  }
  const Status s = m.finishFrame(m.slots[slot], out);
  std::lock_guard lock(m.ring);
  m.head = (m.head + 1) % m.slots.size();
  --m.queued;
  return s;
}

std::size_t ChannelRenderer::inFlight() const {
  std::lock_guard lock(impl_->ring);
  return impl_->queued;
}

Status ChannelRenderer::render(const ipc::SimSnapshot& state, ipc::Clock::time_point now, bool wait,
                               RenderedFrame& out, const HostFrame* host) {
  if (inFlight() != 0) return Error{"ChannelRenderer::render: a frame begun with begin() is not finished"};
  if (Status s = begin(state, now, wait, host); !s) return s;
  return finish(out);
}

}  // namespace fogbeam::plugin
