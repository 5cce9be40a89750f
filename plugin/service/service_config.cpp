// fogbeam — the service configuration (service_config.hpp, docs/service.md).
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/scene/sections.hpp>
#include <fogbeam/util/files.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <sstream>
#include <utility>
#include <vector>

#include "builtin_service_config.hpp"  // generated: kBuiltinServiceConfig (config/service/default.toml)

namespace fogbeam::plugin {

namespace {

namespace fs = std::filesystem;
using config::KeySpec;
using config::Range;
using config::Section;

constexpr std::array kTopKeys{
    KeySpec{"world"},
    KeySpec{"fog"},
    KeySpec{"render"},
    KeySpec{"glow"},
    KeySpec{"glare"},
    KeySpec{"timing"},
    KeySpec{"status"},
    KeySpec{"input"},
    KeySpec{"channel"},
    KeySpec{"ego"},
    KeySpec{"traffic_class"},
};
constexpr std::array kWorldKeys{
    KeySpec{"scene"},
    KeySpec{"scenario"},
    KeySpec{"scenario_loop"},
};
/// The service's own [render] keys; the table also takes the scene's [render] keys
/// (config::renderKeys(): airlight, gpu_pieces).
constexpr std::array kRenderKeys{
    KeySpec{"method"},
    KeySpec{"subsampling"},
    KeySpec{"view_table_step_deg"},
    KeySpec{"moving_lamps"},
    KeySpec{"moving_lamp_cutoff_cd_m2"},
    KeySpec{"max_moving_lamps"},
    KeySpec{"surface"},
    KeySpec{"threads"},
    KeySpec{"table_cache"},
    KeySpec{"pending_tables"},
    KeySpec{"table_adopt_frames"},
    KeySpec{"fog_ladder_ratio"},
    KeySpec{"fog_ladder_rungs"},
    KeySpec{"fog_ladder_adopt_frames"},
    KeySpec{"bending_ladder_step_deg"},
    KeySpec{"bending_ladder_rungs"},
    KeySpec{"overlap_frames"},
};
constexpr std::array kTimingKeys{
    KeySpec{"mode"},
    KeySpec{"rate_hz"},
};
constexpr std::array kStatusKeys{
    KeySpec{"interval_s"},
    KeySpec{"udp_port"},
};
constexpr std::array kInputKeys{
    KeySpec{"udp"},
    KeySpec{"can"},
};
constexpr std::array kUdpKeys{
    KeySpec{"bind"},
    KeySpec{"port"},
    KeySpec{"multicast"},
    KeySpec{"allow"},
    KeySpec{"traffic_timeout_s"},
    KeySpec{"max_traffic_objects"},
};
constexpr std::array kCanKeys{
    KeySpec{"source"},
    KeySpec{"interface"},
    KeySpec{"candump"},
    KeySpec{"candump_speed"},
    KeySpec{"cannelloni_port"},
    KeySpec{"mapping"},
};
constexpr std::array kChannelKeys{
    KeySpec{"name"},
    KeySpec{"width"},
    KeySpec{"height"},
    KeySpec{"fov_x_deg"},
    KeySpec{"frustum_deg"},
    KeySpec{"eye_offset_m"},
    KeySpec{"yaw_deg"},
    KeySpec{"pitch_deg"},
    KeySpec{"roll_deg"},
    KeySpec{"format"},
    KeySpec{"distance"},
    KeySpec{"exposure_ev"},
    KeySpec{"depth_from"},
};
constexpr std::array kEgoKeys{
    KeySpec{"eye_m"},
    KeySpec{"bending_max_deg"},
    KeySpec{"bending_tolerance_deg"},
    KeySpec{"lamp"},
    KeySpec{"bonnet"},
};
// [ego.bonnet]: the scene's [bonnet] keys and `enabled` (a layer can switch off the bonnet a
// lower layer, such as the built-in configuration, gave).
constexpr std::array kBonnetServiceKeys{
    KeySpec{"enabled"},
};
constexpr std::array kClassKeys{
    KeySpec{"class"},
    KeySpec{"name"},
    KeySpec{"lamp"},
};
constexpr std::array kRigLampExtraKeys{
    KeySpec{"role"},
    KeySpec{"bending"},
};

constexpr std::array<std::pair<std::string_view, std::uint32_t>, 8> kRoles{{
    {"low-beam", ipc::light::kLowBeam},
    {"high-beam", ipc::light::kHighBeam},
    {"front-fog", ipc::light::kFrontFog},
    {"rear-fog", ipc::light::kRearFog},
    {"position", ipc::light::kPosition},
    {"brake", ipc::light::kBrake},
    {"drl", ipc::light::kDrl},
    {"always", 0u},
}};

std::string pathOf(const Section& s, std::string_view key, const std::string& baseDir, bool mustExist) {
  const std::string given = s.string(key, "a path");
  if (given.empty()) return {};
  const std::string path = resolvePath(baseDir, given);
  if (mustExist) {
    if (std::string problem = checkFile(path); !problem.empty()) s.failAt(*s.find(key), key, problem);
  }
  return path;
}

/// [[channel]] exposure_ev: "auto" or an EV in [−20, 20]. Left out: "auto" on rgba8-srgb
/// channels of fogbeam's own view, 0 on the others (their EV is fixed: the linear formats have
/// none, and a depth_from channel decodes the host's colour at it). Needs format and depth_from.
void parseExposure(const Section& s, ChannelConfig& ch) {
  constexpr Range kEv{-20.0, 20.0};
  const bool autoAllowed = ch.format == "rgba8-srgb" && ch.depth_from.empty();
  ch.exposure_ev = 0.0;
  ch.exposure_auto = autoAllowed;
  const toml::node* n = s.find("exposure_ev");
  if (!n) return;
  const std::string expected = "expected \"auto\" or " + kEv.expectation() + " (EV), found " + config::describeNode(*n);
  if (const auto* text = n->as_string()) {
    if (text->get() != "auto") s.failAt(*n, "exposure_ev", expected);
    if (ch.format != "rgba8-srgb")
      s.failAt(*n, "exposure_ev", "\"auto\" applies to rgba8-srgb channels only, and format = " + config::inQuotes(ch.format));
    if (!ch.depth_from.empty())
      s.failAt(*n, "exposure_ev",
               "expected a number with depth_from: the host's colour is decoded at the channel's exposure, which must "
               "be fixed, found \"auto\"");
    ch.exposure_auto = true;
    return;
  }
  double ev = std::nan("");
  if (const auto* f = n->as_floating_point()) ev = f->get();
  if (const auto* i = n->as_integer()) ev = static_cast<double>(i->get());
  if (!kEv.contains(ev)) s.failAt(*n, "exposure_ev", expected);
  ch.exposure_ev = ev;
  ch.exposure_auto = false;
}

std::uint16_t portOf(const Section& s, std::string_view key, std::uint16_t fallback) {
  return static_cast<std::uint16_t>(s.integer(key, 0, 65535, fallback));
}

/// A lamp table as TOML text with its profile path resolved (for --print-config).
std::string definitionOf(const toml::table& t, const std::string& baseDir) {
  toml::table copy = t;
  if (const auto* p = copy.get_as<std::string>("profile")) {
    const std::string v = p->get();
    if (v != "isotropic" && v != "spot") copy.insert_or_assign("profile", resolvePath(baseDir, v));
  }
  std::ostringstream out;
  out << toml::toml_formatter(copy);
  return out.str();
}

VehicleRig parseRig(const Section& s, const std::string& baseDir, bool ego) {
  VehicleRig rig;
  config::ProfileCache cache;
  std::set<std::string, std::less<>> names;
  s.forEachEntry("lamp", [&](const toml::table& t, std::string label, std::size_t ordinal) {
    const Section l(s.file(), t, std::move(label));
    RigLamp r;
    r.lamp = config::parseLamp(l, ordinal, baseDir, cache, kRigLampExtraKeys);
    l.forbid("mount", "rig lamps are always mounted on their vehicle");
    r.lamp.mount = LampMount::Vehicle;
    std::array<std::string_view, kRoles.size()> roles{};
    for (std::size_t i = 0; i < kRoles.size(); ++i) roles[i] = kRoles[i].first;
    r.role = l.choice("role", roles, "");
    if (r.role.empty()) l.missing("role", "one of low-beam, high-beam, front-fog, rear-fog, position, brake, drl, always");
    r.light_bit = std::find_if(kRoles.begin(), kRoles.end(), [&](const auto& p) { return p.first == r.role; })->second;
    if (!ego) l.forbid("bending", "only the ego's lamps bend");
    r.bending = l.boolean("bending", false);
    if (!names.insert(r.lamp.name).second) {
      l.fail(l.line(), "name", "expected a unique lamp name, found " + config::inQuotes(r.lamp.name) + " again");
    }
    r.definition = definitionOf(t, baseDir);
    rig.lamps.push_back(std::move(r));
  });
  return rig;
}

void applyRoot(ServiceConfig& c, const toml::table& root, const std::string& name, const std::string& baseDir) {
  const Section top(name, root, "");
  top.checkKeys(kTopKeys);
  if (const toml::table* t = top.optTable("world")) {
    const Section s(name, *t, "[world]");
    s.checkKeys(kWorldKeys);
    if (s.find("scene")) c.scene_path = pathOf(s, "scene", baseDir, true);
    if (s.find("scenario")) c.scenario_path = pathOf(s, "scenario", baseDir, true);
    c.scenario_loop = s.boolean("scenario_loop", c.scenario_loop);
  }
  if (const toml::table* t = top.optTable("fog")) {
    const Section s(name, *t, "[fog]");
    c.fog = config::parseFog(s);
    std::ostringstream out;
    out << toml::toml_formatter(*t);
    c.fog_text = out.str();
  }
  if (const toml::table* t = top.optTable("render")) {
    const Section s(name, *t, "[render]");
    // airlight and gpu_pieces: the scene's [render] keys, parsed by the scene's code.
    c.effects.render = config::parseRenderSettings(s, c.effects.render, kRenderKeys);
    const std::array<std::string_view, 3> methods{"accurate", "seed", "reference"};
    c.method = s.choice("method", methods, c.method);
    c.subsampling = s.boolean("subsampling", c.subsampling);
    c.view_table_step_deg = s.number("view_table_step_deg", Range{0.05, 5.0}, c.view_table_step_deg);
    const std::array<std::string_view, 3> moving{"pencil", "map", "per-ray"};
    c.moving_lamps = s.choice("moving_lamps", moving, c.moving_lamps);
    c.moving_lamp_cutoff_cd_m2 = s.number("moving_lamp_cutoff_cd_m2", Range{0.0, 1.0}, c.moving_lamp_cutoff_cd_m2);
    c.max_moving_lamps = static_cast<int>(s.integer("max_moving_lamps", 0, 100000, c.max_moving_lamps));
    const std::array<std::string_view, 3> surfaces{"auto", "gl", "cpu"};
    c.surface = s.choice("surface", surfaces, c.surface);
    c.threads = static_cast<unsigned>(s.integer("threads", 0, 256, c.threads));
    if (const toml::node* n = s.find("table_cache")) {
      c.table_cache = s.string("table_cache", "expected \"auto\", \"off\" or a directory");
      if (c.table_cache.empty()) s.failAt(*n, "table_cache", "expected \"auto\", \"off\" or a directory, found \"\"");
    }
    const std::array<std::string_view, 2> pending{"per-pixel", "previous"};
    c.pending_tables = s.choice("pending_tables", pending, c.pending_tables);
    c.table_adopt_frames = static_cast<int>(s.integer("table_adopt_frames", 1, 100000, c.table_adopt_frames));
    c.fog_ladder_ratio = s.number("fog_ladder_ratio", Range{0.0, 2.0}, c.fog_ladder_ratio);
    if (c.fog_ladder_ratio != 0.0 && c.fog_ladder_ratio < 1.05)
      s.failAt(*s.find("fog_ladder_ratio"), "fog_ladder_ratio",
               "expected 0 (off) or a ratio in [1.05, 2], found " + std::to_string(c.fog_ladder_ratio));
    c.fog_ladder_rungs = static_cast<int>(s.integer("fog_ladder_rungs", 2, 64, c.fog_ladder_rungs));
    c.fog_ladder_adopt_frames =
        static_cast<int>(s.integer("fog_ladder_adopt_frames", 1, 100000, c.fog_ladder_adopt_frames));
    c.bending_ladder_step_deg = s.number("bending_ladder_step_deg", Range{0.0, 5.0}, c.bending_ladder_step_deg);
    if (c.bending_ladder_step_deg != 0.0 && c.bending_ladder_step_deg < 0.1)
      s.failAt(*s.find("bending_ladder_step_deg"), "bending_ladder_step_deg",
               "expected 0 (off) or a step in [0.1, 5] degrees, found " + std::to_string(c.bending_ladder_step_deg));
    c.bending_ladder_rungs = static_cast<int>(s.integer("bending_ladder_rungs", 2, 64, c.bending_ladder_rungs));
    const std::array<std::string_view, 3> overlap{"auto", "on", "off"};
    c.overlap_frames = s.choice("overlap_frames", overlap, c.overlap_frames);
  }
  // [glow] and [glare]: the scene's tables, parsed by the scene's code. As in a scene file the
  // table's presence turns its effect on unless it says `enabled = false`; its other keys keep
  // the lower layer's value when left out (so `--set glare.age_years=60` turns glare on, for a
  // 60-year-old driver).
  if (const toml::table* t = top.optTable("glow"))
    c.effects.glow = config::parseGlow(Section(name, *t, "[glow]"), c.effects.glow);
  if (const toml::table* t = top.optTable("glare"))
    c.effects.glare = config::parseGlare(Section(name, *t, "[glare]"), c.effects.glare);
  if (const toml::table* t = top.optTable("timing")) {
    const Section s(name, *t, "[timing]");
    s.checkKeys(kTimingKeys);
    const std::array<std::string_view, 2> modes{"free-running", "lock-step"};
    c.lock_step = s.choice("mode", modes, c.lock_step ? "lock-step" : "free-running") == "lock-step";
    c.rate_hz = s.number("rate_hz", Range{0.0, 1000.0, true, false}, c.rate_hz);
  }
  if (const toml::table* t = top.optTable("status")) {
    const Section s(name, *t, "[status]");
    s.checkKeys(kStatusKeys);
    c.status_interval_s = s.number("interval_s", Range{0.1, 3600.0}, c.status_interval_s);
    c.status_udp_port = portOf(s, "udp_port", c.status_udp_port);
  }
  if (const toml::table* in = top.optTable("input")) {
    const Section is(name, *in, "[input]");
    is.checkKeys(kInputKeys);
    if (const toml::table* t = is.optTable("udp")) {
      const Section s(name, *t, "[input.udp]");
      s.checkKeys(kUdpKeys);
      c.udp_bind = s.optString("bind").value_or(c.udp_bind);
      c.udp_port = portOf(s, "port", c.udp_port);
      c.udp_multicast = s.optString("multicast").value_or(c.udp_multicast);
      if (auto allow = s.optStrings("allow")) c.udp_allow = *allow;
      c.traffic_timeout_s = s.number("traffic_timeout_s", Range{0.0, 60.0, true, false}, c.traffic_timeout_s);
      c.max_traffic_objects = static_cast<std::size_t>(
          s.integer("max_traffic_objects", 1, static_cast<std::int64_t>(kMaxTrafficObjectsLimit),
                    static_cast<std::int64_t>(c.max_traffic_objects)));
    }
    if (const toml::table* t = is.optTable("can")) {
      const Section s(name, *t, "[input.can]");
      s.checkKeys(kCanKeys);
      const std::array<std::string_view, 4> sources{"none", "interface", "candump", "cannelloni"};
      c.can_source = s.choice("source", sources, c.can_source);
      c.can_interface = s.optString("interface").value_or(c.can_interface);
      if (s.find("candump")) c.can_candump = pathOf(s, "candump", baseDir, true);
      c.can_candump_speed = s.number("candump_speed", Range{0.0, 100.0, true, false}, c.can_candump_speed);
      c.can_cannelloni_port = portOf(s, "cannelloni_port", c.can_cannelloni_port);
      if (s.find("mapping")) c.can_mapping_path = pathOf(s, "mapping", baseDir, true);
    }
  }
  if (top.find("channel")) {
    c.channels.clear();
    top.forEachEntry("channel", [&](const toml::table& t, std::string label, std::size_t) {
      const Section s(name, t, std::move(label));
      s.checkKeys(kChannelKeys);
      ChannelConfig ch;
      ch.name = s.string("name", "a channel name");
      // The shared-memory segment's rule (docs/shm.md), checked here so that a bad name fails with
      // the file and line rather than when the service creates the channel.
      if (!ipc::validChannelName(ch.name))
        s.failAt(*s.find("name"), "name",
                 "expected 1–" + std::to_string(ipc::kMaxChannelName) + " letters, digits, '_', '-' or '.', found " +
                     config::inQuotes(ch.name));
      ch.width = static_cast<int>(s.integer("width", 1, 16384, ch.width));
      ch.height = static_cast<int>(s.integer("height", 1, 16384, ch.height));
      ch.fov_x_deg = s.number("fov_x_deg", Range{0.0, 180.0, true, true}, ch.fov_x_deg);
      if (const auto f = s.optNumbers("frustum_deg", 4, Range{-89.0, 89.0, true, true})) {
        if (const toml::node* fov = s.find("fov_x_deg")) {
          s.failAt(*fov, "fov_x_deg", "give fov_x_deg or frustum_deg, not both");
        }
        const FrustumAngles a{radians((*f)[0]), radians((*f)[1]), radians((*f)[2]), radians((*f)[3])};
        auto cam = Camera::fromFrustum(a, ch.width, 0);
        if (!cam) s.failAt(*s.find("frustum_deg"), "frustum_deg", cam.error().message);
        if (s.find("height") && std::abs(cam->height - ch.height) > 0) {
          s.failAt(*s.find("height"), "height",
                   "expected " + std::to_string(cam->height) + " (square pixels for frustum_deg and width) or no height, found " +
                       std::to_string(ch.height));
        }
        ch.height = cam->height;
        ch.frustum_deg = std::array<double, 4>{(*f)[0], (*f)[1], (*f)[2], (*f)[3]};
      }
      ch.eye_offset_m = optVec3(s, "eye_offset_m").value_or(ch.eye_offset_m);
      ch.yaw_deg = s.number("yaw_deg", config::kAnyFinite, 0.0);
      ch.pitch_deg = s.number("pitch_deg", config::kAnyFinite, 0.0);
      ch.roll_deg = s.number("roll_deg", config::kAnyFinite, 0.0);
      const std::array<std::string_view, 3> formats{"rgba8-srgb", "rgba16f-linear", "rgba16f-overlay"};
      ch.format = s.choice("format", formats, ch.format);
      ch.distance = s.boolean("distance", false);
      if (const auto from = s.optString("depth_from")) {
        if (!ipc::validChannelName(*from))
          s.failAt(*s.find("depth_from"), "depth_from",
                   "expected a host depth channel name: 1–" + std::to_string(ipc::kMaxChannelName) +
                       " letters, digits, '_', '-' or '.', found " + config::inQuotes(*from));
        ch.depth_from = *from;
      }
      parseExposure(s, ch);
      for (const ChannelConfig& other : c.channels) {
        if (other.name == ch.name) s.failAt(*s.find("name"), "name", "expected a unique name, found " + config::inQuotes(ch.name) + " again");
      }
      c.channels.push_back(ch);
    });
  }
  if (const toml::table* t = top.optTable("ego")) {
    const Section s(name, *t, "[ego]");
    s.checkKeys(kEgoKeys);
    c.eye_m = optVec3(s, "eye_m").value_or(c.eye_m);
    c.bending_max_deg = s.number("bending_max_deg", Range{0.0, 45.0}, c.bending_max_deg);
    c.bending_tolerance_deg = s.number("bending_tolerance_deg", Range{0.0, 5.0}, c.bending_tolerance_deg);
    if (s.find("lamp")) c.ego = parseRig(s, baseDir, true);
    c.ego.name = "ego";
    if (const toml::table* b = s.optTable("bonnet")) {
      const Section bs(name, *b, "[ego.bonnet]");
      const Bonnet parsed = config::parseBonnet(bs, kBonnetServiceKeys);
      if (bs.boolean("enabled", true)) c.bonnet = parsed;
      else c.bonnet.reset();
    }
  }
  if (top.find("traffic_class")) {
    c.traffic.clear();
    top.forEachEntry("traffic_class", [&](const toml::table& t, std::string label, std::size_t) {
      const Section s(name, t, std::move(label));
      s.checkKeys(kClassKeys);
      const auto cls = static_cast<std::uint16_t>(s.integer("class", 0, 65535));
      VehicleRig rig = parseRig(s, baseDir, false);
      rig.name = s.optString("name").value_or("class " + std::to_string(cls));
      if (!c.traffic.emplace(cls, std::move(rig)).second) {
        s.failAt(*s.find("class"), "class", "expected a unique class, found " + std::to_string(cls) + " again");
      }
    });
  }
}

std::string quoted(const std::string& s) {
  std::ostringstream out;
  out << toml::value<std::string>(s);
  return out.str();
}

}  // namespace

Camera channelCamera(const ServiceConfig& config, const ChannelConfig& ch) {
  Camera c;
  if (ch.frustum_deg) {
    const auto& f = *ch.frustum_deg;
    c = Camera::fromFrustum(FrustumAngles{radians(f[0]), radians(f[1]), radians(f[2]), radians(f[3])}, ch.width, 0)
            .value();  // checked when the channel was parsed
  } else {
    c.fov_x = radians(ch.fov_x_deg);
    c.width = ch.width;
    c.height = ch.height;
  }
  c.position_m = config.eye_m + ch.eye_offset_m;
  c.worldFromCamera = worldFromYawPitchRoll(radians(ch.yaw_deg), radians(ch.pitch_deg), radians(ch.roll_deg));
  return c;
}

const VehicleRig* ServiceConfig::rigFor(std::uint16_t vehicleClass) const {
  if (auto it = traffic.find(vehicleClass); it != traffic.end()) return &it->second;
  if (auto it = traffic.find(0); it != traffic.end()) return &it->second;
  return nullptr;
}

std::string_view builtinServiceConfig() { return kBuiltinServiceConfig; }

std::string builtinConfigDir() {
  if (const char* env = std::getenv("FOGBEAM_CONFIG_DIR"); env && *env) return env;
  return FOGBEAM_BUILTIN_CONFIG_DIR;
}

Status applyServiceLayer(ServiceConfig& c, std::string_view text, const std::string& name, const std::string& baseDir) {
  auto r = config::parseTomlFile<Ok>(text, name, [&](const toml::table& root) {
    applyRoot(c, root, name, baseDir);
    return Ok{};
  });
  if (!r) return r.error();
  c.layers.push_back(name);
  return Ok{};
}

Result<ServiceConfig> loadServiceConfig(const std::string& file, const std::vector<std::string>& settings) {
  ServiceConfig c;
  if (Status s = applyServiceLayer(c, builtinServiceConfig(), "built-in service config", builtinConfigDir()); !s) {
    return Error{s.error().message + " (FOGBEAM_CONFIG_DIR or the build's config/ directory must hold the shipped files)"};
  }
  if (!file.empty()) {
    auto text = readTextFile(file);
    if (!text) return text.error();
    if (Status s = applyServiceLayer(c, *text, file, fs::path(file).parent_path().string()); !s) return s.error();
  }
  for (const std::string& kv : settings) {
    const std::size_t eq = kv.find('=');
    if (eq == std::string::npos || eq == 0) {
      return Error{"--set " + kv + ": expected key.path=value (value in TOML syntax, e.g. timing.rate_hz=60)"};
    }
    // "a.b.c=v" is the TOML dotted-key line "a.b.c = v"; paths resolve against the working
    // directory. An array-of-tables entry cannot be set this way (use a file).
    if (Status s = applyServiceLayer(c, kv.substr(0, eq) + " = " + kv.substr(eq + 1) + "\n", "--set " + kv,
                                     fs::current_path().string());
        !s) {
      return s.error();
    }
  }
  if (Status s = validate(c); !s) return s.error();
  return c;
}

Status validate(const ServiceConfig& c) {
  const std::string where = "service config (" + (c.layers.empty() ? std::string("?") : c.layers.back()) + ")";
  if (c.scene_path.empty()) return Error{where + ": [world] scene: missing"};
  if (c.channels.empty()) return Error{where + ": no [[channel]]: at least one output view is needed"};
  for (const ChannelConfig& ch : c.channels) {
    if (ch.format != "rgba8-srgb" && ch.exposure_ev != 0.0) {
      return Error{where + ": [[channel]] " + ch.name + ": exposure_ev applies to rgba8-srgb only"};
    }
    if (!ch.depth_from.empty()) {
      for (const ChannelConfig& other : c.channels)
        if (other.name == ch.depth_from)
          return Error{where + ": [[channel]] " + ch.name + ": depth_from = \"" + ch.depth_from +
                       "\" names one of fogbeam's own output channels; it must be the host's depth channel"};
      if (c.effects.render.airlight == AirlightDevice::Gpu)
        return Error{where + ": [[channel]] " + ch.name + ": depth_from needs [render] airlight = \"cpu\" (the GPU "
                             "airlight is a stage of the surface pass, which a host depth channel does not run)"};
    }
  }
  if (c.ego.lamps.empty()) return Error{where + ": [ego] has no [[ego.lamp]]"};
  if (!c.traffic.contains(0)) return Error{where + ": no [[traffic_class]] with class = 0 (the default rig)"};
  if (c.can_source != "none" && c.can_mapping_path.empty()) {
    return Error{where + ": [input.can] source = \"" + c.can_source + "\" needs mapping (a CAN mapping file)"};
  }
  if (c.can_source == "interface" && c.can_interface.empty()) return Error{where + ": [input.can] interface: missing"};
  if (c.can_source == "candump" && c.can_candump.empty()) return Error{where + ": [input.can] candump: missing"};
  if (c.can_source == "cannelloni" && c.can_cannelloni_port == 0) {
    return Error{where + ": [input.can] cannelloni_port: missing"};
  }
  if (c.status_udp_port != 0 && c.status_udp_port == c.udp_port) {
    return Error{where + ": [status] udp_port equals [input.udp] port " + std::to_string(c.udp_port)};
  }
  if (c.effects.render.airlight == AirlightDevice::Gpu) {
    // The GPU airlight is a stage of the GL surface pass (GlSurfacePass::setAirlight).
    if (c.surface == "cpu") {
      return Error{where + ": [render] airlight = \"gpu\" needs the GL surface pass, but surface = \"cpu\" "
                           "(use surface = \"gl\" or \"auto\", or airlight = \"cpu\")"};
    }
    // Its shader is the accurate method; the seed and the reference exist on the CPU only.
    if (c.method != "accurate") {
      return Error{where + ": [render] airlight = \"gpu\" computes the accurate method, but method = \"" + c.method +
                   "\" (use method = \"accurate\", or airlight = \"cpu\")"};
    }
  }
  return Ok{};
}

std::vector<config::KeyTable> serviceConfigKeyTables() {
  using config::keyNames;
  return {
      {"service.md", "Top level", "service config: top level", keyNames({kTopKeys})},
      {"service.md", "`[world]`", "service [world]", keyNames({kWorldKeys})},
      {"service.md", "`[render]`", "service [render]: its own keys and the scene's [render] keys",
       keyNames({kRenderKeys, config::renderKeys()})},
      {"service.md", "`[glow]`", "service [glow] (the scene's [glow] keys)", keyNames({config::glowKeys()})},
      {"service.md", "`[glare]`", "service [glare] (the scene's [glare] keys)", keyNames({config::glareKeys()})},
      {"service.md", "`[timing]`", "service [timing]", keyNames({kTimingKeys})},
      {"service.md", "`[status]`", "service [status]", keyNames({kStatusKeys})},
      {"service.md", "`[input]`", "service [input]", keyNames({kInputKeys})},
      {"service.md", "`[input.udp]`", "service [input.udp]", keyNames({kUdpKeys})},
      {"service.md", "`[input.can]`", "service [input.can]", keyNames({kCanKeys})},
      {"service.md", "`[[channel]]`: output views", "service [[channel]]", keyNames({kChannelKeys})},
      {"service.md", "`[ego]`", "service [ego]", keyNames({kEgoKeys})},
      {"service.md", "`[ego.bonnet]`", "service [ego.bonnet], beside the scene's [bonnet] keys", keyNames({kBonnetServiceKeys})},
      {"service.md", "`[[traffic_class]]`: traffic rigs", "service [[traffic_class]]", keyNames({kClassKeys})},
      {"service.md", "Rig lamps: `[[ego.lamp]]` and `[[traffic_class.lamp]]`",
       "service [[ego.lamp]], [[traffic_class.lamp]], beside the scene's [[lamp]] keys", keyNames({kRigLampExtraKeys})},
  };
}

std::vector<config::KeyTable> configKeyTables() {
  std::vector<config::KeyTable> all = config::sceneKeyTables();
  for (const std::vector<config::KeyTable>& more :
       {scenarioKeyTables(), serviceConfigKeyTables(), ipc::canConfigKeyTables()}) {
    all.insert(all.end(), more.begin(), more.end());
  }
  return all;
}

std::string toToml(const ServiceConfig& c) {
  std::ostringstream o;
  auto vec = [](const Vec3& v) {
    return "[" + config::formatNumber(v.x) + ", " + config::formatNumber(v.y) + ", " + config::formatNumber(v.z) + "]";
  };
  auto num = [](double x) { return config::formatNumber(x); };
  auto flag = [](bool b) { return b ? "true" : "false"; };
  o << "# fogbeam serve: effective configuration, from these layers in order:\n";
  for (const std::string& l : c.layers) o << "#   " << l << "\n";
  o << "\n[world]\nscene = " << quoted(c.scene_path) << "\nscenario = " << quoted(c.scenario_path)
    << "\nscenario_loop = " << flag(c.scenario_loop) << "\n";
  o << "\n[fog]\n" << c.fog_text << "\n";
  o << "\n[render]\nmethod = " << quoted(c.method) << "\nsubsampling = " << flag(c.subsampling)
    << "\nview_table_step_deg = " << num(c.view_table_step_deg) << "\nmoving_lamps = " << quoted(c.moving_lamps)
    << "\nmoving_lamp_cutoff_cd_m2 = " << num(c.moving_lamp_cutoff_cd_m2) << "\nmax_moving_lamps = " << c.max_moving_lamps
    << "\nsurface = " << quoted(c.surface)
    << "\nthreads = " << c.threads << "\ntable_cache = " << quoted(c.table_cache)
    << "\npending_tables = " << quoted(c.pending_tables) << "\ntable_adopt_frames = " << c.table_adopt_frames
    << "\nfog_ladder_ratio = " << num(c.fog_ladder_ratio) << "\nfog_ladder_rungs = " << c.fog_ladder_rungs
    << "\nfog_ladder_adopt_frames = " << c.fog_ladder_adopt_frames
    << "\nbending_ladder_step_deg = " << num(c.bending_ladder_step_deg)
    << "\nbending_ladder_rungs = " << c.bending_ladder_rungs
    << "\noverlap_frames = " << quoted(c.overlap_frames) << "\nairlight = " << quoted(std::string(toString(c.effects.render.airlight)))
    << "\ngpu_pieces = " << c.effects.render.gpu_pieces << "\n";
  o << "\n[glow]\nenabled = " << flag(c.effects.glow.enabled) << "\nmodel = \"" << toString(c.effects.glow.model)
    << "\"\nfade_in = " << num(c.effects.glow.fade_in) << "\nsurfaces = " << flag(c.effects.glow.surfaces) << "\n";
  o << "\n[glare]\nenabled = " << flag(c.effects.glare.enabled) << "\nage_years = " << num(c.effects.glare.age_years)
    << "\npigmentation = " << num(c.effects.glare.pigmentation) << "\n";
  o << "\n[timing]\nmode = " << quoted(c.lock_step ? "lock-step" : "free-running") << "\nrate_hz = " << num(c.rate_hz)
    << "\n";
  o << "\n[status]\ninterval_s = " << num(c.status_interval_s) << "\nudp_port = " << c.status_udp_port << "\n";
  o << "\n[input.udp]\nbind = " << quoted(c.udp_bind) << "\nport = " << c.udp_port
    << "\nmulticast = " << quoted(c.udp_multicast) << "\nallow = [";
  for (std::size_t i = 0; i < c.udp_allow.size(); ++i) o << (i ? ", " : "") << quoted(c.udp_allow[i]);
  o << "]\ntraffic_timeout_s = " << num(c.traffic_timeout_s) << "\nmax_traffic_objects = " << c.max_traffic_objects
    << "\n";
  o << "\n[input.can]\nsource = " << quoted(c.can_source) << "\ninterface = " << quoted(c.can_interface)
    << "\ncandump = " << quoted(c.can_candump) << "\ncandump_speed = " << num(c.can_candump_speed)
    << "\ncannelloni_port = " << c.can_cannelloni_port << "\nmapping = " << quoted(c.can_mapping_path) << "\n";
  for (const ChannelConfig& ch : c.channels) {
    o << "\n[[channel]]\nname = " << quoted(ch.name) << "\nwidth = " << ch.width << "\nheight = " << ch.height
      << (ch.frustum_deg ? "\nfrustum_deg = [" + num((*ch.frustum_deg)[0]) + ", " + num((*ch.frustum_deg)[1]) + ", " +
                                num((*ch.frustum_deg)[2]) + ", " + num((*ch.frustum_deg)[3]) + "]"
                          : "\nfov_x_deg = " + num(ch.fov_x_deg))
      << "\neye_offset_m = " << vec(ch.eye_offset_m)
      << "\nyaw_deg = " << num(ch.yaw_deg) << "\npitch_deg = " << num(ch.pitch_deg) << "\nroll_deg = " << num(ch.roll_deg)
      << "\nformat = " << quoted(ch.format) << "\ndistance = " << flag(ch.distance)
      << "\nexposure_ev = " << (ch.autoExposure() ? std::string("\"auto\"") : num(ch.exposure_ev)) << (ch.depth_from.empty() ? "" : "\ndepth_from = " + quoted(ch.depth_from))
      << "\n";
  }
  o << "\n[ego]\neye_m = " << vec(c.eye_m) << "\nbending_max_deg = " << num(c.bending_max_deg)
    << "\nbending_tolerance_deg = " << num(c.bending_tolerance_deg) << "\n";
  if (c.bonnet) {
    const Bonnet& b = *c.bonnet;
    o << "\n[ego.bonnet]\nrear_m = " << num(b.rear_m) << "\nfront_m = " << num(b.front_m) << "\nleft_m = " << num(b.left_m)
      << "\nright_m = " << num(b.right_m) << "\nheight_m = " << num(b.height_m) << "\nreflectance = " << num(b.reflectance)
      << "\n";
  }
  for (const RigLamp& l : c.ego.lamps) o << "\n[[ego.lamp]]\n" << l.definition << "\n";
  for (const auto& [cls, rig] : c.traffic) {
    o << "\n[[traffic_class]]\nclass = " << cls << "\nname = " << quoted(rig.name) << "\n";
    for (const RigLamp& l : rig.lamps) o << "\n[[traffic_class.lamp]]\n" << l.definition << "\n";
  }
  return o.str();
}

}  // namespace fogbeam::plugin
