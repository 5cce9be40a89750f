// `fogbeam serve` (issue 5): the process a cab runs. The service configuration
// (docs/service.md; built-in default < --config file < command line) names the world, the ego and
// traffic rigs, the output channels, the inputs and the timing. Inputs arrive over UDP
// (docs/protocol.md), CAN (docs/can.md) or from a scenario (docs/scenario.md) that plays until a
// host sends its first message; every frame takes one state snapshot and renders each channel
// (plugin/frame_renderer.hpp) into its shared-memory segment (docs/shm.md).
//
// Timing: free-running at rate_hz (frames paced on a steady clock; a late frame does not cause a
// burst), or lock-step (one frame per frame-request message, tables awaited so runs are
// deterministic). Status: a log line every interval_s and a JSON reply on the status UDP port.
// SIGINT/SIGTERM: the loop ends, threads are joined and segments unlinked by their destructors.
#include "commands.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/status_server.hpp>
#include <fogbeam/ipc/udp_receiver.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/plugin/service_config.hpp>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace fogbeam::cli {

namespace {

using Clock = std::chrono::steady_clock;
using plugin::ServiceConfig;

std::atomic<bool> gStop{false};
extern "C" void onSignal(int) { gStop.store(true); }

struct ServeOptions {
  std::string config;
  std::vector<std::string> set;
  bool printConfig = false;
  std::string scenario;
  bool noScenario = false;
  std::string channelPrefix;
  double duration_s = 0.0;
  std::uint64_t frames = 0;
  // Shorthands for --set (applied after it): empty / negative = not given.
  bool lockStep = false;
  double rate_hz = 0.0;
  int udpPort = -1;
  int statusPort = -1;
  std::string surface;
  double viewTableStepDeg = 0.0;
  unsigned threads = 0;
};

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

/// What the status line and the status port report; the frame loop updates it under the mutex.
struct StatusBoard {
  std::mutex mutex;
  std::uint64_t frames = 0;
  double fps = 0.0;
  double total_p50 = 0, total_p95 = 0, surface_p50 = 0, airlight_p50 = 0, latency_p50 = 0, latency_p95 = 0;
  double ego_age_s = -1, lamps_age_s = -1, env_age_s = -1;
  std::uint32_t traffic = 0;
  std::uint64_t traffic_expired = 0;  ///< traffic objects removed for want of updates, since start
  bool tables_pending = false;
  std::string input = "none";

  std::string json(const ipc::UdpStats& udp) {
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
      << ", \"tables_pending\": " << (tables_pending ? "true" : "false")
      << ", \"udp\": {\"datagrams\": " << udp.datagrams << ", \"applied\": " << udp.applied << ", \"dropped\": {";
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
  ScenarioPlayer(plugin::Scenario s, bool loop, ipc::StateStore& store, std::function<bool()> hostActive)
      : scenario_(std::move(s)), loop_(loop), store_(store), hostActive_(std::move(hostActive)) {
    // The state at t = 0 before the first frame, so that it is not rendered with the
    // configuration's fog and then again with the scenario's.
    plugin::applyState(plugin::evaluate(scenario_, 0.0), store_, sequence_, Clock::now());
    thread_ = std::thread([this] { run(); });
  }
  ~ScenarioPlayer() {
    stop_ = true;
    thread_.join();
  }
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
      plugin::applyState(plugin::evaluate(scenario_, t), store_, sequence_, Clock::now());
      std::this_thread::sleep_for(std::chrono::microseconds(1'000'000 / 120));  // 120 Hz input
    }
    playing_ = false;
  }
  plugin::Scenario scenario_;
  bool loop_;
  std::uint32_t sequence_ = 1;
  ipc::StateStore& store_;
  std::function<bool()> hostActive_;
  std::atomic<bool> stop_{false}, playing_{true};
  std::thread thread_;
};

int fail(const std::string& what) {
  std::fprintf(stderr, "fogbeam serve: %s\n", what.c_str());
  return 2;
}

int run(const ServeOptions& o) {
  std::vector<std::string> settings = o.set;
  if (!o.scenario.empty()) settings.push_back("world.scenario=\"" + o.scenario + "\"");
  if (o.noScenario) settings.push_back("world.scenario=\"\"");
  if (o.lockStep) settings.push_back("timing.mode=\"lock-step\"");
  if (o.rate_hz > 0) settings.push_back("timing.rate_hz=" + std::to_string(o.rate_hz));
  if (o.udpPort >= 0) settings.push_back("input.udp.port=" + std::to_string(o.udpPort));
  if (o.statusPort >= 0) settings.push_back("status.udp_port=" + std::to_string(o.statusPort));
  if (!o.surface.empty()) settings.push_back("render.surface=\"" + o.surface + "\"");
  if (o.viewTableStepDeg > 0) settings.push_back("render.view_table_step_deg=" + std::to_string(o.viewTableStepDeg));
  if (o.threads > 0) settings.push_back("render.threads=" + std::to_string(o.threads));
  auto loaded = plugin::loadServiceConfig(o.config, settings);
  if (!loaded) return fail(loaded.error().message);
  ServiceConfig cfg = std::move(loaded).value();
  for (plugin::ChannelConfig& ch : cfg.channels) {
    ch.name = o.channelPrefix + ch.name;
    const bool ok = ch.name.size() <= 200 && std::all_of(ch.name.begin(), ch.name.end(), [](unsigned char c) {
                      return std::isalnum(c) || c == '_' || c == '-' || c == '.';
                    });
    if (!ok) return fail("--channel-prefix: channel names take letters, digits, '_', '-' and '.' (200 at most): " + ch.name);
  }
  if (o.printConfig) {
    std::fputs(plugin::toToml(cfg).c_str(), stdout);
    return 0;
  }
  // A scenario brings its own world (its scene); without one, [world] scene is the world.
  std::optional<plugin::Scenario> scenario;
  if (!cfg.scenario_path.empty()) {
    auto sc = plugin::loadScenario(cfg.scenario_path);
    if (!sc) return fail(sc.error().message);
    scenario = std::move(sc).value();
  }
  const std::string worldPath = scenario ? scenario->scene_path : cfg.scene_path;
  auto world = loadScene(worldPath);
  if (!world) return fail(world.error().message);

  ipc::StateStoreOptions so;
  so.traffic_timeout_s = cfg.traffic_timeout_s;
  ipc::StateStore store(so);
  ipc::UdpReceiverOptions udp;
  udp.bind_address = cfg.udp_bind;
  udp.port = cfg.udp_port;
  udp.multicast_group = cfg.udp_multicast;
  udp.allow = cfg.udp_allow;
  auto rx = ipc::UdpReceiver::start(udp, store);
  if (!rx) return fail(rx.error().message);

  std::unique_ptr<ipc::CanSource> can;
  if (cfg.can_source != "none") {
    auto mapping = ipc::loadCanConfig(cfg.can_mapping_path);
    if (!mapping) return fail(mapping.error().message);
    auto dec = ipc::makeDecoder(*mapping);
    if (!dec) return fail(dec.error().message);
    Result<std::unique_ptr<ipc::CanSource>> src = Error{"unknown CAN source"};
    if (cfg.can_source == "candump") src = ipc::startCandumpReplay(cfg.can_candump, cfg.can_candump_speed, std::move(dec).value(), store);
    else if (cfg.can_source == "cannelloni") src = ipc::startCannelloni(cfg.udp_bind, cfg.can_cannelloni_port, std::move(dec).value(), store);
    else src = ipc::startSocketCan(cfg.can_interface, std::move(dec).value(), store);
    if (!src) return fail("CAN: " + src.error().message);
    can = std::move(src).value();
  }

  std::unique_ptr<GlSurfacePass> gl;
  if (cfg.surface != "cpu") {
    if (auto g = GlSurfacePass::create()) gl = std::move(g).value();
    else if (cfg.surface == "gl") return fail(g.error().message);
    else if (cfg.effects.render.airlight == AirlightDevice::Gpu)
      return fail("[render] airlight = \"gpu\" needs the GL surface pass: " + g.error().message);
    else spdlog::warn("serve: GL unavailable ({}); CPU planes only (no glTF)", g.error().message);
  }
  std::vector<std::unique_ptr<plugin::ChannelRenderer>> renderers;
  std::vector<std::unique_ptr<ipc::ShmWriter>> writers;
  for (std::size_t c = 0; c < cfg.channels.size(); ++c) {
    auto r = plugin::ChannelRenderer::create(cfg, c, *world, gl.get());
    if (!r) return fail(r.error().message);
    ipc::ShmChannelOptions ch;
    ch.channel = cfg.channels[c].name;
    ch.width = static_cast<std::uint32_t>(cfg.channels[c].width);
    ch.height = static_cast<std::uint32_t>(cfg.channels[c].height);
    ch.format = (*r)->shmFormat();
    ch.distance = cfg.channels[c].distance;
    auto w = ipc::ShmWriter::create(ch);
    if (!w) return fail(w.error().message);
    renderers.push_back(std::move(r).value());
    writers.push_back(std::move(w).value());
  }

  StatusBoard board;
  std::unique_ptr<ipc::StatusServer> status;
  if (cfg.status_udp_port != 0) {
    ipc::StatusServerOptions so_;
    so_.bind_address = cfg.udp_bind;
    so_.port = cfg.status_udp_port;
    auto s = ipc::StatusServer::start(so_, [&board, &rx] { return board.json((*rx)->stats()); });
    if (!s) return fail(s.error().message);
    status = std::move(s).value();
  }
  std::unique_ptr<ScenarioPlayer> player;
  if (scenario) {
    spdlog::info("serve: playing scenario {} ({} s{}) until a host sends (UDP or CAN)", scenario->name, scenario->duration_s,
                 cfg.scenario_loop ? ", looped" : "");
    const ipc::UdpReceiver* udpIn = rx->get();
    const ipc::CanSource* canIn = can.get();
    player = std::make_unique<ScenarioPlayer>(std::move(*scenario), cfg.scenario_loop, store, [udpIn, canIn] {
      return udpIn->stats().applied > 0 || (canIn && canIn->stats().matched > 0);
    });
  }

  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  // A frame may take longer than a reader's heartbeat timeout (the first one builds tables):
  // the heartbeat says "alive", not "a frame is due", so it beats on its own thread.
  std::atomic<bool> beating{true};
  std::thread heart([&beating, &writers] {
    while (beating.load()) {
      for (auto& w : writers) w->heartbeat();
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
    }
  });
  struct Join {
    std::atomic<bool>& flag;
    std::thread& t;
    ~Join() {
      flag = false;
      t.join();
    }
  } join{beating, heart};
  for (const auto& ch : cfg.channels) {
    if (ch.frustum_deg) {
      spdlog::info("serve: channel /fogbeam.{} {}x{} {} frustum [{}, {}, {}, {}]°", ch.name, ch.width, ch.height, ch.format,
                   (*ch.frustum_deg)[0], (*ch.frustum_deg)[1], (*ch.frustum_deg)[2], (*ch.frustum_deg)[3]);
    } else {
      spdlog::info("serve: channel /fogbeam.{} {}x{} {} fov {}°", ch.name, ch.width, ch.height, ch.format, ch.fov_x_deg);
    }
  }
  spdlog::info("serve: world {}, {} at {} Hz, UDP {}:{}, status port {}", worldPath,
               cfg.lock_step ? "lock-step" : "free-running", cfg.rate_hz, cfg.udp_bind, (*rx)->port(),
               status ? status->port() : 0);
  std::printf("fogbeam serve: ready: UDP %s:%u, status port %u, %zu channel(s)\n", cfg.udp_bind.c_str(),
              static_cast<unsigned>((*rx)->port()), static_cast<unsigned>(status ? status->port() : 0),
              cfg.channels.size());
  std::fflush(stdout);

  const auto start = Clock::now();
  auto nextFrame = start;
  const auto interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(cfg.status_interval_s));
  auto nextStatus = start + interval;
  auto windowStart = start;
  std::uint64_t frame = 0, windowFrames = 0, lastRequestSeq = 0;
  std::vector<double> totalMs, airMs, surfMs, latencyMs;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / cfg.rate_hz));
  plugin::RenderedFrame out;
  HostWatch watch(store, cfg.traffic_timeout_s);
  int exitCode = 0;
  while (!gStop.load()) {
    if (o.duration_s > 0.0 && Clock::now() - start > std::chrono::duration<double>(o.duration_s)) break;
    if (o.frames > 0 && frame >= o.frames) break;
    auto snap = store.snapshot();
    std::uint64_t requested = 0;
    if (cfg.lock_step) {
      if (!snap->frame_request.stamp.valid || snap->frame_request.stamp.sequence == lastRequestSeq) {
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        continue;
      }
      lastRequestSeq = snap->frame_request.stamp.sequence;
      requested = snap->frame_request.value.frame;
    } else {
      std::this_thread::sleep_until(nextFrame);
      nextFrame += period;
      if (Clock::now() > nextFrame + period) nextFrame = Clock::now();  // fell behind: do not burst
      snap = store.snapshot();
    }
    ++frame;
    const auto now = Clock::now();
    watch.check(*snap, now, player && player->playing());
    Clock::time_point newest{};
    for (const ipc::Stamp* s : {&snap->ego.stamp, &snap->lamps.stamp, &snap->environment.stamp, &snap->frame_request.stamp})
      if (s->valid) newest = std::max(newest, s->received);
    bool pending = false;
    for (std::size_t c = 0; c < renderers.size(); ++c) {
      if (Status s = renderers[c]->render(*snap, now, cfg.lock_step, out); !s) {
        spdlog::error("serve: channel {}: {}", cfg.channels[c].name, s.error().message);
        exitCode = 1;
        gStop = true;
        break;
      }
      pending = pending || out.pending;
      out.meta.frame = cfg.lock_step ? requested : frame;
      out.meta.frame_request = requested;
      out.meta.latency_ms =
          newest == Clock::time_point{} ? 0.0 : std::chrono::duration<double, std::milli>(Clock::now() - newest).count();
      writers[c]->publish(out.meta, out.packed,
                          cfg.channels[c].distance ? std::span<const float>(out.layers.distance) : std::span<const float>());
      if (c == 0) {
        totalMs.push_back(out.meta.total_ms);
        airMs.push_back(out.meta.airlight_ms);
        surfMs.push_back(out.meta.surface_ms);
        if (newest != Clock::time_point{}) latencyMs.push_back(out.meta.latency_ms);
      }
    }
    ++windowFrames;
    if (Clock::now() >= nextStatus) {
      const auto t = Clock::now();
      auto age = [&](const ipc::Stamp& s) { return s.valid ? std::chrono::duration<double>(t - s.received).count() : -1.0; };
      {
        std::lock_guard lock(board.mutex);
        board.frames = frame;
        board.fps = static_cast<double>(windowFrames) / std::chrono::duration<double>(t - windowStart).count();
        board.total_p50 = percentile(totalMs, 0.5);
        board.total_p95 = percentile(totalMs, 0.95);
        board.surface_p50 = percentile(surfMs, 0.5);
        board.airlight_p50 = percentile(airMs, 0.5);
        board.latency_p50 = percentile(latencyMs, 0.5);
        board.latency_p95 = percentile(latencyMs, 0.95);
        board.ego_age_s = age(snap->ego.stamp);
        board.lamps_age_s = age(snap->lamps.stamp);
        board.env_age_s = age(snap->environment.stamp);
        board.traffic = out.meta.traffic_count;
        board.traffic_expired = store.expiredTotal();
        board.tables_pending = pending;
        board.input = player && player->playing() ? "scenario" : snap->ego.stamp.valid ? snap->ego.stamp.source : "none";
      }
      const ipc::UdpStats st = (*rx)->stats();
      spdlog::info("serve: {} frames, {:.1f} fps; frame p50 {:.1f} ms p95 {:.1f} (surface {:.1f}, airlight {:.1f}); "
                   "input-to-publish p50 {:.1f} ms p95 {:.1f}; input {}; UDP {} applied, {} dropped; traffic {}{}",
                   frame, board.fps, board.total_p50, board.total_p95, board.surface_p50, board.airlight_p50,
                   board.latency_p50, board.latency_p95, board.input, st.applied, st.droppedTotal(), board.traffic,
                   pending ? "; fog/bending tables building" : "");
      totalMs.clear();
      airMs.clear();
      surfMs.clear();
      latencyMs.clear();
      windowFrames = 0;
      windowStart = t;
      nextStatus += interval;
    }
  }
  player.reset();
  const ipc::UdpStats st = (*rx)->stats();
  std::printf("fogbeam serve: %llu frames published on %zu channel(s); UDP %llu datagrams, %llu applied, %llu dropped\n",
              static_cast<unsigned long long>(frame), cfg.channels.size(),
              static_cast<unsigned long long>(st.datagrams), static_cast<unsigned long long>(st.applied),
              static_cast<unsigned long long>(st.droppedTotal()));
  return exitCode;
}

}  // namespace

void addServeCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<ServeOptions>();
  auto* sub = app.add_subcommand(
      "serve", "Run the cab service: UDP/CAN/scenario in, frames to shared-memory channels (docs/service.md)");
  sub->add_option("--config", o->config, "service config file, merged over the built-in default")
      ->check(CLI::ExistingFile);
  sub->add_option("--set", o->set, "override one key: section.key=value (TOML value), repeatable")
      ->take_all();
  sub->add_flag("--print-config", o->printConfig, "print the effective configuration (TOML) and exit");
  sub->add_option("--scenario", o->scenario, "play this scenario until a host sends (overrides world.scenario)")
      ->check(CLI::ExistingFile);
  sub->add_flag("--no-scenario", o->noScenario, "play no scenario: wait for a host");
  sub->add_option("--channel-prefix", o->channelPrefix, "prefix every channel name (several services on one machine)");
  sub->add_option("--duration", o->duration_s, "stop after this many seconds (default: until SIGINT/SIGTERM)")
      ->check(CLI::Range(0.0, 1e7));
  sub->add_option("--frames", o->frames, "stop after this many frames (default: no limit)");
  sub->add_flag("--lock-step", o->lockStep, "= --set timing.mode=\"lock-step\"");
  sub->add_option("--rate", o->rate_hz, "= --set timing.rate_hz=…")->check(CLI::Range(0.1, 1000.0));
  sub->add_option("--udp-port", o->udpPort, "= --set input.udp.port=… (0 = any free port)")->check(CLI::Range(0, 65535));
  sub->add_option("--status-port", o->statusPort, "= --set status.udp_port=… (0 = off)")->check(CLI::Range(0, 65535));
  sub->add_option("--surface", o->surface, "= --set render.surface=…")->check(CLI::IsMember({"auto", "gl", "cpu"}));
  sub->add_option("--view-table-step", o->viewTableStepDeg, "= --set render.view_table_step_deg=…")
      ->check(CLI::Range(0.05, 5.0));
  sub->add_option("--threads", o->threads, "= --set render.threads=…");
  sub->callback([o, &exitCode] { exitCode = run(*o); });
}

}  // namespace fogbeam::cli
