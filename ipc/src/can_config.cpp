// fogbeam — the CAN mapping table (fogbeam/ipc/can_config.hpp), read with the generic TOML
// access of every configuration format (util/toml_section.hpp), so that its errors read like
// theirs: "file:line: [table] key: expected …, found …", unknown keys with a "did you mean".
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/toml_section.hpp>

#include <algorithm>
#include <array>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace fogbeam::ipc {

namespace {

using config::KeySpec;
using config::Section;

// ---- The keys: each one's description is its row in docs/can.md -------------------------------

constexpr std::array kTopKeys{
    KeySpec{"dbc"},
    KeySpec{"hold_s"},
    KeySpec{"fallback"},
    KeySpec{"speed"},
    KeySpec{"lamps"},
};
/// The lamps a mapping can drive, in CanLamp order: the index of a name is its lamp.
constexpr std::array<KeySpec, kCanLampCount> kLampKeys{
    KeySpec{"low_beam"},
    KeySpec{"high_beam"},
    KeySpec{"front_fog"},
    KeySpec{"rear_fog"},
    KeySpec{"indicator_left"},
    KeySpec{"indicator_right"},
};
/// A signal reference { message = "…", signal = "…" }: each [lamps] entry, and `speed`.
constexpr std::array kSignalKeys{
    KeySpec{"message"},
    KeySpec{"signal"},
};
/// What `speed` adds to a signal reference.
constexpr std::array kSpeedExtraKeys{
    KeySpec{"to_m_s"},
};

/// hold_s: a signal silent for over an hour is no longer a dropout to bridge.
constexpr config::Range kHoldRange{0.0, 3600.0, true, false};

/// A string key that must be given and not be empty.
std::string nonEmpty(const Section& s, std::string_view key, const std::string& expected) {
  std::string v = s.string(key, expected);
  if (v.empty()) s.failAt(*s.find(key), key, "expected " + expected + ", found \"\"");
  return v;
}

/// { message = "…", signal = "…" } plus `extraKeys`, which are left to the caller.
CanSignalRef signalRef(const Section& s, std::span<const KeySpec> extraKeys = {}) {
  s.checkKeys(kSignalKeys, extraKeys);
  CanSignalRef ref;
  ref.message = nonEmpty(s, "message", "a message name of the DBC");
  ref.signal = nonEmpty(s, "signal", "a signal name of the DBC");
  return ref;
}

CanConfig parseRoot(const toml::table& root, const std::string& file, const std::string& baseDir) {
  const Section top(file, root, "");
  top.checkKeys(kTopKeys);
  CanConfig c;
  c.file = file;
  c.dbc_path = resolvePath(baseDir, nonEmpty(top, "dbc", "the path of a DBC file"));
  c.mapping.hold_s = top.number("hold_s", kHoldRange, c.mapping.hold_s);
  if (const auto names = top.optStrings("fallback")) {
    for (std::size_t i = 0; i < names->size(); ++i) {
      const auto it = std::find_if(kLampKeys.begin(), kLampKeys.end(),
                                   [&](const KeySpec& k) { return k.name == (*names)[i]; });
      if (it == kLampKeys.end()) {
        std::string expected;
        for (std::size_t k = 0; k < kLampKeys.size(); ++k)
          expected += (k == 0 ? "" : k + 1 == kLampKeys.size() ? " or " : ", ") + config::inQuotes(kLampKeys[k].name);
        top.failAt(*top.find("fallback")->as_array()->get(i), "fallback[" + std::to_string(i) + "]",
                   "expected a lamp name, " + expected + ", found " + config::inQuotes((*names)[i]));
      }
      c.mapping.fallback_lights |= kCanLampBits[static_cast<std::size_t>(it - kLampKeys.begin())];
    }
  }
  if (const toml::table* t = top.optTable("speed")) {
    const Section s(file, *t, "[speed]");
    c.mapping.speed = signalRef(s, kSpeedExtraKeys);
    c.speed_line = s.line();
    c.mapping.speed_to_m_s = s.number("to_m_s", config::kPositive, c.mapping.speed_to_m_s);
  }
  if (const toml::table* t = top.optTable("lamps")) {
    const Section lamps(file, *t, "[lamps]");
    lamps.checkKeys(kLampKeys);
    for (std::size_t i = 0; i < kLampKeys.size(); ++i) {
      const std::string name(kLampKeys[i].name);
      if (const toml::table* l = lamps.optTable(name)) {
        const Section entry(file, *l, "[lamps." + name + "]");
        c.mapping.lamps[i] = signalRef(entry);
        c.lamp_lines[i] = entry.line();
      }
    }
  }
  return c;
}

}  // namespace

Result<CanConfig> parseCanConfig(std::string_view text, const std::string& fileName, const std::string& baseDir) {
  return config::parseTomlFile<CanConfig>(text, fileName,
                                          [&](const toml::table& root) { return parseRoot(root, fileName, baseDir); });
}

Result<CanConfig> loadCanConfig(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return text.error();
  return parseCanConfig(*text, path, std::filesystem::path(path).parent_path().string());
}

Result<CanDecoder> makeDecoder(const CanConfig& config) {
  auto dbc = loadDbc(config.dbc_path);
  if (!dbc) return dbc.error();
  // Each signal against the DBC first, so that a name it lacks is reported where the mapping
  // file names it (the DBC's message says which file it is and lists what it has).
  if (!config.file.empty()) {
    auto check = [&](const std::optional<CanSignalRef>& ref, std::size_t line, const std::string& key) -> Status {
      if (!ref) return Ok{};
      auto sig = dbc->signal(ref->message, ref->signal);
      if (!sig) return fileError(config.file, line, key + ": " + sig.error().message);
      return Ok{};
    };
    for (std::size_t i = 0; i < kLampKeys.size(); ++i) {
      if (Status s = check(config.mapping.lamps[i], config.lamp_lines[i], "[lamps] " + std::string(kLampKeys[i].name)); !s)
        return s.error();
    }
    if (Status s = check(config.mapping.speed, config.speed_line, "speed"); !s) return s.error();
  }
  auto d = CanDecoder::create(*dbc, config.mapping);
  if (!d) return Error{"CAN mapping against " + config.dbc_path + ": " + d.error().message};
  return d;
}

std::vector<config::KeyTable> canConfigKeyTables() {
  using config::keyNames;
  return {
      {"can.md", "Top level", "CAN mapping: top level", keyNames({kTopKeys})},
      {"can.md", "Signals: `{ message, signal }`", "CAN mapping [lamps.*] entries, and speed beside to_m_s",
       keyNames({kSignalKeys})},
      {"can.md", "`speed`", "CAN mapping speed, beside the signal keys", keyNames({kSpeedExtraKeys})},
      {"can.md", "`[lamps]`", "CAN mapping [lamps]", keyNames({kLampKeys})},
  };
}

}  // namespace fogbeam::ipc
