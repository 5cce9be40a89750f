// `fogbeam tables`: estimates a multiple-scattering table for one phase function and writes it
// (fogbeam/physics/multiple_scattering.hpp), or with --ground the ground's factor on it
// (fogbeam/physics/ground_correction.hpp; the shipped tables in config/multiple_scattering/ were
// written by scripts/multiple_scattering_tables.sh with this command). The options are filled by
// main.cpp, the one translation unit that includes CLI11.
#pragma once

#include <cstdint>
#include <string>

namespace fogbeam::cli {

struct TablesOptions {
  /// --phase: "henyey-greenstein" (default), "fog-mie" or "isotropic".
  std::string phase = "henyey-greenstein";
  /// --g: HG asymmetry (henyey-greenstein only).
  double g = 0.85;
  /// --droplet-diameter: µm (fog-mie only).
  double dropletDiameter_um = 10.0;
  /// --paths, --seed: Monte Carlo paths and seed (MultipleScatteringOptions).
  std::uint64_t paths = 80000;
  std::uint64_t seed = 1;
  /// --threads: 0 = all hardware threads.
  unsigned threads = 0;
  /// --out (required): the table file.
  std::string out;
  /// --ground: estimate the ground's factor on the shipped multiple-scattering table of the phase
  /// function instead (fogbeam/physics/ground_correction.hpp; --paths per optical distance,
  /// reflectance and ring).
  bool ground = false;
};

/// Builds and writes the table, prints its figures; returns 0, or 1 on an error.
int runTables(const TablesOptions& o);

}  // namespace fogbeam::cli
