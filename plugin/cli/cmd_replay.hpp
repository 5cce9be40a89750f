// `fogbeam replay` (issue 5): a scenario rendered headless, frame by frame at a fixed simulation
// rate, into files (cmd_replay.cpp). The options are filled by main.cpp, the one translation unit
// that includes CLI11 (its option names, help texts and checks are there).
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace fogbeam::cli {

struct ReplayOptions {
  /// --scenario (required): scenario file (TOML, docs/scenario.md).
  std::string scenario;
  /// --out (required): output directory, created.
  std::string out;
  /// --fps: frames per second of simulation time (default 10).
  double fps = 10.0;
  /// --method: airlight method, accurate | seed | reference; empty (default): the config's.
  std::string method;
  /// --config: service config for rigs and views; empty (default): the built-in one.
  std::string config;
  /// --set: service config overrides, "section.key=value" each, applied in order.
  std::vector<std::string> set;
  /// --channel: which [[channel]] view is rendered; empty (default): the first.
  std::string channel;
  bool exr = true;  ///< false with --no-exr: no EXR frames
  bool png = true;  ///< false with --no-png: no PNG frames (the contact sheet is still written)
  /// --full: evaluate every pixel, no adaptive subsampling (default off).
  bool full = false;
  /// --exposure: PNG exposure in EV (x = L·2^EV / (1 cd/m2), Reinhard, sRGB); empty (default,
  /// "auto"): each frame's automatic night exposure, adapted over simulation time like the eye
  /// (autoExposureEv and ExposureAdaptation, fogbeam/render/exposure.hpp).
  std::optional<double> exposure;
  /// --start: first frame's time, s (default 0).
  double start_s = 0.0;
  /// --end: last frame's time, s; negative (default): the scenario's duration.
  double end_s = -1.0;
  /// --sheet-columns: contact sheet columns (default 6).
  int sheetColumns = 6;
  /// --sheet-width: contact sheet width, px (default 1536).
  int sheetWidth = 1536;
  /// --surface: auto | gl | cpu; empty (default): the config's.
  std::string surface;
  /// --overlap: auto | on | off, frame overlap ([render] overlap_frames); empty (default): the
  /// config's ("auto").
  std::string overlap;
  /// --width, --height: image size, px; 0 (default): the channel's (height: width · 9/16 when
  /// only the width is given).
  int width = 0, height = 0;
};

/// Renders the scenario; returns the exit status: 0, or 2 on an error.
int runReplay(const ReplayOptions& o);

}  // namespace fogbeam::cli
