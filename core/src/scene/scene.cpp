// fogbeam — scene files (TOML): fog, camera, lamps, planes, optional glTF.
//
// The lists of keys below are the parser's contract: a key that is not in its list is an error,
// never ignored. docs/scene.md documents each key (type, unit, default, range) in one place, its
// key tables; sceneKeyTables() binds each list to its table, and a test requires that the table
// lists exactly these keys (tests/plugin/test_config_docs.cpp).
//
// Errors read "file:line: [section] key: expected …, found …" (util/toml_section.hpp); the [fog]
// and lamp tables are read by scene/sections.hpp, shared with the scenario and service-config
// parsers, which embed them.
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/scene/sections.hpp>
#include <fogbeam/util/files.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
#include <utility>
#include <vector>

namespace fogbeam {

namespace {

namespace fs = std::filesystem;
using namespace config;  // NOLINT(google-build-using-namespace): this file is the scene format's part of it

// ---- The keys -------------------------------------------------------------------------------

constexpr std::array kTopKeys{
    KeySpec{"fog"},
    KeySpec{"camera"},
    KeySpec{"lamp"},
    KeySpec{"plane"},
    KeySpec{"gltf"},
    KeySpec{"glow"},
    KeySpec{"glare"},
    KeySpec{"render"},
    KeySpec{"bonnet"},
};

constexpr std::array kCameraKeys{
    KeySpec{"position_m"},
    KeySpec{"yaw_deg"},
    KeySpec{"pitch_deg"},
    KeySpec{"roll_deg"},
    KeySpec{"fov_x_deg"},
    KeySpec{"frustum_deg"},
    KeySpec{"width"},
    KeySpec{"height"},
};

constexpr std::array kPlaneKeys{
    KeySpec{"point_m"},
    KeySpec{"normal"},
    KeySpec{"reflectance"},
};

constexpr double kDefaultFovX_deg = 60.0;
constexpr std::int64_t kMaxImageSide = 16384;
constexpr double kDefaultReflectance = 0.15;

// ---- Sections -------------------------------------------------------------------------------

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
  const Vec3 position = vec3(s, "position_m");
  const Mat3 worldFromCamera = orientation(s);
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
  c.worldFromCamera = worldFromCamera;
  return c;
}

Plane parsePlane(const Section& s) {
  s.checkKeys(kPlaneKeys);
  Plane pl;
  pl.point_m = vec3(s, "point_m");
  const Vec3 n = vec3(s, "normal");
  // Scaled by its largest component first: |n|² of [0, 0, 1e-300] underflows to 0, yet it is a
  // direction.
  const double big = std::max({std::abs(n.x), std::abs(n.y), std::abs(n.z)});
  if (!(big > 0.0)) s.failAt(*s.find("normal"), "normal", "expected a non-zero vector, found [0, 0, 0]");
  pl.normal = glm::normalize(n / big);
  pl.reflectance = s.number("reflectance", kUnit, kDefaultReflectance);
  return pl;
}

Scene parseRoot(const toml::table& root, const std::string& name, const std::string& baseDir) {
  const Section top(name, root, "");
  top.checkKeys(kTopKeys);
  Scene scene;
  scene.source = name;
  scene.fog = parseFog(Section(name, top.requiredTable("fog"), "[fog]"));
  scene.camera = parseCamera(Section(name, top.requiredTable("camera"), "[camera]"));

  ProfileCache cache;
  std::map<std::string, std::string, std::less<>> usedNames;  // lamp name → its section
  top.forEachEntry("lamp", [&](const toml::table& t, std::string label, std::size_t ordinal) {
    const Section s(name, t, std::move(label));
    SceneLamp lamp = parseLamp(s, ordinal, baseDir, cache);
    if (auto [it, fresh] = usedNames.emplace(lamp.name, s.label()); !fresh) {
      const toml::node* n = s.find("name");
      s.fail(n ? lineOf(n->source()) : s.line(), "name", "expected a unique name, found " + inQuotes(lamp.name) +
                                                             " again (first used by " + it->second + ")");
    }
    // A lamp with an aperture becomes its point lamps here, so that every renderer of the
    // scene (airlight, GL and CPU surfaces) sees the near field without knowing of apertures.
    for (SceneLamp& point : expandSceneLamp(lamp)) scene.lamps.push_back(std::move(point));
  });
  top.forEachEntry("plane", [&](const toml::table& t, std::string label, std::size_t) {
    scene.planes.push_back(parsePlane(Section(name, t, std::move(label))));
  });

  if (auto gltf = top.optString("gltf")) {
    const std::string path = resolvePath(baseDir, *gltf);
    if (std::string problem = checkFile(path); !problem.empty()) top.failAt(*top.find("gltf"), "gltf", problem);
    scene.gltf_path = path;
  }
  scene.effects = parseEffects(top);
  if (const toml::table* t = top.optTable("bonnet")) scene.body.push_back(parseBonnet(Section(name, *t, "[bonnet]")).quad());
  return scene;
}

}  // namespace

Quad Bonnet::quad(const Mat3& worldFromFrame, const Vec3& origin_m) const {
  Quad q;
  q.corner_m = origin_m + worldFromFrame * Vec3(rear_m, right_m, height_m);
  q.edge_u_m = worldFromFrame * Vec3(front_m - rear_m, 0.0, 0.0);
  q.edge_v_m = worldFromFrame * Vec3(0.0, left_m - right_m, 0.0);
  q.reflectance = reflectance;
  return q;
}

std::vector<SceneLamp> expandSceneLamp(const SceneLamp& lamp) {
  if (lamp.aperture.shape == ApertureShape::Point) return {lamp};
  const std::vector<Lamp> points = expandAperture(lamp.lamp, lamp.aperture);
  std::vector<SceneLamp> out;
  out.reserve(points.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    SceneLamp p;
    p.name = lamp.name + " [" + std::to_string(k + 1) + "/" + std::to_string(points.size()) + "]";
    p.lamp = points[k];
    p.mount = lamp.mount;
    out.push_back(std::move(p));
  }
  return out;
}

Result<Scene> parseScene(std::string_view text, const std::string& name, const std::string& baseDir) {
  return parseTomlFile<Scene>(text, name, [&](const toml::table& root) { return parseRoot(root, name, baseDir); });
}

Result<Scene> loadScene(const std::string& path) {
  auto text = readTextFile(path);
  if (!text) return text.error();
  return parseScene(text.value(), path, fs::path(path).parent_path().string());
}

std::vector<config::KeyTable> config::sceneKeyTables() {
  return {
      {"scene.md", "Top level", "scene file: top level", keyNames({kTopKeys})},
      {"scene.md", "`[fog]`: homogeneous medium",
       "scene [fog]; scenario [fog] and service [fog] (docs there refer to this table)", keyNames({fogKeys()})},
      {"scene.md", "`[camera]`: pinhole, square pixels, centred or off-axis", "scene [camera]", keyNames({kCameraKeys})},
      {"scene.md", "`[[lamp]]`: point lamp (any number)",
       "scene [[lamp]]; service [[ego.lamp]] and [[traffic_class.lamp]] (there without mount, plus their own keys)",
       keyNames({lampKeys()})},
      {"scene.md", "`[[plane]]`: infinite Lambertian plane (any number)", "scene [[plane]]", keyNames({kPlaneKeys})},
      {"scene.md", "`[bonnet]`: the ego car's bonnet", "scene [bonnet]; service [ego.bonnet]", keyNames({bonnetKeys()})},
      {"scene.md", "`[glow]`", "scene [glow]", keyNames({glowKeys()})},
      {"scene.md", "`[glare]`", "scene [glare]", keyNames({glareKeys()})},
      {"scene.md", "`[render]`", "scene [render]", keyNames({renderKeys()})},
  };
}

}  // namespace fogbeam
