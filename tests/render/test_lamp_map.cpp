// Tests of the moving lamps' per-frame maps (render/lamp_map.hpp) against the per-ray accurate
// method, the definition, on every pixel.
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/lamp_map.hpp>
#include <fogbeam/render/surface.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

namespace fogbeam {
namespace {

std::shared_ptr<const Profile> lowBeam() {
  static const std::shared_ptr<const Profile> p = [] {
    auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
    EXPECT_TRUE(low.has_value());
    return *low;
  }();
  return p;
}

// Two oncoming cars' low beams on a road plane (the traffic of issue 15 at test size), in fog
// of `phase`; the eye 1.2 m above the road.
Scene traffic(int width, int height, const Phase& phase, double visibility = 80.0) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(visibility);
  s.fog.albedo = 0.95;
  s.fog.phase = phase;
  s.camera.position_m = {0.0, 0.35, 1.2};
  s.camera.width = width;
  s.camera.height = height;
  auto add = [&](const char* name, Vec3 pos, double yawDeg) {
    Lamp l;
    l.position_m = pos;
    l.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(0.57), 0.0);
    l.profile = lowBeam();
    s.lamps.push_back({name, l});
  };
  add("car 1 left", {28.0, 4.2, 0.65}, 183.0);
  add("car 1 right", {28.0, 2.8, 0.65}, 183.0);
  add("car 2 left", {75.0, 4.6, 0.65}, 178.0);
  add("car 2 right", {75.0, 3.2, 0.65}, 178.0);
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  return s;
}

struct ErrorFigures {
  double p95 = 0.0, p99 = 0.0, max = 0.0;
  std::size_t pixels = 0;
};

// Relative error of `got` against `want` over pixels (channel R) above 1 % of want's 99.5th
// percentile: the measure.
ErrorFigures errorOver(const AirlightImage& got, const AirlightImage& want) {
  std::vector<double> v;
  for (std::size_t k = 0; k < want.rgb.size(); k += 3) v.push_back(want.rgb[k]);
  std::vector<double> sorted = v;
  std::sort(sorted.begin(), sorted.end());
  const double threshold = 0.01 * sorted[sorted.size() * 995 / 1000];
  std::vector<double> rel;
  for (std::size_t k = 0; k < want.rgb.size(); k += 3) {
    const double a = want.rgb[k];
    if (a <= threshold) continue;
    rel.push_back(std::abs(static_cast<double>(got.rgb[k]) - a) / a);
  }
  std::sort(rel.begin(), rel.end());
  ErrorFigures e;
  e.pixels = rel.size();
  if (rel.empty()) return e;
  e.p95 = rel[rel.size() * 95 / 100];
  e.p99 = rel[rel.size() * 99 / 100];
  e.max = rel.back();
  return e;
}

AirlightImage render(const Scene& scene, const SurfaceBuffers& surf, MovingLampPath path, bool full) {
  FastPathOptions f;
  f.moving_lamps = path;
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, f);
  EXPECT_TRUE(ev.has_value());
  AirlightImage img;
  ev->evaluate(scene, surf, SubsamplingOptions{.full = full}, img);
  return img;
}

// Two oncoming cars' low beams at 320×180 on a road plane: the maps (full and subsampled)
// against the per-ray accurate method on every pixel above 1 % of the frame's 99.5th percentile,
// and the pencil per pixel (what they replace) beside them.
TEST(LampMap, OncomingTrafficAgainstPerRayOnEveryPixel) {
  const Scene scene = traffic(320, 180, makeHenyeyGreenstein(0.85).value());
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  const AirlightImage perRay = render(scene, surf, MovingLampPath::PerRay, true);
  const AirlightImage mapFull = render(scene, surf, MovingLampPath::Map, true);
  const AirlightImage mapSub = render(scene, surf, MovingLampPath::Map, false);
  const AirlightImage pencilSub = render(scene, surf, MovingLampPath::Pencil, false);
  const ErrorFigures full = errorOver(mapFull, perRay), sub = errorOver(mapSub, perRay),
                     pen = errorOver(pencilSub, perRay);
  std::printf("per ray, every pixel: %.0f ms\n", 1e3 * perRay.seconds);
  std::printf("map, every pixel: %.1f ms (maps %.1f ms, %zu pixels evaluated for them): p95 %.2e p99 %.2e max %.2e "
              "over %zu px\n", 1e3 * mapFull.seconds, 1e3 * mapFull.map_seconds, mapFull.map_nodes, full.p95, full.p99,
              full.max, full.pixels);
  std::printf("map, subsampled: %.1f ms (%zu evaluated): p95 %.2e p99 %.2e max %.2e\n", 1e3 * mapSub.seconds,
              mapSub.evaluated, sub.p95, sub.p99, sub.max);
  std::printf("pencil, subsampled: %.1f ms (%zu evaluated): p95 %.2e p99 %.2e max %.2e\n", 1e3 * pencilSub.seconds,
              pencilSub.evaluated, pen.p95, pen.p99, pen.max);
  EXPECT_GT(full.pixels, 5000u);
  EXPECT_LE(full.p95, 0.01);
  EXPECT_LE(full.max, 0.05);
  EXPECT_LE(sub.p95, 0.01);
  EXPECT_LE(sub.max, 0.1);
  // Fewer pencil evaluations than every pixel for every moving lamp: the point of a map.
  EXPECT_LT(mapFull.map_nodes, 4u * 320u * 180u / 2u);
}

// The map's quadtree refines around the lamp's own image down to single pixels, and a lookup
// at a node is the pencil's own value at that pixel.
TEST(LampMap, RefinesAtTheLampsImageAndIsExactAtItsNodes) {
  const Scene scene = traffic(320, 180, makeHenyeyGreenstein(0.85).value());
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto ev = AirlightEvaluator::build(scene.lamps[0].lamp, scene.fog, AirlightMethod::Accurate);
  ASSERT_TRUE(ev.has_value());
  auto pa = PencilAirlight::build(*ev, scene.camera.position_m);
  ASSERT_TRUE(pa.has_value());
  ThreadPool pool(2);
  DepthEdges edges;
  const LampMapOptions mo;
  edges.build(surf.distance.data(), 320, 180, mo.coarse_px, 0.02, 0.0, pool);
  LampMap m;
  m.build(*pa, scene.camera, edges, mo, pool);
  // The lamp's image: the camera looks along +x (y left, z up), f = 160 / tan 30°.
  const Vec3 rel = scene.lamps[0].lamp.position_m - scene.camera.position_m;
  const double f = scene.camera.focalLengthPixels();
  const int ii = static_cast<int>(160.0 - f * rel.y / rel.x), jj = static_cast<int>(90.0 - f * rel.z / rel.x);
  EXPECT_EQ(m.leafSide(ii, jj), 1) << ii << "," << jj;
  EXPECT_EQ(m.leafSide(2, 2), mo.coarse_px);  // the top-left corner, far from anything: one coarse cell
  for (const auto& [i, j] : {std::pair{0, 0}, std::pair{16, 32}, std::pair{ii, jj}, std::pair{ii + 1, jj}}) {
    const double d = surf.distance[static_cast<std::size_t>(j * 320 + i)];
    const double want = pa->evaluate(scene.camera.rayDirection(i + 0.5, j + 0.5), d);
    EXPECT_NEAR(m.lookup(i, j), want, 1e-5 * want) << i << "," << j;
  }
}

// Odd sizes (cells past the image's edge), an off-axis camera, a following car's low beams
// behind the eye (no image, rays looking away from them) and an oncoming car: the maps on every
// pixel against per ray.
TEST(LampMap, OddSizesOffAxisAndLampsBehindTheEye) {
  Scene scene = traffic(77, 41, makeHenyeyGreenstein(0.85).value());
  scene.camera.principal_px = Vec2(20.0, 30.0);
  scene.lamps.resize(2);  // the near oncoming car
  for (double y : {0.7, -0.7}) {
    Lamp l;
    l.position_m = {-15.0, y, 0.65};  // a following car, facing +x like the ego
    l.worldFromLamp = worldFromYawPitchRoll(0.0, radians(0.57), 0.0);
    l.profile = lowBeam();
    scene.lamps.push_back({"following", l});
  }
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  const AirlightImage perRay = render(scene, surf, MovingLampPath::PerRay, true);
  const AirlightImage mapFull = render(scene, surf, MovingLampPath::Map, true);
  const AirlightImage mapSub = render(scene, surf, MovingLampPath::Map, false);
  const ErrorFigures full = errorOver(mapFull, perRay), sub = errorOver(mapSub, perRay);
  std::printf("77x41 off-axis, 4 moving lamps (2 behind the eye): map every pixel p95 %.2e max %.2e over %zu px; "
              "subsampled p95 %.2e max %.2e\n", full.p95, full.max, full.pixels, sub.p95, sub.max);
  EXPECT_GT(full.pixels, 200u);  // a tenth of the image: the comparison has something to judge
  EXPECT_LE(full.p95, 0.01);
  EXPECT_LE(sub.p95, 0.01);
  EXPECT_LE(full.max, 0.1);
}

}  // namespace
}  // namespace fogbeam
