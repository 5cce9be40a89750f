// fogbeam — scripted traffic scenarios (docs/scenario.md): the world scene, fog over time, the
// ego trajectory, traffic vehicles with trajectories (timed keyframes or an esmini CSV export)
// and lamp switching events. A Scenario is evaluated at a time into the same messages a host
// sends over UDP (ipc/protocol.hpp), so `fogbeam replay`, `fogbeam serve --scenario` and
// `fogbeam send` all drive the renderer through one path.
//
// Interpolation (documented in docs/scenario.md):
// - positions: cubic Hermite through the keyframes with Catmull–Rom tangents for uneven times,
//   m_k = (p_{k+1} − p_{k−1}) / (t_{k+1} − t_{k−1}), one-sided at the ends: C¹ (velocity is
//   continuous, so speed and heading do not jump at keyframes);
// - yaw, pitch, roll: the same Hermite on unwrapped angles when keyframes give them; a path
//   without yaw keys heads along its velocity (atan2 of dp/dt);
// - speed: |dp/dt| of the position curve;
// - fog: visibility keys interpolated linearly in log V (so K_t = ln 20 / V changes by a
//   constant factor per second) or held ("step");
// - lights: events set a vehicle's whole light state from their time on.
// Before its first keyframe a traffic vehicle does not exist, after its last it is removed; the
// ego holds its first / last pose.
//
// Thread-safety: a Scenario is immutable after loading; at() is const and reentrant.
#pragma once

#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/physics/math.hpp>
#include <fogbeam/util/key_table.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::plugin {

/// One keyframe of a trajectory, in the world frame (m, deg).
struct PoseKey {
  double t_s = 0.0;
  Vec3 position_m{0.0};
  double yaw_deg = 0.0, pitch_deg = 0.0, roll_deg = 0.0;
};

/// A C¹ path through timed keyframes (see the file comment).
class Trajectory {
 public:
  struct Sample {
    ipc::Pose pose;
    double speed_m_s = 0.0;
  };
  /// `keys` sorted by strictly increasing t_s (at least one); `hasYaw`: false = head along the
  /// velocity. Errors say which key is out of order.
  [[nodiscard]] static Result<Trajectory> make(std::vector<PoseKey> keys, bool hasYaw, const std::string& what);
  /// The pose at t (clamped to the first / last key).
  [[nodiscard]] Sample at(double t_s) const;
  [[nodiscard]] double start_s() const { return keys_.front().t_s; }
  [[nodiscard]] double end_s() const { return keys_.back().t_s; }
  [[nodiscard]] const std::vector<PoseKey>& keys() const { return keys_; }

 private:
  std::vector<PoseKey> keys_;
  bool hasYaw_ = true;
};

/// From t_s on, a vehicle's lights are `lights` (ipc::light bits) and its bending angle
/// `bending_deg` (ego only; + = left).
struct LightEvent {
  double t_s = 0.0;
  std::uint32_t lights = 0;
  float bending_deg = 0.0f;
};

struct ScenarioVehicle {
  std::string name;
  std::uint32_t id = 0;               ///< traffic object id (the ego's is unused)
  std::uint16_t vehicle_class = 0;    ///< selects a rig in the service config
  Trajectory path;
  std::vector<LightEvent> lights;     ///< sorted by time; the first one is at −∞ (the initial state)
  [[nodiscard]] LightEvent lightsAt(double t_s) const;
};

struct FogKey {
  double t_s = 0.0;
  double visibility_m = 0.0;
};

struct Scenario {
  std::string source;       ///< file path, for messages
  std::string name, description;
  std::string scene_path;   ///< the world (resolved): fog defaults, world lamps, planes, glTF
  double duration_s = 0.0;
  ipc::Environment fog;     ///< the fog at t = 0 (phase, albedo, ambient; visibility or extinction)
  std::vector<FogKey> fog_keys;  ///< empty: constant fog
  bool fog_step = false;         ///< hold each key instead of interpolating
  ScenarioVehicle ego;
  std::vector<ScenarioVehicle> traffic;
};

/// The state of a scenario at one time, as the messages a host would send.
struct ScenarioState {
  double t_s = 0.0;
  ipc::EgoState ego;
  ipc::LampState ego_lamps;
  ipc::Environment environment;
  ipc::TrafficList traffic;  ///< complete = true: vehicles not present are removed
};

/// Evaluates the scenario at t (seconds from its start).
[[nodiscard]] ScenarioState evaluate(const Scenario& s, double t_s);

/// The datagrams (encoded protocol messages) of one state, sequence numbers from `sequence`
/// (advanced), in this order: environment, lamps, traffic (split over datagrams when needed),
/// ego last (the pose a frame is stamped with completes the state).
[[nodiscard]] std::vector<std::vector<std::uint8_t>> encodeState(const ScenarioState& state,
                                                                 std::uint32_t& sequence);

/// Applies one state to a store as if its messages had arrived at `received` (source
/// "scenario"; sequence numbers from `sequence`, advanced): what `fogbeam replay` and
/// `fogbeam serve --scenario` do instead of going through UDP.
void applyState(const ScenarioState& state, ipc::StateStore& store, std::uint32_t& sequence,
                ipc::Clock::time_point received);

/// Light bits from names: "position", "low-beam", "high-beam", "brake", "indicator-left",
/// "indicator-right", "front-fog", "rear-fog", "drl". Unknown names: error listing them.
[[nodiscard]] Result<std::uint32_t> lightsFromNames(const std::vector<std::string>& names);
[[nodiscard]] std::string lightNames(std::uint32_t lights);

/// Parses a scenario file; relative paths (scene, CSV) resolve against `baseDir`.
[[nodiscard]] Result<Scenario> parseScenario(std::string_view text, const std::string& name, const std::string& baseDir);
[[nodiscard]] Result<Scenario> loadScenario(const std::string& path);
/// The scenario format's key tables in docs/scenario.md (config::KeyTable): the top level, the
/// [fog] key it adds to the scene's, [[fog_key]], [ego] / [[vehicle]], their [[…key]] and
/// [[…event]] entries.
[[nodiscard]] std::vector<config::KeyTable> scenarioKeyTables();

/// One row of an esmini CSV export (time, id, name, x, y, z, h, p, r, speed, …). esmini writes
/// h, p, r in radians; they are converted to degrees here.
struct EsminiRow {
  double t_s = 0.0;
  std::uint32_t id = 0;
  std::string name;
  Vec3 position_m{0.0};
  double yaw_deg = 0.0, pitch_deg = 0.0, roll_deg = 0.0;
  double speed_m_s = 0.0;
};
/// Reads an esmini CSV (dat2csv / --csv_logger): lines before the header row ("time, id, name,
/// …") are skipped, columns are found by header name, extra columns are ignored. Errors name the
/// file, line and column.
[[nodiscard]] Result<std::vector<EsminiRow>> parseEsminiCsv(std::string_view text, const std::string& name);

}  // namespace fogbeam::plugin
