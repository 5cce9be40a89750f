// `fogbeam serve` (issue 5): the process a cab runs. The service configuration
// (docs/service.md; built-in default < --config file < command line) names the world, the ego and
// traffic rigs, the output channels, the inputs and the timing; plugin::Service
// (fogbeam/plugin/service.hpp) runs it: inputs over UDP (docs/protocol.md), CAN (docs/can.md) or
// from a scenario (docs/scenario.md) that plays until a host sends its first message; every frame
// takes one state snapshot and renders each channel into its shared-memory segment (docs/shm.md).
//
// This file is the command line: options, the configuration's layers, --channel-prefix,
// --print-config, the ready and summary lines, and SIGINT/SIGTERM, whose handler asks the
// service to stop (the loop ends, threads are joined and segments unlinked).
#include "commands.hpp"

#include <fogbeam/ipc/shm_channel.hpp>

#include <fogbeam/plugin/service.hpp>
#include <fogbeam/plugin/service_config.hpp>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam::cli {

namespace {

using plugin::ServiceConfig;

/// The running service, for the signal handler (set while its frame loop may run).
std::atomic<plugin::Service*> gService{nullptr};
static_assert(std::atomic<plugin::Service*>::is_always_lock_free);
/// SIGINT/SIGTERM: asks the frame loop to end (Service::requestStop: one atomic store).
extern "C" void onSignal(int) {
  if (plugin::Service* s = gService.load()) s->requestStop();
}

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
    if (!ipc::validChannelName(ch.name))
      return fail("--channel-prefix: channel names take letters, digits, '_', '-' and '.' (" +
                  std::to_string(ipc::kMaxChannelName) + " at most): " + ch.name);
  }
  if (o.printConfig) {
    std::fputs(plugin::toToml(cfg).c_str(), stdout);
    return 0;
  }
  auto created = plugin::Service::create(std::move(cfg));
  if (!created) return fail(created.error().message);
  plugin::Service& service = **created;

  gService.store(&service);
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  std::printf("fogbeam serve: ready: UDP %s:%u, status port %u, %zu channel(s)\n", service.config().udp_bind.c_str(),
              static_cast<unsigned>(service.udpPort()), static_cast<unsigned>(service.statusPort()),
              service.config().channels.size());
  std::fflush(stdout);

  plugin::RunLimits limits;
  limits.duration_s = o.duration_s;
  limits.frames = o.frames;
  // A failed frame is logged by the service ("serve: channel …"); exit status 1.
  const int exitCode = service.run(limits) ? 0 : 1;
  service.stop();
  // A late signal finds no service (the handler stays: a second SIGTERM is ignored, as before).
  gService.store(nullptr);
  const ipc::UdpStats st = service.udpStats();
  std::printf("fogbeam serve: %llu frames published on %zu channel(s); UDP %llu datagrams, %llu applied, %llu dropped\n",
              static_cast<unsigned long long>(service.frames()), service.config().channels.size(),
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
