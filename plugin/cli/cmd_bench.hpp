// `fogbeam bench`: the paper's headline scene at simulator sizes, every stage timed and every
// airlight method's error measured (cmd_bench.cpp). The options are filled by main.cpp, the one
// translation unit that includes CLI11 (its option names, help texts and checks are there).
#pragma once

#include <fogbeam/render/airlight_image.hpp>

#include <string>
#include <vector>

namespace fogbeam::cli {

/// The shipped config/scenes/bench.toml (an absolute path set by plugin/CMakeLists.txt, defined
/// in cmd_bench.cpp: the one source that gets the path as a compile definition).
extern const char* const kBenchDefaultScene;
/// The shipped config/scenes/traffic.toml (issue 15's moving lamps), the same way.
extern const char* const kBenchTrafficScene;

struct BenchOptions {
  /// --scene: scene file (default: the shipped bench scene).
  std::string scene = kBenchDefaultScene;
  /// --sizes: image sizes as WIDTHxHEIGHT, checked by the run (default 1280x720 and 1920x1080).
  std::vector<std::string> sizes = {"1280x720", "1920x1080"};
  /// --frames: repeated frames per stage (default 5).
  int frames = 5;
  /// --quick: CI mode, overriding sizes, frames, stage budget, view-table step, GPU and aperture
  /// sizes with small values (default off).
  bool quick = false;
  /// --json: also every figure written to this JSON file; empty (default): none.
  std::string jsonPath;
  /// --threads: worker threads; 0 (default): all cores.
  unsigned threads = 0;
  /// --sample-pixels: random pixels for the error figures (default 500).
  int samplePixels = 500;
  /// Seed of those pixels' generator: fixed (no option), so that runs measure the same pixels.
  unsigned seed = 1;
  /// --stage-budget: wall seconds allowed to each airlight stage per size: fewer frames (at least
  /// one) when they do not fit (default 30).
  double stageBudgetSeconds = 30.0;
  /// --max-raymarch-steps: largest ray-marcher step count tried, powers of two from 16 (default 2^14).
  int maxRayMarchSteps = 1 << 14;
  /// --view-table-step: view-table direction spacing, degrees (default: the renderer's, 0.2).
  double viewTableStepDeg = FastPathOptions{}.view_table_step_deg;
  // Issue 7's additions: glow and glare at every size; the GPU airlight path and near-field
  // (aperture) lamps at one size each (llvmpipe runs the GPU path on the CPU: minutes at 720p).
  std::string gpuSize = "160x90";        ///< --gpu-size: WIDTHxHEIGHT of the GPU airlight comparison
  std::string apertureSize = "320x180";  ///< --aperture-size: WIDTHxHEIGHT of the near-field lamps' comparison
  // Issue 15: lamps that move relative to the eye (oncoming traffic), on their own scene.
  std::string trafficScene = kBenchTrafficScene;  ///< --traffic-scene: scene with moving measured lamps
  std::string trafficSize = "1280x720";          ///< --traffic-size: WIDTHxHEIGHT of the traffic drive
  bool onlyTraffic = false;                      ///< --only-traffic: the moving-lamp section alone
  bool onlyPencil = false;                       ///< --only-pencil: of that section, the pencil frames alone
};

/// Runs the benchmark; returns the exit status: 0, 1 when the JSON file cannot be written, 2 on
/// bad input.
int runBench(const BenchOptions& options);

}  // namespace fogbeam::cli
