// `fogbeam serve` (first version, issue 5): the frame loop a cab runs. Inputs arrive over UDP
// (docs/protocol.md) and optionally CAN (docs/can.md); every frame takes one state snapshot,
// places the scene at the ego pose, renders surfaces (GL or CPU), airlight and the composite,
// packs the channel's format and publishes it to shared memory (docs/shm.md) with its metadata.
//
// Until the service configuration of issue 5 exists, the rig and the world come from a scene
// file (docs/scene.md) read in the vehicle's frame: its camera is the driver's eye relative to the
// vehicle reference point, lamps with mount = "vehicle" are the ego rig (a lamp whose name says
// "low beam", "high beam", "front fog", "rear fog" or "tail" follows that light bit; others are
// always on), world lamps and geometry stay where they are. Traffic objects are drawn with the
// rig of --traffic-rig (a scene file read the same way: its vehicle lamps in the traffic vehicle's
// frame), for every vehicle class; their lamps are evaluated per ray (world-fixed measured
// profiles: the slow path). Fog comes from the environment message once one has arrived.
#include "commands.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/ipc/udp_receiver.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/frame.hpp>
#include <fogbeam/render/pixel_pack.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace fogbeam::cli {

namespace {

using Clock = std::chrono::steady_clock;

std::atomic<bool> gStop{false};
extern "C" void onSignal(int) { gStop.store(true); }

struct ServeOptions {
  std::string scene = "config/scenes/night_road.toml";
  std::string channel = "main";
  std::string format = "rgba8-srgb";
  bool distance = false;
  double rate_hz = 30.0;
  bool lockStep = false;
  double duration_s = 0.0;
  std::uint64_t frames = 0;
  std::string udpBind = "127.0.0.1";
  std::uint16_t udpPort = 47800;
  std::string multicast;
  std::vector<std::string> allow;
  double exposure = 0.0;
  std::string surface = "auto";
  double statusInterval_s = 5.0;
  std::string canConfig;
  std::string canCandump;
  int canCannelloniPort = -1;
  std::string canInterface;
  double viewTableStepDeg = 0.5;
  std::string trafficRig;
  unsigned threads = 0;
};

std::uint32_t lightBitFor(const std::string& name) {
  std::string n = name;
  std::transform(n.begin(), n.end(), n.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (n.find("low beam") != std::string::npos) return ipc::light::kLowBeam;
  if (n.find("high beam") != std::string::npos) return ipc::light::kHighBeam;
  if (n.find("front fog") != std::string::npos) return ipc::light::kFrontFog;
  if (n.find("rear fog") != std::string::npos) return ipc::light::kRearFog;
  if (n.find("tail") != std::string::npos) return ipc::light::kPosition;
  return 0;  // always on
}

Medium fogFrom(const ipc::Environment& e, const Medium& fallback) {
  Medium m = fallback;
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

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

int run(const ServeOptions& o) {
  auto base = loadScene(o.scene);
  if (!base) {
    std::fprintf(stderr, "fogbeam serve: %s\n", base.error().message.c_str());
    return 2;
  }
  std::uint32_t format = 0;
  if (o.format == "rgba8-srgb") format = FOGBEAM_FORMAT_RGBA8_SRGB;
  else if (o.format == "rgba16f-linear") format = FOGBEAM_FORMAT_RGBA16F_LINEAR;
  else if (o.format == "rgba16f-overlay") format = FOGBEAM_FORMAT_RGBA16F_OVERLAY;
  const Scene& local = *base;  // in the vehicle frame
  const int W = local.camera.width, H = local.camera.height;
  const std::size_t n = static_cast<std::size_t>(W) * static_cast<std::size_t>(H);

  ipc::StateStore store;
  ipc::UdpReceiverOptions udp;
  udp.bind_address = o.udpBind;
  udp.port = o.udpPort;
  udp.multicast_group = o.multicast;
  udp.allow = o.allow;
  auto rx = ipc::UdpReceiver::start(udp, store);
  if (!rx) {
    std::fprintf(stderr, "fogbeam serve: %s\n", rx.error().message.c_str());
    return 2;
  }
  std::unique_ptr<ipc::CanSource> can;
  if (!o.canConfig.empty()) {
    auto cfg = ipc::loadCanConfig(o.canConfig);
    if (!cfg) {
      std::fprintf(stderr, "fogbeam serve: %s\n", cfg.error().message.c_str());
      return 2;
    }
    auto dec = ipc::makeDecoder(*cfg);
    if (!dec) {
      std::fprintf(stderr, "fogbeam serve: %s\n", dec.error().message.c_str());
      return 2;
    }
    Result<std::unique_ptr<ipc::CanSource>> src = Error{"no CAN source given (--can-candump, --can-cannelloni or --can-interface)"};
    if (!o.canCandump.empty()) src = ipc::startCandumpReplay(o.canCandump, 1.0, std::move(dec).value(), store);
    else if (o.canCannelloniPort >= 0)
      src = ipc::startCannelloni(o.udpBind, static_cast<std::uint16_t>(o.canCannelloniPort), std::move(dec).value(), store);
    else if (!o.canInterface.empty()) src = ipc::startSocketCan(o.canInterface, std::move(dec).value(), store);
    if (!src) {
      std::fprintf(stderr, "fogbeam serve: CAN: %s\n", src.error().message.c_str());
      return 2;
    }
    can = std::move(src).value();
  }
  ipc::ShmChannelOptions ch;
  ch.channel = o.channel;
  ch.width = static_cast<std::uint32_t>(W);
  ch.height = static_cast<std::uint32_t>(H);
  ch.format = format;
  ch.distance = o.distance;
  auto writer = ipc::ShmWriter::create(ch);
  if (!writer) {
    std::fprintf(stderr, "fogbeam serve: %s\n", writer.error().message.c_str());
    return 2;
  }
  std::unique_ptr<GlSurfacePass> gl;
  if (o.surface != "cpu") {
    if (auto g = GlSurfacePass::create()) gl = std::move(g).value();
    else if (o.surface == "gl") {
      std::fprintf(stderr, "fogbeam serve: %s\n", g.error().message.c_str());
      return 2;
    } else spdlog::warn("serve: GL unavailable ({}); CPU planes only", g.error().message);
  }

  std::vector<SceneLamp> rig;  // traffic rig, in the traffic vehicle's frame
  if (!o.trafficRig.empty()) {
    auto r = loadScene(o.trafficRig);
    if (!r) {
      std::fprintf(stderr, "fogbeam serve: --traffic-rig: %s\n", r.error().message.c_str());
      return 2;
    }
    for (const SceneLamp& l : r->lamps)
      if (l.mount == LampMount::Vehicle) rig.push_back(l);
    if (rig.empty()) {
      std::fprintf(stderr, "fogbeam serve: --traffic-rig %s has no lamp with mount = \"vehicle\"\n", o.trafficRig.c_str());
      return 2;
    }
  }
  FastPathOptions fast;
  fast.view_table_step_deg = o.viewTableStepDeg;
  AirlightImage trafficAir;
  Scene world = local;
  std::unique_ptr<AirlightImageEvaluator> eval;
  std::uint32_t evalEnvSequence = 0;
  bool evalHasEnv = false;
  SurfaceBuffers surface;
  AirlightImage air;
  FrameLayers layers;
  std::vector<std::byte> packed(n * ipc::bytesPerPixel(format));
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  // A frame may take longer than a reader's heartbeat timeout (the first one builds tables):
  // the heartbeat says "alive", not "a frame is due", so it beats on its own thread.
  std::atomic<bool> beating{true};
  ipc::ShmWriter* beatWriter = writer->get();
  std::thread heart([&beating, beatWriter] {
    while (beating.load()) {
      beatWriter->heartbeat();
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
  spdlog::info("serve: scene {}, channel /fogbeam.{} {}x{} {}, {} at {} Hz, UDP {}:{}", o.scene, o.channel, W, H,
               o.format, o.lockStep ? "lock-step" : "free-running", o.rate_hz, o.udpBind, (*rx)->port());

  const auto start = Clock::now();
  auto nextFrame = start;
  auto nextStatus = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.statusInterval_s));
  std::uint64_t frame = 0, lastRequestSeq = 0;
  std::vector<double> totalMs, airMs, surfMs, latencyMs;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / o.rate_hz));
  while (!gStop.load()) {
    if (o.duration_s > 0.0 && Clock::now() - start > std::chrono::duration<double>(o.duration_s)) break;
    if (o.frames > 0 && frame >= o.frames) break;
    auto snap = store.snapshot();
    std::uint64_t requested = 0;
    if (o.lockStep) {
      if (!snap->frame_request.stamp.valid || snap->frame_request.stamp.sequence == lastRequestSeq) {
        (*writer)->heartbeat();
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
    const auto t0 = Clock::now();
    // Place the vehicle: camera and vehicle lamps follow the ego pose.
    const ipc::Pose& pose = snap->ego.value.pose;
    const Mat3 R = worldFromYawPitchRoll(radians(static_cast<double>(pose.yaw_deg)),
                                         radians(static_cast<double>(pose.pitch_deg)),
                                         radians(static_cast<double>(pose.roll_deg)));
    const Vec3 origin(pose.position_m[0], pose.position_m[1], pose.position_m[2]);
    world.camera.position_m = origin + R * local.camera.position_m;
    world.camera.worldFromCamera = R * local.camera.worldFromCamera;
    const std::uint32_t lights =
        snap->lamps.stamp.valid ? snap->lamps.value.lights : (ipc::light::kLowBeam | ipc::light::kPosition);
    for (std::size_t i = 0; i < local.lamps.size(); ++i) {
      if (local.lamps[i].mount != LampMount::Vehicle) continue;
      world.lamps[i].lamp.position_m = origin + R * local.lamps[i].lamp.position_m;
      world.lamps[i].lamp.worldFromLamp = R * local.lamps[i].lamp.worldFromLamp;
    }
    const bool envNew = snap->environment.stamp.valid &&
                        (!evalHasEnv || snap->environment.stamp.sequence != evalEnvSequence);
    if (!eval || envNew) {
      if (snap->environment.stamp.valid) world.fog = fogFrom(snap->environment.value, local.fog);
      auto e = AirlightImageEvaluator::build(world, AirlightMethod::Accurate, {}, o.threads, fast);
      if (!e) {
        spdlog::error("serve: {}", e.error().message);
        return 1;
      }
      eval = std::make_unique<AirlightImageEvaluator>(std::move(e).value());
      evalHasEnv = snap->environment.stamp.valid;
      evalEnvSequence = snap->environment.stamp.sequence;
    }
    (void)eval->setLampPoses(world);
    Scene lit = world;  // the lamps that are on, for the surface pass
    lit.lamps.clear();
    for (std::size_t i = 0; i < world.lamps.size(); ++i) {
      const std::uint32_t bit = local.lamps[i].mount == LampMount::Vehicle ? lightBitFor(local.lamps[i].name) : 0;
      const bool on = bit == 0 || (lights & bit) != 0;
      eval->setLampEnabled(i, on);
      if (on) lit.lamps.push_back(world.lamps[i]);
    }
    // Traffic: each live object's rig lamps that its light bits switch on, placed at its pose.
    Scene traffic = world;
    traffic.lamps.clear();
    if (!rig.empty()) {
      const auto now = Clock::now();
      for (const ipc::TrafficEntry& e : snap->traffic) {
        if (!snap->live(e, now)) continue;
        const ipc::Pose& tp = e.object.pose;
        const Mat3 TR = worldFromYawPitchRoll(radians(static_cast<double>(tp.yaw_deg)),
                                              radians(static_cast<double>(tp.pitch_deg)),
                                              radians(static_cast<double>(tp.roll_deg)));
        const Vec3 to(tp.position_m[0], tp.position_m[1], tp.position_m[2]);
        for (const SceneLamp& l : rig) {
          const std::uint32_t bit = lightBitFor(l.name);
          if (bit != 0 && (e.object.lights & bit) == 0) continue;
          SceneLamp w = l;
          w.mount = LampMount::World;
          w.lamp.position_m = to + TR * l.lamp.position_m;
          w.lamp.worldFromLamp = TR * l.lamp.worldFromLamp;
          traffic.lamps.push_back(w);
          lit.lamps.push_back(w);
        }
      }
    }
    const auto tS = Clock::now();
    if (!gl || !gl->render(lit, surface)) renderSurfacesCpu(lit, surface);
    const auto tA = Clock::now();
    eval->evaluate(world, surface, SubsamplingOptions{}, air);
    if (!traffic.lamps.empty()) {
      // Built per frame on the same pool: per-lamp tables come from the caches.
      auto te = AirlightImageEvaluator::build(traffic, AirlightMethod::Accurate, {}, eval->pool(), fast);
      if (te) {
        te->evaluate(traffic, surface, SubsamplingOptions{}, trafficAir);
        for (std::size_t k = 0; k < air.rgb.size(); ++k) air.rgb[k] += trafficAir.rgb[k];
      } else {
        spdlog::error("serve: traffic lamps: {}", te.error().message);
      }
    }
    const auto tC = Clock::now();
    compositeFrame(world.fog, surface, air, layers);
    if (format == FOGBEAM_FORMAT_RGBA8_SRGB)
      packRgba8Srgb(layers.composite.data(), n, o.exposure, reinterpret_cast<std::uint8_t*>(packed.data()));
    else if (format == FOGBEAM_FORMAT_RGBA16F_LINEAR)
      packRgba16F(layers.composite.data(), nullptr, 1.0f, n, reinterpret_cast<std::uint16_t*>(packed.data()));
    else
      packRgba16F(layers.overlay.data(), layers.transmittance.data(), 1.0f, n,
                  reinterpret_cast<std::uint16_t*>(packed.data()));
    const auto tE = Clock::now();
    ++frame;
    ipc::FrameMeta m;
    m.frame = o.lockStep ? requested : frame;
    m.frame_request = requested;
    m.sim_time_s = snap->ego.stamp.sim_time_s;
    m.position_m = {world.camera.position_m.x, world.camera.position_m.y, world.camera.position_m.z};
    m.yaw_deg = pose.yaw_deg;
    m.pitch_deg = pose.pitch_deg;
    m.roll_deg = pose.roll_deg;
    m.lights = lights;
    m.ego_sequence = snap->ego.stamp.sequence;
    m.lamp_sequence = snap->lamps.stamp.sequence;
    m.environment_sequence = snap->environment.stamp.sequence;
    m.traffic_count = static_cast<std::uint32_t>(snap->traffic.size());
    auto ms = [](Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
    m.surface_ms = ms(tS, tA);
    m.airlight_ms = ms(tA, tC);
    m.composite_ms = ms(tC, tE);
    m.total_ms = ms(t0, tE);
    Clock::time_point newest{};
    for (const ipc::Stamp* s : {&snap->ego.stamp, &snap->lamps.stamp, &snap->environment.stamp, &snap->frame_request.stamp})
      if (s->valid) newest = std::max(newest, s->received);
    m.latency_ms = newest == Clock::time_point{} ? 0.0 : ms(newest, Clock::now());
    (*writer)->publish(m, packed, o.distance ? std::span<const float>(layers.distance) : std::span<const float>());
    totalMs.push_back(m.total_ms);
    airMs.push_back(m.airlight_ms);
    surfMs.push_back(m.surface_ms);
    if (newest != Clock::time_point{}) latencyMs.push_back(m.latency_ms);
    if (Clock::now() >= nextStatus) {
      const ipc::UdpStats st = (*rx)->stats();
      spdlog::info("serve: {} frames; frame median {:.1f} ms (surface {:.1f}, airlight {:.1f}); input-to-publish median "
                   "{:.1f} ms; UDP {} applied, {} dropped; traffic {}",
                   frame, median(totalMs), median(surfMs), median(airMs), median(latencyMs), st.applied,
                   st.droppedTotal(), snap->traffic.size());
      totalMs.clear();
      airMs.clear();
      surfMs.clear();
      latencyMs.clear();
      nextStatus += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.statusInterval_s));
    }
  }
  const ipc::UdpStats st = (*rx)->stats();
  std::printf("fogbeam serve: %llu frames published on /fogbeam.%s; UDP %llu datagrams, %llu applied, %llu dropped\n",
              static_cast<unsigned long long>(frame), o.channel.c_str(), static_cast<unsigned long long>(st.datagrams),
              static_cast<unsigned long long>(st.applied), static_cast<unsigned long long>(st.droppedTotal()));
  return 0;
}

}  // namespace

void addServeCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<ServeOptions>();
  auto* sub = app.add_subcommand("serve", "Run the cab service: UDP/CAN in, frames to a shared-memory channel (first "
                                          "version: the rig and world come from a scene file in the vehicle frame)");
  sub->add_option("--scene", o->scene, "scene file in the vehicle frame (default config/scenes/night_road.toml)")
      ->check(CLI::ExistingFile);
  sub->add_option("--channel", o->channel, "shared-memory channel name: /fogbeam.<name> (default main)");
  sub->add_option("--format", o->format, "rgba8-srgb | rgba16f-linear | rgba16f-overlay (default rgba8-srgb)")
      ->check(CLI::IsMember({"rgba8-srgb", "rgba16f-linear", "rgba16f-overlay"}));
  sub->add_flag("--distance", o->distance, "also publish the f32 distance plane (m, inf = sky)");
  sub->add_option("--rate", o->rate_hz, "free-running frame rate, Hz (default 30)")->check(CLI::Range(0.1, 1000.0));
  sub->add_flag("--lock-step", o->lockStep, "render one frame per frame-request message instead of free-running");
  sub->add_option("--duration", o->duration_s, "stop after this many seconds (default: until SIGINT/SIGTERM)")
      ->check(CLI::Range(0.0, 1e7));
  sub->add_option("--frames", o->frames, "stop after this many frames (default: no limit)");
  sub->add_option("--udp-bind", o->udpBind, "UDP bind address (default 127.0.0.1)");
  sub->add_option("--udp-port", o->udpPort, "UDP port (default 47800; 0 = any)");
  sub->add_option("--multicast", o->multicast, "multicast group to join (e.g. 239.255.47.80)");
  sub->add_option("--allow", o->allow, "sender IPv4 addresses allowed (default: any)")->delimiter(',');
  sub->add_option("--exposure", o->exposure, "RGBA8 output exposure, EV (default 0)");
  sub->add_option("--surface", o->surface, "auto | gl | cpu (default auto)")->check(CLI::IsMember({"auto", "gl", "cpu"}));
  sub->add_option("--status-interval", o->statusInterval_s, "seconds between status lines (default 5)")
      ->check(CLI::Range(0.1, 3600.0));
  sub->add_option("--can-config", o->canConfig, "CAN mapping file (docs/can.md)")->check(CLI::ExistingFile);
  sub->add_option("--can-candump", o->canCandump, "replay this candump -L log as the CAN bus")->check(CLI::ExistingFile);
  sub->add_option("--can-cannelloni", o->canCannelloniPort, "receive cannelloni on this UDP port");
  sub->add_option("--can-interface", o->canInterface, "SocketCAN interface (e.g. can0)");
  sub->add_option("--view-table-step", o->viewTableStepDeg, "view-table direction spacing, deg (default 0.5)")
      ->check(CLI::Range(0.05, 5.0));
  sub->add_option("--traffic-rig", o->trafficRig,
                  "scene file whose mount = \"vehicle\" lamps are the traffic vehicles' rig (in their frame)")
      ->check(CLI::ExistingFile);
  sub->add_option("--threads", o->threads, "worker threads (default: all cores)");
  sub->callback([o, &exitCode] { exitCode = run(*o); });
}

}  // namespace fogbeam::cli
