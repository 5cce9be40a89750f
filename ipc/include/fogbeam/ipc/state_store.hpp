// fogbeam — the simulation state the frame loop renders: ego pose and speed, ego lamp states,
// traffic objects, fog, and the latest lock-step frame request, each stamped with the sender's
// simulation time, sequence number and the local receive time.
//
// Concurrency: receivers (UDP, CAN, scenario players) are writers; the frame loop reads.
// Writers serialise on a mutex among themselves, copy the current snapshot, change the copy and
// publish it through one atomic shared_ptr; snapshot() is a single atomic load. The frame loop
// therefore never blocks a receiver and always sees one consistent state (never half of an
// update). Copy-on-write costs one copy of the traffic list per update (a few kB at 60 Hz).
//
// Traffic: an object disappears at once when removed (flag or a complete list without it) and
// expires when it has not been updated for `traffic_timeout_s` (StateStoreOptions); expired
// objects are skipped by SimSnapshot::live() and purged by expire(). Memory is bounded by
// `max_traffic_objects`: updates that would exceed it are refused and counted.
//
// Lamps: the mask starts as light::kInitialEgo (low beam + position, docs/service.md) and its
// stamp stays invalid until the first lamp state. A bus input (CAN) owns the bits its mapping
// maps (docs/can.md): setBusLights() claims and sets them, and setLamps() (UDP, scenario) leaves
// them as they are and sets the others.
#pragma once

#include <fogbeam/ipc/protocol.hpp>

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace fogbeam::ipc {

using Clock = std::chrono::steady_clock;

/// Where and when a value came from.
struct Stamp {
  bool valid = false;            ///< false until the first update
  double sim_time_s = 0.0;       ///< sender's simulation time
  std::uint32_t sequence = 0;    ///< sender's sequence number
  Clock::time_point received{};  ///< local receive time (input-to-frame latency starts here)
  std::string source;            ///< "udp 127.0.0.1:40000", "can vcan0", "scenario", …
};

template <class T>
struct Stamped {
  T value{};
  Stamp stamp;
};

struct TrafficEntry {
  TrafficObject object;  ///< removed is always false here
  Stamp stamp;
};

/// One consistent state. Immutable once published.
struct SimSnapshot {
  std::uint64_t version = 0;  ///< +1 per published update
  Stamped<EgoState> ego;
  Stamped<LampState> lamps;
  Stamped<Environment> environment;
  Stamped<FrameRequest> frame_request;
  Stamped<float> vehicle_speed_m_s;   ///< from the vehicle bus (CAN), beside ego.value.speed_m_s
  std::vector<TrafficEntry> traffic;  ///< sorted by object id
  double traffic_timeout_s = 1.0;

  /// True when `e` has been updated within the timeout as of `now`.
  [[nodiscard]] bool live(const TrafficEntry& e, Clock::time_point now) const noexcept {
    return now - e.stamp.received <= std::chrono::duration<double>(traffic_timeout_s);
  }
};

struct StateStoreOptions {
  double traffic_timeout_s = 1.0;         ///< objects not updated for this long expire
  std::size_t max_traffic_objects = 256;  ///< bound on the traffic list (network-controlled)
};

class StateStore {
 public:
  explicit StateStore(const StateStoreOptions& options = {});

  /// The current state: one atomic load, never blocks. Thread-safe.
  [[nodiscard]] std::shared_ptr<const SimSnapshot> snapshot() const;

  // Writers (thread-safe among themselves).
  void setEgo(const EgoState& v, const Stamp& s);
  /// A host's lamp state (UDP, scenario): its bits replace the mask's, except those a bus input
  /// owns (setBusLights()), which keep their values; the bending angle is taken as given.
  void setLamps(const LampState& v, const Stamp& s);
  /// A bus input's lamp bits (light:: bits; the CAN input): the bits of `owned` are this input's
  /// from now on, and setLamps() no longer changes them. The bits of `known` (within `owned`:
  /// the signals decoded or fallen back so far) take their values from `bits`; the rest of the
  /// mask and the bending angle stay. With `known` 0 the bits are claimed and nothing is
  /// published. The lamps' stamp becomes `s`, with the later of the two receive times: `s`
  /// carries the receipt of the newest bus frame used, which may be older than a host's lamp
  /// state that the mask still holds (input-to-publish latency counts from the newest input).
  void setBusLights(std::uint32_t owned, std::uint32_t known, std::uint32_t bits, const Stamp& s);
  void setEnvironment(const Environment& v, const Stamp& s);
  void setFrameRequest(const FrameRequest& v, const Stamp& s);
  void setVehicleSpeed(float speed_m_s, const Stamp& s);
  /// Applies a traffic list: adds/updates objects, removes flagged ones and, for a complete
  /// list, every other object. Returns how many objects were refused because the store is
  /// full (the rest of the list is applied).
  std::size_t applyTraffic(const TrafficList& list, const Stamp& s);
  /// Purges objects older than the timeout (the frame loop or a receiver calls this now and
  /// then; live() already hides them). Returns how many were purged.
  std::size_t expire(Clock::time_point now);
  /// Traffic objects purged by expire() since construction (any thread).
  [[nodiscard]] std::uint64_t expiredTotal() const noexcept { return expired_.load(std::memory_order_relaxed); }

  [[nodiscard]] const StateStoreOptions& options() const noexcept { return options_; }

 private:
  template <class F>
  void update(F&& change);

  StateStoreOptions options_;
  std::mutex writers_;
  std::atomic<std::shared_ptr<const SimSnapshot>> current_;
  std::atomic<std::uint64_t> expired_{0};  ///< expire() purges, for the log and the status reply
  std::uint32_t busOwnedLights_ = 0;  ///< light:: bits a bus input owns (setBusLights); under writers_
};

}  // namespace fogbeam::ipc
