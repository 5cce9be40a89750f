// fogbeam — the CAN mapping table (fogbeam/ipc/can_config.hpp).
#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/util/files.hpp>

#include <toml++/toml.h>

#include <array>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fogbeam::ipc {

namespace {

constexpr std::array<std::string_view, kCanLampCount> kLampKeys{"low_beam",  "high_beam",      "front_fog",
                                                                "rear_fog",  "indicator_left", "indicator_right"};

std::size_t lineOf(const toml::node& n) { return static_cast<std::size_t>(n.source().begin.line); }

struct Reader {
  const std::string& file;
  Error at(const toml::node& n, const std::string& what) const { return fileError(file, lineOf(n), what); }
  Error at(std::size_t line, const std::string& what) const { return fileError(file, line, what); }
};

// { message = "…", signal = "…" } (plus `extra` keys allowed).
Result<CanSignalRef> signalRef(const Reader& r, const toml::node& n, const std::string& key,
                               std::initializer_list<std::string_view> extra = {}) {
  const auto* t = n.as_table();
  if (!t) return r.at(n, key + ": expected a table { message = \"…\", signal = \"…\" }");
  for (const auto& [k, v] : *t) {
    const std::string_view name = k.str();
    if (name == "message" || name == "signal" || std::find(extra.begin(), extra.end(), name) != extra.end()) continue;
    return r.at(v, key + ": unknown key '" + std::string(name) + "' (expected message, signal" +
                       (extra.size() ? ", " + std::string(*extra.begin()) : std::string()) + ")");
  }
  CanSignalRef ref;
  for (auto [field, out] : {std::pair<const char*, std::string*>{"message", &ref.message}, {"signal", &ref.signal}}) {
    const toml::node* f = t->get(field);
    if (!f) return r.at(n, key + "." + field + ": missing (expected a string)");
    const auto* s = f->as_string();
    if (!s || s->get().empty()) return r.at(*f, key + "." + field + ": expected a non-empty string");
    *out = s->get();
  }
  return ref;
}

}  // namespace

Result<CanConfig> parseCanConfig(std::string_view text, const std::string& fileName, const std::string& baseDir) {
  toml::table root;
  try {
    root = toml::parse(text, fileName);
  } catch (const toml::parse_error& e) {
    return fileError(fileName, static_cast<std::size_t>(e.source().begin.line),
                     "TOML syntax: " + std::string(e.description()));
  }
  const Reader r{fileName};
  CanConfig c;
  for (const auto& [k, v] : root) {
    const std::string_view key = k.str();
    if (key != "dbc" && key != "hold_s" && key != "fallback" && key != "speed" && key != "lamps")
      return r.at(v, "unknown key '" + std::string(key) + "' (expected dbc, hold_s, fallback, speed, lamps)");
  }
  const toml::node* dbc = root.get("dbc");
  if (!dbc) return r.at(1, "dbc: missing (expected the path of a DBC file)");
  if (const auto* s = dbc->as_string(); s && !s->get().empty()) {
    std::filesystem::path p(s->get());
    c.dbc_path = p.is_absolute() ? p.string() : (std::filesystem::path(baseDir) / p).lexically_normal().string();
  } else {
    return r.at(*dbc, "dbc: expected a non-empty string (a path)");
  }
  if (const toml::node* h = root.get("hold_s")) {
    const auto v = h->value<double>();
    if (!v || !(*v > 0.0) || *v > 3600.0) return r.at(*h, "hold_s: expected a number of seconds in (0, 3600]");
    c.mapping.hold_s = *v;
  }
  if (const toml::node* f = root.get("fallback")) {
    const auto* a = f->as_array();
    if (!a) return r.at(*f, "fallback: expected an array of lamp names");
    for (const toml::node& e : *a) {
      const auto* s = e.as_string();
      const auto it = s ? std::find(kLampKeys.begin(), kLampKeys.end(), s->get()) : kLampKeys.end();
      if (it == kLampKeys.end())
        return r.at(e, "fallback: expected lamp names (low_beam, high_beam, front_fog, rear_fog, indicator_left, "
                       "indicator_right)");
      c.mapping.fallback_lights |= kCanLampBits[static_cast<std::size_t>(it - kLampKeys.begin())];
    }
  }
  if (const toml::node* s = root.get("speed")) {
    auto ref = signalRef(r, *s, "speed", {"to_m_s"});
    if (!ref) return ref.error();
    c.mapping.speed = *ref;
    if (const toml::node* f = s->as_table()->get("to_m_s")) {
      const auto v = f->value<double>();
      if (!v || !(*v > 0.0)) return r.at(*f, "speed.to_m_s: expected a number > 0 (1/3.6 for km/h)");
      c.mapping.speed_to_m_s = *v;
    }
  }
  if (const toml::node* l = root.get("lamps")) {
    const auto* t = l->as_table();
    if (!t) return r.at(*l, "lamps: expected a table");
    for (const auto& [k, v] : *t) {
      const auto it = std::find(kLampKeys.begin(), kLampKeys.end(), k.str());
      if (it == kLampKeys.end())
        return r.at(v, "lamps: unknown lamp '" + std::string(k.str()) +
                           "' (expected low_beam, high_beam, front_fog, rear_fog, indicator_left, indicator_right)");
      auto ref = signalRef(r, v, "lamps." + std::string(k.str()));
      if (!ref) return ref.error();
      c.mapping.lamps[static_cast<std::size_t>(it - kLampKeys.begin())] = *ref;
    }
  }
  return c;
}

Result<CanConfig> loadCanConfig(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return text.error();
  return parseCanConfig(*text, path, std::filesystem::path(path).parent_path().string());
}

Result<CanDecoder> makeDecoder(const CanConfig& config) {
  auto dbc = loadDbc(config.dbc_path);
  if (!dbc) return dbc.error();
  auto d = CanDecoder::create(*dbc, config.mapping);
  if (!d) return Error{"CAN mapping against " + config.dbc_path + ": " + d.error().message};
  return d;
}

}  // namespace fogbeam::ipc
