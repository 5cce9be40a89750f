// fogbeam — the scene sections every configuration format embeds (sections.hpp): [fog],
// lamps, [glow], [glare], [render].
#include <fogbeam/physics/glow.hpp>
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/scene/sections.hpp>
#include <fogbeam/util/files.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <utility>

namespace fogbeam::config {

namespace {

// Names only: each key's description is its row in docs/scene.md (sceneKeyTables()).
constexpr std::array kFogKeys{
    KeySpec{"extinction_per_m"},
    KeySpec{"visibility_m"},
    KeySpec{"albedo"},
    KeySpec{"phase"},
    KeySpec{"g"},
    KeySpec{"droplet_diameter_um"},
    KeySpec{"ambient_cd_m2"},
};

constexpr std::array kLampKeys{
    KeySpec{"name"},
    KeySpec{"position_m"},
    KeySpec{"yaw_deg"},
    KeySpec{"pitch_deg"},
    KeySpec{"roll_deg"},
    KeySpec{"profile"},
    KeySpec{"intensity_cd"},
    KeySpec{"inner_deg"},
    KeySpec{"outer_deg"},
    KeySpec{"scale"},
    KeySpec{"color"},
    KeySpec{"mount"},
    KeySpec{"aperture"},
    KeySpec{"aperture_size_m"},
    KeySpec{"aperture_samples"},
};

/// aperture_samples: 8 per axis is 64 point lamps for one lamp, far past the point where the
/// aperture rule's error drops below the airlight method's own (3 suffices: docs/scene.md).
constexpr std::int64_t kMaxConfigApertureSamples = 8;
/// aperture_size_m: a lamp's face; a street-lamp luminaire is under 1 m across.
constexpr Range kApertureSize{0.0, 2.0, true, false};

constexpr double kDefaultAlbedo = 1.0;
constexpr std::string_view kDefaultPhase = "henyey-greenstein";
constexpr double kDefaultG = 0.85;
constexpr double kDefaultDropletDiameter_um = 10.0;

}  // namespace

std::span<const KeySpec> fogKeys() { return kFogKeys; }
std::span<const KeySpec> lampKeys() { return kLampKeys; }

// ---- Vectors and orientations -------------------------------------------------------------

std::optional<Vec3> optVec3(const Section& s, std::string_view key, const Range& r) {
  const toml::node* n = s.find(key);
  if (!n) return std::nullopt;
  const auto* a = n->as_array();
  if (!a || a->size() != 3) {
    s.failAt(*n, key, "expected an array of 3 numbers [x, y, z], found " + describeNode(*n));
  }
  Vec3 v{0.0};
  for (glm::length_t c = 0; c < 3; ++c) {
    const std::string element = std::string(key) + "[" + std::to_string(c) + "]";
    v[c] = s.numberOf(*a->get(static_cast<std::size_t>(c)), element, r);
  }
  return v;
}

Vec3 vec3(const Section& s, std::string_view key, const Range& r) {
  if (auto v = optVec3(s, key, r)) return *v;
  s.missing(key, "an array of 3 numbers [x, y, z]");
}

Mat3 orientation(const Section& s) {
  const double yaw = s.number("yaw_deg", kAnyFinite, 0.0);
  const double pitch = s.number("pitch_deg", kAnyFinite, 0.0);
  const double roll = s.number("roll_deg", kAnyFinite, 0.0);
  return worldFromYawPitchRoll(radians(yaw), radians(pitch), radians(roll));
}

// ---- Profiles ------------------------------------------------------------------------------

namespace {

bool hasProfileExtension(std::string_view s) {
  const std::size_t dot = s.find_last_of('.');
  if (dot == std::string_view::npos) return false;
  std::string ext(s.substr(dot + 1));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == "ies" || ext == "ldt" || ext == "csv";
}

}  // namespace

Result<ProfileCache::Ptr> ProfileCache::model(const std::string& key, Profile::Model m) {
  if (auto it = byKey_.find(key); it != byKey_.end()) return it->second;
  auto p = makeProfile(std::move(m));
  if (!p) return p.error();
  byKey_.emplace(key, p.value());
  return p;
}

Result<ProfileCache::Ptr> ProfileCache::file(const std::string& path, double scale) {
  const std::string key = "file:" + path + "|scale:" + formatNumber(scale);
  if (auto it = byKey_.find(key); it != byKey_.end()) return it->second;
  Ptr base;
  if (auto it = files_.find(path); it != files_.end()) {
    base = it->second;
  } else {
    auto loaded = loadProfileFile(path);
    if (!loaded) return loaded.error();
    base = files_.emplace(path, std::move(loaded).value()).first->second;
  }
  Ptr p = base;
  if (scale != 1.0) {
    TabulatedProfile t = std::get<TabulatedProfile>(base->model());
    for (double& c : t.candela) c *= scale;
    auto scaled = makeProfile(std::move(t));
    if (!scaled) return scaled.error();
    p = std::move(scaled).value();
  }
  byKey_.emplace(key, p);
  return p;
}

// ---- Scene sections shared by every format ---------------------------------------------------

Medium parseFog(const Section& s, std::span<const KeySpec> extraKeys) {
  s.checkKeys(kFogKeys, extraKeys);
  Medium m;
  const toml::node* ext = s.find("extinction_per_m");
  const toml::node* vis = s.find("visibility_m");
  if (ext && vis) {
    s.failAt(*vis, "",
             "give exactly one of extinction_per_m and visibility_m, found both (extinction_per_m on line " +
                 std::to_string(lineOf(ext->source())) + ")");
  }
  if (ext) {
    m.extinction_per_m = s.numberOf(*ext, "extinction_per_m", kPositive);
  } else if (vis) {
    m.extinction_per_m = extinctionFromVisibility(s.numberOf(*vis, "visibility_m", kPositive));
    // A visibility so small that ln 20 / V overflows (V = 1e-320 m) is the key's error, not one of
    // an extinction the file never named.
    if (!std::isfinite(m.extinction_per_m))
      s.failAt(*vis, "visibility_m",
               "expected a number > 0 whose extinction ln(20) / visibility_m is finite, found " + describeNode(*vis));
  } else {
    s.fail(s.line(), "", "missing extinction_per_m or visibility_m (exactly one is required)");
  }
  m.albedo = s.number("albedo", kUnit, kDefaultAlbedo);
  m.ambient_cd_m2 = s.number("ambient_cd_m2", kNonNegative, 0.0);

  const std::string phase = s.optString("phase").value_or(std::string(kDefaultPhase));
  const std::string phaseIs = "found phase = " + inQuotes(phase);
  if (phase == "isotropic") {
    s.forbid("g", "only allowed with phase = \"henyey-greenstein\", " + phaseIs);
    s.forbid("droplet_diameter_um", "only allowed with phase = \"fog-mie\", " + phaseIs);
    m.phase = IsotropicPhase{};
  } else if (phase == "henyey-greenstein") {
    s.forbid("droplet_diameter_um", "only allowed with phase = \"fog-mie\", " + phaseIs);
    const double g = s.number("g", Range{-1.0, 1.0, true, true}, kDefaultG);
    m.phase = makeHenyeyGreenstein(g).value();
  } else if (phase == "fog-mie") {
    s.forbid("g", "only allowed with phase = \"henyey-greenstein\", " + phaseIs);
    const double d = s.number("droplet_diameter_um", Range{5.0, 50.0}, kDefaultDropletDiameter_um);
    m.phase = makeFogMie(d).value();
  } else {
    s.failAt(*s.find("phase"), "phase",
             "expected \"isotropic\", \"henyey-greenstein\" or \"fog-mie\", found " + inQuotes(phase));
  }
  if (Status ok = m.validate(); !ok) s.fail(s.line(), "", ok.error().message);
  return m;
}

namespace {

/// The keys aperture, aperture_size_m and aperture_samples of a lamp table (docs/scene.md).
Aperture parseAperture(const Section& s) {
  constexpr std::array<std::string_view, 3> kShapes{"point", "rectangle", "disc"};
  const std::string shape = s.choice("aperture", kShapes, "point");
  Aperture a;
  if (shape == "point") {
    const std::string why = "only allowed with aperture = \"rectangle\" or \"disc\", found " +
                            std::string(s.find("aperture") ? "aperture = \"point\"" : "no aperture (a point lamp)");
    s.forbid("aperture_size_m", why);
    s.forbid("aperture_samples", why);
    return a;
  }
  const std::string size = "aperture_size_m";
  const toml::node* n = s.find(size);
  const std::string within = "in (0, " + formatNumber(kApertureSize.hi) + "] m";
  if (shape == "rectangle") {
    a.shape = ApertureShape::Rectangle;
    const std::string expected = "[width, height], two numbers " + within + " for aperture = \"rectangle\"";
    if (!n) s.missing(size, expected);
    const auto* arr = n->as_array();
    if (!arr || arr->size() != 2) s.failAt(*n, size, "expected " + expected + ", found " + describeNode(*n));
    a.width_m = s.numberOf(*arr->get(0), size + "[0]", kApertureSize);
    a.height_m = s.numberOf(*arr->get(1), size + "[1]", kApertureSize);
  } else {
    a.shape = ApertureShape::Disc;
    const std::string expected = "the diameter, a number " + within + " for aperture = \"disc\"";
    if (!n) s.missing(size, expected);
    if (!n->is_number() || !kApertureSize.contains(n->value_or(0.0)))
      s.failAt(*n, size, "expected " + expected + ", found " + describeNode(*n));
    a.width_m = n->value_or(0.0);
  }
  a.samples = static_cast<int>(s.integer("aperture_samples", 1, kMaxConfigApertureSamples, kDefaultApertureSamples));
  return a;
}

}  // namespace

SceneLamp parseLamp(const Section& s, std::size_t ordinal, const std::string& baseDir, ProfileCache& cache,
                    std::span<const KeySpec> extraKeys) {
  s.checkKeys(kLampKeys, extraKeys);
  SceneLamp out;
  if (auto name = s.optString("name")) {
    if (name->empty()) s.failAt(*s.find("name"), "name", "expected a non-empty string, found \"\"");
    out.name = *name;
  } else {
    out.name = "lamp[" + std::to_string(ordinal) + "]";
  }
  out.lamp.position_m = vec3(s, "position_m");
  out.lamp.worldFromLamp = orientation(s);
  out.lamp.color = optVec3(s, "color", kNonNegative).value_or(Vec3(1.0));
  if (auto mount = s.optString("mount")) {
    if (*mount == "vehicle") {
      out.mount = LampMount::Vehicle;
    } else if (*mount != "world") {
      s.failAt(*s.find("mount"), "mount", "expected \"world\" or \"vehicle\", found " + inQuotes(*mount));
    }
  }

  const std::string kinds = "\"isotropic\", \"spot\" or a path to a .ies, .ldt or .csv file";
  const std::string profile = s.string("profile", kinds);
  const toml::node& profileNode = *s.find("profile");
  const std::string found = "found profile = " + inQuotes(profile);

  // scale is meant for files, but issue 3's example writes scale = 1.0 in a spot lamp and
  // must parse as written: for a closed form it multiplies intensity_cd.
  const double scale = s.number("scale", kPositive, 1.0);
  Result<ProfileCache::Ptr> p = Error{""};
  if (profile == "isotropic" || profile == "spot") {
    const double intensity = s.number("intensity_cd", kNonNegative) * scale;
    if (profile == "isotropic") {
      s.forbid("inner_deg", "only allowed with profile = \"spot\", " + found);
      s.forbid("outer_deg", "only allowed with profile = \"spot\", " + found);
      p = cache.model("isotropic:" + formatNumber(intensity), IsotropicProfile{intensity});
    } else {
      const double outer = s.number("outer_deg", Range{0.0, 180.0, true, false});
      const double inner = s.number("inner_deg", Range{0.0, outer, false, true});
      p = cache.model("spot:" + formatNumber(intensity) + ":" + formatNumber(inner) + ":" + formatNumber(outer),
                      SpotProfile{intensity, radians(inner), radians(outer)});
    }
  } else if (hasProfileExtension(profile)) {
    s.forbid("intensity_cd", "not allowed with a profile file (use scale), " + found);
    s.forbid("inner_deg", "only allowed with profile = \"spot\", " + found);
    s.forbid("outer_deg", "only allowed with profile = \"spot\", " + found);
    const std::string path = resolvePath(baseDir, profile);
    if (std::string problem = checkFile(path); !problem.empty()) s.failAt(profileNode, "profile", problem);
    p = cache.file(path, scale);
  } else {
    s.failAt(profileNode, "profile", "expected " + kinds + ", found " + inQuotes(profile));
  }
  if (!p) s.failAt(profileNode, "profile", p.error().message);
  out.lamp.profile = std::move(p).value();
  out.aperture = parseAperture(s);
  return out;
}

// ---- [glow], [glare], [render] ------------------------------------------------------------

namespace {

// [glow], [glare], [render]: shared by scene files and service configs, so both accept exactly
// the same keys with the same checks.
constexpr std::array kGlowKeys{
    KeySpec{"enabled"},
    KeySpec{"model"},
    KeySpec{"fade_in"},
    KeySpec{"surfaces"},
    KeySpec{"ground"},
    KeySpec{"ground_reflectance"},
    KeySpec{"ground_height_m"},
};
constexpr std::array kGlareKeys{
    KeySpec{"enabled"},
    KeySpec{"age_years"},
    KeySpec{"pigmentation"},
};
constexpr std::array kRenderKeys{
    KeySpec{"airlight"},
    KeySpec{"gpu_pieces"},
};

constexpr std::array<std::string_view, 2> kDevices{"cpu", "gpu"};
constexpr std::array<std::string_view, 2> kGlowModels{"table", "apsf"};

}  // namespace

namespace {
constexpr std::array kBonnetKeys{
    KeySpec{"rear_m"}, KeySpec{"front_m"}, KeySpec{"left_m"}, KeySpec{"right_m"}, KeySpec{"height_m"}, KeySpec{"reflectance"},
};
}  // namespace

std::span<const KeySpec> bonnetKeys() { return kBonnetKeys; }

Bonnet parseBonnet(const Section& s, std::span<const KeySpec> extraKeys) {
  s.checkKeys(kBonnetKeys, extraKeys);
  Bonnet b;
  constexpr Range kAlong{-20.0, 20.0};
  b.rear_m = s.number("rear_m", kAlong, b.rear_m);
  b.front_m = s.number("front_m", kAlong, b.front_m);
  b.left_m = s.number("left_m", kAlong, b.left_m);
  b.right_m = s.number("right_m", kAlong, b.right_m);
  b.height_m = s.number("height_m", kAlong, b.height_m);
  b.reflectance = s.number("reflectance", kUnit, b.reflectance);
  if (!(b.front_m > b.rear_m))
    s.fail(s.line(), "front_m", "expected front_m > rear_m, found front_m = " + formatNumber(b.front_m) +
                                    ", rear_m = " + formatNumber(b.rear_m));
  if (!(b.left_m > b.right_m))
    s.fail(s.line(), "left_m", "expected left_m > right_m (y points left), found left_m = " + formatNumber(b.left_m) +
                                   ", right_m = " + formatNumber(b.right_m));
  return b;
}

std::span<const KeySpec> glowKeys() { return kGlowKeys; }
std::span<const KeySpec> glareKeys() { return kGlareKeys; }
std::span<const KeySpec> renderKeys() { return kRenderKeys; }

GlowOptions parseGlow(const Section& s, const GlowOptions& fallback) {
  s.checkKeys(kGlowKeys);
  GlowOptions g = fallback;
  g.enabled = s.boolean("enabled", true);
  g.model = s.choice("model", kGlowModels, toString(g.model)) == "apsf" ? GlowModel::Apsf : GlowModel::Table;
  g.fade_in = s.number("fade_in", Range{Apsf::minOpticalDistance(), kInf, false, false}, g.fade_in);
  g.surfaces = s.boolean("surfaces", g.surfaces);
  // The ground under the lamps (ground_correction.hpp): on with the fallback's reflectance (or
  // 0.1, dry asphalt, where the fallback has none) unless `ground = false`.
  const bool ground = s.boolean("ground", fallback.ground_reflectance >= 0.0);
  const double rho = s.number("ground_reflectance", Range{0.0, 0.95, false, false},
                              fallback.ground_reflectance >= 0.0 ? fallback.ground_reflectance : 0.1);
  g.ground_reflectance = ground ? rho : -1.0;
  g.ground_height_m = s.number("ground_height_m", Range{-1e4, 1e4, false, false}, fallback.ground_height_m);
  return g;
}

GlareOptions parseGlare(const Section& s, const GlareOptions& fallback) {
  s.checkKeys(kGlareKeys);
  GlareOptions g = fallback;
  g.enabled = s.boolean("enabled", true);
  g.age_years = s.number("age_years", Range{0.0, 120.0, false, false}, g.age_years);
  g.pigmentation = s.number("pigmentation", kUnit, g.pigmentation);
  return g;
}

RenderSettings parseRenderSettings(const Section& s, const RenderSettings& fallback, std::span<const KeySpec> extraKeys) {
  s.checkKeys(kRenderKeys, extraKeys);
  RenderSettings r = fallback;
  r.airlight = s.choice("airlight", kDevices, toString(r.airlight)) == "gpu" ? AirlightDevice::Gpu : AirlightDevice::Cpu;
  r.gpu_pieces = static_cast<int>(s.integer("gpu_pieces", 4, 1024, r.gpu_pieces));
  return r;
}

SceneEffects parseEffects(const Section& top) {
  SceneEffects fx;
  const std::string& file = top.file();
  const std::string prefix = top.label().empty() ? "" : top.label() + " ";
  if (const toml::table* t = top.optTable("glow")) fx.glow = parseGlow(Section(file, *t, prefix + "[glow]"));
  if (const toml::table* t = top.optTable("glare")) fx.glare = parseGlare(Section(file, *t, prefix + "[glare]"));
  if (const toml::table* t = top.optTable("render")) fx.render = parseRenderSettings(Section(file, *t, prefix + "[render]"));
  return fx;
}

}  // namespace fogbeam::config
