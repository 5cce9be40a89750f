// fogbeam — scenario files, trajectories and their evaluation (scenario.hpp, docs/scenario.md).
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/scene/sections.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/text_scan.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <optional>
#include <utility>

namespace fogbeam::plugin {

namespace {

namespace fs = std::filesystem;
using config::KeySpec;
using config::Section;

// ---- Hermite interpolation ------------------------------------------------------------------

/// Catmull–Rom tangent (per second) of the k-th of n values at uneven times: central difference
/// over the neighbours, one-sided at the ends.
template <class V, class Get>
V tangent(std::size_t k, std::size_t n, const std::vector<PoseKey>& keys, Get&& get) {
  if (n < 2) return V{};
  const std::size_t a = k == 0 ? 0 : k - 1;
  const std::size_t b = k + 1 >= n ? n - 1 : k + 1;
  return (get(keys[b]) - get(keys[a])) / (keys[b].t_s - keys[a].t_s);
}

/// Cubic Hermite between keys k and k+1 at u ∈ [0, 1] over an interval of h seconds: the value
/// and its time derivative.
template <class V>
std::pair<V, V> hermite(const V& p0, const V& m0, const V& p1, const V& m1, double u, double h) {
  const double u2 = u * u, u3 = u2 * u;
  const double h00 = 2 * u3 - 3 * u2 + 1, h10 = u3 - 2 * u2 + u, h01 = -2 * u3 + 3 * u2, h11 = u3 - u2;
  const V value = h00 * p0 + h10 * h * m0 + h01 * p1 + h11 * h * m1;
  const double d00 = 6 * u2 - 6 * u, d10 = 3 * u2 - 4 * u + 1, d01 = -6 * u2 + 6 * u, d11 = 3 * u2 - 2 * u;
  const V derivative = (d00 * p0 + d01 * p1) / h + d10 * m0 + d11 * m1;
  return {value, derivative};
}

double degreesOf(double rad) { return rad * 180.0 / std::numbers::pi; }

// ---- Light names ----------------------------------------------------------------------------

constexpr std::array<std::pair<std::string_view, std::uint32_t>, 9> kLightNames{{
    {"position", ipc::light::kPosition},
    {"low-beam", ipc::light::kLowBeam},
    {"high-beam", ipc::light::kHighBeam},
    {"brake", ipc::light::kBrake},
    {"indicator-left", ipc::light::kIndicatorLeft},
    {"indicator-right", ipc::light::kIndicatorRight},
    {"front-fog", ipc::light::kFrontFog},
    {"rear-fog", ipc::light::kRearFog},
    {"drl", ipc::light::kDrl},
}};

// ---- The keys -------------------------------------------------------------------------------
// Names only: each key's description is its row in docs/scenario.md (scenarioKeyTables()).

constexpr std::array kTopKeys{
    KeySpec{"name"},
    KeySpec{"description"},
    KeySpec{"scene"},
    KeySpec{"duration_s"},
    KeySpec{"fog"},
    KeySpec{"fog_key"},
    KeySpec{"ego"},
    KeySpec{"vehicle"},
};
constexpr std::array kFogExtraKeys{
    KeySpec{"interpolation"},
};
constexpr std::array kFogKeyKeys{
    KeySpec{"t_s"},
    KeySpec{"visibility_m"},
};
constexpr std::array kVehicleKeys{
    KeySpec{"name"},
    KeySpec{"id"},
    KeySpec{"class"},
    KeySpec{"lights"},
    KeySpec{"bending_deg"},
    KeySpec{"key"},
    KeySpec{"csv"},
    KeySpec{"csv_id"},
    KeySpec{"csv_name"},
    KeySpec{"event"},
};
constexpr std::array kPoseKeyKeys{
    KeySpec{"t_s"},
    KeySpec{"position_m"},
    KeySpec{"yaw_deg"},
    KeySpec{"pitch_deg"},
    KeySpec{"roll_deg"},
};
constexpr std::array kEventKeys{
    KeySpec{"t_s"},
    KeySpec{"lights"},
    KeySpec{"bending_deg"},
};

std::uint32_t lightsOf(const Section& s, std::string_view key, std::uint32_t fallback) {
  const auto names = s.optStrings(key);
  if (!names) return fallback;
  auto bits = lightsFromNames(*names);
  if (!bits) s.failAt(*s.find(key), key, bits.error().message);
  return *bits;
}

ipc::Environment environmentOf(const Section& s) {
  const Medium m = config::parseFog(s, kFogExtraKeys);  // validates every scene [fog] key
  ipc::Environment e;
  if (auto v = s.optNumber("visibility_m", config::kPositive)) {
    e.visibility_m = static_cast<float>(*v);
  } else {
    e.visibility_m = 0.0f;
    e.extinction_per_m = static_cast<float>(m.extinction_per_m);
  }
  e.albedo = static_cast<float>(m.albedo);
  e.ambient_cd_m2 = static_cast<float>(m.ambient_cd_m2);
  const std::string phase = s.optString("phase").value_or("henyey-greenstein");
  e.phase = phase == "isotropic" ? ipc::PhaseCode::Isotropic
            : phase == "fog-mie" ? ipc::PhaseCode::FogMie
                                 : ipc::PhaseCode::HenyeyGreenstein;
  e.g = static_cast<float>(s.number("g", config::kAnyFinite, 0.85));
  e.droplet_diameter_um = static_cast<float>(s.number("droplet_diameter_um", config::kAnyFinite, 10.0));
  return e;
}

ScenarioVehicle parseVehicle(const Section& s, bool ego, const std::string& baseDir,
                             std::map<std::string, std::vector<EsminiRow>>& csvCache) {
  s.checkKeys(kVehicleKeys);
  ScenarioVehicle v;
  v.name = s.optString("name").value_or(ego ? "ego" : s.label());
  if (ego) {
    s.forbid("id", "the ego has no traffic id");
    s.forbid("class", "the ego's rig is the service config's [ego]");
  } else {
    v.id = static_cast<std::uint32_t>(s.integer("id", 0, 0xFFFF'FFFFll));
    v.vehicle_class = static_cast<std::uint16_t>(s.integer("class", 0, 0xFFFF, 0));
    s.forbid("bending_deg", "only the ego's lamps bend");
  }
  LightEvent initial;
  initial.t_s = -std::numeric_limits<double>::infinity();
  initial.lights = lightsOf(s, "lights", ego ? ipc::light::kInitialEgo : 0u);
  initial.bending_deg = static_cast<float>(s.number("bending_deg", config::Range{-45.0, 45.0}, 0.0));
  v.lights.push_back(initial);
  s.forEachEntry("event", [&](const toml::table& t, std::string label, std::size_t) {
    const Section e(s.file(), t, std::move(label));
    e.checkKeys(kEventKeys);
    LightEvent ev;
    ev.t_s = e.number("t_s", config::kNonNegative);
    ev.lights = lightsOf(e, "lights", 0);
    if (!e.find("lights")) e.missing("lights", "an array of light names");
    if (!ego) e.forbid("bending_deg", "only the ego's lamps bend");
    ev.bending_deg = static_cast<float>(e.number("bending_deg", config::Range{-45.0, 45.0}, 0.0));
    if (ev.t_s < v.lights.back().t_s) e.fail(e.line(), "t_s", "events must be in time order");
    v.lights.push_back(ev);
  });

  std::vector<PoseKey> keys;
  bool hasYaw = true;
  const bool fromCsv = s.find("csv") != nullptr;
  if (fromCsv) {
    if (s.find("key")) s.failAt(*s.find("key"), "key", "give keyframes or csv, not both");
    const std::string path = resolvePath(baseDir, s.string("csv", "a path"));
    if (std::string problem = checkFile(path); !problem.empty()) s.failAt(*s.find("csv"), "csv", problem);
    auto it = csvCache.find(path);
    if (it == csvCache.end()) {
      auto text = readTextFile(path);
      if (!text) s.failAt(*s.find("csv"), "csv", text.error().message);
      auto rows = parseEsminiCsv(*text, path);
      if (!rows) s.failAt(*s.find("csv"), "csv", rows.error().message);
      it = csvCache.emplace(path, std::move(rows).value()).first;
    }
    const auto id = s.optInteger("csv_id", 0, 0xFFFF'FFFFll);
    const auto name = s.optString("csv_name");
    if (id.has_value() == name.has_value()) s.fail(s.line(), "csv_id", "give exactly one of csv_id and csv_name");
    for (const EsminiRow& r : it->second) {
      if (id ? r.id != static_cast<std::uint32_t>(*id) : r.name != *name) continue;
      if (!keys.empty() && r.t_s <= keys.back().t_s) continue;  // esmini repeats the last step
      keys.push_back(PoseKey{r.t_s, r.position_m, r.yaw_deg, r.pitch_deg, r.roll_deg});
    }
    if (keys.empty()) {
      s.fail(s.line(), "csv", "no rows for " + (id ? "id " + std::to_string(*id) : "name " + config::inQuotes(*name)) +
                                  " in " + path);
    }
  } else {
    std::size_t withYaw = 0;
    s.forEachEntry("key", [&](const toml::table& t, std::string label, std::size_t) {
      const Section k(s.file(), t, std::move(label));
      k.checkKeys(kPoseKeyKeys);
      PoseKey p;
      p.t_s = k.number("t_s", config::kAnyFinite);
      p.position_m = vec3(k, "position_m");
      if (auto y = k.optNumber("yaw_deg", config::kAnyFinite)) {
        p.yaw_deg = *y;
        ++withYaw;
      }
      p.pitch_deg = k.number("pitch_deg", config::kAnyFinite, 0.0);
      p.roll_deg = k.number("roll_deg", config::kAnyFinite, 0.0);
      if (!keys.empty() && !(p.t_s > keys.back().t_s)) {
        k.failAt(*k.find("t_s"), "t_s", "expected a time after the previous key's " +
                                            config::formatNumber(keys.back().t_s) + " s, found " +
                                            config::formatNumber(p.t_s));
      }
      keys.push_back(p);
    });
    if (keys.empty()) s.missing("key", "[[…key]] keyframes or csv");
    if (withYaw != 0 && withYaw != keys.size()) {
      s.fail(s.line(), "key", "yaw_deg is given in " + std::to_string(withYaw) + " of " + std::to_string(keys.size()) +
                                  " keys: give it in all (or none, to head along the path)");
    }
    hasYaw = withYaw != 0;
  }
  auto path = Trajectory::make(std::move(keys), hasYaw, s.label());
  if (!path) s.fail(s.line(), "", path.error().message);
  v.path = std::move(path).value();
  return v;
}

Scenario parseRoot(const toml::table& root, const std::string& name, const std::string& baseDir) {
  const Section top(name, root, "");
  top.checkKeys(kTopKeys);
  Scenario sc;
  sc.source = name;
  sc.name = top.optString("name").value_or(fs::path(name).stem().string());
  sc.description = top.optString("description").value_or("");
  sc.scene_path = resolvePath(baseDir, top.string("scene", "a path to a scene file"));
  if (std::string problem = checkFile(sc.scene_path); !problem.empty()) {
    top.failAt(*top.find("scene"), "scene", problem);
  }
  sc.duration_s = top.number("duration_s", config::kPositive);
  if (const toml::table* f = top.optTable("fog")) {
    const Section fs_(name, *f, "[fog]");
    sc.fog = environmentOf(fs_);
    const std::array<std::string_view, 2> interp{"log-linear", "step"};
    sc.fog_step = fs_.choice("interpolation", interp, "log-linear") == "step";
  } else {
    // The scene's fog: read it from the scene file's own [fog] table.
    auto text = readTextFile(sc.scene_path);
    if (!text) top.failAt(*top.find("scene"), "scene", text.error().message);
    toml::table sceneRoot;
    try {
      sceneRoot = toml::parse(*text, sc.scene_path);
    } catch (const toml::parse_error& e) {
      throw config::ConfigError{fileError(sc.scene_path, e.source().begin.line, std::string(e.description()))};
    }
    const Section sceneTop(sc.scene_path, sceneRoot, "");
    sc.fog = environmentOf(Section(sc.scene_path, sceneTop.requiredTable("fog"), "[fog]"));
  }
  top.forEachEntry("fog_key", [&](const toml::table& t, std::string label, std::size_t) {
    const Section k(name, t, std::move(label));
    k.checkKeys(kFogKeyKeys);
    FogKey key{k.number("t_s", config::kNonNegative), k.number("visibility_m", config::kPositive)};
    if (!sc.fog_keys.empty() && !(key.t_s > sc.fog_keys.back().t_s)) {
      k.failAt(*k.find("t_s"), "t_s", "expected a time after the previous key's " +
                                          config::formatNumber(sc.fog_keys.back().t_s) + " s");
    }
    sc.fog_keys.push_back(key);
  });
  std::map<std::string, std::vector<EsminiRow>> csvCache;
  sc.ego = parseVehicle(Section(name, top.requiredTable("ego"), "[ego]"), true, baseDir, csvCache);
  std::map<std::uint32_t, std::string> ids;
  top.forEachEntry("vehicle", [&](const toml::table& t, std::string label, std::size_t) {
    const Section s(name, t, std::move(label));
    ScenarioVehicle v = parseVehicle(s, false, baseDir, csvCache);
    if (auto [it, fresh] = ids.emplace(v.id, s.label()); !fresh) {
      s.failAt(*s.find("id"), "id", "expected a unique id, found " + std::to_string(v.id) + " again (first used by " +
                                        it->second + ")");
    }
    sc.traffic.push_back(std::move(v));
  });
  return sc;
}

}  // namespace

// ---- Trajectory -------------------------------------------------------------------------------

Result<Trajectory> Trajectory::make(std::vector<PoseKey> keys, bool hasYaw, const std::string& what) {
  if (keys.empty()) return Error{what + ": a trajectory needs at least one key"};
  for (std::size_t k = 1; k < keys.size(); ++k) {
    if (!(keys[k].t_s > keys[k - 1].t_s)) {
      return Error{what + ": key " + std::to_string(k + 1) + " at t = " + config::formatNumber(keys[k].t_s) +
                   " s is not after key " + std::to_string(k) + " at " + config::formatNumber(keys[k - 1].t_s) + " s"};
    }
  }
  // Unwrap angles so that interpolation takes the short way round (350° → 10° passes 0°).
  for (std::size_t k = 1; k < keys.size(); ++k) {
    for (double PoseKey::*a : {&PoseKey::yaw_deg, &PoseKey::pitch_deg, &PoseKey::roll_deg}) {
      const double d = keys[k].*a - keys[k - 1].*a;
      keys[k].*a -= 360.0 * std::round(d / 360.0);
    }
  }
  Trajectory t;
  t.keys_ = std::move(keys);
  t.hasYaw_ = hasYaw;
  return t;
}

Trajectory::Sample Trajectory::at(double t) const {
  const std::size_t n = keys_.size();
  Sample s;
  auto set = [&](const Vec3& p, const Vec3& angles) {
    s.pose.position_m = {p.x, p.y, p.z};
    s.pose.yaw_deg = static_cast<float>(std::remainder(angles.x, 360.0));
    s.pose.pitch_deg = static_cast<float>(angles.y);
    s.pose.roll_deg = static_cast<float>(angles.z);
  };
  auto angles = [](const PoseKey& k) { return Vec3(k.yaw_deg, k.pitch_deg, k.roll_deg); };
  auto position = [](const PoseKey& k) { return k.position_m; };
  if (n == 1 || t <= keys_.front().t_s || t >= keys_.back().t_s) {
    const std::size_t k = (n == 1 || t <= keys_.front().t_s) ? 0 : n - 1;
    Vec3 a = angles(keys_[k]);
    if (!hasYaw_ && n > 1) {
      const Vec3 m = tangent<Vec3>(k, n, keys_, position);
      a.x = degreesOf(std::atan2(m.y, m.x));
    }
    set(keys_[k].position_m, a);
    return s;  // holding still: speed 0
  }
  const auto it = std::upper_bound(keys_.begin(), keys_.end(), t, [](double x, const PoseKey& k) { return x < k.t_s; });
  const std::size_t k = static_cast<std::size_t>(it - keys_.begin()) - 1;
  const double h = keys_[k + 1].t_s - keys_[k].t_s;
  const double u = (t - keys_[k].t_s) / h;
  const auto [p, v] = hermite(keys_[k].position_m, tangent<Vec3>(k, n, keys_, position), keys_[k + 1].position_m,
                              tangent<Vec3>(k + 1, n, keys_, position), u, h);
  Vec3 a = hermite(angles(keys_[k]), tangent<Vec3>(k, n, keys_, angles), angles(keys_[k + 1]),
                   tangent<Vec3>(k + 1, n, keys_, angles), u, h)
               .first;
  if (!hasYaw_) a.x = degreesOf(std::atan2(v.y, v.x));
  set(p, a);
  s.speed_m_s = glm::length(v);
  return s;
}

LightEvent ScenarioVehicle::lightsAt(double t_s) const {
  LightEvent e = lights.front();
  for (const LightEvent& l : lights)
    if (l.t_s <= t_s) e = l;
  return e;
}

// ---- Evaluation -------------------------------------------------------------------------------

ScenarioState evaluate(const Scenario& s, double t) {
  ScenarioState st;
  st.t_s = t;
  const Trajectory::Sample ego = s.ego.path.at(t);
  st.ego.pose = ego.pose;
  st.ego.speed_m_s = static_cast<float>(ego.speed_m_s);
  const LightEvent el = s.ego.lightsAt(t);
  st.ego_lamps.lights = el.lights;
  st.ego_lamps.bending_deg = el.bending_deg;
  st.environment = s.fog;
  if (!s.fog_keys.empty()) {
    const auto& k = s.fog_keys;
    double v = k.front().visibility_m;
    if (t >= k.back().t_s) {
      v = k.back().visibility_m;
    } else if (t > k.front().t_s) {
      const auto it = std::upper_bound(k.begin(), k.end(), t, [](double x, const FogKey& f) { return x < f.t_s; });
      const FogKey& a = *(it - 1);
      const FogKey& b = *it;
      const double u = (t - a.t_s) / (b.t_s - a.t_s);
      v = s.fog_step ? a.visibility_m : std::exp(std::log(a.visibility_m) + u * std::log(b.visibility_m / a.visibility_m));
    }
    st.environment.visibility_m = static_cast<float>(v);
  }
  st.traffic.complete = true;
  for (const ScenarioVehicle& v : s.traffic) {
    if (t < v.path.start_s() || t > v.path.end_s()) continue;
    ipc::TrafficObject o;
    o.id = v.id;
    o.vehicle_class = v.vehicle_class;
    o.pose = v.path.at(t).pose;
    o.lights = v.lightsAt(t).lights;
    st.traffic.objects.push_back(o);
  }
  return st;
}

std::vector<std::vector<std::uint8_t>> encodeState(const ScenarioState& state, std::uint32_t& sequence) {
  std::vector<std::vector<std::uint8_t>> out;
  auto add = [&](ipc::Payload p) {
    ipc::Message m;
    m.header.sequence = sequence++;
    m.header.sim_time_s = state.t_s;
    m.payload = std::move(p);
    out.push_back(ipc::encode(m));
  };
  add(state.environment);
  add(state.ego_lamps);
  // Traffic in chunks; only the last chunk says "complete" would remove the earlier ones, so a
  // list longer than one datagram is sent as incomplete chunks (objects leave by expiry).
  const auto& objs = state.traffic.objects;
  if (objs.size() <= ipc::kMaxTrafficPerDatagram) {
    add(state.traffic);
  } else {
    for (std::size_t i = 0; i < objs.size(); i += ipc::kMaxTrafficPerDatagram) {
      ipc::TrafficList part;
      part.objects.assign(objs.begin() + static_cast<std::ptrdiff_t>(i),
                          objs.begin() + static_cast<std::ptrdiff_t>(std::min(objs.size(), i + ipc::kMaxTrafficPerDatagram)));
      add(std::move(part));
    }
  }
  add(state.ego);  // last: the ego pose is what a frame is stamped with
  return out;
}

void applyState(const ScenarioState& state, ipc::StateStore& store, std::uint32_t& sequence,
                ipc::Clock::time_point received) {
  auto stamp = [&] {
    ipc::Stamp s;
    s.valid = true;
    s.sim_time_s = state.t_s;
    s.sequence = sequence++;
    s.received = received;
    s.source = "scenario";
    return s;
  };
  store.setEnvironment(state.environment, stamp());
  store.setLamps(state.ego_lamps, stamp());
  (void)store.applyTraffic(state.traffic, stamp());
  store.setEgo(state.ego, stamp());
}

Result<std::uint32_t> lightsFromNames(const std::vector<std::string>& names) {
  std::uint32_t bits = 0;
  for (const std::string& n : names) {
    const auto it = std::find_if(kLightNames.begin(), kLightNames.end(), [&](const auto& p) { return p.first == n; });
    if (it == kLightNames.end()) {
      std::string known;
      for (const auto& p : kLightNames) known += (known.empty() ? "" : ", ") + std::string(p.first);
      return Error{"unknown light " + config::inQuotes(n) + " (known: " + known + ")"};
    }
    bits |= it->second;
  }
  return bits;
}

std::string lightNames(std::uint32_t lights) {
  std::string s;
  for (const auto& [name, bit] : kLightNames)
    if (lights & bit) s += (s.empty() ? "" : "+") + std::string(name);
  return s.empty() ? "off" : s;
}

Result<Scenario> parseScenario(std::string_view text, const std::string& name, const std::string& baseDir) {
  return config::parseTomlFile<Scenario>(text, name,
                                         [&](const toml::table& root) { return parseRoot(root, name, baseDir); });
}

Result<Scenario> loadScenario(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return text.error();
  return parseScenario(*text, path, fs::path(path).parent_path().string());
}

std::vector<config::KeyTable> scenarioKeyTables() {
  using config::keyNames;
  return {
      {"scenario.md", "Top level", "scenario: top level", keyNames({kTopKeys})},
      {"scenario.md", "`[fog]`", "scenario [fog], beside the scene [fog] keys", keyNames({kFogExtraKeys})},
      {"scenario.md", "`[[fog_key]]`", "scenario [[fog_key]]", keyNames({kFogKeyKeys})},
      {"scenario.md", "`[ego]` and `[[vehicle]]`", "scenario [ego], [[vehicle]]", keyNames({kVehicleKeys})},
      {"scenario.md", "Keyframes: `[[…key]]`", "scenario [[ego.key]], [[vehicle.key]]", keyNames({kPoseKeyKeys})},
      {"scenario.md", "Light events: `[[…event]]`", "scenario [[ego.event]], [[vehicle.event]]",
       keyNames({kEventKeys})},
  };
}

// ---- esmini CSV ---------------------------------------------------------------------------------

Result<std::vector<EsminiRow>> parseEsminiCsv(std::string_view text, const std::string& name) {
  const std::vector<text::Line> lines = text::splitLines(text);
  std::size_t first = 0;
  std::map<std::string, std::size_t, std::less<>> column;
  auto split = [](std::string_view line) {
    std::vector<std::string_view> cells;
    std::size_t start = 0;
    for (std::size_t i = 0; i <= line.size(); ++i) {
      if (i == line.size() || line[i] == ',') {
        cells.push_back(text::trim(line.substr(start, i - start)));
        start = i + 1;
      }
    }
    return cells;
  };
  for (; first < lines.size(); ++first) {
    const auto cells = split(lines[first].text);
    if (cells.empty() || cells[0] != "time") continue;
    for (std::size_t c = 0; c < cells.size(); ++c) column.emplace(std::string(cells[c]), c);
    break;
  }
  if (first == lines.size()) return Error{name + ": no header row starting with \"time\" (an esmini CSV export)"};
  static constexpr std::array<std::string_view, 9> kNeeded{"time", "id", "name", "x", "y", "z", "h", "p", "r"};
  for (std::string_view c : kNeeded) {
    if (!column.contains(c)) {
      return fileError(name, lines[first].number, "the header has no column " + config::inQuotes(c));
    }
  }
  const auto speedColumn = column.find("speed");
  std::vector<EsminiRow> rows;
  for (std::size_t l = first + 1; l < lines.size(); ++l) {
    const std::string_view text_ = text::trim(lines[l].text);
    if (text_.empty()) continue;
    const auto cells = split(text_);
    const std::size_t line = lines[l].number;
    auto num = [&](std::string_view col) -> Result<double> {
      const std::size_t c = column.find(col)->second;
      if (c >= cells.size()) return fileError(name, line, "column " + config::inQuotes(col) + " is missing");
      return text::finiteNumber(cells[c], name, line, "column " + std::string(col));
    };
    EsminiRow r;
    std::array<double, 8> v{};
    std::size_t i = 0;
    for (std::string_view col : {"time", "id", "x", "y", "z", "h", "p", "r"}) {
      auto x = num(col);
      if (!x) return x.error();
      v[i++] = *x;
    }
    if (v[1] < 0 || v[1] > 4294967295.0 || v[1] != std::floor(v[1])) {
      return fileError(name, line, "column id: expected an integer in [0, 2^32), found " + config::formatNumber(v[1]));
    }
    r.t_s = v[0];
    r.id = static_cast<std::uint32_t>(v[1]);
    const std::size_t nc = column.find("name")->second;
    r.name = nc < cells.size() ? std::string(cells[nc]) : std::string();
    r.position_m = Vec3(v[2], v[3], v[4]);
    r.yaw_deg = degreesOf(v[5]);
    r.pitch_deg = degreesOf(v[6]);
    r.roll_deg = degreesOf(v[7]);
    if (speedColumn != column.end() && speedColumn->second < cells.size()) {
      auto sp = text::finiteNumber(cells[speedColumn->second], name, line, "column speed");
      if (!sp) return sp.error();
      r.speed_m_s = *sp;
    }
    rows.push_back(std::move(r));
  }
  return rows;
}

}  // namespace fogbeam::plugin
