#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/files.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <string_view>
#include <variant>

namespace fogbeam {
namespace {

const std::string kScenes = std::string(FOGBEAM_TEST_DATA_DIR) + "/scenes";
const std::string kShipped = std::string(FOGBEAM_CONFIG_DIR) + "/scenes";

bool Contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

/// The error message of a scene that must not parse (relative paths resolve in kScenes).
std::string errorOf(const std::string& text) {
  const Result<Scene> r = parseScene(text, "bad.toml", kScenes);
  if (r) {
    ADD_FAILURE() << "parsed without error:\n" << text;
    return {};
  }
  return r.error().message;
}

Scene parse(const std::string& text) {
  Result<Scene> r = parseScene(text, "good.toml", kScenes);
  if (!r) {
    ADD_FAILURE() << r.error().message;
    return {};
  }
  return std::move(r).value();
}

// A valid fog and camera on lines 1–6, so that a snippet appended to it starts on line 7.
const std::string kFogAndCamera =
    "[fog]\n"
    "extinction_per_m = 0.04\n"
    "[camera]\n"
    "position_m = [0, 0, 1.2]\n"
    "width = 64\n"
    "height = 36\n";

void expectVecNear(const Vec3& actual, const Vec3& expected, double tol = 1e-12) {
  EXPECT_NEAR(actual.x, expected.x, tol);
  EXPECT_NEAR(actual.y, expected.y, tol);
  EXPECT_NEAR(actual.z, expected.z, tol);
}

void expectMatNear(const Mat3& actual, const Mat3& expected) {
  for (glm::length_t c = 0; c < 3; ++c) expectVecNear(actual[c], expected[c]);
}

double peakOf(const Profile& p) { return p.peak().intensity_cd; }

// ---- Every key ---------------------------------------------------------------------------------

TEST(SceneFile, ParsesEveryKeyIntoItsField) {
  const std::string path = kScenes + "/full.toml";
  const Result<Scene> r = loadScene(path);
  ASSERT_TRUE(r) << r.error().message;
  const Scene& s = r.value();
  EXPECT_EQ(s.source, path);

  // [fog]: visibility 50 m → K_t = ln 20 / 50; fog-mie with a 20 µm droplet.
  EXPECT_NEAR(s.fog.extinction_per_m, std::log(20.0) / 50.0, 1e-15);
  EXPECT_DOUBLE_EQ(s.fog.albedo, 0.9);
  EXPECT_DOUBLE_EQ(s.fog.ambient_cd_m2, 0.25);
  const auto* mie = std::get_if<FogMiePhase>(&s.fog.phase);
  ASSERT_NE(mie, nullptr) << describe(s.fog.phase);
  EXPECT_DOUBLE_EQ(mie->diameter_um, 20.0);
  EXPECT_DOUBLE_EQ(mie->g_hg, std::get<FogMiePhase>(makeFogMie(20.0).value()).g_hg);

  // [camera]
  expectVecNear(s.camera.position_m, Vec3(1.0, -2.0, 1.5));
  expectMatNear(s.camera.worldFromCamera, worldFromYawPitchRoll(radians(90.0), radians(10.0), radians(5.0)));
  EXPECT_DOUBLE_EQ(s.camera.fov_x, radians(45.0));
  EXPECT_EQ(s.camera.width, 320);
  EXPECT_EQ(s.camera.height, 200);

  // [[lamp]] × 5
  ASSERT_EQ(s.lamps.size(), 5u);
  EXPECT_EQ(s.lamps[0].name, "street");
  EXPECT_EQ(s.lamps[1].name, "torch");
  EXPECT_EQ(s.lamps[2].name, "lamp[3]");
  EXPECT_EQ(s.lamps[4].name, "lamp[5]");

  const Lamp& street = s.lamps[0].lamp;
  expectVecNear(street.position_m, Vec3(20.0, 5.0, 8.0));
  expectVecNear(street.color, Vec3(1.0, 0.8, 0.6));
  const auto* iso = std::get_if<IsotropicProfile>(&street.profile->model());
  ASSERT_NE(iso, nullptr);
  EXPECT_DOUBLE_EQ(iso->intensity_cd, 500.0);

  EXPECT_EQ(s.lamps[0].mount, LampMount::World);  // the default
  EXPECT_EQ(s.lamps[1].mount, LampMount::Vehicle);
  const Lamp& torch = s.lamps[1].lamp;
  expectMatNear(torch.worldFromLamp, worldFromYawPitchRoll(radians(180.0), 0.0, radians(30.0)));
  expectVecNear(torch.color, Vec3(1.0));
  const auto* spot = std::get_if<SpotProfile>(&torch.profile->model());
  ASSERT_NE(spot, nullptr);
  EXPECT_DOUBLE_EQ(spot->peak_cd, 2000.0);
  EXPECT_DOUBLE_EQ(spot->inner, radians(5.0));
  EXPECT_DOUBLE_EQ(spot->outer, radians(15.0));

  // The CSV lamp: the fixture peaks at 1000 cd; scale = 2.5 multiplies every value.
  const auto* tab = std::get_if<TabulatedProfile>(&s.lamps[2].lamp.profile->model());
  ASSERT_NE(tab, nullptr);
  EXPECT_NEAR(peakOf(*s.lamps[2].lamp.profile), 2500.0, 1e-9);
  EXPECT_NEAR(peakOf(*s.lamps[4].lamp.profile), 1000.0, 1e-9);
  expectVecNear(s.lamps[3].lamp.position_m, Vec3(45.0, 2.1, 0.65));

  // [[plane]] × 2: the normal is normalised; reflectance defaults to 0.15.
  ASSERT_EQ(s.planes.size(), 2u);
  expectVecNear(s.planes[0].point_m, Vec3(0.0, 0.0, -0.1));
  expectVecNear(s.planes[0].normal, Vec3(0.0, 0.0, 1.0));
  EXPECT_DOUBLE_EQ(s.planes[0].reflectance, 0.3);
  expectVecNear(s.planes[1].normal, Vec3(0.0, -1.0, 0.0));
  EXPECT_DOUBLE_EQ(s.planes[1].reflectance, 0.15);

  // gltf: resolved against the scene file's directory.
  ASSERT_TRUE(s.gltf_path.has_value());
  EXPECT_EQ(std::filesystem::path(*s.gltf_path), std::filesystem::path(kScenes + "/placeholder.glb").lexically_normal());
}

TEST(SceneFile, LampsWithTheSameFileAndScaleShareOneProfile) {
  const Result<Scene> r = loadScene(kScenes + "/full.toml");
  ASSERT_TRUE(r) << r.error().message;
  const auto& lamps = r.value().lamps;
  // "tiny_lamp.csv" and "./tiny_lamp.csv" with the same scale: one Profile (one set of tables).
  EXPECT_EQ(lamps[2].lamp.profile.get(), lamps[3].lamp.profile.get());
  // The same file with another scale is another profile.
  EXPECT_NE(lamps[2].lamp.profile.get(), lamps[4].lamp.profile.get());
}

TEST(SceneFile, OrientationFollowsThePhysicsNotes) {
  const Scene s = parse(kFogAndCamera +
                        "[[lamp]]\nposition_m = [0, 0, 0]\nyaw_deg = 180.0\nprofile = \"isotropic\"\nintensity_cd = 1\n"
                        "[[lamp]]\nposition_m = [0, 0, 0]\npitch_deg = 10.0\nprofile = \"isotropic\"\nintensity_cd = 1\n"
                        "[[lamp]]\nposition_m = [0, 0, 0]\nyaw_deg = 90.0\nprofile = \"isotropic\"\nintensity_cd = 1\n");
  ASSERT_EQ(s.lamps.size(), 3u);
  // yaw 180°: the photometric axis (+x column) points to world −x, the lamp's left to −y.
  expectVecNear(s.lamps[0].lamp.worldFromLamp[0], Vec3(-1.0, 0.0, 0.0));
  expectVecNear(s.lamps[0].lamp.worldFromLamp[1], Vec3(0.0, -1.0, 0.0));
  // positive pitch tilts the axis down.
  expectVecNear(s.lamps[1].lamp.worldFromLamp[0], Vec3(std::cos(radians(10.0)), 0.0, -std::sin(radians(10.0))));
  // positive yaw turns left (+y).
  expectVecNear(s.lamps[2].lamp.worldFromLamp[0], Vec3(0.0, 1.0, 0.0));
}

TEST(SceneFile, CameraLooksAlongItsYawAndPitch) {
  const Scene s = parse(
      "[fog]\nextinction_per_m = 0.04\n"
      "[camera]\nposition_m = [0, 0, 1.2]\nyaw_deg = 180.0\npitch_deg = 5.0\nwidth = 64\nheight = 36\n");
  const Vec3 axis(-std::cos(radians(5.0)), 0.0, -std::sin(radians(5.0)));
  expectVecNear(s.camera.worldFromCamera[0], axis);
  expectVecNear(s.camera.rayDirection(32.0, 18.0), axis, 1e-12);  // the image centre
}

TEST(SceneFile, VisibilityIsConvertedWithTheMorFormula) {
  const Scene s = parse(
      "[fog]\nvisibility_m = 75.0\n"
      "[camera]\nposition_m = [0, 0, 1.2]\nwidth = 64\nheight = 36\n");
  EXPECT_NEAR(s.fog.extinction_per_m, std::log(20.0) / 75.0, 1e-15);
  EXPECT_NEAR(s.fog.extinction_per_m, 0.03994, 1e-5);
  EXPECT_DOUBLE_EQ(s.fog.extinction_per_m, extinctionFromVisibility(75.0));
}

TEST(SceneFile, DefaultsApplyToOmittedKeys) {
  const Scene s = parse(kFogAndCamera +
                        "[[lamp]]\nposition_m = [1, 2, 3]\nprofile = \"isotropic\"\nintensity_cd = 100\n"
                        "[[plane]]\npoint_m = [0, 0, 0]\nnormal = [0, 0, 1]\n");
  EXPECT_DOUBLE_EQ(s.fog.albedo, 1.0);
  EXPECT_DOUBLE_EQ(s.fog.ambient_cd_m2, 0.0);
  const auto* hg = std::get_if<HenyeyGreensteinPhase>(&s.fog.phase);
  ASSERT_NE(hg, nullptr) << describe(s.fog.phase);
  EXPECT_DOUBLE_EQ(hg->g, 0.85);
  expectMatNear(s.camera.worldFromCamera, Mat3(1.0));
  EXPECT_DOUBLE_EQ(s.camera.fov_x, radians(60.0));
  ASSERT_EQ(s.lamps.size(), 1u);
  EXPECT_EQ(s.lamps[0].name, "lamp[1]");
  expectMatNear(s.lamps[0].lamp.worldFromLamp, Mat3(1.0));
  expectVecNear(s.lamps[0].lamp.color, Vec3(1.0));
  ASSERT_EQ(s.planes.size(), 1u);
  EXPECT_DOUBLE_EQ(s.planes[0].reflectance, 0.15);
  EXPECT_FALSE(s.gltf_path.has_value());
}

TEST(SceneFile, AScaledFileMultipliesEveryCandelaValue) {
  const Scene s = parse(kFogAndCamera +
                        "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"tiny_lamp.csv\"\n"
                        "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"tiny_lamp.csv\"\nscale = 0.5\n");
  const auto& a = std::get<TabulatedProfile>(s.lamps[0].lamp.profile->model());
  const auto& b = std::get<TabulatedProfile>(s.lamps[1].lamp.profile->model());
  ASSERT_EQ(a.candela.size(), b.candela.size());
  for (std::size_t i = 0; i < a.candela.size(); ++i) EXPECT_DOUBLE_EQ(b.candela[i], 0.5 * a.candela[i]);
}

TEST(SceneFile, ScaleAlsoMultipliesAClosedFormIntensity) {
  // Issue 3's example writes scale = 1.0 in a spot lamp; it must parse, and then it scales.
  const Scene s = parse(kFogAndCamera +
                        "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"spot\"\nintensity_cd = 5\n"
                        "inner_deg = 1\nouter_deg = 5\nscale = 2\n"
                        "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 5\nscale = 0.5\n");
  EXPECT_DOUBLE_EQ(std::get<SpotProfile>(s.lamps[0].lamp.profile->model()).peak_cd, 10.0);
  EXPECT_DOUBLE_EQ(std::get<IsotropicProfile>(s.lamps[1].lamp.profile->model()).intensity_cd, 2.5);
}

TEST(SceneFile, IsotropicPhaseAndIntegerNumbersAreAccepted) {
  const Scene s = parse(
      "[fog]\nextinction_per_m = 1\nphase = \"isotropic\"\nalbedo = 1\n"
      "[camera]\nposition_m = [0, 0, 1]\nfov_x_deg = 90\nwidth = 16384\nheight = 1\n");
  EXPECT_TRUE(std::holds_alternative<IsotropicPhase>(s.fog.phase));
  EXPECT_DOUBLE_EQ(s.fog.extinction_per_m, 1.0);
  EXPECT_EQ(s.camera.width, 16384);
  EXPECT_EQ(s.camera.height, 1);
}

TEST(SceneFile, FrustumGivesAnOffAxisCameraAndItsHeight) {
  // One channel of a three-screen cab: 40° to the left, 10° to the right of the view axis.
  const Scene s = parse(
      "[fog]\nextinction_per_m = 0.04\n"
      "[camera]\nposition_m = [0, 0, 1.2]\nyaw_deg = 30\nfrustum_deg = [40, 10, 12.5, 7.5]\nwidth = 800\n");
  const Camera& c = s.camera;
  const double f = 800.0 / (std::tan(radians(40.0)) + std::tan(radians(10.0)));
  EXPECT_NEAR(c.focalLengthPixels(), f, 1e-9);
  EXPECT_EQ(c.height, static_cast<int>(std::round(f * (std::tan(radians(12.5)) + std::tan(radians(7.5))))));
  ASSERT_TRUE(c.principal_px.has_value());
  EXPECT_NEAR(c.principal_px->x, f * std::tan(radians(40.0)), 1e-9);
  EXPECT_NEAR(c.principal_px->y, f * std::tan(radians(12.5)), 1e-9);
  EXPECT_NEAR(c.frustum().left, radians(40.0), 1e-12);
  EXPECT_NEAR(c.frustum().right, radians(10.0), 1e-12);
  EXPECT_NEAR(c.frustum().up, radians(12.5), 1e-12);
  // The left edge's ray: the camera's yaw plus its left half-angle.
  const Vec3 left = c.rayDirection(0.0, c.principal_px->y);
  EXPECT_NEAR(std::atan2(left.y, left.x), radians(70.0), 1e-12);
  // An explicit height within 0.5 px of f (tan up + tan down) is accepted as written.
  const Scene t = parse(
      "[fog]\nextinction_per_m = 0.04\n"
      "[camera]\nposition_m = [0, 0, 1.2]\nfrustum_deg = [30, 30, 20, 20]\nwidth = 640\nheight = 403\n");
  EXPECT_EQ(t.camera.height, 403);
  EXPECT_NEAR(t.camera.focalLengthPixels(), 320.0 / std::tan(radians(30.0)), 1e-9);
  // Without frustum_deg the camera stays centred.
  EXPECT_FALSE(parse(kFogAndCamera).camera.principal_px.has_value());
}

// ---- Shipped scenes ----------------------------------------------------------------------------

TEST(SceneFile, ShippedOncomingSceneLoadsWithOneSharedLowBeamProfile) {
  const Result<Scene> r = loadScene(kShipped + "/oncoming.toml");
  ASSERT_TRUE(r) << r.error().message;
  const Scene& s = r.value();
  EXPECT_NEAR(s.fog.extinction_per_m, std::log(20.0) / 75.0, 1e-15);
  ASSERT_TRUE(std::holds_alternative<HenyeyGreensteinPhase>(s.fog.phase));
  EXPECT_DOUBLE_EQ(std::get<HenyeyGreensteinPhase>(s.fog.phase).g, 0.85);
  ASSERT_EQ(s.lamps.size(), 4u);
  for (const SceneLamp& l : s.lamps) {
    EXPECT_EQ(l.lamp.profile.get(), s.lamps[0].lamp.profile.get()) << l.name;
    EXPECT_TRUE(std::holds_alternative<TabulatedProfile>(l.lamp.profile->model())) << l.name;
  }
  // The ego lamps look ahead, the oncoming ones back towards the camera.
  expectVecNear(s.lamps[0].lamp.worldFromLamp[0], Vec3(1.0, 0.0, 0.0));
  expectVecNear(s.lamps[2].lamp.worldFromLamp[0], Vec3(-1.0, 0.0, 0.0));
  EXPECT_GT(s.lamps[2].lamp.position_m.y, 1.75);  // in the other lane
  ASSERT_EQ(s.planes.size(), 1u);
}

TEST(SceneFile, ShippedSpotsSceneIsTheIssueExample) {
  const Result<Scene> r = loadScene(kShipped + "/spots.toml");
  ASSERT_TRUE(r) << r.error().message;
  const Scene& s = r.value();
  EXPECT_DOUBLE_EQ(s.fog.extinction_per_m, 0.04);
  EXPECT_DOUBLE_EQ(s.fog.albedo, 0.95);
  ASSERT_EQ(s.lamps.size(), 1u);
  const auto& spot = std::get<SpotProfile>(s.lamps[0].lamp.profile->model());
  EXPECT_DOUBLE_EQ(spot.peak_cd, 20000.0);
  EXPECT_EQ(s.camera.width, 640);
  EXPECT_EQ(s.camera.height, 360);
  ASSERT_EQ(s.planes.size(), 1u);
}

TEST(SceneFile, TheDocumentedExampleParses) {
  const auto doc = readTextFile(std::string(FOGBEAM_CONFIG_DIR) + "/../docs/scene.md");
  ASSERT_TRUE(doc) << doc.error().message;
  const std::size_t begin = doc.value().find("```toml\n");
  ASSERT_NE(begin, std::string::npos);
  const std::size_t end = doc.value().find("```", begin + 8);
  ASSERT_NE(end, std::string::npos);
  const Scene s = parse(doc.value().substr(begin + 8, end - begin - 8));
  EXPECT_EQ(s.lamps.size(), 1u);
  EXPECT_EQ(s.planes.size(), 1u);
}

// ---- Bad files: each message names file, line, section, key and what was expected -------------

TEST(SceneFileErrors, MissingTableOrKey) {
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\n"), "bad.toml: missing table [camera]");
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\nheight = 36\n"),
               "bad.toml:3: [camera] width: missing (expected an integer in [1, 16384])");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nprofile = \"isotropic\"\nintensity_cd = 1\n"),
               "bad.toml:7: [[lamp]] #1 position_m: missing");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\n"),
               "bad.toml:7: [[lamp]] #1 profile: missing");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\n"),
               "bad.toml:7: [[lamp]] #1 intensity_cd: missing (expected a number >= 0)");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera +
                       "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"spot\"\nintensity_cd = 1\nouter_deg = 10\n"),
               "bad.toml:7: [[lamp]] #1 inner_deg: missing (expected a number in [0, 10))");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[plane]]\npoint_m = [0, 0, 0]\n"),
               "bad.toml:7: [[plane]] #1 normal: missing");
}

TEST(SceneFileErrors, VisibilityAndExtinctionAreExclusiveAndOneIsRequired) {
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nextinction_per_m = 0.04\nvisibility_m = 75\n[camera]\nposition_m = [0, 0, 1]\n"
                       "width = 4\nheight = 4\n"),
               "bad.toml:3: [fog]: give exactly one of extinction_per_m and visibility_m, found both "
               "(extinction_per_m on line 2)");
  EXPECT_PRED2(Contains, errorOf("[fog]\nalbedo = 0.9\n[camera]\nposition_m = [0, 0, 1]\nwidth = 4\nheight = 4\n"),
               "bad.toml:1: [fog]: missing extinction_per_m or visibility_m");
}

TEST(SceneFileErrors, UnknownKeysAreNamedWithTheirLine) {
  const std::string lamp = kFogAndCamera +
                           "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 1\n"
                           "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\nintensty_cd = 1\n";
  EXPECT_PRED2(Contains, errorOf(lamp),
               "bad.toml:14: [[lamp]] #2: unknown key 'intensty_cd' (did you mean 'intensity_cd'?)");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "fov = 60\n"), "bad.toml:7: [camera]: unknown key 'fov'");
  EXPECT_PRED2(Contains, errorOf("gltff = \"x.glb\"\n" + kFogAndCamera),
               "bad.toml:1: unknown top-level key 'gltff' (did you mean 'gltf'?)");
  // A top-level key written after a table header belongs to that table (TOML scoping).
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "gltf = \"road.glb\"\n"), "bad.toml:7: [camera]: unknown key 'gltf'");
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\nvisibility = 3\n"),
               "bad.toml:3: [fog]: unknown key 'visibility'");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[plane]]\npoint_m = [0, 0, 0]\nnormal = [0, 0, 1]\nalbedo = 0.1\n"),
               "bad.toml:10: [[plane]] #1: unknown key 'albedo'");
}

TEST(SceneFileErrors, UnknownProfileOrPhase) {
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"laser\"\n"),
               "bad.toml:9: [[lamp]] #1 profile: expected \"isotropic\", \"spot\" or a path to a .ies, .ldt or "
               ".csv file, found \"laser\"");
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nextinction_per_m = 0.04\nphase = \"rayleigh\"\n[camera]\nposition_m = [0, 0, 1]\n"
                       "width = 4\nheight = 4\n"),
               "bad.toml:3: [fog] phase: expected \"isotropic\", \"henyey-greenstein\" or \"fog-mie\", found "
               "\"rayleigh\"");
}

// Found by a sweep of odd scenes (2026-11-29): each message names the key and line the file
// wrote and the value as written.
TEST(SceneFileErrors, ValuesAreShownAsWrittenAtTheirKey) {
  // A float where an integer is expected reads as a float.
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\nwidth = 320.0\nheight = 36\n"),
               "bad.toml:5: [camera] width: expected an integer in [1, 16384], found 320.0");
  // A visibility whose extinction overflows is the visibility's error, at its line.
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nvisibility_m = 1e-320\n[camera]\nposition_m = [0, 0, 1]\nwidth = 4\nheight = 4\n"),
               "bad.toml:2: [fog] visibility_m: expected a number > 0 whose extinction ln(20) / visibility_m is finite, "
               "found ");
  // A tiny normal is a direction (its length squared underflows), a zero one an error.
  const Scene tiny = parse(kFogAndCamera + "[[plane]]\npoint_m = [0, 0, 0]\nnormal = [0, 0, 1e-300]\n");
  ASSERT_EQ(tiny.planes.size(), 1u);
  EXPECT_EQ(tiny.planes[0].normal, Vec3(0.0, 0.0, 1.0));
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[plane]]\npoint_m = [0, 0, 0]\nnormal = [0, 0, 0]\n"),
               "bad.toml:9: [[plane]] #1 normal: expected a non-zero vector, found [0, 0, 0]");
}

TEST(SceneFileErrors, ProfileFileNotFoundNamesSceneLineAndResolvedPath) {
  const std::string resolved = (std::filesystem::path(kScenes) / "no_such_lamp.ies").lexically_normal().string();
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"./no_such_lamp.ies\"\n"),
               "bad.toml:9: [[lamp]] #1 profile: file not found: " + resolved);
  EXPECT_PRED2(Contains, errorOf("gltf = \"road.glb\"\n" + kFogAndCamera),
               "bad.toml:1: gltf: file not found: " + kScenes + "/road.glb");
  // A profile file that exists but does not parse: the scene's place, then the file's own message.
  const std::string broken =
      errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"broken_lamp.csv\"\n");
  EXPECT_PRED2(Contains, broken, "bad.toml:9: [[lamp]] #1 profile: ");
  EXPECT_PRED2(Contains, broken, "broken_lamp.csv:4:");
  const Result<Scene> missing = loadScene(kScenes + "/no_such_scene.toml");
  ASSERT_FALSE(missing);
  EXPECT_PRED2(Contains, missing.error().message, kScenes + "/no_such_scene.toml: cannot open");
}

TEST(SceneFileErrors, NonFiniteNumbersAreRejected) {
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = nan\n"),
               "bad.toml:2: [fog] extinction_per_m: expected a number > 0, found nan");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, inf, 0]\n"),
               "bad.toml:8: [[lamp]] #1 position_m[1]: expected a finite number, found inf");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nyaw_deg = -nan\n"),
               "bad.toml:9: [[lamp]] #1 yaw_deg: expected a finite number, found");
}

TEST(SceneFileErrors, SizesMustBePositiveIntegers) {
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\nwidth = -640\n"),
               "bad.toml:5: [camera] width: expected an integer in [1, 16384], found -640");
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\nwidth = 64\nheight = 0\n"),
               "bad.toml:6: [camera] height: expected an integer in [1, 16384], found 0");
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\nwidth = 64.5\n"),
               "bad.toml:5: [camera] width: expected an integer in [1, 16384], found 64.5");
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\nwidth = 16385\n"),
               "found 16385");
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = -0.04\n"),
               "bad.toml:2: [fog] extinction_per_m: expected a number > 0, found -0.04");
  EXPECT_PRED2(Contains, errorOf("[fog]\nvisibility_m = 0\n"),
               "bad.toml:2: [fog] visibility_m: expected a number > 0, found 0");
}

TEST(SceneFileErrors, WrongTypesSayWhatWasFound) {
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = \"bright\"\n"),
               "bad.toml:10: [[lamp]] #1 intensity_cd: expected a number >= 0, found the string \"bright\"");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0]\n"),
               "bad.toml:8: [[lamp]] #1 position_m: expected an array of 3 numbers [x, y, z], found an array of 2 "
               "elements");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = 3\n"),
               "bad.toml:9: [[lamp]] #1 profile: expected a string, found 3");
  EXPECT_PRED2(Contains, errorOf("fog = 3\n"), "bad.toml:1: fog: expected a table [fog], found 3");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[lamp]\nposition_m = [0, 0, 0]\n"),
               "bad.toml:7: lamp: expected an array of tables [[lamp]], found a table");
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\nalbedo = true\n"),
               "bad.toml:3: [fog] albedo: expected a number in [0, 1], found the boolean true");
}

TEST(SceneFileErrors, KeysOfAnotherModelAreRejected) {
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\nphase = \"isotropic\"\ng = 0.85\n"),
               "bad.toml:4: [fog] g: only allowed with phase = \"henyey-greenstein\", found phase = \"isotropic\"");
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\ng = 0.8\ndroplet_diameter_um = 10\n"),
               "bad.toml:4: [fog] droplet_diameter_um: only allowed with phase = \"fog-mie\"");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"tiny_lamp.csv\"\nintensity_cd = 5\n"),
               "bad.toml:10: [[lamp]] #1 intensity_cd: not allowed with a profile file (use scale)");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera +
                       "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 5\nouter_deg = 5\n"),
               "bad.toml:11: [[lamp]] #1 outer_deg: only allowed with profile = \"spot\"");
}

TEST(SceneFileErrors, FrustumKeysSayWhatWasExpected) {
  const std::string head = "[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\n";  // lines 1-4
  EXPECT_PRED2(Contains, errorOf(head + "fov_x_deg = 60\nfrustum_deg = [30, 30, 20, 20]\nwidth = 640\n"),
               "bad.toml:6: [camera]: give at most one of fov_x_deg and frustum_deg, found both (fov_x_deg on line 5)");
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [30, 30, 20]\nwidth = 640\n"),
               "bad.toml:5: [camera] frustum_deg: expected an array of 4 numbers [left, right, up, down], found an "
               "array of 3 elements");
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [30, 89, 20, 20]\nwidth = 640\n"),
               "bad.toml:5: [camera] frustum_deg[1]: expected a number in (-89, 89), found 89");
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [30, 30, \"up\", 20]\nwidth = 640\n"),
               "bad.toml:5: [camera] frustum_deg[2]: expected a number in (-89, 89), found the string \"up\"");
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [-20, 10, 20, 20]\nwidth = 640\n"),
               "bad.toml:5: [camera] frustum_deg: expected left + right > 0, found left = -20, right = 10");
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [30, 30, 5, -5]\nwidth = 640\n"),
               "bad.toml:5: [camera] frustum_deg: expected up + down > 0, found up = 5, down = -5");
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [30, 30, 20, 20]\n"),
               "bad.toml:3: [camera] width: missing (expected an integer in [1, 16384])");
  // f = 640 / (2 tan 30°), so square pixels need 2 f tan 20° = 403.46 px.
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [30, 30, 20, 20]\nwidth = 640\nheight = 360\n"),
               "bad.toml:7: [camera] height: expected 403 (within 0.5 of 403.46");
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [30, 30, 20, 20]\nwidth = 640\nheight = 360\n"),
               "square pixels; or leave height out), found 360");
  // A frustum so flat that no pixel row is left.
  EXPECT_PRED2(Contains, errorOf(head + "frustum_deg = [80, 80, 0.001, 0]\nwidth = 4\n"),
               "bad.toml:5: [camera] frustum_deg: the derived height");
}

TEST(SceneFileErrors, ValuesOutOfRange) {
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\ng = 1.0\n"),
               "bad.toml:3: [fog] g: expected a number in (-1, 1), found 1");
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\nphase = \"fog-mie\"\ndroplet_diameter_um = 2\n"),
               "bad.toml:4: [fog] droplet_diameter_um: expected a number in [5, 50], found 2");
  EXPECT_PRED2(Contains,
               errorOf("[fog]\nextinction_per_m = 0.04\n[camera]\nposition_m = [0, 0, 1]\nfov_x_deg = 180\n"),
               "bad.toml:5: [camera] fov_x_deg: expected a number in (0, 180), found 180");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"spot\"\nintensity_cd = 5\n"
                                       "inner_deg = 20\nouter_deg = 10\n"),
               "bad.toml:11: [[lamp]] #1 inner_deg: expected a number in [0, 10), found 20");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"tiny_lamp.csv\"\nscale = 0\n"),
               "bad.toml:10: [[lamp]] #1 scale: expected a number > 0, found 0");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\ncolor = [1, -0.5, 1]\n"),
               "bad.toml:9: [[lamp]] #1 color[1]: expected a number >= 0, found -0.5");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[lamp]]\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\n"
                                       "intensity_cd = 5\nmount = \"car\"\n"),
               "bad.toml:11: [[lamp]] #1 mount: expected \"world\" or \"vehicle\", found \"car\"");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[[plane]]\npoint_m = [0, 0, 0]\nnormal = [0, 0, 0]\n"),
               "bad.toml:9: [[plane]] #1 normal: expected a non-zero vector");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + "[[plane]]\npoint_m = [0, 0, 0]\nnormal = [0, 0, 1]\nreflectance = 1.5\n"),
               "bad.toml:10: [[plane]] #1 reflectance: expected a number in [0, 1], found 1.5");
}

TEST(SceneFileErrors, LampNamesAreUnique) {
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera +
                       "[[lamp]]\nname = \"a\"\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 1\n"
                       "[[lamp]]\nname = \"a\"\nposition_m = [0, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 1\n"),
               "bad.toml:13: [[lamp]] #2 name: expected a unique name, found \"a\" again (first used by [[lamp]] #1)");
}

TEST(SceneFileErrors, SyntaxErrorsGiveLineAndColumn) {
  const std::string msg = errorOf("[fog]\nextinction_per_m = 0.04\nalbedo = = 0.9\n");
  EXPECT_PRED2(Contains, msg, "bad.toml:3:");
  EXPECT_PRED2(Contains, errorOf("[fog]\nextinction_per_m = 0.04\nextinction_per_m = 0.05\n"), "bad.toml:3:");
  EXPECT_PRED2(Contains, errorOf("[[lamp]]\nposition_m = [0, 0, 0\n"), "bad.toml:");
}

// ---- Issue 7's keys: [glow], [glare], [render] and lamp apertures ------------------------------

const std::string kLamp =
    "[[lamp]]\n"
    "name = \"head\"\n"
    "position_m = [2, 0.7, 0.65]\n"
    "profile = \"spot\"\n"
    "intensity_cd = 20000\n"
    "inner_deg = 4\n"
    "outer_deg = 14\n"
    "color = [1, 0.5, 0.25]\n";

TEST(SceneEffects, OffAndCpuByDefault) {
  const Scene s = parse(kFogAndCamera);
  EXPECT_FALSE(s.effects.glow.enabled);
  EXPECT_FALSE(s.effects.glare.enabled);
  EXPECT_EQ(s.effects.render.airlight, AirlightDevice::Cpu);
  EXPECT_EQ(s.effects.render.gpu_pieces, 64);
}

TEST(SceneEffects, EveryKeyIntoItsField) {
  const Scene s = parse(kFogAndCamera +
                        "[glow]\nfade_in = 3.5\n"
                        "[glare]\nage_years = 65\npigmentation = 0.2\n"
                        "[render]\nairlight = \"gpu\"\ngpu_pieces = 128\n");
  EXPECT_TRUE(s.effects.glow.enabled);  // the table's presence turns it on
  EXPECT_DOUBLE_EQ(s.effects.glow.fade_in, 3.5);
  EXPECT_TRUE(s.effects.glare.enabled);
  EXPECT_DOUBLE_EQ(s.effects.glare.age_years, 65.0);
  EXPECT_DOUBLE_EQ(s.effects.glare.pigmentation, 0.2);
  EXPECT_EQ(s.effects.render.airlight, AirlightDevice::Gpu);
  EXPECT_EQ(s.effects.render.gpu_pieces, 128);
  const Scene off = parse(kFogAndCamera + "[glow]\nenabled = false\n[glare]\nenabled = false\n");
  EXPECT_FALSE(off.effects.glow.enabled);
  EXPECT_FALSE(off.effects.glare.enabled);
}

// [glow] ground, ground_reflectance, ground_height_m (docs/scene.md): on with ρ 0.1 on z = 0 by
// default; `ground = false` is infinite fog (ground_reflectance < 0 in GlowOptions); ρ in [0, 0.95].
TEST(SceneEffects, TheGroundKeys) {
  const Scene d = parse(kFogAndCamera + "[glow]\n");
  EXPECT_DOUBLE_EQ(d.effects.glow.ground_reflectance, 0.1);
  EXPECT_DOUBLE_EQ(d.effects.glow.ground_height_m, 0.0);
  const Scene snow = parse(kFogAndCamera + "[glow]\nground_reflectance = 0.8\nground_height_m = -1.5\n");
  EXPECT_DOUBLE_EQ(snow.effects.glow.ground_reflectance, 0.8);
  EXPECT_DOUBLE_EQ(snow.effects.glow.ground_height_m, -1.5);
  const Scene off = parse(kFogAndCamera + "[glow]\nground = false\nground_reflectance = 0.3\n");
  EXPECT_LT(off.effects.glow.ground_reflectance, 0.0);
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glow]\nground_reflectance = 0.99\n"),
               "bad.toml:8: [glow] ground_reflectance");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glow]\nground = 1\n"), "bad.toml:8: [glow] ground");
}

TEST(SceneEffects, BadValuesSayWhereAndWhat) {
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glow]\nfade_in = 0.5\n"), "bad.toml:8: [glow] fade_in");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glow]\nradius = 2\n"), "bad.toml:8: [glow]: unknown key 'radius'");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glare]\nage_years = 130\n"), "bad.toml:8: [glare] age_years");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glare]\npigmentation = -0.1\n"), "bad.toml:8: [glare] pigmentation");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glare]\nenabled = 1\n"), "bad.toml:8: [glare] enabled");
  const std::string device = errorOf(kFogAndCamera + "[render]\nairlight = \"cuda\"\n");
  EXPECT_PRED2(Contains, device, "bad.toml:8: [render] airlight");
  EXPECT_PRED2(Contains, device, "\"gpu\"");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[render]\ngpu_pieces = 2\n"), "bad.toml:8: [render] gpu_pieces");
}

TEST(SceneEffects, ApertureLampsBecomeTheirPointLamps) {
  const Scene s = parse(kFogAndCamera + kLamp + "aperture = \"rectangle\"\naperture_size_m = [0.2, 0.1]\n");
  ASSERT_EQ(s.lamps.size(), 9u);  // 3 × 3 by default
  Vec3 color{0.0};
  for (const SceneLamp& l : s.lamps) {
    EXPECT_EQ(l.lamp.profile, s.lamps[0].lamp.profile);  // one shared profile
    color += l.lamp.color;
    EXPECT_NEAR(std::abs(l.lamp.position_m.y - 0.7), 0.0, 0.1 + 1e-12);
    EXPECT_NEAR(std::abs(l.lamp.position_m.z - 0.65), 0.0, 0.05 + 1e-12);
    EXPECT_DOUBLE_EQ(l.lamp.position_m.x, 2.0);  // the face is ⟂ to the lamp's +x
  }
  EXPECT_NEAR(color.x, 1.0, 1e-14);
  EXPECT_NEAR(color.y, 0.5, 1e-14);
  EXPECT_NEAR(color.z, 0.25, 1e-14);
  EXPECT_EQ(s.lamps[0].name, "head [1/9]");
  const Scene disc = parse(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = 0.15\naperture_samples = 2\n");
  EXPECT_EQ(disc.lamps.size(), 4u);  // 1 ring × 4 angles
  const Scene point = parse(kFogAndCamera + kLamp + "aperture = \"point\"\n");
  EXPECT_EQ(point.lamps.size(), 1u);
  EXPECT_EQ(point.lamps[0].name, "head");
}

TEST(SceneEffects, BadAperturesSayWhereAndWhat) {
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"square\"\n"), "[[lamp]] #1 aperture");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"rectangle\"\n"),
               "bad.toml:7: [[lamp]] #1 aperture_size_m: missing (expected [width, height]");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"rectangle\"\naperture_size_m = 0.2\n"),
               "bad.toml:16: [[lamp]] #1 aperture_size_m: expected [width, height]");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = [0.2, 0.1]\n"),
               "bad.toml:16: [[lamp]] #1 aperture_size_m: expected the diameter");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = 0\n"),
               "[[lamp]] #1 aperture_size_m");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"rectangle\"\naperture_size_m = [0.2, 3]\n"),
               "[[lamp]] #1 aperture_size_m[1]");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = 0.1\naperture_samples = 9\n"),
               "bad.toml:17: [[lamp]] #1 aperture_samples");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture_size_m = 0.1\n"),
               "bad.toml:15: [[lamp]] #1 aperture_size_m: only allowed with aperture = \"rectangle\" or \"disc\"");
}

// A lamp with a face (physics/aperture.hpp) as the scene expands it into named point lamps.
TEST(ApertureLamps, SceneLampsExpandWithNumberedNames) {
  SceneLamp sl;
  sl.name = "ego left low beam";
  sl.mount = LampMount::Vehicle;
  sl.lamp.profile = makeProfile(IsotropicProfile{100.0}).value();
  sl.aperture = Aperture{ApertureShape::Rectangle, 0.2, 0.1, 3};
  const std::vector<SceneLamp> points = expandSceneLamp(sl);
  ASSERT_EQ(points.size(), 9u);
  EXPECT_EQ(points[0].name, "ego left low beam [1/9]");
  EXPECT_EQ(points[8].name, "ego left low beam [9/9]");
  for (const SceneLamp& p : points) {
    EXPECT_EQ(p.mount, LampMount::Vehicle);
    EXPECT_EQ(p.aperture.shape, ApertureShape::Point);
  }
  sl.aperture = Aperture{};
  const std::vector<SceneLamp> same = expandSceneLamp(sl);
  ASSERT_EQ(same.size(), 1u);
  EXPECT_EQ(same[0].name, sl.name);
}

}  // namespace
}  // namespace fogbeam
