// The GL surface pass against the CPU analytic renderer (renderSurfacesCpu), closed forms and
// ray–plane / ray–quad distances. Needs EGL (Mesa surfaceless here): without it every test skips
// with the reason; set FOGBEAM_REQUIRE_GL=1 to turn such a skip into a failure (GPU CI).
// On failure the GL and expected images are written as PFM next to each other in the build dir.
// FOGBEAM_TEST_GL_SHADING=gpu|cpu picks where the suite's pass lights its pixels (GlOptions::shading;
// default: auto, the CPU on llvmpipe): ctest runs the suite once each way (tests/CMakeLists.txt).
#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/physics/profile.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

namespace fogbeam {
namespace {

// ---------------------------------------------------------------------------------------------
// Fixture: one GL surface pass for the whole suite.

std::unique_ptr<GlSurfacePass>& sharedPass() {
  static std::unique_ptr<GlSurfacePass> pass;
  return pass;
}
std::string& skipReason() {
  static std::string reason;
  return reason;
}

GlOptions suiteOptions() {
  GlOptions o;
  const char* mode = std::getenv("FOGBEAM_TEST_GL_SHADING");
  if (mode && std::string(mode) == "gpu") o.shading = SurfaceShading::Gpu;
  if (mode && std::string(mode) == "cpu") o.shading = SurfaceShading::Cpu;
  return o;
}

class GlSurfacePassTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (sharedPass() || !skipReason().empty()) return;
    auto pass = GlSurfacePass::create(suiteOptions());
    if (pass) {
      sharedPass() = std::move(pass).value();
      std::printf("GL surface pass: %s\n", sharedPass()->description().c_str());
    } else {
      skipReason() = pass.error().message;
    }
  }

  void SetUp() override {
    if (sharedPass()) return;
    const std::string& why = skipReason();
    // Missing EGL / GL 4.3 is the environment; anything else (a shader that does not compile) is a bug.
    const bool environment = why.rfind("no EGL available", 0) == 0 || why.rfind("could not create an OpenGL", 0) == 0 ||
                             why.rfind("EGL platform", 0) == 0 || why.rfind("OpenGL 4.3 or later", 0) == 0;
    const char* require = std::getenv("FOGBEAM_REQUIRE_GL");
    if (environment && !(require && std::string(require) == "1")) GTEST_SKIP() << "no usable EGL/OpenGL: " << why;
    FAIL() << "GlSurfacePass::create failed: " << why;
  }

  GlSurfacePass& pass() { return *sharedPass(); }
};

// ---------------------------------------------------------------------------------------------
// Helpers.

void writePfm(const std::string& path, int w, int h, const std::vector<float>& data, int channels) {
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return;
  std::fprintf(f, "%s\n%d %d\n-1.0\n", channels == 3 ? "PF" : "Pf", w, h);
  for (int j = h - 1; j >= 0; --j)  // PFM stores the bottom row first
    std::fwrite(data.data() + static_cast<std::size_t>(j) * static_cast<std::size_t>(w * channels), sizeof(float),
                static_cast<std::size_t>(w * channels), f);
  std::fclose(f);
}

/// Writes <name>_gl_{rgb,distance}.pfm and <name>_expected_{rgb,distance}.pfm when the test failed.
void dumpOnFailure(const std::string& name, const SurfaceBuffers& gl, const SurfaceBuffers& expected) {
  if (!::testing::Test::HasFailure()) return;
  const std::string base = std::string(FOGBEAM_TEST_OUTPUT_DIR) + "/" + name;
  writePfm(base + "_gl_rgb.pfm", gl.width, gl.height, gl.rgb, 3);
  writePfm(base + "_expected_rgb.pfm", expected.width, expected.height, expected.rgb, 3);
  writePfm(base + "_gl_distance.pfm", gl.width, gl.height, gl.distance, 1);
  writePfm(base + "_expected_distance.pfm", expected.width, expected.height, expected.distance, 1);
  std::printf("images written to %s_{gl,expected}_{rgb,distance}.pfm\n", base.c_str());
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto k = static_cast<std::size_t>(std::clamp(p / 100.0 * static_cast<double>(v.size() - 1), 0.0,
                                                      static_cast<double>(v.size() - 1)));
  return v[k];
}

struct ErrorStats {
  std::size_t n = 0;
  double p50 = 0, p95 = 0, p99 = 0, max = 0;
};

ErrorStats stats(const std::vector<double>& errs) {
  ErrorStats s;
  s.n = errs.size();
  s.p50 = percentile(errs, 50);
  s.p95 = percentile(errs, 95);
  s.p99 = percentile(errs, 99);
  s.max = errs.empty() ? 0.0 : *std::max_element(errs.begin(), errs.end());
  return s;
}

void print(const char* what, const ErrorStats& s) {
  std::printf("%s: %zu px, relative error p50 %.2e  p95 %.2e  p99 %.2e  max %.2e\n", what, s.n, s.p50, s.p95, s.p99, s.max);
}

Camera makeCamera(const Vec3& pos, double yawDeg, double pitchDeg, int w, int h, double fovDeg = 60.0) {
  Camera c;
  c.position_m = pos;
  c.worldFromCamera = worldFromYawPitchRoll(radians(yawDeg), radians(pitchDeg), 0.0);
  c.fov_x = radians(fovDeg);
  c.width = w;
  c.height = h;
  return c;
}

SceneLamp makeLamp(const std::string& name, const Vec3& pos, double yawDeg, double pitchDeg, Profile::Model model,
                   const Vec3& color = Vec3(1.0)) {
  SceneLamp sl;
  sl.name = name;
  sl.lamp.position_m = pos;
  sl.lamp.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(pitchDeg), 0.0);
  auto p = makeProfile(std::move(model));
  EXPECT_TRUE(p.has_value()) << (p ? "" : p.error().message);
  if (p) sl.lamp.profile = std::move(p).value();
  sl.lamp.color = color;
  return sl;
}

Medium fog(double kt, double ambient) {
  Medium m;
  m.extinction_per_m = kt;
  m.albedo = 0.95;
  m.ambient_cd_m2 = ambient;
  return m;
}

/// Relative errors of channel `c` over pixels where the expected value exceeds `floor`.
std::vector<double> luminanceErrors(const SurfaceBuffers& gl, const SurfaceBuffers& ref, double floor) {
  std::vector<double> errs;
  for (std::size_t k = 0; k < ref.rgb.size(); ++k) {
    const double e = ref.rgb[k];
    if (e > floor) errs.push_back(std::abs(static_cast<double>(gl.rgb[k]) - e) / e);
  }
  return errs;
}

// ---------------------------------------------------------------------------------------------
// (1) A plane lit by a spot: GL luminance against the closed-form illuminance.

Scene spotScene() {
  Scene s;
  s.source = "spot test";
  s.fog = fog(0.03, 0.0);
  s.camera = makeCamera(Vec3(-4.0, 0.0, 3.0), 0.0, 25.0, 320, 180);
  // A spot 4 m above the road, 6 m ahead, aimed 50° down and a little to the left.
  s.lamps.push_back(makeLamp("spot", Vec3(2.0, 0.0, 4.0), 10.0, 50.0, SpotProfile{20000.0, radians(8.0), radians(20.0)}));
  s.planes.push_back(Plane{Vec3(0.0), Vec3(0.0, 0.0, 1.0), 0.3});
  return s;
}

TEST_F(GlSurfacePassTest, PlaneLitBySpotMatchesAnalyticIlluminance) {
  const Scene scene = spotScene();
  SurfaceBuffers gl;
  ASSERT_TRUE(pass().render(scene, gl).has_value());
  ASSERT_EQ(gl.width, scene.camera.width);
  ASSERT_EQ(gl.height, scene.camera.height);

  // The closed form, written out here independently of renderSurfacesCpu:
  //   L_s = ρ/π · I(ψ) cos(inc) e^{−K_t r}/r² · e^{−K_t t},  I(ψ) = peak (ψ ≤ inner), linear to 0 at outer.
  const Camera& cam = scene.camera;
  const Lamp& lamp = scene.lamps[0].lamp;
  const auto& spot = std::get<SpotProfile>(lamp.profile->model());
  const double kt = scene.fog.extinction_per_m, rho = scene.planes[0].reflectance;
  SurfaceBuffers expected;
  expected.resize(cam.width, cam.height);
  double peak = 0.0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const Vec3 d = cam.rayDirection(i + 0.5, j + 0.5);
      const auto px = static_cast<std::size_t>(j * cam.width + i);
      if (d.z >= 0.0) continue;
      const double t = -cam.position_m.z / d.z;
      const Vec3 x = cam.position_m + t * d;
      const Vec3 toX = x - lamp.position_m;
      const double r = glm::length(toX);
      const double psi = std::acos(std::clamp(glm::dot(toX / r, lamp.worldFromLamp[0]), -1.0, 1.0));
      const double intensity = psi <= spot.inner   ? spot.peak_cd
                               : psi >= spot.outer ? 0.0
                                                   : spot.peak_cd * (spot.outer - psi) / (spot.outer - spot.inner);
      const double cosInc = -toX.z / r;
      const double l = rho / kPi * intensity * cosInc * std::exp(-kt * r) / (r * r) * std::exp(-kt * t);
      for (int c = 0; c < 3; ++c) expected.rgb[3 * px + static_cast<std::size_t>(c)] = static_cast<float>(l);
      expected.distance[px] = static_cast<float>(t);
      peak = std::max(peak, l);
    }
  ASSERT_GT(peak, 0.0);

  // Lit pixels: expected > 1e-3 of the peak. This keeps the whole cone including the linear
  // ramp and drops only the outermost sliver where I → 0 at the outer edge and a relative
  // error is meaningless (there the absolute error is < 1e-3 · peak anyway).
  const auto errs = luminanceErrors(gl, expected, 1e-3 * peak);
  const ErrorStats s = stats(errs);
  print("spot vs closed form", s);
  EXPECT_GT(s.n, 3000u) << "the spot should light a good part of the image";
  EXPECT_LT(s.p99, 1e-3);
  EXPECT_LT(s.max, 1e-2) << "every lit pixel within 1 %";

  // The same against renderSurfacesCpu (the project's oracle for the GL pass).
  SurfaceBuffers cpu;
  renderSurfacesCpu(scene, cpu);
  const ErrorStats sc = stats(luminanceErrors(gl, cpu, 1e-3 * peak));
  print("spot vs renderSurfacesCpu", sc);
  EXPECT_LT(sc.max, 1e-2);
  // Unlit road and sky are black (no ambient in this scene).
  for (std::size_t k = 0; k < cpu.rgb.size(); ++k)
    if (cpu.rgb[k] == 0.0f) {
      ASSERT_LT(std::abs(gl.rgb[k]), 1e-6f * static_cast<float>(peak)) << "pixel " << k / 3;
    }
  dumpOnFailure("spot_plane", gl, expected);
}

// ---------------------------------------------------------------------------------------------
// (2) Distance buffer: true distances along each pixel's ray, +inf for sky.

TEST_F(GlSurfacePassTest, DistanceBufferMatchesRayPlaneDistances) {
  Scene scene = spotScene();
  scene.fog = fog(0.02, 0.7);
  // Road, a slanted wall on the left (from 6 m to the side, closing in ahead), and the horizon
  // and sky in view (camera pitched 2° down).
  scene.camera = makeCamera(Vec3(0.0, 0.0, 1.2), 5.0, 2.0, 320, 180);
  scene.planes = {Plane{Vec3(0.0, 6.0, 0.0), glm::normalize(Vec3(0.15, -1.0, 0.0)), 0.5},
                  Plane{Vec3(0.0, 0.0, 0.0), Vec3(0.0, 0.0, 1.0), 0.1}};
  SurfaceBuffers gl, cpu;
  ASSERT_TRUE(pass().render(scene, gl).has_value());
  renderSurfacesCpu(scene, cpu);

  std::vector<double> errs;
  std::size_t sky = 0, mismatch = 0;
  for (std::size_t k = 0; k < cpu.distance.size(); ++k) {
    const double e = cpu.distance[k], a = gl.distance[k];
    if (std::isinf(e)) {
      ++sky;
      if (!std::isinf(a)) ++mismatch;
      // Sky: L_s = I_a (d = ∞).
      EXPECT_NEAR(gl.rgb[3 * k], scene.fog.ambient_cd_m2, 1e-6) << "sky pixel " << k;
      continue;
    }
    if (std::isinf(a)) {
      ++mismatch;
      continue;
    }
    errs.push_back(std::abs(a - e) / e);
  }
  const ErrorStats s = stats(errs);
  print("distance vs ray-plane", s);
  std::printf("distance: %zu sky pixels, %zu hit/miss mismatches\n", sky, mismatch);
  EXPECT_GT(sky, 1000u);
  EXPECT_EQ(mismatch, 0u);
  EXPECT_LT(s.max, 1e-5) << "float storage of a double-precision ray–plane distance";
  // The luminance with ambient and a wall lit at grazing and normal incidence.
  double peak = 0.0;
  for (float v : cpu.rgb) peak = std::max(peak, static_cast<double>(v));
  const ErrorStats sl = stats(luminanceErrors(gl, cpu, 1e-3 * peak));
  print("luminance (road + wall + ambient) vs renderSurfacesCpu", sl);
  EXPECT_LT(sl.max, 1e-2);
  dumpOnFailure("distance_planes", gl, cpu);
}

// ---------------------------------------------------------------------------------------------
// (3) Tabulated profiles: the shipped low beam (type B, full H −90…90) and synthetic
// grids of every type and symmetry, against renderSurfacesCpu.

TEST_F(GlSurfacePassTest, ShippedLowBeamLightsRoadAsCpuRenderer) {
  auto lowBeam = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  ASSERT_TRUE(lowBeam.has_value()) << lowBeam.error().message;
  Scene scene;
  scene.fog = fog(0.01, 0.05);
  scene.camera = makeCamera(Vec3(-1.0, 0.0, 1.2), 0.0, 3.0, 480, 270);
  for (double y : {0.7, -0.7}) {
    SceneLamp sl;
    sl.name = y > 0 ? "left" : "right";
    sl.lamp.position_m = Vec3(0.0, y, 0.65);
    sl.lamp.worldFromLamp = worldFromYawPitchRoll(0.0, radians(0.6), 0.0);
    sl.lamp.profile = *lowBeam;
    scene.lamps.push_back(sl);
  }
  scene.planes.push_back(Plane{Vec3(0.0), Vec3(0.0, 0.0, 1.0), 0.15});
  scene.planes.push_back(Plane{Vec3(30.0, 0.0, 0.0), Vec3(-1.0, 0.0, 0.0), 0.6});  // an aiming wall at 30 m: the cut-off
  SurfaceBuffers gl, cpu;
  ASSERT_TRUE(pass().render(scene, gl).has_value());
  renderSurfacesCpu(scene, cpu);
  double peak = 0.0;
  for (float v : cpu.rgb) peak = std::max(peak, static_cast<double>(v));
  const ErrorStats s = stats(luminanceErrors(gl, cpu, 1e-3 * peak));
  print("low beam (type B) vs renderSurfacesCpu", s);
  EXPECT_GT(s.n, 10000u);
  EXPECT_LT(s.p99, 1e-3);
  EXPECT_LT(s.max, 1e-2);
  dumpOnFailure("low_beam", gl, cpu);
}

struct SyntheticCase {
  const char* name;
  PhotometricType type;
  PlaneSymmetry symmetry;
  double h0, h1, hStep;  // degrees
  double v0, v1, vStep;
};

/// A smooth-ish but anisotropic test pattern with a sharp step (a cut-off) in v.
double pattern(double hDeg, double vDeg) {
  const double base = 2000.0 + 1500.0 * std::cos(radians(hDeg) * 1.7) + 800.0 * std::sin(radians(vDeg) * 2.3);
  return (vDeg < 20.0 ? 3.0 : 1.0) * std::max(base, 50.0) * (1.0 + 0.3 * std::sin(radians(hDeg + 2.0 * vDeg)));
}

class GlTabulatedProfileTest : public GlSurfacePassTest, public ::testing::WithParamInterface<SyntheticCase> {};

TEST_P(GlTabulatedProfileTest, MatchesCpuRenderer) {
  const SyntheticCase& c = GetParam();
  TabulatedProfile t;
  t.type = c.type;
  t.symmetry = c.symmetry;
  t.source = c.name;
  for (double h = c.h0; h <= c.h1 + 1e-9; h += c.hStep) t.horizontal.push_back(radians(h));
  for (double v = c.v0; v <= c.v1 + 1e-9; v += c.vStep) t.vertical.push_back(radians(v));
  for (double h : t.horizontal)
    for (double v : t.vertical) t.candela.push_back(pattern(degrees(h), degrees(v)));

  Scene scene;
  scene.fog = fog(0.02, 0.0);
  // Looking down at the ground from 12 m; the lamp 5 m up, aimed 60° down and yawed, so that the
  // visible ground spans a wide range of (h, v) including folds and the wrap of type C planes.
  scene.camera = makeCamera(Vec3(-6.0, 2.0, 12.0), -10.0, 60.0, 320, 240, 90.0);
  const double pitch = c.type == PhotometricType::C ? 70.0 : 40.0;
  scene.lamps.push_back(makeLamp("tab", Vec3(0.0, 0.0, 5.0), 20.0, pitch, std::move(t)));
  scene.planes.push_back(Plane{Vec3(0.0), Vec3(0.0, 0.0, 1.0), 0.4});
  SurfaceBuffers gl, cpu;
  ASSERT_TRUE(pass().render(scene, gl).has_value());
  renderSurfacesCpu(scene, cpu);
  double peak = 0.0;
  for (float v : cpu.rgb) peak = std::max(peak, static_cast<double>(v));
  ASSERT_GT(peak, 0.0);
  const ErrorStats s = stats(luminanceErrors(gl, cpu, 1e-3 * peak));
  print(c.name, s);
  EXPECT_GT(s.n, 5000u);
  EXPECT_LT(s.p99, 1e-3);
  // The max is looser: a pixel whose direction lies within float rounding (~1e-7 rad) of a
  // sharp step may take the other side's cell.
  EXPECT_LT(percentile(luminanceErrors(gl, cpu, 1e-3 * peak), 99.9), 1e-2);
  dumpOnFailure(std::string("tabulated_") + c.name, gl, cpu);
}

INSTANTIATE_TEST_SUITE_P(
    TypesAndSymmetries, GlTabulatedProfileTest,
    ::testing::Values(SyntheticCase{"typeB_full", PhotometricType::B, PlaneSymmetry::None, -90, 90, 5, -90, 90, 2.5},
                      SyntheticCase{"typeB_mirror", PhotometricType::B, PlaneSymmetry::MirrorH, 0, 90, 5, -90, 90, 2.5},
                      SyntheticCase{"typeA_full", PhotometricType::A, PlaneSymmetry::None, -180, 180, 10, -90, 90, 2.5},
                      SyntheticCase{"typeA_mirror", PhotometricType::A, PlaneSymmetry::MirrorH, 0, 90, 5, -90, 90, 2.5},
                      SyntheticCase{"typeC_full", PhotometricType::C, PlaneSymmetry::None, 0, 345, 15, 0, 180, 2.5},
                      SyntheticCase{"typeC_half0to180", PhotometricType::C, PlaneSymmetry::Half0To180, 0, 180, 15, 0, 180, 2.5},
                      SyntheticCase{"typeC_half90to270", PhotometricType::C, PlaneSymmetry::Half90To270, 90, 270, 15, 0, 180, 2.5},
                      SyntheticCase{"typeC_quadrant", PhotometricType::C, PlaneSymmetry::Quadrant, 0, 90, 15, 0, 180, 2.5},
                      SyntheticCase{"typeC_rotational", PhotometricType::C, PlaneSymmetry::Rotational, 0, 0, 1, 0, 180, 2.5}),
    [](const ::testing::TestParamInfo<SyntheticCase>& p) { return std::string(p.param.name); });

// ---------------------------------------------------------------------------------------------
// (4) glTF: a hand-written quad (tests/data/gltf/wall_quad.gltf) becomes a wall at x = 10 m.

TEST_F(GlSurfacePassTest, GltfQuadDistanceAndShading) {
  Scene scene;
  scene.fog = fog(0.02, 0.0);
  scene.camera = makeCamera(Vec3(0.0, 0.0, 1.2), 0.0, 0.0, 160, 90);
  scene.gltf_path = std::string(FOGBEAM_TEST_DATA_DIR) + "/gltf/wall_quad.gltf";
  scene.lamps.push_back(makeLamp("bulb", Vec3(1.0, 0.5, 2.0), 0.0, 0.0, IsotropicProfile{500.0}));
  SurfaceBuffers gl;
  auto st = pass().render(scene, gl);
  ASSERT_TRUE(st.has_value()) << st.error().message;
  EXPECT_EQ(pass().stats().triangles, 2u);

  // Expected: the wall x = 10, |y| ≤ 2, 0 ≤ z ≤ 3, normal −x, ρ = (0.5, 0.25, 0.125).
  const Camera& cam = scene.camera;
  const Lamp& lamp = scene.lamps[0].lamp;
  const double rho[3] = {0.5, 0.25, 0.125};
  SurfaceBuffers expected;
  expected.resize(cam.width, cam.height);
  std::vector<double> distErr, lumErr;
  std::size_t coverageMismatch = 0, edge = 0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const auto px = static_cast<std::size_t>(j * cam.width + i);
      const Vec3 d = cam.rayDirection(i + 0.5, j + 0.5);
      const double t = 10.0 / d.x;
      const Vec3 x = cam.position_m + t * d;
      const double margin = 1e-4;  // pixel centres within 0.1 mm of the quad's border are not judged
      const bool inside = std::abs(x.y) < 2.0 - margin && x.z > margin && x.z < 3.0 - margin;
      const bool outside = std::abs(x.y) > 2.0 + margin || x.z < -margin || x.z > 3.0 + margin;
      if (inside) {
        expected.distance[px] = static_cast<float>(t);
        const double l = lambertianLuminance(lamp, scene.fog, x, Vec3(-1, 0, 0), 1.0) * std::exp(-scene.fog.extinction_per_m * t);
        for (int c = 0; c < 3; ++c) {
          expected.rgb[3 * px + static_cast<std::size_t>(c)] = static_cast<float>(rho[c] * l);
          lumErr.push_back(std::abs(static_cast<double>(gl.rgb[3 * px + static_cast<std::size_t>(c)]) - rho[c] * l) / (rho[c] * l));
        }
        if (std::isinf(gl.distance[px])) ++coverageMismatch;
        else distErr.push_back(std::abs(static_cast<double>(gl.distance[px]) - t) / t);
      } else if (outside) {
        if (!std::isinf(gl.distance[px])) ++coverageMismatch;
      } else {
        ++edge;
      }
    }
  const ErrorStats sd = stats(distErr), sl = stats(lumErr);
  print("glTF quad distance", sd);
  print("glTF quad luminance (rgb)", sl);
  std::printf("glTF quad: %zu coverage mismatches, %zu edge pixels not judged\n", coverageMismatch, edge);
  EXPECT_GT(sd.n, 2000u);
  EXPECT_EQ(coverageMismatch, 0u);
  EXPECT_LT(sd.max, 1e-5);
  EXPECT_LT(sl.max, 1e-3);
  dumpOnFailure("gltf_quad", gl, expected);
}

TEST_F(GlSurfacePassTest, GltfAndPlanesCompositeByTrueDistance) {
  // The glTF wall (x = 10) standing on the road plane (z = 0): nearer surface wins per pixel.
  Scene scene;
  scene.fog = fog(0.02, 0.3);
  scene.camera = makeCamera(Vec3(0.0, 0.0, 1.2), 0.0, 0.0, 160, 90);
  scene.gltf_path = std::string(FOGBEAM_TEST_DATA_DIR) + "/gltf/wall_quad.gltf";
  scene.lamps.push_back(makeLamp("bulb", Vec3(1.0, 0.5, 2.0), 0.0, 0.0, IsotropicProfile{500.0}));
  scene.planes.push_back(Plane{Vec3(0.0), Vec3(0.0, 0.0, 1.0), 0.2});
  SurfaceBuffers gl;
  auto st = pass().render(scene, gl);
  ASSERT_TRUE(st.has_value()) << st.error().message;
  const Camera& cam = scene.camera;
  SurfaceBuffers expected;
  expected.resize(cam.width, cam.height);
  std::size_t wall = 0, road = 0, sky = 0, wrong = 0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const auto px = static_cast<std::size_t>(j * cam.width + i);
      const Vec3 d = cam.rayDirection(i + 0.5, j + 0.5);
      const double tWall = 10.0 / d.x;
      const Vec3 x = cam.position_m + tWall * d;
      const double tRoad = d.z < 0.0 ? -cam.position_m.z / d.z : std::numeric_limits<double>::infinity();
      const double margin = 1e-3;
      double t = 0.0;
      if (std::abs(x.y) < 2.0 - margin && x.z > margin && x.z < 3.0 - margin) {
        t = tWall;
        ++wall;
      } else if (std::abs(x.y) > 2.0 + margin || x.z < -margin || x.z > 3.0 + margin) {
        t = tRoad;
        std::isinf(t) ? ++sky : ++road;
      } else {
        continue;  // on the wall's border
      }
      expected.distance[px] = static_cast<float>(t);
      const double a = gl.distance[px];
      if (std::isinf(t) ? !std::isinf(a) : !(std::abs(a - t) <= 1e-5 * t)) ++wrong;
    }
  std::printf("composite: %zu wall, %zu road, %zu sky pixels, %zu wrong\n", wall, road, sky, wrong);
  EXPECT_GT(wall, 1000u);
  EXPECT_GT(road, 1000u);
  EXPECT_GT(sky, 1000u);
  EXPECT_EQ(wrong, 0u);
  dumpOnFailure("gltf_composite", gl, expected);
}

// An off-axis camera (principal point away from the image centre): the plane shader and the
// mesh projection must both put pixel centres on Camera::rayDirection's rays. The glTF wall
// (x = 10) on the road, seen with the view axis near the top-right corner of the image.
TEST_F(GlSurfacePassTest, OffAxisCameraDistancesMatchRayPlaneAndTheCentredCrop) {
  Scene scene;
  scene.fog = fog(0.02, 0.3);
  scene.camera = makeCamera(Vec3(0.0, 0.0, 1.2), 0.0, 0.0, 160, 90);
  // f = 138.6 px; half-angles 40.9° left, 16.1° right, 8.2° up, 26.8° down.
  scene.camera.principal_px = Vec2(120.0, 20.0);
  scene.gltf_path = std::string(FOGBEAM_TEST_DATA_DIR) + "/gltf/wall_quad.gltf";
  scene.lamps.push_back(makeLamp("bulb", Vec3(1.0, 0.5, 2.0), 0.0, 0.0, IsotropicProfile{500.0}));
  scene.planes.push_back(Plane{Vec3(0.0), Vec3(0.0, 0.0, 1.0), 0.2});
  SurfaceBuffers gl;
  auto st = pass().render(scene, gl);
  ASSERT_TRUE(st.has_value()) << st.error().message;
  const Camera& cam = scene.camera;
  SurfaceBuffers expected;
  expected.resize(cam.width, cam.height);
  std::vector<bool> border(static_cast<std::size_t>(cam.width * cam.height), false);
  std::size_t wall = 0, road = 0, sky = 0, wrong = 0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const auto px = static_cast<std::size_t>(j * cam.width + i);
      const Vec3 d = cam.rayDirection(i + 0.5, j + 0.5);
      const double tWall = 10.0 / d.x;
      const Vec3 x = cam.position_m + tWall * d;
      const double tRoad = d.z < 0.0 ? -cam.position_m.z / d.z : std::numeric_limits<double>::infinity();
      const double margin = 1e-3;
      double t = 0.0;
      if (std::abs(x.y) < 2.0 - margin && x.z > margin && x.z < 3.0 - margin) {
        t = tWall;
        ++wall;
      } else if (std::abs(x.y) > 2.0 + margin || x.z < -margin || x.z > 3.0 + margin) {
        t = tRoad;
        std::isinf(t) ? ++sky : ++road;
      } else {
        border[px] = true;
        continue;
      }
      expected.distance[px] = static_cast<float>(t);
      const double a = gl.distance[px];
      if (std::isinf(t) ? !std::isinf(a) : !(std::abs(a - t) <= 1e-5 * t)) ++wrong;
    }
  std::printf("off-axis composite: %zu wall, %zu road, %zu sky pixels, %zu wrong\n", wall, road, sky, wrong);
  EXPECT_GT(wall, 1000u);
  EXPECT_GT(road, 1000u);
  EXPECT_GT(sky, 1000u);
  EXPECT_EQ(wrong, 0u);
  dumpOnFailure("offaxis_composite", gl, expected);

  // The centred camera with the same focal length that contains this one: 240×140, centre
  // (120, 70); the off-axis image is its window from (0, 50).
  Scene big = scene;
  big.camera.principal_px.reset();
  big.camera.width = 240;
  big.camera.height = 140;
  big.camera.fov_x = 2.0 * std::atan(120.0 / cam.focalLengthPixels());
  SurfaceBuffers bigGl;
  ASSERT_TRUE(pass().render(big, bigGl).has_value());
  std::size_t compared = 0, differ = 0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const auto px = static_cast<std::size_t>(j * cam.width + i);
      if (border[px]) continue;
      const auto pb = static_cast<std::size_t>((50 + j) * 240 + i);
      const double a = bigGl.distance[pb], b = gl.distance[px];
      ++compared;
      if (std::isinf(a) ? !std::isinf(b) : !(std::abs(a - b) <= 1e-5 * a)) ++differ;
      else if (!(std::abs(bigGl.rgb[3 * pb] - gl.rgb[3 * px]) <= 1e-4f * std::max(bigGl.rgb[3 * pb], 1e-3f))) ++differ;
    }
  std::printf("off-axis vs crop of centred: %zu pixels compared, %zu differ\n", compared, differ);
  EXPECT_EQ(differ, 0u);
}

TEST_F(GlSurfacePassTest, MissingGltfFileIsAnErrorNamingTheFile) {
  Scene scene = spotScene();
  scene.gltf_path = "/nonexistent/road.glb";
  SurfaceBuffers out;
  auto st = pass().render(scene, out);
  ASSERT_FALSE(st.has_value());
  EXPECT_NE(st.error().message.find("/nonexistent/road.glb"), std::string::npos) << st.error().message;
}

// ---------------------------------------------------------------------------------------------
// Pipelined readback: two frames in flight through the double-buffered PBOs come back in order.

TEST_F(GlSurfacePassTest, PipelinedSubmitCollectReturnsFramesInOrder) {
  Scene a = spotScene();
  Scene b = spotScene();
  b.camera.position_m.z = 5.0;  // a different distance buffer
  ASSERT_TRUE(pass().submit(a).has_value());
  ASSERT_TRUE(pass().submit(b).has_value());
  EXPECT_FALSE(pass().submit(a).has_value()) << "a third frame in flight must be refused";
  SurfaceBuffers outA, outB, cpuA, cpuB;
  ASSERT_TRUE(pass().collect(outA).has_value());
  ASSERT_TRUE(pass().collect(outB).has_value());
  renderSurfacesCpu(a, cpuA);
  renderSurfacesCpu(b, cpuB);
  const std::size_t centre = static_cast<std::size_t>(a.camera.height / 2 * a.camera.width + a.camera.width / 2);
  EXPECT_NEAR(outA.distance[centre], cpuA.distance[centre], 1e-4f * cpuA.distance[centre]);
  EXPECT_NEAR(outB.distance[centre], cpuB.distance[centre], 1e-4f * cpuB.distance[centre]);
  // Each frame lit with its own camera and lamps (with shading on the CPU, the lamps and camera
  // of a submit() wait in a queue beside the readback slots).
  EXPECT_NEAR(outA.rgb[3 * centre + 1], cpuA.rgb[3 * centre + 1], 1e-3f * cpuA.rgb[3 * centre + 1]);
  EXPECT_NEAR(outB.rgb[3 * centre + 1], cpuB.rgb[3 * centre + 1], 1e-3f * cpuB.rgb[3 * centre + 1]);
  EXPECT_GT(std::abs(outA.rgb[3 * centre + 1] - outB.rgb[3 * centre + 1]), 1e-2f * outA.rgb[3 * centre + 1]);
  std::printf("timings (last frame, %dx%d): surface %.3f ms (GPU), submit %.3f ms, readback %.3f ms\n", b.camera.width,
              b.camera.height, pass().stats().surface_ms, pass().stats().submit_ms, pass().stats().readback_ms);
}

// ---------------------------------------------------------------------------------------------
// (7) Where the pixels are lit: the shaders (GlOptions::shading = Gpu) and the CPU from the
// geometry buffer (Cpu) on the shipped bench scene — the road model, its ground plane, the ego's
// measured low beams and five street lamps, coloured here so that every channel differs.

/// Two passes, one lighting in the shaders and one on the CPU (GlOptions::shading); null without
/// EGL (skipReason() says why).
std::pair<std::unique_ptr<GlSurfacePass>, std::unique_ptr<GlSurfacePass>> passesShadingBothWays() {
  GlOptions gpuOpt, cpuOpt;
  gpuOpt.shading = SurfaceShading::Gpu;
  cpuOpt.shading = SurfaceShading::Cpu;
  auto gpu = GlSurfacePass::create(gpuOpt);
  auto cpu = GlSurfacePass::create(cpuOpt);
  if (!gpu || !cpu) {
    skipReason() = !gpu ? gpu.error().message : cpu.error().message;
    return {};
  }
  EXPECT_EQ((*gpu)->shading(), SurfaceShading::Gpu);
  EXPECT_EQ((*cpu)->shading(), SurfaceShading::Cpu);
  return {std::move(gpu).value(), std::move(cpu).value()};
}

/// The shipped bench scene at width × height without its bonnet, its lamps coloured so that every
/// channel differs.
Scene colouredBenchRoad(int width, int height) {
  auto loaded = loadScene(std::string(FOGBEAM_CONFIG_DIR) + "/scenes/bench.toml");
  EXPECT_TRUE(loaded.has_value()) << loaded.error().message;
  Scene scene = loaded.has_value() ? *loaded : Scene{};
  scene.camera.width = width;
  scene.camera.height = height;
  scene.body.clear();  // the bonnet: its own test below (rasterised vs cast, distances within rounding)
  for (std::size_t i = 0; i < scene.lamps.size(); ++i)
    scene.lamps[i].lamp.color = Vec3(1.0, 0.8 + 0.05 * static_cast<double>(i), 0.6);
  return scene;
}

TEST(GlSurfaceShading, CpuShadingMatchesTheShadersOnTheBenchRoad) {
  Scene scene = colouredBenchRoad(480, 270);
  ASSERT_FALSE(scene.lamps.empty());
  scene.fog.ambient_cd_m2 = 0.02;
  auto [gpu, cpu] = passesShadingBothWays();
  if (!gpu || !cpu) GTEST_SKIP() << "no usable EGL/OpenGL: " << skipReason();
  SurfaceBuffers a, b;
  ASSERT_TRUE(gpu->render(scene, a).has_value());
  ASSERT_TRUE(cpu->render(scene, b).has_value());
  ASSERT_EQ(a.rgb.size(), b.rgb.size());
  EXPECT_EQ(a.distance, b.distance) << "the same geometry passes write the distances";
  double peak = 0.0;
  for (float v : a.rgb) peak = std::max(peak, static_cast<double>(v));
  ASSERT_GT(peak, 0.0);
  const ErrorStats s = stats(luminanceErrors(b, a, 1e-3 * peak));
  print("bench road, shading on the CPU vs the shaders", s);
  EXPECT_GT(s.n, 30000u);
  EXPECT_LT(s.p99, 1e-3);
  EXPECT_LT(s.max, 1e-2);
  std::size_t sky = 0;
  for (std::size_t k = 0; k < b.distance.size(); ++k)
    if (!std::isfinite(b.distance[k])) {
      ++sky;
      EXPECT_EQ(b.rgb[3 * k], static_cast<float>(scene.fog.ambient_cd_m2));
    }
  EXPECT_GT(sky, 0u);
  std::printf("shading on the CPU: %.2f ms for %dx%d (readback %.2f ms)\n", cpu->stats().shade_ms,
              scene.camera.width, scene.camera.height, cpu->stats().readback_ms);
  dumpOnFailure("shading_cpu_vs_gpu", b, a);
}

// (7b) The fog's scattered light on the surfaces ([glow] surfaces): per pixel in the shaders, over
// the CPU shading's adaptive grid from the geometry buffer; the same model (render/fog_light.hpp).
TEST(GlSurfaceShading, TheShadersLightTheFogLightAsTheCpuShadingDoes) {
  Scene scene = colouredBenchRoad(240, 135);
  ASSERT_FALSE(scene.lamps.empty());
  scene.effects.glow.enabled = true;
  scene.effects.glow.surfaces = true;
  auto [gpu, cpu] = passesShadingBothWays();
  if (!gpu || !cpu) GTEST_SKIP() << "no usable EGL/OpenGL: " << skipReason();
  SurfaceBuffers a, b, without;
  ASSERT_TRUE(gpu->render(scene, a).has_value());
  ASSERT_TRUE(cpu->render(scene, b).has_value());
  Scene off = scene;
  off.effects.glow.surfaces = false;
  ASSERT_TRUE(gpu->render(off, without).has_value());
  EXPECT_EQ(a.distance, b.distance);
  double peak = 0.0, with = 0.0, direct = 0.0;
  for (float v : a.rgb) peak = std::max(peak, static_cast<double>(v));
  for (std::size_t k = 0; k < a.rgb.size(); ++k) {
    with += static_cast<double>(a.rgb[k]);
    direct += static_cast<double>(without.rgb[k]);
  }
  std::printf("the fog light adds %.1f %% to the surfaces' light (shaders)\n", 100.0 * (with / direct - 1.0));
  EXPECT_GT(with, 1.05 * direct);
  const ErrorStats s = stats(luminanceErrors(b, a, 1e-3 * peak));
  print("bench road with the fog light, shading on the CPU (grid) vs the shaders (per pixel)", s);
  EXPECT_GT(s.n, 8000u);
  EXPECT_LT(s.p99, 1e-2);
  EXPECT_LT(s.max, 5e-2);
}

// (8) The ego car's bonnet (Scene::body): the shaders and the CPU shading agree, its distances
// are those of the plate, and it hides the ego's low beams from the eye.
TEST(GlSurfaceShading, TheBonnetHidesTheEgoLampsInBothShadings) {
  auto loaded = loadScene(std::string(FOGBEAM_CONFIG_DIR) + "/scenes/bench.toml");
  ASSERT_TRUE(loaded.has_value()) << loaded.error().message;
  Scene scene = *loaded;
  scene.camera.width = 480;
  scene.camera.height = 270;
  scene.camera.worldFromCamera = worldFromYawPitchRoll(0.0, radians(8.0), 0.0);  // looking down: the lamps in view
  const Bonnet bonnet;  // defaults: x 0.8–2.3 m, y ±0.85 m, z 0.9 m
  scene.body = {bonnet.quad()};
  auto [gpu, cpu] = passesShadingBothWays();
  if (!gpu || !cpu) GTEST_SKIP() << "no usable EGL/OpenGL: " << skipReason();
  SurfaceBuffers a, b;
  ASSERT_TRUE(gpu->render(scene, a).has_value());
  ASSERT_TRUE(cpu->render(scene, b).has_value());
  const Camera& cam = scene.camera;
  std::size_t onPlate = 0, agree = 0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const Vec3 d = cam.rayDirection(i + 0.5, j + 0.5);
      if (!(d.z < 0.0)) continue;
      const double t = (bonnet.height_m - cam.position_m.z) / d.z;  // the plate's plane
      const Vec3 x = cam.position_m + t * d;
      // Pixels whose centre is well inside the plate (a few mm from its edges).
      if (x.x < bonnet.rear_m + 0.01 || x.x > bonnet.front_m - 0.01 || x.y < bonnet.right_m + 0.01 ||
          x.y > bonnet.left_m - 0.01)
        continue;
      ++onPlate;
      const std::size_t k = static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
      const bool ok = std::abs(static_cast<double>(a.distance[k]) - t) < 1e-5 * t &&
                      std::abs(static_cast<double>(b.distance[k]) - t) < 1e-6 * t;
      agree += ok ? 1 : 0;
    }
  std::printf("bonnet: %zu pixels inside the plate, %zu at its distance in both shadings\n", onPlate, agree);
  EXPECT_GT(onPlate, 5000u);
  EXPECT_EQ(agree, onPlate);
  // The ego's low beams lie below the plate: the rays towards them end on it.
  for (const SceneLamp& l : scene.lamps) {
    if (l.mount != LampMount::Vehicle) continue;
    const Vec3 toLamp = l.lamp.position_m - cam.position_m;
    const Vec3 local = glm::transpose(cam.worldFromCamera) * toLamp;
    const double f = cam.focalLengthPixels();
    const Vec2 c = cam.principalPoint();
    const int i = static_cast<int>(c.x - f * local.y / local.x), j = static_cast<int>(c.y - f * local.z / local.x);
    ASSERT_TRUE(i >= 0 && i < cam.width && j >= 0 && j < cam.height) << l.name << " is not in view";
    const std::size_t k = static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
    EXPECT_LT(b.distance[k], glm::length(toLamp) - 0.2) << l.name << ": the bonnet should hide it";
  }
  double peak = 0.0;
  for (float v : a.rgb) peak = std::max(peak, static_cast<double>(v));
  const ErrorStats s = stats(luminanceErrors(b, a, 1e-3 * peak));
  print("bench road with a bonnet, shading on the CPU vs the shaders", s);
  EXPECT_LT(s.p99, 1e-3);
  dumpOnFailure("bonnet_cpu_vs_gpu", b, a);
  // Without the road model, against the double-precision CPU renderer, which casts the bonnet too.
  scene.gltf_path.reset();
  SurfaceBuffers g, oracle;
  ASSERT_TRUE(cpu->render(scene, g).has_value());
  renderSurfacesCpu(scene, oracle);
  std::size_t mismatched = 0;
  for (std::size_t k = 0; k < g.distance.size(); ++k)
    if (std::isfinite(g.distance[k]) != std::isfinite(oracle.distance[k]) ||
        (std::isfinite(g.distance[k]) && std::abs(g.distance[k] - oracle.distance[k]) > 1e-6f * oracle.distance[k]))
      ++mismatched;
  EXPECT_EQ(mismatched, 0u);
  double top = 0.0;
  for (float v : oracle.rgb) top = std::max(top, static_cast<double>(v));
  const ErrorStats so = stats(luminanceErrors(g, oracle, 1e-3 * top));
  print("planes + bonnet, shading on the CPU vs renderSurfacesCpu", so);
  EXPECT_LT(so.p99, 1e-4);
  EXPECT_LT(so.max, 1e-3);
}

}  // namespace
}  // namespace fogbeam
