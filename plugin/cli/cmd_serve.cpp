// `fogbeam serve` (issue 5): the process a cab runs. The service configuration
// (docs/service.md; built-in default < --config file < command line) names the world, the ego and
// traffic rigs, the output channels, the inputs and the timing; plugin::Service
// (fogbeam/plugin/service.hpp) runs it: inputs over UDP (docs/protocol.md), CAN (docs/can.md) or
// from a scenario (docs/scenario.md) that plays until a host sends its first message; every frame
// takes one state snapshot and renders each channel into its shared-memory segment (docs/shm.md).
//
// This file is the command line's side of it (the options themselves are registered in
// main.cpp): the configuration's layers, --channel-prefix, --print-config, the ready and summary
// lines, and SIGINT/SIGTERM, whose handler asks the service to stop (the loop ends, threads are
// joined and segments unlinked).
#include "cmd_serve.hpp"

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

int fail(const std::string& what) {
  std::fprintf(stderr, "fogbeam serve: %s\n", what.c_str());
  return 2;
}

}  // namespace

int runServe(const ServeOptions& o) {
  std::vector<std::string> settings = o.set;
  if (!o.scenario.empty()) settings.push_back("world.scenario=\"" + o.scenario + "\"");
  if (o.noScenario) settings.push_back("world.scenario=\"\"");
  if (o.lockStep) settings.push_back("timing.mode=\"lock-step\"");
  if (o.rate_hz > 0) settings.push_back("timing.rate_hz=" + std::to_string(o.rate_hz));
  if (o.udpPort >= 0) settings.push_back("input.udp.port=" + std::to_string(o.udpPort));
  if (o.statusPort >= 0) settings.push_back("status.udp_port=" + std::to_string(o.statusPort));
  if (!o.surface.empty()) settings.push_back("render.surface=\"" + o.surface + "\"");
  if (!o.overlap.empty()) settings.push_back("render.overlap_frames=\"" + o.overlap + "\"");
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

}  // namespace fogbeam::cli
