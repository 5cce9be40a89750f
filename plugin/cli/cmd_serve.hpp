// `fogbeam serve` (issue 5): the process a cab runs (cmd_serve.cpp). The options are filled by
// main.cpp, the one translation unit that includes CLI11 (its option names, help texts and checks
// are there).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace fogbeam::cli {

struct ServeOptions {
  /// --config: service config file merged over the built-in default; empty (default): none.
  std::string config;
  /// --set: overrides, one key each, "section.key=value" (TOML value), applied in order.
  std::vector<std::string> set;
  /// --print-config: print the effective configuration (TOML) and exit 0 (default off).
  bool printConfig = false;
  /// --scenario: scenario played until a host sends (= world.scenario); empty (default): the config's.
  std::string scenario;
  /// --no-scenario: play no scenario, wait for a host (default off).
  bool noScenario = false;
  /// --channel-prefix: prefix of every channel name (several services on one machine); default none.
  std::string channelPrefix;
  /// --duration: stop after this many seconds; 0 (default): until SIGINT/SIGTERM.
  double duration_s = 0.0;
  /// --frames: stop after this many frames; 0 (default): no limit.
  std::uint64_t frames = 0;
  // Shorthands for --set (applied after it): false / empty / zero or negative = not given.
  bool lockStep = false;          ///< --lock-step: timing.mode = "lock-step"
  double rate_hz = 0.0;           ///< --rate: timing.rate_hz, Hz
  int udpPort = -1;               ///< --udp-port: input.udp.port (0 = any free port)
  int statusPort = -1;            ///< --status-port: status.udp_port (0 = off)
  std::string surface;            ///< --surface: render.surface, auto | gl | cpu
  std::string overlap;            ///< --overlap: render.overlap_frames, auto | on | off
  double viewTableStepDeg = 0.0;  ///< --view-table-step: render.view_table_step_deg, degrees
  unsigned threads = 0;           ///< --threads: render.threads
};

/// Runs the service until a limit or a signal; returns the exit status: 0, 1 when a frame
/// failed, 2 on bad configuration.
int runServe(const ServeOptions& o);

}  // namespace fogbeam::cli
