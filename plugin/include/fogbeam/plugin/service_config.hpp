// fogbeam — the service configuration of `fogbeam serve` (docs/service.md, key by key).
//
// Layers, later ones winning: the built-in default (config/service/default.toml, embedded in
// the binary), then a file (--config), then command-line settings (--set key=value and the
// named options). Each layer is parsed on its own, so an error names the layer's file (or
// "command line") and line; a key a layer leaves out keeps its value from the layer below.
// Tables merge key by key; an array of tables ([[channel]], [[ego.lamp]], [[traffic_class]])
// and the [fog] table replace the layer below's whole.
//
// Thread-safety: plain values; loading is reentrant.
#pragma once

#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/scene/effects.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/key_table.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::plugin {

/// A lamp of a vehicle rig, in the vehicle frame.
struct RigLamp {
  /// mount is Vehicle; pose relative to the vehicle reference point. `lamp.aperture` (keys
  /// aperture, aperture_size_m, aperture_samples) is kept as written: the frame renderer expands
  /// the lamp into its point lamps once it is placed (expandRig in frame_renderer.hpp).
  SceneLamp lamp;
  std::string role;        ///< "low-beam", "high-beam", "front-fog", "rear-fog", "position", "brake", "drl", "always"
  std::uint32_t light_bit = 0;  ///< ipc::light bit that switches it; 0 = always on
  bool bending = false;    ///< swivels about the vehicle's z with the host's bending angle (ego only)
  std::string definition;  ///< its TOML table with resolved paths (for --print-config)
};

struct VehicleRig {
  std::string name;
  std::vector<RigLamp> lamps;
};

/// One output view: a shared-memory channel.
struct ChannelConfig {
  std::string name = "main";       ///< segment /fogbeam.<name>
  int width = 320, height = 180;   ///< pixels
  double fov_x_deg = 60.0;         ///< horizontal field of view of a centred pinhole
  /// Off-axis view instead: half-angles [left, right, up, down], deg (Camera::fromFrustum);
  /// height follows from square pixels.
  std::optional<std::array<double, 4>> frustum_deg;
  Vec3 eye_offset_m{0.0};          ///< from the driver's eye, vehicle frame
  double yaw_deg = 0.0, pitch_deg = 0.0, roll_deg = 0.0;  ///< relative to the vehicle
  std::string format = "rgba8-srgb";  ///< "rgba8-srgb" | "rgba16f-linear" | "rgba16f-overlay"
  bool distance = false;           ///< also publish the f32 distance plane
  double exposure_ev = 0.0;        ///< rgba8-srgb tone mapping exposure, EV (when not automatic)
  /// exposure_ev = "auto" (the parser's default for rgba8-srgb channels without depth_from): the
  /// frame's automatic night exposure, adapted over time (fogbeam/render/exposure.hpp). Applies
  /// where autoExposure() says so; elsewhere exposure_ev is used.
  bool exposure_auto = true;
  /// The host's depth channel this view takes its camera and distances from (docs/service.md,
  /// "Host depth"); empty = fogbeam's own view and surface pass.
  std::string depth_from;

  /// Whether the rgba8-srgb frames are packed at the automatic exposure: exposure_auto on an
  /// rgba8-srgb channel of fogbeam's own view (a depth_from channel's exposure is fixed: the host's
  /// colour is decoded at it).
  [[nodiscard]] bool autoExposure() const { return exposure_auto && format == "rgba8-srgb" && depth_from.empty(); }
};

struct ServiceConfig {
  std::vector<std::string> layers;  ///< where each layer came from, in order

  // [world]
  std::string scene_path;     ///< resolved: the world scene (world lamps, planes, glTF)
  std::string scenario_path;  ///< resolved; empty = no scenario
  bool scenario_loop = true;

  Medium fog;                 ///< [fog]: until an environment message arrives
  std::string fog_text;       ///< [fog] as given (for --print-config)

  // [render]
  std::string method = "accurate";
  bool subsampling = true;
  double view_table_step_deg = 0.5;
  std::string moving_lamps = "pencil";  ///< traffic and world lamps: "pencil" | "map" | "per-ray" (MovingLampPath)
  /// cd/m² per channel: the most the moving lamps left out of a pixel add there together
  /// (FastPathOptions::moving_lamp_cutoff_cd_m2); 0: none left out.
  double moving_lamp_cutoff_cd_m2 = FastPathOptions{}.moving_lamp_cutoff_cd_m2;
  /// At most this many lit traffic lamps (and as many of the world's moving lamps) evaluated per
  /// frame, the dimmest by their bound left out (FastPathOptions::max_moving_lamps); 0: no budget.
  int max_moving_lamps = 64;
  std::string surface = "auto";
  unsigned threads = 0;
  /// Where the ego lamps' view tables are kept between starts: "auto" ($XDG_CACHE_HOME/fogbeam
  /// or ~/.cache/fogbeam), "off", or a directory (tableCacheDirFor, render/airlight_image.hpp).
  std::string table_cache = "auto";
  /// What frames do while the ego lamps' tables for a new fog or bending angle are built:
  /// "per-pixel" (the ego lamps go through the moving-lamp path in the new fog and bending; no
  /// frame waits) or "previous" (free-running keeps the previous fog and bending, lock-step and
  /// replay wait for the build). docs/service.md, "How a frame is made", step 5.
  std::string pending_tables = "per-pixel";
  /// pending_tables = "per-pixel", lock-step and replay: a build started at frame N is used from
  /// frame N + table_adopt_frames on (waited for there if it is not done), so that the frames a
  /// run makes do not depend on how fast the machine builds.
  int table_adopt_frames = 60;
  /// The fog ladder (pending_tables = "per-pixel"; docs/service.md, "The fog ladder"): the ego
  /// lamps' view tables built in the background at K_t = fog_ladder_ratio^m per metre (rungs),
  /// around the fog while tables serve it and where it heads while it changes; a frame between
  /// two rungs reads both instead of going per pixel. 0 = off; else a ratio in [1.05, 2]. At
  /// most fog_ladder_rungs rungs are kept (those nearest the fog; ~20 MB each at the default
  /// view_table_step_deg).
  double fog_ladder_ratio = 1.2;
  int fog_ladder_rungs = 8;
  /// Lock-step and replay: a rung started at frame N is read from frame N + this on (waited for
  /// there if it is not done), as table_adopt_frames for whole builds; shorter, since a ramp
  /// crosses a rung every few tenths of a second.
  int fog_ladder_adopt_frames = 20;
  /// The bending ladder (pending_tables = "per-pixel"; docs/service.md, "The bending ladder"):
  /// for an ego rig with bending lamps, their view tables built in the background at bending
  /// angles j · bending_ladder_step_deg (rungs, for the fog as it is), around the angle while
  /// tables serve it and where it turns while it turns; a frame whose angle lies between two
  /// rungs reads both, each through its turn, instead of going per pixel. 0 = off; else
  /// [0.1, 5] degrees. At most bending_ladder_rungs rungs are kept (those nearest the angle).
  double bending_ladder_step_deg = 1.0;
  int bending_ladder_rungs = 12;
  /// Frame overlap (docs/service.md, "Overlapped frames"): the surface pass of the next frame
  /// beside the airlight, glow, glare and composite of the previous one, on a second thread.
  /// "auto" (on where cores allow: overlapsFrames in frame_pipeline.hpp), "on" or "off". Frames
  /// are byte for byte the same either way.
  std::string overlap_frames = "auto";

  /// [render] airlight, gpu_pieces; [glow]; [glare]: the scene's tables (docs/scene.md), all
  /// off and the CPU airlight by default.
  SceneEffects effects;

  // [timing]
  bool lock_step = false;
  double rate_hz = 30.0;

  // [status]
  double status_interval_s = 5.0;
  std::uint16_t status_udp_port = 47801;  ///< 0 = off

  // [input.udp]
  std::string udp_bind = "127.0.0.1";
  std::uint16_t udp_port = 47800;
  std::string udp_multicast;
  std::vector<std::string> udp_allow;
  double traffic_timeout_s = 1.0;
  /// The state store's bound on traffic objects (ipc::StateStoreOptions::max_traffic_objects);
  /// objects beyond it are refused and counted (docs/protocol.md).
  std::size_t max_traffic_objects = 256;

  // [input.can]
  std::string can_source = "none";  ///< "none" | "interface" | "candump" | "cannelloni"
  std::string can_interface;        ///< SocketCAN interface
  std::string can_candump;          ///< resolved candump -L log
  double can_candump_speed = 1.0;   ///< replay speed factor
  std::uint16_t can_cannelloni_port = 0;
  std::string can_mapping_path;     ///< resolved CAN mapping file (docs/can.md)

  std::vector<ChannelConfig> channels;

  // [ego]
  Vec3 eye_m{1.3, 0.37, 1.2};
  double bending_max_deg = 15.0;
  /// View tables built for one bending angle serve frames whose angle is within this of it;
  /// beyond it a frame shows its exact angle per pixel until tables for that angle are in use
  /// (a bending signal that jitters by less than this does not keep frames per pixel), deg.
  double bending_tolerance_deg = 0.05;
  VehicleRig ego;
  /// [ego.bonnet]: the ego car's bonnet in the vehicle frame (docs/service.md); empty: none.
  std::optional<Bonnet> bonnet;

  /// By class; class 0 stands in for classes without a rig.
  std::map<std::uint16_t, VehicleRig> traffic;
  [[nodiscard]] const VehicleRig* rigFor(std::uint16_t vehicleClass) const;
};

/// The largest `[input.udp] max_traffic_objects`: every state-store update copies the traffic
/// list (copy-on-write, ipc/state_store.hpp), about 0.5 MB at this many objects.
inline constexpr std::size_t kMaxTrafficObjectsLimit = 4096;

/// The channel's camera in the vehicle frame: at the driver's eye + the channel's offset, with
/// its orientation, field of view or frustum and size.
[[nodiscard]] Camera channelCamera(const ServiceConfig& config, const ChannelConfig& channel);

/// The built-in default's text and the directory its relative paths resolve against
/// ($FOGBEAM_CONFIG_DIR, else the repository's config/ directory fixed at build time).
[[nodiscard]] std::string_view builtinServiceConfig();
[[nodiscard]] std::string builtinConfigDir();

/// Applies one layer (TOML text) over `config`. `name` is used in messages, `baseDir` resolves
/// relative paths. On error `config` may be partly updated: callers discard it.
[[nodiscard]] Status applyServiceLayer(ServiceConfig& config, std::string_view text, const std::string& name,
                                       const std::string& baseDir);

/// Built-in default, then `file` (when not empty), then each "key.path=value" of `settings`
/// (value in TOML syntax: 60, "text", [1, 2, 3], true); then checks the whole.
[[nodiscard]] Result<ServiceConfig> loadServiceConfig(const std::string& file, const std::vector<std::string>& settings);

/// Cross-key checks (unique channel names, overlay format needs no exposure, a rig for class 0,
/// a CAN source with its mapping, the GPU airlight with a GL surface and the accurate method …).
[[nodiscard]] Status validate(const ServiceConfig& config);

/// The effective configuration as TOML (every key, resolved paths), for --print-config.
[[nodiscard]] std::string toToml(const ServiceConfig& config);

/// The service config's own key tables in docs/service.md (config::KeyTable): the top level,
/// [world], [render] (its keys and the scene's), [glow], [glare], [timing], [status], [input],
/// [input.udp], [input.can], [[channel]], [ego], [[traffic_class]] and the keys rig lamps add to
/// the scene's lamp keys. [fog] and the rig lamps' scene keys are the scene's tables
/// (config::sceneKeyTables()).
[[nodiscard]] std::vector<config::KeyTable> serviceConfigKeyTables();

/// Every key table of every format fogbeam reads, the one registry the docs check walks
/// (tests/plugin/test_config_docs.cpp): the scene's (config::sceneKeyTables()), the scenario's
/// (scenarioKeyTables()), the service config's (serviceConfigKeyTables()) and the CAN
/// mapping's (ipc::canConfigKeyTables()). Here because the service config embeds or names every
/// other format. Reentrant.
[[nodiscard]] std::vector<config::KeyTable> configKeyTables();

}  // namespace fogbeam::plugin
