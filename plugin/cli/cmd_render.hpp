// `fogbeam render`: one frame of a scene file to EXR (and PNG) (cmd_render.cpp). The options are
// filled by main.cpp, the one translation unit that includes CLI11 (its option names, help texts
// and checks are there).
#pragma once

#include <fogbeam/render/airlight_image.hpp>

#include <optional>
#include <string>

namespace fogbeam::cli {

struct RenderOptions {
  /// --scene (required): scene file (TOML, docs/scene.md).
  std::string scene;
  /// --out (required): the OpenEXR file written (linear layers, cd/m2).
  std::string out;
  /// --png: also the composite tone-mapped to 8-bit sRGB here; empty (default): no PNG.
  std::string png;
  /// --method: airlight method, seed | accurate | reference (default accurate).
  std::string method = "accurate";
  /// --surface: surface layer, auto (GL if available, else CPU) | gl | cpu (default auto).
  std::string surface = "auto";
  /// --full: evaluate every pixel, no adaptive subsampling (default off).
  bool full = false;
  /// --exposure: PNG exposure in EV (x = L·2^EV / (1 cd/m2), Reinhard, sRGB); empty (default,
  /// "auto"): the frame's automatic night exposure (autoExposureEv, fogbeam/render/exposure.hpp).
  std::optional<double> exposure;
  /// --coarse-step: subsampling's initial block size in pixels; 0 (default, the library's): chosen
  /// from the camera.
  int coarseStep = SubsamplingOptions{}.coarse_step;
  /// --tolerance: subsampling's relative error allowed between a block's centre and its bilinear
  /// prediction (default: the library's, 0.005).
  double tolerance = SubsamplingOptions{}.rel_tolerance;
  /// --moving-lamps: measured and spot lamps fixed in the world, pencil | map | per-ray (default pencil).
  std::string movingLamps = "pencil";
  /// --table-cache: where the vehicle lamps' view tables are kept between runs: auto (default:
  /// $XDG_CACHE_HOME/fogbeam or ~/.cache/fogbeam) | off | a directory.
  std::string tableCache = "auto";
  /// --threads: worker threads; 0 (default): all cores.
  unsigned threads = 0;
  // Issue 7's additions; empty (default): as the scene's [glow], [glare], [render] say.
  std::string glow;            ///< --glow: on | off
  std::string fogLight;        ///< --fog-light: on | off
  std::string glare;           ///< --glare: on | off
  std::string airlightDevice;  ///< --airlight: cpu | gpu
  /// True when --method was given (not only defaulted): the GPU airlight path, accurate only,
  /// then refuses another method instead of ignoring it.
  bool methodGiven = false;
};

/// Renders the frame; returns the exit status: 0, 1 when the GL pass or writing a file fails, 2 on
/// bad input.
int runRender(const RenderOptions& o);

}  // namespace fogbeam::cli
