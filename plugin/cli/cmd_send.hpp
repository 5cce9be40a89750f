// `fogbeam send` (issue 5): a host stand-in that plays a scenario (or keyboard driving) into a
// running `fogbeam serve` over UDP, optionally CAN (cmd_send.cpp). The options are filled by
// main.cpp, the one translation unit that includes CLI11 (its option names, help texts and checks
// are there).
#pragma once

#include <string>

namespace fogbeam::cli {

struct SendOptions {
  /// --scenario: scenario file played in real time; exactly one of it and --keyboard is needed.
  std::string scenario;
  /// --keyboard: drive with the keyboard instead (default off).
  bool keyboard = false;
  /// --to: the service's UDP input, HOST:PORT, IPv4 (default 127.0.0.1:47800).
  std::string to = "127.0.0.1:47800";
  /// --rate: states sent per second, Hz (default 60).
  double rate_hz = 60.0;
  /// --speed: scenario seconds per wall-clock second (default 1).
  double speed = 1.0;
  /// --duration: stop after this many wall-clock seconds; 0 (default): no limit.
  double duration_s = 0.0;
  /// --loop: start the scenario again at its end (default off).
  bool loop = false;
  /// --lock-step: a frame request after each state (default off).
  bool lockStep = false;
  /// --log: CSV of what was sent (ego sequence, time, pose, lights); empty (default): none.
  std::string log;
  /// --can-config: CAN mapping file (docs/can.md): also lamps and speed on CAN; empty (default): no CAN.
  std::string canConfig;
  std::string canCannelloni;          ///< --can-cannelloni: HOST:PORT the CAN frames go to as cannelloni
  std::string canCandump;             ///< --can-candump: candump -L log the CAN frames are written to
  std::string canInterface = "can0";  ///< --can-interface: interface name written in the candump log
};

/// Sends until the scenario ends, a limit or a signal; returns the exit status: 0, 1 when
/// datagrams could not be sent, 2 on bad input.
int runSend(const SendOptions& o);

}  // namespace fogbeam::cli
