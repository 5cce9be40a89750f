// renderSurfacesCpu (SIMD batches of pixels, rows over a pool) against its scalar definition:
// the one-pixel-at-a-time renderer it was until 2026-11-26, kept here verbatim as the
// reference (it is the oracle of the GL pass's tests, so it must not move). Every value must be
// bit-identical, on every compiled SIMD target, with and without a pool.
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_kernels.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <thread>

namespace fogbeam {
namespace {

// renderSurfacesCpu as it was (surface.cpp before the batches), unchanged.
void renderSurfacesCpuScalar(const Scene& scene, SurfaceBuffers& out) {
  const Camera& cam = scene.camera;
  out.resize(cam.width, cam.height);
  const double kt = scene.fog.extinction_per_m, ia = scene.fog.ambient_cd_m2;
  auto rows = [&](int j0, int j1) {
    for (int j = j0; j < j1; ++j) {
      for (int i = 0; i < cam.width; ++i) {
        const Vec3 d = cam.rayDirection(i + 0.5, j + 0.5);
        double best = std::numeric_limits<double>::infinity();
        const Plane* hit = nullptr;
        for (const Plane& p : scene.planes) {
          const double denom = glm::dot(d, p.normal);
          if (std::abs(denom) < 1e-12) continue;
          const double t = glm::dot(p.point_m - cam.position_m, p.normal) / denom;
          if (t > 0.0 && t < best) {
            best = t;
            hit = &p;
          }
        }
        const auto px = static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
        double rgb[3] = {0.0, 0.0, 0.0};
        if (hit) {
          const Vec3 x = cam.position_m + best * d;
          const Vec3 n = glm::dot(hit->normal, d) < 0.0 ? hit->normal : -hit->normal;  // faces the eye
          for (const SceneLamp& sl : scene.lamps) {
            const double l = lambertianLuminance(sl.lamp, scene.fog, x, n, hit->reflectance);
            for (int c = 0; c < 3; ++c) rgb[c] += l * sl.lamp.color[c];
          }
        }
        const double t = hit ? std::exp(-kt * best) : 0.0;
        for (int c = 0; c < 3; ++c) out.rgb[3 * px + static_cast<std::size_t>(c)] = static_cast<float>(rgb[c] * t + ia * (1.0 - t));
        out.distance[px] = hit ? static_cast<float>(best) : std::numeric_limits<float>::infinity();
      }
    }
  };
  const int nThreads = std::max(1, std::min(static_cast<int>(std::thread::hardware_concurrency()), cam.height));
  std::vector<std::thread> pool;
  for (int k = 0; k < nThreads; ++k)
    pool.emplace_back(rows, cam.height * k / nThreads, cam.height * (k + 1) / nThreads);
  for (auto& th : pool) th.join();
}

long firstDifference(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return 0;
  for (std::size_t k = 0; k < a.size(); ++k)
    if (std::memcmp(&a[k], &b[k], sizeof(float)) != 0) return static_cast<long>(k);
  return -1;
}

void expectIdentical(const SurfaceBuffers& got, const SurfaceBuffers& want, const std::string& what) {
  ASSERT_EQ(got.width, want.width) << what;
  ASSERT_EQ(got.height, want.height) << what;
  const long kr = firstDifference(got.rgb, want.rgb), kd = firstDifference(got.distance, want.distance);
  EXPECT_EQ(kr, -1) << what << ": rgb differs first at value " << kr << ": "
                    << (kr >= 0 ? got.rgb[static_cast<std::size_t>(kr)] : 0.0f) << " vs "
                    << (kr >= 0 ? want.rgb[static_cast<std::size_t>(kr)] : 0.0f);
  EXPECT_EQ(kd, -1) << what << ": distance differs first at " << kd;
}

SceneLamp lampAt(Vec3 p, double yawDeg, double pitchDeg, std::shared_ptr<const Profile> prof, glm::dvec3 colour) {
  SceneLamp l;
  l.name = "lamp";
  l.lamp.position_m = p;
  l.lamp.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(pitchDeg), 0.0);
  l.lamp.profile = std::move(prof);
  l.lamp.color = colour;
  return l;
}

// A night road: the shipped low beams (tabulated, type B), a spot, isotropic street lamps of
// several colours, the road, a slanted wall, a wall facing away (lit from behind: two-sided),
// a lamp on a plane (r² of 0 along it is not hit: a lamp exactly on the surface point).
Scene roadScene(int w, int h, double ambient) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(90.0);
  s.fog.ambient_cd_m2 = ambient;
  s.camera.position_m = {0.0, 0.37, 1.2};
  s.camera.width = w;
  s.camera.height = h;
  s.camera.fov_x = radians(70.0);
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  EXPECT_TRUE(low);
  s.lamps.push_back(lampAt({2.2, 0.7, 0.65}, 0.0, -1.0, *low, {1.0, 1.0, 1.0}));
  s.lamps.push_back(lampAt({2.2, -0.7, 0.65}, 0.0, -1.0, *low, {1.0, 0.97, 0.9}));
  s.lamps.push_back(lampAt({40.0, 3.5, 0.65}, 180.0, 0.0,
                           makeProfile(SpotProfile{20000.0, radians(5.0), radians(15.0)}).value(), {1.0, 1.0, 1.0}));
  s.lamps.push_back(lampAt({15.0, -2.75, 8.0}, 0.0, 0.0, makeProfile(IsotropicProfile{4000.0}).value(), {1.0, 0.8, 0.5}));
  s.lamps.push_back(lampAt({45.0, 2.75, 8.0}, 0.0, 0.0, makeProfile(IsotropicProfile{6000.0}).value(), {0.6, 0.8, 1.0}));
  s.lamps.push_back(lampAt({25.0, -8.0, 0.0}, 0.0, 0.0, makeProfile(IsotropicProfile{500.0}).value(), {1.0, 1.0, 1.0}));
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.12});
  s.planes.push_back(Plane{{30.0, 0, 0}, glm::normalize(Vec3(-1.0, 0.2, 0.1)), 0.5});
  s.planes.push_back(Plane{{0, -8.0, 0}, {0, -1, 0}, 0.3});  // normal away from the eye
  return s;
}

TEST(SurfaceCpu, BitIdenticalToScalarOnEveryTargetWithAndWithoutPool) {
  ThreadPool pool(3);
  const std::vector<std::string> targets = kernels::availableTargets();
  ASSERT_FALSE(targets.empty());
  for (const double ambient : {0.0, 0.03}) {
    Scene s = roadScene(331, 187, ambient);  // rows of hit pixels not a multiple of the batch
    SurfaceBuffers want;
    renderSurfacesCpuScalar(s, want);
    for (const std::string& target : targets) {
      ASSERT_TRUE(kernels::forceTarget(target));
      SurfaceBuffers got, gotPool;
      renderSurfacesCpu(s, got);
      renderSurfacesCpu(s, gotPool, &pool);
      const std::string what = target + ", I_a " + std::to_string(ambient);
      expectIdentical(got, want, what + ", no pool");
      expectIdentical(gotPool, want, what + ", pool");
    }
  }
  kernels::forceTarget("");
}

// An off-axis camera (the host's frustum), pitched and rolled, at 1280×720 with the default
// target: what `fogbeam bench` and the GL tests render.
TEST(SurfaceCpu, BitIdenticalOffAxisAtFullSize) {
  Scene s = roadScene(1280, 720, 0.01);
  s.camera.worldFromCamera = worldFromYawPitchRoll(radians(3.0), radians(-2.0), radians(1.0));
  s.camera.principal_px = Vec2(600.25, 380.5);
  ThreadPool pool(2);
  SurfaceBuffers want, got;
  renderSurfacesCpuScalar(s, want);
  renderSurfacesCpu(s, got, &pool);
  expectIdentical(got, want, "off-axis 1280x720");
  // The same buffers again (kept, not re-sized) and a smaller frame into them.
  renderSurfacesCpu(s, got, &pool);
  expectIdentical(got, want, "second frame");
  s.camera.width = 97;
  s.camera.height = 41;
  s.camera.principal_px.reset();
  renderSurfacesCpuScalar(s, want);
  renderSurfacesCpu(s, got, &pool);
  expectIdentical(got, want, "97x41 into 1280x720 buffers");
}

// No planes: all sky (I_a, +inf); no lamps: the fog's in-scatter over the planes only.
TEST(SurfaceCpu, SkyOnlyAndNoLamps) {
  Scene s = roadScene(64, 36, 0.2);
  SurfaceBuffers want, got;
  s.lamps.clear();
  renderSurfacesCpuScalar(s, want);
  renderSurfacesCpu(s, got);
  expectIdentical(got, want, "no lamps");
  s.planes.clear();
  renderSurfacesCpuScalar(s, want);
  renderSurfacesCpu(s, got);
  expectIdentical(got, want, "no planes");
  for (float d : got.distance) ASSERT_TRUE(std::isinf(d));
  for (float v : got.rgb) ASSERT_EQ(v, 0.2f);
}

}  // namespace
}  // namespace fogbeam
