// `fogbeam profile`: describes a lamp intensity file and optionally charts it (cmd_profile.cpp).
// The options are filled by main.cpp, the one translation unit that includes CLI11 (its option
// names, help texts and checks are there).
#pragma once

#include <string>
#include <vector>

namespace fogbeam::cli {

struct ProfileOptions {
  /// FILE (required): lamp intensity file, .ies, .ldt or .csv.
  std::string file;
  /// --png: false-colour H-V chart written here; empty (default): no chart.
  std::string png;
  /// --size: chart width in pixels (default 1200); the height follows from the ranges.
  int size = 1200;
  /// --h-range: horizontal chart range in degrees, D (for -D..+D) or LO HI (default 45).
  std::vector<double> hRange{45.0};
  /// --v-range: vertical chart range in degrees, D (for -D..+D) or LO HI (default -15 10).
  std::vector<double> vRange{-15.0, 10.0};
};

/// Prints the report (and writes the chart); returns the exit status: 0, or 1 on an error.
int runProfile(const ProfileOptions& o);

}  // namespace fogbeam::cli
