// `fogbeam view` (issue 5): a window on one or more shared-memory channels (cmd_view.cpp). The
// options are filled by main.cpp, the one translation unit that includes CLI11 (its option names,
// help texts and checks are there).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace fogbeam::cli {

struct ViewOptions {
  /// --channel: channel names, tiled side by side; empty names are skipped (default: main).
  std::vector<std::string> channels{"main"};
  /// --layer: initial layer, composite | airlight | transmittance (default composite).
  std::string layer = "composite";
  /// --exposure: initial exposure of linear formats, EV; empty (default, "auto"): the automatic
  /// night exposure of the frames shown, adapted like the eye (key A toggles it).
  std::optional<double> exposure;
  /// --no-stats: start without the stats overlay (default off).
  bool noStats = false;
  /// --width, --height: window size, pixels, both or neither; 0 (default): from the frames.
  int width = 0, height = 0;
  /// --screenshot: PNG of the window written after --after-frames new frames, then exit 0;
  /// empty (default): none.
  std::string screenshot;
  /// --after-frames: new frames every channel shows before the screenshot (default 1).
  std::uint64_t afterFrames = 1;
  /// --timeout: exit 1 when a channel shows no new frame for this many seconds; 0 (default):
  /// wait forever.
  double timeout_s = 0.0;
};

/// Shows the channels until closed; returns the exit status: 0, 1 on a timeout or a failed
/// screenshot, 2 on bad input or no display.
int runView(const ViewOptions& o);

}  // namespace fogbeam::cli
