// fogbeam — the CAN mapping as a TOML table (docs/can.md): which DBC file, which message and
// signal mean which lamp and the speed, the hold time and the fallback. The same table is the
// `[can]` section of the service configuration (issue 5); a standalone file works too:
//
//   dbc = "vehicle.dbc"                    # relative to the file that names it
//   hold_s = 0.5                           # s, > 0
//   fallback = ["low_beam"]                # lamps that are ON when their signal is silent
//   speed = { message = "SPEED", signal = "SPEED", to_m_s = 0.2777777778 }
//   [lamps]                                # any of: low_beam, high_beam, front_fog, rear_fog,
//   low_beam = { message = "LIGHT_STALK", signal = "LOW_BEAM" }   #  indicator_left, indicator_right
//
// Unknown keys, wrong types and names the DBC lacks are errors with file, line and what was
// expected.
#pragma once

#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/util/result.hpp>

#include <string>
#include <string_view>

namespace fogbeam::ipc {

struct CanConfig {
  std::string dbc_path;  ///< resolved against the configuration file's directory
  CanMapping mapping;
};

/// Parses the table in `text` (`fileName` for messages, `baseDir` for the DBC path).
[[nodiscard]] Result<CanConfig> parseCanConfig(std::string_view text, const std::string& fileName,
                                               const std::string& baseDir);
[[nodiscard]] Result<CanConfig> loadCanConfig(const std::string& path);
/// Loads the DBC a configuration names and builds the decoder (errors name the config file).
[[nodiscard]] Result<CanDecoder> makeDecoder(const CanConfig& config);

}  // namespace fogbeam::ipc
