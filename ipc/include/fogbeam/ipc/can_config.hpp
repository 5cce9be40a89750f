// fogbeam — the CAN mapping as a TOML file (docs/can.md): which DBC file, which message and
// signal mean which lamp and the speed, the hold time and the fallback. The service config names
// it (`[input.can] mapping`), and so does `fogbeam send --can-config`:
//
//   dbc = "vehicle.dbc"                    # relative to the file that names it
//   hold_s = 0.5                           # s, > 0
//   fallback = ["low_beam"]                # lamps that are ON when their signal is silent
//   speed = { message = "SPEED", signal = "SPEED", to_m_s = 0.2777777778 }
//   [lamps]                                # any of: low_beam, high_beam, front_fog, rear_fog,
//   low_beam = { message = "LIGHT_STALK", signal = "LOW_BEAM" }   #  indicator_left, indicator_right
//
// It is read like every configuration format (util/toml_section.hpp): unknown keys (with a "did
// you mean") and wrong types are errors with file, line, table, key and what was expected; names
// the DBC lacks are errors of makeDecoder() that list what the DBC has.
//
// Thread-safety: plain functions and values; parsing is reentrant.
#pragma once

#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/util/key_table.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::ipc {

struct CanConfig {
  std::string dbc_path;  ///< resolved against the configuration file's directory
  CanMapping mapping;
  /// Where each signal was named, for makeDecoder()'s errors: the mapping file ("" for a
  /// configuration built in code) and the line of each [lamps] entry (by CanLamp) and of
  /// `speed` (0 = not named).
  std::string file;
  std::array<std::size_t, kCanLampCount> lamp_lines{};
  std::size_t speed_line = 0;
};

/// Parses the table in `text` (`fileName` for messages, `baseDir` for the DBC path).
[[nodiscard]] Result<CanConfig> parseCanConfig(std::string_view text, const std::string& fileName,
                                               const std::string& baseDir);
[[nodiscard]] Result<CanConfig> loadCanConfig(const std::string& path);
/// Loads the DBC a configuration names and builds the decoder. A message or signal the DBC
/// lacks is an error that names the mapping file, the line, the table and the key that name it,
/// then the DBC file and what it has ("map.toml:8: [lamps] low_beam: vehicle.dbc: no signal …").
[[nodiscard]] Result<CanDecoder> makeDecoder(const CanConfig& config);

/// The mapping's key tables in docs/can.md (config::KeyTable): the top level, the signal keys of
/// a [lamps] entry and of `speed`, what `speed` adds, and [lamps].
[[nodiscard]] std::vector<config::KeyTable> canConfigKeyTables();

}  // namespace fogbeam::ipc
