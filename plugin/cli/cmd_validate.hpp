// `fogbeam validate`: the three airlight methods against a reference, as a table
// (cmd_validate.cpp). The options are filled by main.cpp, the one translation unit that includes
// CLI11 (its option names, help texts and checks are there).
#pragma once

#include <fogbeam/physics/airlight.hpp>

#include <string>
#include <vector>

namespace fogbeam::cli {

struct ValidateOptions {
  /// --vectors: CSV of rays, lamps and fogs with expected airlight (columns as
  /// tests/data/airlight_vectors.csv). Empty (default): the built-in sweep, against the
  /// reference method.
  std::string vectors;
  /// --out: CSV written with one row per case and method; empty (default): none.
  std::string out;
  /// --methods: the methods run, by name (parseAirlightMethod); default all three.
  std::vector<std::string> methods{"seed", "accurate", "reference"};
  /// --headlamp: sweep only: headlamp profile file (.ies/.ldt/.csv); empty (default): the
  /// built-in low beam.
  std::string headlamp;
  /// --rays: sweep only: rays per situation (default 24).
  int rays = 24;
  /// --segments: accurate method: quadratic pieces per ray for tabulated profiles (default:
  /// the library's, 48).
  int segments = AirlightOptions{}.accurate_segments;
  /// false with --no-additions: skip the checks of issue 7's additions (default: run them).
  bool additions = true;
};

/// Runs the validation; returns the exit status: 0, 1 when a bound is missed, 2 on bad input.
int runValidate(const ValidateOptions& o);

}  // namespace fogbeam::cli
