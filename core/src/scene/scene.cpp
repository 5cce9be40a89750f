// fogbeam — scene files (TOML): fog, camera, lamps, planes, optional glTF.
//
// The tables of keys below are the parser's contract; docs/scene.md documents each key with
// its type, unit, default and range (Mitsuba style: one place, next to the parser). A key
// that is not in its table is an error, never ignored.
//
// Errors read "file:line: [section] key: expected …, found …". Inside this file a failure
// is thrown as SceneError and turned into an Error at the two entry points, so the checks
// read as straight-line code; no exception leaves parseScene / loadScene.
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/scene/scene.hpp>

#include <toml++/toml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <span>
#include <system_error>
#include <utility>

namespace fogbeam {

namespace {

namespace fs = std::filesystem;

// ---- The keys -------------------------------------------------------------------------------

/// One accepted key: its name and a one-line summary (type, unit, default, range).
struct KeySpec {
  std::string_view name;
  std::string_view summary;
};

constexpr std::array kTopKeys{
    KeySpec{"fog", "table [fog], required"},
    KeySpec{"camera", "table [camera], required"},
    KeySpec{"lamp", "array of tables [[lamp]], optional, any number"},
    KeySpec{"plane", "array of tables [[plane]], optional, any number"},
    KeySpec{"gltf", "string, path relative to the scene file, optional; the file must exist"},
};

constexpr std::array kFogKeys{
    KeySpec{"extinction_per_m", "number, 1/m, > 0; exactly one of extinction_per_m and visibility_m"},
    KeySpec{"visibility_m", "number, m, > 0; MOR: K_t = ln(20) / V"},
    KeySpec{"albedo", "number, default 1.0, [0, 1]"},
    KeySpec{"phase", "string, default \"henyey-greenstein\": \"isotropic\" | \"henyey-greenstein\" | \"fog-mie\""},
    KeySpec{"g", "number, default 0.85, (-1, 1); henyey-greenstein only"},
    KeySpec{"droplet_diameter_um", "number, um, default 10, [5, 50]; fog-mie only"},
    KeySpec{"ambient_cd_m2", "number, cd/m2, default 0, >= 0"},
};

constexpr std::array kCameraKeys{
    KeySpec{"position_m", "[x, y, z], m, required"},
    KeySpec{"yaw_deg", "number, deg, default 0"},
    KeySpec{"pitch_deg", "number, deg, default 0; positive tilts the view down"},
    KeySpec{"roll_deg", "number, deg, default 0"},
    KeySpec{"fov_x_deg", "number, deg, default 60, (0, 180); a centred camera; not with frustum_deg"},
    KeySpec{"frustum_deg", "[left, right, up, down], deg, optional, each in (-89, 89), left + right > 0, "
                           "up + down > 0; an off-axis camera; not with fov_x_deg"},
    KeySpec{"width", "integer, pixels, required, [1, 16384]"},
    KeySpec{"height", "integer, pixels, [1, 16384]; required unless frustum_deg gives it (then within 0.5 px)"},
};

constexpr std::array kLampKeys{
    KeySpec{"name", "string, default \"lamp[N]\" (N counts [[lamp]] entries from 1), unique"},
    KeySpec{"position_m", "[x, y, z], m, required"},
    KeySpec{"yaw_deg", "number, deg, default 0"},
    KeySpec{"pitch_deg", "number, deg, default 0; positive tilts the beam down"},
    KeySpec{"roll_deg", "number, deg, default 0"},
    KeySpec{"profile", "string, required: \"isotropic\" | \"spot\" | path to .ies/.ldt/.csv"},
    KeySpec{"intensity_cd", "number, cd, >= 0; required for isotropic and spot, forbidden for files"},
    KeySpec{"inner_deg", "number, deg, spot only, required; 0 <= inner_deg < outer_deg"},
    KeySpec{"outer_deg", "number, deg, spot only, required; outer_deg <= 180"},
    KeySpec{"scale", "number, default 1, > 0; multiplies every candela value (meant for files)"},
    KeySpec{"color", "[r, g, b], default [1, 1, 1], each >= 0"},
    KeySpec{"mount", "string, default \"world\": \"world\" | \"vehicle\" (moves with the camera)"},
};

constexpr std::array kPlaneKeys{
    KeySpec{"point_m", "[x, y, z], m, required"},
    KeySpec{"normal", "[x, y, z], required, non-zero; normalised on load"},
    KeySpec{"reflectance", "number, default 0.15, [0, 1]"},
};

constexpr double kDefaultAlbedo = 1.0;
constexpr std::string_view kDefaultPhase = "henyey-greenstein";
constexpr double kDefaultG = 0.85;
constexpr double kDefaultDropletDiameter_um = 10.0;
constexpr double kDefaultFovX_deg = 60.0;
constexpr std::int64_t kMaxImageSide = 16384;
constexpr double kDefaultReflectance = 0.15;

// ---- Messages -------------------------------------------------------------------------------

struct SceneError {
  Error error;
};

constexpr double kInf = std::numeric_limits<double>::infinity();

std::string formatNumber(double x) {
  std::array<char, 32> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), x);
  if (ec != std::errc()) return "?";
  return std::string(buf.data(), end);
}

std::string inQuotes(std::string_view s) { return "\"" + std::string(s) + "\""; }

/// What a node holds, for "found …": a value as written, or its kind.
std::string describeNode(const toml::node& n) {
  if (const auto* v = n.as_integer()) return std::to_string(v->get());
  if (const auto* v = n.as_floating_point()) return formatNumber(v->get());
  if (const auto* v = n.as_string()) return "the string " + inQuotes(v->get());
  if (const auto* v = n.as_boolean()) return std::string("the boolean ") + (v->get() ? "true" : "false");
  if (const auto* v = n.as_array()) return "an array of " + std::to_string(v->size()) + " elements";
  if (n.is_table()) return "a table";
  if (n.is_date()) return "a date";
  if (n.is_time()) return "a time";
  if (n.is_date_time()) return "a date-time";
  return "an unknown value";
}

std::size_t lineOf(const toml::source_region& r) { return r.begin.line; }

std::size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0u : 1u)});
      diag = up;
    }
  }
  return row[b.size()];
}

/// A closed or open interval for numeric keys; infinite ends are unbounded.
struct Range {
  double lo = -kInf;
  double hi = kInf;
  bool loOpen = false;
  bool hiOpen = false;

  [[nodiscard]] bool contains(double x) const {
    if (!std::isfinite(x)) return false;
    return (loOpen ? x > lo : x >= lo) && (hiOpen ? x < hi : x <= hi);
  }
  [[nodiscard]] std::string expectation() const {
    const bool hasLo = std::isfinite(lo), hasHi = std::isfinite(hi);
    if (!hasLo && !hasHi) return "a finite number";
    if (!hasHi) return std::string("a number ") + (loOpen ? "> " : ">= ") + formatNumber(lo);
    if (!hasLo) return std::string("a number ") + (hiOpen ? "< " : "<= ") + formatNumber(hi);
    return std::string("a number in ") + (loOpen ? "(" : "[") + formatNumber(lo) + ", " + formatNumber(hi) +
           (hiOpen ? ")" : "]");
  }
};

constexpr Range kAnyFinite{};
constexpr Range kPositive{0.0, kInf, true, false};
constexpr Range kNonNegative{0.0, kInf, false, false};
constexpr Range kUnit{0.0, 1.0, false, false};

// ---- One table of the file ------------------------------------------------------------------

/// Typed, range-checked access to one TOML table; every failure names file, line, section
/// and key.
class Section {
 public:
  Section(const std::string& file, const toml::table& table, std::string label)
      : file_(file), table_(table), label_(std::move(label)) {}

  [[noreturn]] void fail(std::size_t line, std::string_view key, const std::string& what) const {
    std::string where = label_;
    if (!key.empty()) where += (where.empty() ? "" : " ") + std::string(key);
    throw SceneError{fileError(file_, line, where.empty() ? what : where + ": " + what)};
  }
  [[noreturn]] void failAt(const toml::node& n, std::string_view key, const std::string& what) const {
    fail(lineOf(n.source()), key, what);
  }

  /// Rejects every key that is not in `allowed`, suggesting the closest accepted one.
  template <std::size_t N>
  void checkKeys(const std::array<KeySpec, N>& allowed) const {
    for (const auto& [key, node] : table_) {
      const std::string_view k = key.str();
      if (std::any_of(allowed.begin(), allowed.end(), [&](const KeySpec& s) { return s.name == k; })) continue;
      std::string what = (label_.empty() ? "unknown top-level key '" : "unknown key '") + std::string(k) + "'";
      std::string_view best;
      std::size_t bestDistance = 3;  // suggest only near misses (at most 2 edits)
      for (const KeySpec& s : allowed) {
        if (const std::size_t d = editDistance(k, s.name); d < bestDistance) {
          bestDistance = d;
          best = s.name;
        }
      }
      if (!best.empty()) what += " (did you mean '" + std::string(best) + "'?)";
      fail(lineOf(key.source()), "", what);
    }
  }

  [[nodiscard]] const toml::node* find(std::string_view key) const { return table_.get(key); }
  [[nodiscard]] std::size_t line() const { return lineOf(table_.source()); }
  [[nodiscard]] const std::string& label() const { return label_; }

  [[noreturn]] void missing(std::string_view key, const std::string& expected) const {
    fail(line(), key, "missing (expected " + expected + ")");
  }

  /// A key that must not appear here: `why` says when it is allowed.
  void forbid(std::string_view key, const std::string& why) const {
    if (const toml::node* n = find(key)) failAt(*n, key, why);
  }

  [[nodiscard]] double numberOf(const toml::node& n, std::string_view key, const Range& r) const {
    double x = 0.0;
    if (const auto* f = n.as_floating_point()) {
      x = f->get();
    } else if (const auto* i = n.as_integer()) {
      x = static_cast<double>(i->get());
    } else {
      failAt(n, key, "expected " + r.expectation() + ", found " + describeNode(n));
    }
    if (!r.contains(x)) failAt(n, key, "expected " + r.expectation() + ", found " + describeNode(n));
    return x;
  }

  [[nodiscard]] std::optional<double> optNumber(std::string_view key, const Range& r) const {
    const toml::node* n = find(key);
    if (!n) return std::nullopt;
    return numberOf(*n, key, r);
  }
  [[nodiscard]] double number(std::string_view key, const Range& r, double fallback) const {
    return optNumber(key, r).value_or(fallback);
  }
  [[nodiscard]] double number(std::string_view key, const Range& r) const {
    if (auto x = optNumber(key, r)) return *x;
    missing(key, r.expectation());
  }

  [[nodiscard]] std::int64_t integer(std::string_view key, std::int64_t lo, std::int64_t hi) const {
    const std::string expected = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    const toml::node* n = find(key);
    if (!n) missing(key, expected);
    const auto* i = n->as_integer();
    if (!i || i->get() < lo || i->get() > hi) failAt(*n, key, "expected " + expected + ", found " + describeNode(*n));
    return i->get();
  }

  /// [x, y, z]: an array of exactly three numbers, each within `r`.
  [[nodiscard]] std::optional<Vec3> optVec3(std::string_view key, const Range& r = kAnyFinite) const {
    const toml::node* n = find(key);
    if (!n) return std::nullopt;
    const auto* a = n->as_array();
    if (!a || a->size() != 3) {
      failAt(*n, key, "expected an array of 3 numbers [x, y, z], found " + describeNode(*n));
    }
    Vec3 v{0.0};
    for (glm::length_t c = 0; c < 3; ++c) {
      const std::string element = std::string(key) + "[" + std::to_string(c) + "]";
      v[c] = numberOf(*a->get(static_cast<std::size_t>(c)), element, r);
    }
    return v;
  }
  [[nodiscard]] Vec3 vec3(std::string_view key, const Range& r = kAnyFinite) const {
    if (auto v = optVec3(key, r)) return *v;
    missing(key, "an array of 3 numbers [x, y, z]");
  }

  [[nodiscard]] std::optional<std::string> optString(std::string_view key) const {
    const toml::node* n = find(key);
    if (!n) return std::nullopt;
    const auto* s = n->as_string();
    if (!s) failAt(*n, key, "expected a string, found " + describeNode(*n));
    return s->get();
  }
  [[nodiscard]] std::string string(std::string_view key, const std::string& expected) const {
    if (auto s = optString(key)) return *s;
    missing(key, expected);
  }

  /// worldFromBody from yaw_deg, pitch_deg, roll_deg (each default 0).
  [[nodiscard]] Mat3 orientation() const {
    const double yaw = number("yaw_deg", kAnyFinite, 0.0);
    const double pitch = number("pitch_deg", kAnyFinite, 0.0);
    const double roll = number("roll_deg", kAnyFinite, 0.0);
    return worldFromYawPitchRoll(radians(yaw), radians(pitch), radians(roll));
  }

 private:
  const std::string& file_;
  const toml::table& table_;
  std::string label_;
};

// ---- Paths and profiles ---------------------------------------------------------------------

std::string resolvePath(const std::string& baseDir, const std::string& relative) {
  const fs::path p(relative);
  if (p.is_absolute() || baseDir.empty()) return p.lexically_normal().string();
  return (fs::path(baseDir) / p).lexically_normal().string();
}

/// Empty when `path` is a readable regular file's name, else what is wrong with it.
std::string checkFile(const std::string& path) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) return "file not found: " + path;
  if (!fs::is_regular_file(st)) return "not a regular file: " + path;
  return {};
}

bool hasProfileExtension(std::string_view s) {
  const std::size_t dot = s.find_last_of('.');
  if (dot == std::string_view::npos) return false;
  std::string ext(s.substr(dot + 1));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == "ies" || ext == "ldt" || ext == "csv";
}

/// Profiles loaded during one scene load, so that lamps with equal parameters (the same
/// file and scale, the same spot) share one Profile and hence one set of airlight tables.
class ProfileCache {
 public:
  using Ptr = std::shared_ptr<const Profile>;

  /// A closed-form model; `key` identifies its parameters exactly.
  Result<Ptr> model(const std::string& key, Profile::Model m) {
    if (auto it = byKey_.find(key); it != byKey_.end()) return it->second;
    auto p = makeProfile(std::move(m));
    if (!p) return p.error();
    byKey_.emplace(key, p.value());
    return p;
  }

  /// A profile file (already resolved and checked to exist), every candela value × scale.
  Result<Ptr> file(const std::string& path, double scale) {
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

 private:
  std::map<std::string, Ptr> files_;  // resolved path → unscaled profile
  std::map<std::string, Ptr> byKey_;
};

// ---- Sections -------------------------------------------------------------------------------

Medium parseFog(const Section& s) {
  s.checkKeys(kFogKeys);
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

/// frustum_deg = [left, right, up, down] with width and an optional height: an off-axis camera.
Camera parseFrustumCamera(const Section& s, const toml::node& node) {
  const auto* a = node.as_array();
  if (!a || a->size() != 4)
    s.failAt(node, "frustum_deg", "expected an array of 4 numbers [left, right, up, down], found " + describeNode(node));
  constexpr Range kHalfAngle{-89.0, 89.0, true, true};
  std::array<double, 4> deg{};
  for (std::size_t i = 0; i < 4; ++i)
    deg[i] = s.numberOf(*a->get(i), "frustum_deg[" + std::to_string(i) + "]", kHalfAngle);
  if (!(deg[0] + deg[1] > 0.0))
    s.failAt(node, "frustum_deg",
             "expected left + right > 0, found left = " + formatNumber(deg[0]) + ", right = " + formatNumber(deg[1]));
  if (!(deg[2] + deg[3] > 0.0))
    s.failAt(node, "frustum_deg",
             "expected up + down > 0, found up = " + formatNumber(deg[2]) + ", down = " + formatNumber(deg[3]));
  const FrustumAngles angles{radians(deg[0]), radians(deg[1]), radians(deg[2]), radians(deg[3])};
  const int width = static_cast<int>(s.integer("width", 1, kMaxImageSide));
  Result<Camera> derived = Camera::fromFrustum(angles, width, 0);
  // Camera::fromFrustum's messages start with "frustum: "; here the key already says so.
  auto what = [](const Error& e) {
    constexpr std::string_view kPrefix = "frustum: ";
    return e.message.rfind(kPrefix, 0) == 0 ? e.message.substr(kPrefix.size()) : e.message;
  };
  if (!derived) s.failAt(node, "frustum_deg", what(derived.error()));
  const toml::node* h = s.find("height");
  if (!h) return std::move(derived).value();
  const int height = static_cast<int>(s.integer("height", 1, kMaxImageSide));
  // Square pixels fix the height: f (tan up + tan down), f = width / (tan left + tan right).
  const double exact = derived->focalLengthPixels() * (std::tan(angles.up) + std::tan(angles.down));
  if (!(std::abs(exact - height) <= 0.5))
    s.failAt(*h, "height",
             "expected " + formatNumber(std::round(exact)) + " (within 0.5 of " + formatNumber(exact) +
                 " px, the height that frustum_deg and width give square pixels; or leave height out), found " +
                 std::to_string(height));
  Result<Camera> c = Camera::fromFrustum(angles, width, height);
  if (!c) s.failAt(*h, "height", what(c.error()));
  return std::move(c).value();
}

Camera parseCamera(const Section& s) {
  s.checkKeys(kCameraKeys);
  const Vec3 position = s.vec3("position_m");
  const Mat3 orientation = s.orientation();
  Camera c;
  if (const toml::node* frustum = s.find("frustum_deg")) {
    if (const toml::node* fov = s.find("fov_x_deg"))
      s.failAt(*frustum, "",
               "give at most one of fov_x_deg and frustum_deg, found both (fov_x_deg on line " +
                   std::to_string(lineOf(fov->source())) + ")");
    c = parseFrustumCamera(s, *frustum);
  } else {
    c.fov_x = radians(s.number("fov_x_deg", Range{0.0, 180.0, true, true}, kDefaultFovX_deg));
    c.width = static_cast<int>(s.integer("width", 1, kMaxImageSide));
    c.height = static_cast<int>(s.integer("height", 1, kMaxImageSide));
  }
  c.position_m = position;
  c.worldFromCamera = orientation;
  return c;
}

SceneLamp parseLamp(const Section& s, std::size_t ordinal, const std::string& baseDir, ProfileCache& cache) {
  s.checkKeys(kLampKeys);
  SceneLamp out;
  if (auto name = s.optString("name")) {
    if (name->empty()) s.failAt(*s.find("name"), "name", "expected a non-empty string, found \"\"");
    out.name = *name;
  } else {
    out.name = "lamp[" + std::to_string(ordinal) + "]";
  }
  out.lamp.position_m = s.vec3("position_m");
  out.lamp.worldFromLamp = s.orientation();
  out.lamp.color = s.optVec3("color", kNonNegative).value_or(Vec3(1.0));
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
  return out;
}

Plane parsePlane(const Section& s) {
  s.checkKeys(kPlaneKeys);
  Plane pl;
  pl.point_m = s.vec3("point_m");
  const Vec3 n = s.vec3("normal");
  if (!(glm::length(n) > 0.0)) s.failAt(*s.find("normal"), "normal", "expected a non-zero vector, found [0, 0, 0]");
  pl.normal = glm::normalize(n);
  pl.reflectance = s.number("reflectance", kUnit, kDefaultReflectance);
  return pl;
}

/// The tables of an array of tables ([[lamp]], [[plane]]), each with its section label.
template <class F>
void forEachEntry(const Section& top, std::string_view key, F&& f) {
  const toml::node* n = top.find(key);
  if (!n) return;
  const std::string expected = "expected an array of tables [[" + std::string(key) + "]], found ";
  const auto* a = n->as_array();
  if (!a) top.failAt(*n, key, expected + describeNode(*n));
  for (std::size_t i = 0; i < a->size(); ++i) {
    const toml::node& e = *a->get(i);
    const auto* t = e.as_table();
    if (!t) top.failAt(e, key, expected + "an array holding " + describeNode(e));
    f(*t, "[[" + std::string(key) + "]] #" + std::to_string(i + 1), i + 1);
  }
}

const toml::table& requiredTable(const Section& top, std::string_view key) {
  const toml::node* n = top.find(key);
  if (!n) top.fail(0, "", "missing table [" + std::string(key) + "]");
  const auto* t = n->as_table();
  if (!t) top.failAt(*n, key, "expected a table [" + std::string(key) + "], found " + describeNode(*n));
  return *t;
}

Scene parseRoot(const toml::table& root, const std::string& name, const std::string& baseDir) {
  const Section top(name, root, "");
  top.checkKeys(kTopKeys);
  Scene scene;
  scene.source = name;
  scene.fog = parseFog(Section(name, requiredTable(top, "fog"), "[fog]"));
  scene.camera = parseCamera(Section(name, requiredTable(top, "camera"), "[camera]"));

  ProfileCache cache;
  std::map<std::string, std::string, std::less<>> usedNames;  // lamp name → its section
  forEachEntry(top, "lamp", [&](const toml::table& t, std::string label, std::size_t ordinal) {
    const Section s(name, t, std::move(label));
    SceneLamp lamp = parseLamp(s, ordinal, baseDir, cache);
    if (auto [it, fresh] = usedNames.emplace(lamp.name, s.label()); !fresh) {
      const toml::node* n = s.find("name");
      s.fail(n ? lineOf(n->source()) : s.line(), "name", "expected a unique name, found " + inQuotes(lamp.name) +
                                                             " again (first used by " + it->second + ")");
    }
    scene.lamps.push_back(std::move(lamp));
  });
  forEachEntry(top, "plane", [&](const toml::table& t, std::string label, std::size_t) {
    scene.planes.push_back(parsePlane(Section(name, t, std::move(label))));
  });

  if (auto gltf = top.optString("gltf")) {
    const std::string path = resolvePath(baseDir, *gltf);
    if (std::string problem = checkFile(path); !problem.empty()) top.failAt(*top.find("gltf"), "gltf", problem);
    scene.gltf_path = path;
  }
  return scene;
}

}  // namespace

Result<Scene> parseScene(std::string_view text, const std::string& name, const std::string& baseDir) {
  try {
    const toml::table root = toml::parse(text, name);
    return parseRoot(root, name, baseDir);
  } catch (const toml::parse_error& e) {
    const toml::source_position& at = e.source().begin;
    return Error{name + ":" + std::to_string(at.line) + ":" + std::to_string(at.column) + ": " +
                 std::string(e.description())};
  } catch (const SceneError& e) {
    return e.error;
  } catch (const std::exception& e) {  // allocation failure and the like: still no throw
    return Error{name + ": " + e.what()};
  }
}

Result<Scene> loadScene(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return text.error();
  return parseScene(text.value(), path, fs::path(path).parent_path().string());
}

}  // namespace fogbeam
