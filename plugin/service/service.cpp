// fogbeam — the cab service (service.hpp).
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/ipc/status_server.hpp>
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/plugin/service.hpp>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>
#include <span>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

namespace fogbeam::plugin {

namespace {

using Clock = std::chrono::steady_clock;

// requestStop() is called from signal handlers: its store must not take a lock.
static_assert(std::atomic<bool>::is_always_lock_free);

/// The longest a free-running loop sleeps without looking at a stop request: 50 ms, a period
/// at 20 Hz (faster rates never wait longer than their period anyway).
constexpr std::chrono::milliseconds kStopCheck{50};

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

/// What the status line and the status port report; the frame loop updates it under the mutex
/// once per status interval, the status server's thread reads it.
struct StatusBoard {
  mutable std::mutex mutex;
  std::uint64_t frames = 0;
  double fps = 0.0;
  double total_p50 = 0, total_p95 = 0, surface_p50 = 0, airlight_p50 = 0, latency_p50 = 0, latency_p95 = 0;
  double ego_age_s = -1, lamps_age_s = -1, env_age_s = -1;  ///< s; −1 = never received
  std::uint32_t traffic = 0;
  std::uint64_t traffic_expired = 0;  ///< traffic objects removed for want of updates, since start
  bool tables_pending = false;
  std::string input = "none";
  double vehicle_speed_m_s = -1.0;  ///< from CAN; −1 = none received
  std::uint64_t frame_requests_refused = 0;  ///< lock-step requests for frame 0 (frames start at 1)
  /// Per channel with depth_from: its host depth link's figures (HostDepthLink::counts).
  std::vector<std::pair<std::string, HostDepthCounts>> host_depth;

  std::string json(const ipc::UdpStats& udp) const {
    std::lock_guard lock(mutex);
    std::ostringstream o;
    o.setf(std::ios::fixed);
    o.precision(3);
    o << "{\"frames\": " << frames << ", \"fps\": " << fps << ", \"frame_ms_p50\": " << total_p50
      << ", \"frame_ms_p95\": " << total_p95 << ", \"surface_ms_p50\": " << surface_p50
      << ", \"airlight_ms_p50\": " << airlight_p50 << ", \"latency_ms_p50\": " << latency_p50
      << ", \"latency_ms_p95\": " << latency_p95 << ", \"input\": \"" << input << "\", \"ego_age_s\": " << ego_age_s
      << ", \"lamps_age_s\": " << lamps_age_s << ", \"environment_age_s\": " << env_age_s
      << ", \"traffic\": " << traffic << ", \"traffic_expired\": " << traffic_expired
      << ", \"tables_pending\": " << (tables_pending ? "true" : "false");
    if (vehicle_speed_m_s >= 0.0) o << ", \"vehicle_speed_m_s\": " << vehicle_speed_m_s;
    else o << ", \"vehicle_speed_m_s\": null";
    o << ", \"frame_requests_refused\": " << frame_requests_refused << ", \"host_depth\": [";
    for (std::size_t i = 0; i < host_depth.size(); ++i) {
      const auto& [name, c] = host_depth[i];
      o << (i ? ", " : "") << "{\"channel\": \"" << name << "\", \"connected\": " << (c.connected ? "true" : "false")
        << ", \"stale\": " << (c.stale ? "true" : "false") << ", \"last_frame\": " << c.last_frame
        << ", \"frames\": " << c.frames << ", \"repeated\": " << c.repeated << ", \"refused\": " << c.refused
        << ", \"lost\": " << c.lost << ", \"attached\": " << c.attached << "}";
    }
    o << "]"
      << ", \"udp\": {\"datagrams\": " << udp.datagrams << ", \"applied\": " << udp.applied
      << ", \"traffic_refused\": " << udp.traffic_refused << ", \"restarts\": " << udp.restarts << ", \"dropped\": {";
    bool first = true;
    for (std::size_t r = 0; r < ipc::kDropReasonCount; ++r) {
      if (udp.dropped[r] == 0) continue;
      o << (first ? "" : ", ") << "\"" << ipc::toString(static_cast<ipc::DropReason>(r)) << "\": " << udp.dropped[r];
      first = false;
    }
    o << "}}}";
    return o.str();
  }
};

/// A host that stops sending (issue 6): frames go on with the last state; traffic not updated for
/// traffic_timeout_s is purged from the store (by the UDP receiver when its socket is idle, and
/// here once per frame, which also covers a socket kept busy by other senders), so the snapshot
/// holds only live objects whatever was ever sent. Both are logged: the silence once per
/// transition, the purges at most once per second (a count), so that a silent or flapping host
/// cannot flood the log.
class HostWatch {
 public:
  /// Seconds without an ego-state message before the host counts as silent: 1 s is 60 frames of
  /// a 60 Hz host and well above any scheduling hiccup of a live one.
  static constexpr double kSilentS = 1.0;

  HostWatch(ipc::StateStore& store, double trafficTimeout_s) : store_(store), trafficTimeout_s_(trafficTimeout_s) {}

  /// Once per frame, with the frame's snapshot; `scenario`: a scenario is playing (not a host).
  void check(const ipc::SimSnapshot& snap, Clock::time_point now, bool scenario) {
    (void)store_.expire(now);
    const std::uint64_t expired = store_.expiredTotal();
    if (expired > logged_ && now - lastExpiryLog_ >= std::chrono::seconds(1)) {
      spdlog::warn("serve: {} traffic object(s) removed: not updated for {} s (input.udp.traffic_timeout_s)",
                   expired - logged_, trafficTimeout_s_);
      logged_ = expired;
      lastExpiryLog_ = now;
    }
    const ipc::Stamp& ego = snap.ego.stamp;
    if (scenario || !ego.valid) return;
    const double age_s = std::chrono::duration<double>(now - ego.received).count();
    if (age_s > kSilentS && !silent_) {
      spdlog::warn("serve: no ego state from {} for {:.1f} s: frames go on with the last state", ego.source, age_s);
      silent_ = true;
      silentSince_ = ego.received;
    } else if (age_s <= kSilentS && silent_) {
      spdlog::info("serve: ego state from {} again after {:.1f} s", ego.source,
                   std::chrono::duration<double>(ego.received - silentSince_).count());
      silent_ = false;
    }
  }

 private:
  ipc::StateStore& store_;
  double trafficTimeout_s_;
  bool silent_ = false;
  Clock::time_point silentSince_{};
  std::uint64_t logged_ = 0;  ///< expired objects already logged
  Clock::time_point lastExpiryLog_{};
};

/// Plays a scenario into the store at wall-clock pace until a host's first message (a UDP
/// message applied, or a CAN frame of a mapped message).
class ScenarioPlayer {
 public:
  /// Input updates per second: twice a 60 Hz frame rate, so a frame never shows a state older
  /// than half a frame.
  static constexpr int kRateHz = 120;

  ScenarioPlayer(Scenario s, bool loop, ipc::StateStore& store, std::function<bool()> hostActive)
      : scenario_(std::move(s)), loop_(loop), store_(store), hostActive_(std::move(hostActive)) {
    // The state at t = 0 before the first frame, so that it is not rendered with the
    // configuration's fog and then again with the scenario's.
    applyState(evaluate(scenario_, 0.0), store_, sequence_, Clock::now());
    thread_ = std::thread([this] { run(); });
  }
  ~ScenarioPlayer() {
    stop_ = true;
    thread_.join();
  }
  ScenarioPlayer(const ScenarioPlayer&) = delete;
  ScenarioPlayer& operator=(const ScenarioPlayer&) = delete;
  [[nodiscard]] bool playing() const { return playing_.load(); }

 private:
  void run() {
    const auto start = Clock::now();
    while (!stop_.load()) {
      if (hostActive_()) {
        spdlog::info("serve: a host is sending: scenario {} stopped", scenario_.name);
        break;
      }
      double t = std::chrono::duration<double>(Clock::now() - start).count();
      if (t > scenario_.duration_s) {
        if (!loop_) break;
        t = std::fmod(t, scenario_.duration_s);
      }
      applyState(evaluate(scenario_, t), store_, sequence_, Clock::now());
      std::this_thread::sleep_for(std::chrono::microseconds(1'000'000 / kRateHz));
    }
    playing_ = false;
  }
  Scenario scenario_;
  bool loop_;
  std::uint32_t sequence_ = 1;
  ipc::StateStore& store_;
  std::function<bool()> hostActive_;
  std::atomic<bool> stop_{false}, playing_{true};
  std::thread thread_;
};

/// Marks every channel alive every 250 ms on its own thread. A frame may take longer than a
/// reader's heartbeat timeout (2 s; the first frame builds tables): the heartbeat says "alive",
/// not "a frame is due". Stopping wakes the thread at once.
class Heartbeat {
 public:
  static constexpr std::chrono::milliseconds kPeriod{250};

  explicit Heartbeat(std::vector<std::unique_ptr<ipc::ShmWriter>>& writers) : writers_(writers) {
    thread_ = std::thread([this] { run(); });
  }
  ~Heartbeat() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    thread_.join();
  }
  Heartbeat(const Heartbeat&) = delete;
  Heartbeat& operator=(const Heartbeat&) = delete;

 private:
  void run() {
    std::unique_lock lock(mutex_);
    while (!stop_) {
      for (auto& w : writers_) w->heartbeat();
      wake_.wait_for(lock, kPeriod, [this] { return stop_; });
    }
  }
  std::vector<std::unique_ptr<ipc::ShmWriter>>& writers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::thread thread_;
};

/// The service's sink: each channel's frame mapped to the wire (wireMeta) and published in its
/// segment, with the distance plane where the channel has one; the first channel's stage times
/// and latency kept for the status figures.
class ShmSink final : public FrameSink {
 public:
  ShmSink(std::vector<std::unique_ptr<ipc::ShmWriter>>& writers, const std::vector<ChannelConfig>& channels)
      : writers_(writers), channels_(channels) {}

  Status consume(std::size_t channel, const RenderedFrame& frame, const FrameBookkeeping& book) override {
    writers_[channel]->publish(wireMeta(frame, book), frame.packed,
                               channels_[channel].distance ? std::span<const float>(frame.layers.distance)
                                                           : std::span<const float>());
    pending = pending || frame.pending;
    traffic = frame.inputs.traffic_count;
    if (channel == 0) {
      totalMs.push_back(frame.timings.total_ms);
      airMs.push_back(frame.timings.airlight_ms);
      surfMs.push_back(frame.timings.surface_ms);
      if (book.latency_ms) latencyMs.push_back(*book.latency_ms);
    }
    return Ok{};
  }

  // Per step (reset by the frame loop before each):
  bool pending = false;       ///< a channel's tables are still being built
  std::uint32_t traffic = 0;  ///< live traffic objects of the last channel rendered
  // Per status interval (cleared by the frame loop after each status line), the first channel's, ms:
  std::vector<double> totalMs, airMs, surfMs, latencyMs;

 private:
  std::vector<std::unique_ptr<ipc::ShmWriter>>& writers_;
  const std::vector<ChannelConfig>& channels_;
};

}  // namespace

ipc::FrameMeta wireMeta(const RenderedFrame& frame, const FrameBookkeeping& book) {
  ipc::FrameMeta meta;
  meta.frame = book.frame;
  meta.frame_request = book.frame_request;
  meta.latency_ms = book.latency_ms.value_or(0.0);
  meta.sim_time_s = frame.inputs.sim_time_s;
  meta.position_m = {frame.view.eye_m.x, frame.view.eye_m.y, frame.view.eye_m.z};
  meta.yaw_deg = frame.view.yaw_deg;
  meta.pitch_deg = frame.view.pitch_deg;
  meta.roll_deg = frame.view.roll_deg;
  meta.fov_x_deg = frame.view.fov_x_deg;
  meta.fov_y_deg = frame.view.fov_y_deg;
  meta.frustum_deg = frame.view.frustum_deg;
  meta.host_frame = frame.host_frame;
  meta.lights = frame.inputs.lights;
  meta.ego_sequence = frame.inputs.ego_sequence;
  meta.lamp_sequence = frame.inputs.lamp_sequence;
  meta.environment_sequence = frame.inputs.environment_sequence;
  meta.traffic_count = frame.inputs.traffic_count;
  // Glow and glare have no field of their own: they count in total_ms only.
  meta.surface_ms = frame.timings.surface_ms;
  meta.airlight_ms = frame.timings.airlight_ms;
  meta.composite_ms = frame.timings.composite_ms;
  meta.total_ms = frame.timings.total_ms;
  return meta;
}

// Members in the order they are built; destroyed in reverse, which is also a safe teardown of a
// create() that failed halfway: the heartbeat before the writers it beats, the player before the
// store and the receivers it reads, the status server before the board and receiver it reports.
struct Service::Impl {
  ServiceConfig config;
  ServiceOptions options;
  std::string worldPath;
  std::unique_ptr<ipc::StateStore> store;
  std::unique_ptr<ipc::UdpReceiver> udp;
  std::unique_ptr<ipc::CanSource> can;
  /// The CAN source as the scenario player's thread sees it (a candump replay starts after the
  /// first frame, on the frame loop's thread).
  std::atomic<const ipc::CanSource*> canIn{nullptr};
  /// [input.can] source = "candump": the replay's decoder until the first frame is published.
  std::optional<ipc::CanDecoder> candumpDecoder;
  std::unique_ptr<FramePipeline> pipeline;
  /// Per channel: its host depth link (depth_from), or null; and the frame step's host views.
  std::vector<std::unique_ptr<HostDepthLink>> hostLinks;
  std::vector<HostFrame> hostFrames;
  std::vector<const HostFrame*> hostPtrs;
  bool hostPaced = false;  ///< a channel has depth_from: lock-step runs on the host's depth frames
  std::uint64_t frameRequestsRefused = 0;
  Clock::time_point lastRefusedRequestLog{};
  std::vector<std::unique_ptr<ipc::ShmWriter>> writers;
  StatusBoard board;
  std::unique_ptr<ipc::StatusServer> status;
  std::unique_ptr<ScenarioPlayer> player;
  std::unique_ptr<Heartbeat> heart;
  std::optional<HostWatch> watch;
  std::optional<ShmSink> sink;
  std::uint16_t udpPort = 0, statusPort = 0;

  // The frame loop's state, kept across run() calls.
  std::atomic<bool> stopRequested{false};
  std::mutex running;  ///< held by run() for its whole duration; stop() takes it to wait for it
  bool stopped = false;  ///< under `running`
  std::atomic<std::uint64_t> frames{0};  ///< = pipeline->handed(), for readers on other threads
  std::uint64_t submitted = 0;  ///< frames given to the pipeline (free-running frame numbers)
  std::uint64_t lastRequestSeq = 0;  ///< lock-step: the sequence number of the last request served

  mutable std::mutex life;  ///< guards `udp` against its teardown in stop() for udpStats()/statusJson()
  ipc::UdpStats finalUdp;   ///< the receiver's counts when stop() ended it

  [[nodiscard]] bool playing() const { return player && player->playing(); }
  /// The status board's figures and the status line, for the `windowFrames` frames since
  /// `windowStart`; clears the sink's per-interval figures. Returns the time the figures are of
  /// (the next window's start).
  Clock::time_point updateStatus(const ipc::SimSnapshot& snap, std::uint64_t windowFrames, Clock::time_point windowStart);
};

Service::Service(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Service::~Service() { stop(); }

Result<std::unique_ptr<Service>> Service::create(ServiceConfig config, const ServiceOptions& options) {
  auto m = std::make_unique<Impl>();
  m->config = std::move(config);
  m->options = options;
  const ServiceConfig& cfg = m->config;

  // A scenario brings its own world (its scene); without one, [world] scene is the world.
  std::optional<Scenario> scenario;
  if (!cfg.scenario_path.empty()) {
    auto sc = loadScenario(cfg.scenario_path);
    if (!sc) return sc.error();
    scenario = std::move(sc).value();
  }
  m->worldPath = scenario ? scenario->scene_path : cfg.scene_path;
  auto world = loadScene(m->worldPath);
  if (!world) return world.error();

  ipc::StateStoreOptions so;
  so.traffic_timeout_s = cfg.traffic_timeout_s;
  so.max_traffic_objects = cfg.max_traffic_objects;
  m->store = std::make_unique<ipc::StateStore>(so);
  ipc::UdpReceiverOptions udp;
  udp.bind_address = cfg.udp_bind;
  udp.port = cfg.udp_port;
  udp.multicast_group = cfg.udp_multicast;
  udp.allow = cfg.udp_allow;
  auto rx = ipc::UdpReceiver::start(udp, *m->store);
  if (!rx) return rx.error();
  m->udp = std::move(rx).value();
  m->udpPort = m->udp->port();

  if (cfg.can_source != "none") {
    auto mapping = ipc::loadCanConfig(cfg.can_mapping_path);
    if (!mapping) return mapping.error();
    auto dec = ipc::makeDecoder(*mapping);
    if (!dec) return dec.error();
    Result<std::unique_ptr<ipc::CanSource>> src = Error{"unknown CAN source"};
    if (cfg.can_source == "candump") {
      // The log is checked now (a bad line fails the start) and replayed from the first frame
      // published on (run()): frames before it may wait for tables, and the log's start would
      // otherwise never be seen.
      if (auto log = ipc::loadCandump(cfg.can_candump); !log) return Error{"CAN: " + log.error().message};
      m->candumpDecoder.emplace(std::move(dec).value());
      src = std::unique_ptr<ipc::CanSource>();
    } else if (cfg.can_source == "cannelloni") {
      src = ipc::startCannelloni(cfg.udp_bind, cfg.can_cannelloni_port, std::move(dec).value(), *m->store);
    } else {
      src = ipc::startSocketCan(cfg.can_interface, std::move(dec).value(), *m->store);
    }
    if (!src) return Error{"CAN: " + src.error().message};
    m->can = std::move(src).value();
    m->canIn = m->can.get();
  }

  auto surface = openSurfacePass(cfg);
  if (!surface) return surface.error();
  if (!surface->fallback.empty()) spdlog::warn("serve: GL unavailable ({}); CPU planes only (no glTF)", surface->fallback);
  // Lock-step frames await table builds (deterministic); free-running ones go on meanwhile.
  auto pipeline = FramePipeline::create(cfg, *world, std::move(surface->gl), cfg.lock_step);
  if (!pipeline) return pipeline.error();
  m->pipeline = std::move(pipeline).value();
  for (std::size_t c = 0; c < cfg.channels.size(); ++c) {
    ipc::ShmChannelOptions ch;
    ch.channel = cfg.channels[c].name;
    ch.width = static_cast<std::uint32_t>(cfg.channels[c].width);
    ch.height = static_cast<std::uint32_t>(cfg.channels[c].height);
    ch.format = m->pipeline->renderer(c).shmFormat();
    ch.distance = cfg.channels[c].distance;
    auto w = ipc::ShmWriter::create(ch);
    if (!w) return w.error();
    m->writers.push_back(std::move(w).value());
  }

  if (cfg.status_udp_port != 0 || options.any_status_port) {
    ipc::StatusServerOptions st;
    st.bind_address = cfg.udp_bind;
    st.port = cfg.status_udp_port;
    // The server's thread reads the board (its mutex) and the receiver's counts (thread-safe);
    // both outlive it (stop() ends it first).
    auto s = ipc::StatusServer::start(st, [board = &m->board, rx = m->udp.get()] { return board->json(rx->stats()); });
    if (!s) return s.error();
    m->status = std::move(s).value();
    m->statusPort = m->status->port();
  }
  if (scenario) {
    spdlog::info("serve: playing scenario {} ({} s{}) until a host sends (UDP or CAN)", scenario->name, scenario->duration_s,
                 cfg.scenario_loop ? ", looped" : "");
    const ipc::UdpReceiver* udpIn = m->udp.get();
    const std::atomic<const ipc::CanSource*>* canIn = &m->canIn;
    m->player = std::make_unique<ScenarioPlayer>(std::move(*scenario), cfg.scenario_loop, *m->store, [udpIn, canIn] {
      const ipc::CanSource* can = canIn->load();
      return udpIn->stats().applied > 0 || (can && can->stats().matched > 0);
    });
  }
  m->hostLinks.resize(cfg.channels.size());
  m->hostFrames.resize(cfg.channels.size());
  m->hostPtrs.assign(cfg.channels.size(), nullptr);
  for (std::size_t c = 0; c < cfg.channels.size(); ++c) {
    const ChannelConfig& ch = cfg.channels[c];
    if (ch.depth_from.empty()) continue;
    // A composite channel needs the host's colour (host·T + A); an overlay channel does not.
    m->hostLinks[c] = std::make_unique<HostDepthLink>(ch.depth_from, ch.width, ch.height, ch.name,
                                                      ch.format != "rgba16f-overlay", ch.exposure_ev);
    std::lock_guard lock(m->board.mutex);
    m->board.host_depth.emplace_back(ch.name, HostDepthCounts{});
  }
  m->heart = std::make_unique<Heartbeat>(m->writers);
  m->watch.emplace(*m->store, cfg.traffic_timeout_s);
  m->sink.emplace(m->writers, m->config.channels);

  for (const auto& ch : cfg.channels) {
    if (!ch.depth_from.empty()) {
      spdlog::info("serve: channel /fogbeam.{} {}x{} {}: the view and distances of host depth channel /fogbeam.{}", ch.name,
                   ch.width, ch.height, ch.format, ch.depth_from);
    } else if (ch.frustum_deg) {
      spdlog::info("serve: channel /fogbeam.{} {}x{} {} frustum [{}, {}, {}, {}]°", ch.name, ch.width, ch.height, ch.format,
                   (*ch.frustum_deg)[0], (*ch.frustum_deg)[1], (*ch.frustum_deg)[2], (*ch.frustum_deg)[3]);
    } else {
      spdlog::info("serve: channel /fogbeam.{} {}x{} {} fov {}°", ch.name, ch.width, ch.height, ch.format, ch.fov_x_deg);
    }
  }
  m->hostPaced = std::any_of(m->hostLinks.begin(), m->hostLinks.end(), [](const auto& l) { return l != nullptr; });
  const bool hostPaced = m->hostPaced;
  spdlog::info("serve: world {}, {}, UDP {}:{}, status port {}", m->worldPath,
               cfg.lock_step ? (hostPaced ? std::string("lock-step on the host's depth frames")
                                          : std::string("lock-step on frame requests"))
                             : fmt::format("free-running at {} Hz", cfg.rate_hz),
               cfg.udp_bind, m->udpPort, m->statusPort);
  return std::unique_ptr<Service>(new Service(std::move(m)));
}

Clock::time_point Service::Impl::updateStatus(const ipc::SimSnapshot& snap, std::uint64_t windowFrames,
                                              Clock::time_point windowStart) {
  const auto t = Clock::now();
  auto age = [&](const ipc::Stamp& s) { return s.valid ? std::chrono::duration<double>(t - s.received).count() : -1.0; };
  {
    std::lock_guard lock(board.mutex);
    board.frames = frames.load();
    board.fps = static_cast<double>(windowFrames) / std::chrono::duration<double>(t - windowStart).count();
    board.total_p50 = percentile(sink->totalMs, 0.5);
    board.total_p95 = percentile(sink->totalMs, 0.95);
    board.surface_p50 = percentile(sink->surfMs, 0.5);
    board.airlight_p50 = percentile(sink->airMs, 0.5);
    board.latency_p50 = percentile(sink->latencyMs, 0.5);
    board.latency_p95 = percentile(sink->latencyMs, 0.95);
    board.ego_age_s = age(snap.ego.stamp);
    board.lamps_age_s = age(snap.lamps.stamp);
    board.env_age_s = age(snap.environment.stamp);
    board.traffic = sink->traffic;
    board.traffic_expired = store->expiredTotal();
    board.tables_pending = sink->pending;
    // The source of the newest message that set the state (a host driving the lamps over
    // CAN while the scenario's ego pose stays is "can …", not "scenario").
    const ipc::Stamp* newest = nullptr;
    for (const ipc::Stamp* s : {&snap.ego.stamp, &snap.lamps.stamp, &snap.environment.stamp, &snap.vehicle_speed_m_s.stamp})
      if (s->valid && (!newest || s->received > newest->received)) newest = s;
    board.input = playing() ? "scenario" : newest ? newest->source : "none";
    board.vehicle_speed_m_s = snap.vehicle_speed_m_s.stamp.valid ? static_cast<double>(snap.vehicle_speed_m_s.value) : -1.0;
    board.frame_requests_refused = frameRequestsRefused;
    for (std::size_t c = 0, k = 0; c < hostLinks.size(); ++c)
      if (hostLinks[c]) board.host_depth[k++].second = hostLinks[c]->counts();
  }
  const ipc::UdpStats st = udp->stats();
  spdlog::info("serve: {} frames, {:.1f} fps; frame p50 {:.1f} ms p95 {:.1f} (surface {:.1f}, airlight {:.1f}); "
               "input-to-publish p50 {:.1f} ms p95 {:.1f}; input {}; UDP {} applied, {} dropped; traffic {}{}",
               board.frames, board.fps, board.total_p50, board.total_p95, board.surface_p50, board.airlight_p50,
               board.latency_p50, board.latency_p95, board.input, st.applied, st.droppedTotal(), board.traffic,
               sink->pending ? "; fog/bending tables building" : "");
  sink->totalMs.clear();
  sink->airMs.clear();
  sink->surfMs.clear();
  sink->latencyMs.clear();
  return t;
}

Status Service::run(const RunLimits& limits) {
  Impl& m = *impl_;
  std::unique_lock running(m.running, std::try_to_lock);
  if (!running.owns_lock()) {
    // Held by stop() (then there is nothing left to run) or by a run() on another thread.
    if (m.stopRequested.load()) return Ok{};
    return Error{"Service::run: the frame loop is already running"};
  }
  if (m.stopped) return Ok{};
  const ServiceConfig& cfg = m.config;
  const auto start = Clock::now();
  auto nextFrame = start;
  const auto interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(cfg.status_interval_s));
  auto nextStatus = start + interval;
  auto windowStart = start;
  std::uint64_t windowFrames = 0, framesThisRun = 0;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / cfg.rate_hz));
  std::optional<Error> failure;
  const bool hostPaced = m.hostPaced;
  // After each call that may hand frames to the sink (the pipeline's step, submit or flush):
  // its failure, the published count, the candump replay's start with the first frame.
  auto settle = [&](const Status& s, std::size_t failed) {
    if (!s) {
      spdlog::error("serve: channel {}: {}", cfg.channels[failed].name, s.error().message);
      failure = Error{"channel " + cfg.channels[failed].name + ": " + s.error().message};
      m.stopRequested = true;  // a renderer that failed is not trusted with another frame
    }
    const std::uint64_t handed = m.pipeline->handed();
    windowFrames += handed - m.frames.load();
    m.frames.store(handed);  // published on every channel
    if (handed > 0 && m.candumpDecoder && !failure) {
      // The first frame is out: the candump replay starts now (create()).
      auto src = ipc::startCandumpReplay(cfg.can_candump, cfg.can_candump_speed, std::move(*m.candumpDecoder), *m.store);
      m.candumpDecoder.reset();
      if (!src) {
        failure = Error{"CAN: " + src.error().message};  // the log changed since create()
        return;
      }
      std::lock_guard life(m.life);
      m.can = std::move(src).value();
      m.canIn = m.can.get();
      spdlog::info("serve: candump replay of {} started with the first frame", cfg.can_candump);
    }
  };
  // Overlapped frames (FramePipeline::submit): the frame in flight goes out when no next frame
  // is to be begun now.
  auto flushInFlight = [&] {
    if (!m.pipeline->inFlight()) return;
    m.sink->pending = false;
    std::size_t failed = 0;
    const Status s = m.pipeline->flush(*m.sink, &failed);
    settle(s, failed);
  };
  while (!m.stopRequested.load() && !failure) {
    if (limits.duration_s > 0.0 && Clock::now() - start > std::chrono::duration<double>(limits.duration_s)) break;
    if (limits.frames > 0 && framesThisRun >= limits.frames) break;
    auto snap = m.store->snapshot();
    std::uint64_t requested = 0;
    if (cfg.lock_step && hostPaced) {
      // The host's depth frames are the requests: a frame once every depth-fed channel has a
      // host frame newer than the one it last rendered (a host draws all its channels each
      // frame); polled every 200 µs, one atomic load per channel.
      const auto t = Clock::now();
      bool ready = true;
      for (auto& link : m.hostLinks)
        if (link && !link->newFrameReady(t)) ready = false;
      if (!ready) {
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        continue;
      }
      snap = m.store->snapshot();
    } else if (cfg.lock_step) {
      // A frame per new request; polled every 200 µs (0.2 ms of a request's latency at most).
      // Overlapped, a frame is begun beside the previous one's rest only when its request is
      // already here; otherwise the previous one is published now (its host may be waiting
      // for it before it sends the next request).
      if (!snap->frame_request.stamp.valid || snap->frame_request.stamp.sequence == m.lastRequestSeq) {
        if (m.pipeline->inFlight()) {
          flushInFlight();
          continue;
        }
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        continue;
      }
      m.lastRequestSeq = snap->frame_request.stamp.sequence;
      requested = snap->frame_request.value.frame;
      if (requested == 0) {
        // Frame numbers start at 1: a `latest` word of 0 means "no frame yet" (docs/shm.md), so
        // frame 0 could never be seen. Refused, counted, logged at most once per second.
        ++m.frameRequestsRefused;
        if (Clock::now() - m.lastRefusedRequestLog >= std::chrono::seconds(1)) {
          spdlog::warn("serve: frame request for frame 0 refused (frames start at 1; {} so far)", m.frameRequestsRefused);
          m.lastRefusedRequestLog = Clock::now();
        }
        continue;
      }
    } else {
      // Overlapped frames: a loop ahead of its rate publishes the frame in flight now rather
      // than with the next frame's surfaces a period later; one behind goes straight on.
      if (Clock::now() < nextFrame) flushInFlight();
      if (failure) break;
      // Until the frame is due, in slices of at most kStopCheck, so that a stop request at a
      // low rate is not kept waiting for a whole period; the last slice ends on time.
      for (auto t = Clock::now(); t < nextFrame && !m.stopRequested.load(); t = Clock::now())
        std::this_thread::sleep_until(std::min(nextFrame, t + kStopCheck));
      if (m.stopRequested.load()) break;
      nextFrame += period;
      if (Clock::now() > nextFrame + period) nextFrame = Clock::now();  // fell behind: do not burst
      snap = m.store->snapshot();
    }
    const std::uint64_t frame = ++m.submitted;
    ++framesThisRun;
    const auto now = Clock::now();
    m.watch->check(*snap, now, m.playing());
    // Host views: the newest of each depth-fed channel (or its last one, when the host is slow,
    // stopped or gone: HostDepthLink).
    for (std::size_t c = 0; c < m.hostLinks.size(); ++c) {
      HostDepthLink* link = m.hostLinks[c].get();
      m.hostPtrs[c] = nullptr;
      if (!link || !link->poll(now)) continue;
      m.hostFrames[c] = HostFrame{&link->view(), &link->surface()};
      m.hostPtrs[c] = &m.hostFrames[c];
      // Lock-step on depth frames: the frame number and request are the host's (the first
      // depth-fed channel's).
      if (cfg.lock_step && requested == 0) requested = link->view().frame;
    }

    // The step: every channel rendered from this snapshot, mapped to the wire and published;
    // overlapped, this snapshot's surfaces beside the previous frame's rest, which is published.
    FrameBookkeeping book;
    book.frame = cfg.lock_step ? requested : frame;
    book.frame_request = requested;
    m.sink->pending = false;
    std::size_t failed = 0;
    const Status s = m.pipeline->submit(*snap, now, book, *m.sink, &failed, m.hostPtrs);
    settle(s, failed);
    if (failure) break;
    if (Clock::now() >= nextStatus) {
      windowStart = m.updateStatus(*snap, windowFrames, windowStart);
      windowFrames = 0;
      nextStatus += interval;
    }
  }
  // The frame in flight (overlapped) is published before the loop returns: a stop or a limit
  // ends the loop after the frame in progress, as in sequence.
  if (!failure) flushInFlight();
  if (failure) return *failure;
  return Ok{};
}

void Service::requestStop() noexcept { impl_->stopRequested.store(true); }

void Service::stop() {
  Impl& m = *impl_;
  m.stopRequested.store(true);
  std::lock_guard running(m.running);  // run() returns after its frame in progress
  if (m.stopped) return;
  m.stopped = true;
  m.player.reset();  // writes the store, reads the receivers' counts
  m.status.reset();  // its replies read the board and the UDP counts
  m.heart.reset();   // beats the writers
  {
    std::lock_guard life(m.life);
    m.can.reset();
    if (m.udp) m.finalUdp = m.udp->stats();
    m.udp.reset();
  }
  m.pipeline.reset();  // the renderers wait for table builds in flight
  m.writers.clear();   // each channel marked closed and unlinked
}

std::uint16_t Service::udpPort() const noexcept { return impl_->udpPort; }
std::uint16_t Service::statusPort() const noexcept { return impl_->statusPort; }
std::uint64_t Service::frames() const noexcept { return impl_->frames.load(); }

ipc::UdpStats Service::udpStats() const {
  std::lock_guard life(impl_->life);
  return impl_->udp ? impl_->udp->stats() : impl_->finalUdp;
}

std::string Service::statusJson() const { return impl_->board.json(udpStats()); }

const ServiceConfig& Service::config() const noexcept { return impl_->config; }
const std::string& Service::worldPath() const noexcept { return impl_->worldPath; }

}  // namespace fogbeam::plugin
