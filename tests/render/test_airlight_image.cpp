// The airlight layer: subsampled against full per-pixel evaluation, and the CPU surface layer
// against its formula. Scenes are built in code (the scene-file parser has its own tests).
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/surface.hpp>

#include <gtest/gtest.h>

#include "test_scale.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <tuple>
#include <vector>

namespace fogbeam {
namespace {

Scene nightRoad(int width, int height) {
  Scene s;
  s.fog.extinction_per_m = extinctionFromVisibility(80.0);
  s.fog.albedo = 0.95;
  s.fog.phase = makeHenyeyGreenstein(0.85).value();
  s.camera.position_m = {0.0, 0.35, 1.2};
  s.camera.width = width;
  s.camera.height = height;
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  EXPECT_TRUE(low.has_value());
  auto add = [&](const char* name, Vec3 pos, double yawDeg) {
    Lamp l;
    l.position_m = pos;
    l.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(0.57), 0.0);
    l.profile = *low;
    s.lamps.push_back({name, l});
  };
  add("ego-left", {2.0, 0.7, 0.65}, 0.0);
  add("ego-right", {2.0, -0.7, 0.65}, 0.0);
  s.lamps[0].mount = s.lamps[1].mount = LampMount::Vehicle;
  add("oncoming-left", {45.0, 4.2, 0.65}, 180.0);
  add("oncoming-right", {45.0, 2.8, 0.65}, 180.0);
  Lamp street;
  street.position_m = {25.0, -6.0, 8.0};
  street.profile = makeProfile(IsotropicProfile{3000.0}).value();
  s.lamps.push_back({"street", street});
  s.planes.push_back(Plane{{0, 0, 0}, {0, 0, 1}, 0.15});
  return s;
}

// View tables at 0.25° (the renderer's default is 0.2°): two thirds of the build time. At 0.5°
// the accurate image's p95 against the reference is 1.07 % on this scene, at 0.25° 0.3 %.
FastPathOptions testFastPath() {
  FastPathOptions f;
  f.view_table_step_deg = 0.25;
  return f;
}

// The same for the tests whose assertions do not depend on the tables' nodes: images against
// images made with the same tables (subsampled against full, switched lamps against their sum,
// tiles against the whole), or one camera's window of another's whose nodes coincide at any
// step (ViewTable::build: both windows start at the same corner). Their cost is the vehicle
// lamps' view tables, one evaluation per direction and distance node, so FOGBEAM_TEST_SCALE
// scales the nodes: the step grows by 1/√scale (the frustum table's directions × scale) and
// the distance nodes × scale (0.5° and 12 at 0.25). The insets around each lamp's image keep
// the directions the renderer gives them, so only their distances shrink: under ASan at 0.25
// the tables cost ~0.3 of their full-size time. The tables' accuracy is
// ImagesOfEachMethodAgainstTheReference's subject, which keeps testFastPath().
FastPathOptions scaledFastPath() {
  FastPathOptions f = testFastPath();
  f.view_table_step_deg /= std::sqrt(test::scale());
  f.view_table_distances = static_cast<int>(test::scaled(static_cast<std::size_t>(f.view_table_distances), 8));
  return f;
}

// Every method's image against the reference method on random pixels; the accurate method's
// fast path (F table, view tables, SIMD) full and subsampled within 1 % at the 95th percentile;
// the seed image is its own per-ray evaluation (the image path adds nothing to its error).
TEST(AirlightImage, ImagesOfEachMethodAgainstTheReference) {
  const Scene scene = nightRoad(128, 72);
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto ref = AirlightImageEvaluator::build(scene, AirlightMethod::Reference, {}, 0);
  auto seed = AirlightImageEvaluator::build(scene, AirlightMethod::Seed, {}, 0);
  auto acc = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, testFastPath());
  ASSERT_TRUE(ref && seed && acc);
  EXPECT_NE(acc->describe().find("2 vehicle lamp(s) by view table"), std::string::npos) << acc->describe();
  AirlightImage accFull, accSub, seedFull;
  acc->evaluate(scene, surf, SubsamplingOptions{.full = true}, accFull);
  acc->evaluate(scene, surf, SubsamplingOptions{}, accSub);
  seed->evaluate(scene, surf, SubsamplingOptions{.full = true}, seedFull);
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> di(0, 127), dj(0, 71);
  std::vector<double> eFull, eSub, eSeed;
  for (int n = 0; n < 150; ++n) {
    const int i = di(rng), j = dj(rng);
    const std::size_t k = static_cast<std::size_t>(j) * 128 + static_cast<std::size_t>(i);
    const Ray ray{scene.camera.position_m, scene.camera.rayDirection(i + 0.5, j + 0.5),
                  static_cast<double>(surf.distance[k])};
    float r[3], sd[3];
    ref->evaluateRay(ray, r);
    seed->evaluateRay(ray, sd);
    const double want = static_cast<double>(r[0]);
    if (want < 1e-3) continue;
    eFull.push_back(std::abs(static_cast<double>(accFull.rgb[3 * k]) - want) / want);
    eSub.push_back(std::abs(static_cast<double>(accSub.rgb[3 * k]) - want) / want);
    eSeed.push_back(std::abs(static_cast<double>(seedFull.rgb[3 * k]) - want) / want);
    EXPECT_NEAR(seedFull.rgb[3 * k], sd[0], 1e-5f * std::abs(sd[0]) + 1e-9f);
  }
  ASSERT_GT(eFull.size(), 100u);
  auto p95 = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() * 95 / 100];
  };
  std::printf("vs reference, p95: accurate full %.2e, accurate subsampled %.2e, seed %.2e (%zu pixels)\n",
              p95(eFull), p95(eSub), p95(eSeed), eFull.size());
  EXPECT_LE(p95(eFull), 0.01);
  EXPECT_LE(p95(eSub), 0.01);
}

TEST(AirlightImage, SubsampledMatchesFullWithinOnePercentP95) {
  const Scene scene = nightRoad(256, 144);
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, scaledFastPath());
  ASSERT_TRUE(ev.has_value());
  AirlightImage full, sub;
  ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, full);
  ev->evaluate(scene, surf, SubsamplingOptions{}, sub);
  ASSERT_EQ(full.evaluated, 256u * 144u);
  std::vector<double> rel;
  for (std::size_t k = 0; k < 256u * 144u; ++k) {
    const double a = full.rgb[3 * k], b = sub.rgb[3 * k];
    rel.push_back(std::abs(b - a) / std::max(a, 1e-3));
  }
  std::sort(rel.begin(), rel.end());
  const double p95 = rel[rel.size() * 95 / 100], mx = rel.back();
  std::printf("subsampled: %zu of %zu pixels evaluated (%.1f %%), p95 %.3g max %.3g; full %.0f ms, sub %.0f ms\n",
              sub.evaluated, full.evaluated, 100.0 * static_cast<double>(sub.evaluated) / static_cast<double>(full.evaluated),
              p95, mx, 1e3 * full.seconds, 1e3 * sub.seconds);
  EXPECT_LE(p95, 0.01);
  EXPECT_LT(sub.evaluated, full.evaluated / 2);
}

// Per-pixel relative error of `got` against `want` over all pixels and channels (floored at
// 1e-3 cd/m²): p95 and max.
std::pair<double, double> imageError(const AirlightImage& got, const AirlightImage& want) {
  std::vector<double> rel;
  for (std::size_t k = 0; k < want.rgb.size(); ++k) {
    const double a = want.rgb[k], b = got.rgb[k];
    rel.push_back(std::abs(b - a) / std::max(a, 1e-3));
  }
  std::sort(rel.begin(), rel.end());
  return {rel[rel.size() * 95 / 100], rel.back()};
}

// The oncoming car's measured lamps of nightRoad move relative to the eye: the pencil path for
// such lamps (MovingLampPath::Pencil, the default) against the per-ray accurate method, the
// definition, and both against the reference method.
// nightRoad's oncoming car alone at 128×72, its surfaces those of the whole scene.
struct OncomingCar {
  Scene scene = nightRoad(128, 72);
  Scene oncoming;
  SurfaceBuffers surf;
  OncomingCar() {
    oncoming = scene;
    oncoming.lamps = {scene.lamps[2], scene.lamps[3]};
    renderSurfacesCpu(scene, surf);
  }
  /// Every pixel of the car's airlight through `path` (the pencil with `spokeTolerance`).
  void image(MovingLampPath path, double spokeTolerance, AirlightImage& img) const {
    FastPathOptions f = testFastPath();
    f.moving_lamps = path;
    f.pencil_options.spoke_tolerance = spokeTolerance;
    auto ev = AirlightImageEvaluator::build(oncoming, AirlightMethod::Accurate, {}, 0, f);
    ASSERT_TRUE(ev.has_value());
    ev->evaluate(oncoming, surf, SubsamplingOptions{.full = true}, img);
    std::printf("%s: %.1f ms\n", ev->describe().c_str(), 1e3 * img.seconds);
  }
};

TEST(AirlightImage, MovingLampPathsAgainstPerRay) {
  const OncomingCar car;
  const Scene& scene = car.scene;
  const Scene& oncoming = car.oncoming;
  const SurfaceBuffers& surf = car.surf;
  AirlightImage perRay, pencil;
  car.image(MovingLampPath::PerRay, 0.0, perRay);
  car.image(MovingLampPath::Pencil, PencilOptions{}.spoke_tolerance, pencil);
  // Both against the reference method on random pixels: the truth both approximate.
  auto ref = AirlightImageEvaluator::build(oncoming, AirlightMethod::Reference, {}, 0);
  ASSERT_TRUE(ref.has_value());
  std::mt19937 rng(5);
  std::vector<double> eRay, ePencil;
  for (int n = 0; n < 400; ++n) {
    const int i = static_cast<int>(rng() % 128), j = static_cast<int>(rng() % 72);
    const std::size_t k = static_cast<std::size_t>(j) * 128 + static_cast<std::size_t>(i);
    const Ray ray{scene.camera.position_m, scene.camera.rayDirection(i + 0.5, j + 0.5), static_cast<double>(surf.distance[k])};
    float r[3];
    ref->evaluateRay(ray, r);
    const double want = std::max(static_cast<double>(r[0]), 1e-3);
    eRay.push_back(std::abs(static_cast<double>(perRay.rgb[3 * k]) - static_cast<double>(r[0])) / want);
    ePencil.push_back(std::abs(static_cast<double>(pencil.rgb[3 * k]) - static_cast<double>(r[0])) / want);
  }
  std::sort(eRay.begin(), eRay.end());
  std::sort(ePencil.begin(), ePencil.end());
  std::printf("against the reference (400 pixels): per ray p95 %.2e max %.2e, pencil p95 %.2e max %.2e\n",
              eRay[380], eRay.back(), ePencil[380], ePencil.back());
  EXPECT_LE(ePencil[380], 0.01);
  const auto [pencilP95, pencilMax] = imageError(pencil, perRay);
  std::printf("pencil against per ray: p95 %.2e max %.2e; %.1f× faster\n", pencilP95, pencilMax,
              perRay.seconds / pencil.seconds);
  EXPECT_LE(pencilP95, 1e-3);
  EXPECT_LE(pencilMax, 0.02);
}

// FastPathOptions::moving_lamp_cutoff_cd_m2: moving lamps left out where AirlightBound bounds
// their light below their share of the cutoff. nightRoad plus distant traffic (low beams facing
// the eye at 150–400 m, tail lamps at 120 and 250 m, a car 300 m behind the eye): every pixel
// within the cutoff of the image with every lamp everywhere (the bound is strict, so this holds
// at any pixel), fewer (pixel, lamp) evaluations, the car behind left out of the frame, and
// nothing left out at cutoff 0.
Scene withDistantTraffic() {
  Scene scene = nightRoad(128, 72);
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  auto tail = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/tail_lamp.ies");
  EXPECT_TRUE(low.has_value() && tail.has_value());
  auto add = [&](Vec3 pos, double yawDeg, std::shared_ptr<const Profile> profile, glm::dvec3 colour) {
    Lamp l;
    l.position_m = pos;
    l.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), 0.0, 0.0);
    l.profile = std::move(profile);
    l.color = colour;
    scene.lamps.push_back({"traffic", l});
  };
  for (double x : {150.0, 250.0, 400.0}) {
    add({x, 4.2, 0.65}, 180.0, *low, glm::dvec3(1.0));
    add({x, 2.8, 0.65}, 180.0, *low, glm::dvec3(1.0));
  }
  for (double x : {120.0, 250.0}) add({x, -0.7, 0.8}, 180.0, *tail, glm::dvec3(1.0, 0.05, 0.02));
  add({-300.0, 0.7, 0.65}, 0.0, *low, glm::dvec3(1.0));  // behind the eye, lighting the road ahead
  return scene;
}

TEST(AirlightImage, MovingLampsThatCannotMatterAreLeftOut) {
  const Scene scene = withDistantTraffic();
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto image = [&](double cutoff, AirlightImage& img) {
    FastPathOptions f = scaledFastPath();
    f.moving_lamp_cutoff_cd_m2 = cutoff;
    auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, f);
    ASSERT_TRUE(ev.has_value());
    ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, img);
  };
  const double cutoff = FastPathOptions{}.moving_lamp_cutoff_cd_m2;
  AirlightImage with, without;
  image(cutoff, with);
  image(0.0, without);
  double maxDiff = 0.0, maxValue = 0.0;
  for (std::size_t k = 0; k < with.rgb.size(); ++k) {
    maxDiff = std::max(maxDiff, static_cast<double>(std::abs(with.rgb[k] - without.rgb[k])));
    maxValue = std::max(maxValue, static_cast<double>(without.rgb[k]));
  }
  std::printf("cutoff %.0e cd/m2: %zu lamps out of the frame, %zu (pixel, lamp) pairs against %zu; largest difference "
              "%.2e cd/m2 (largest value %.1f)\n",
              cutoff, with.moving_culled, with.moving_evaluated, without.moving_evaluated, maxDiff, maxValue);
  EXPECT_LE(maxDiff, cutoff);
  EXPECT_GT(maxDiff, 0.0);  // something was left out
  EXPECT_GE(with.moving_culled, 1u);
  EXPECT_LT(with.moving_evaluated, without.moving_evaluated * 9 / 10);
  EXPECT_EQ(without.moving_culled, 0u);
  // A cutoff that is not a luminance is refused.
  for (double bad : {-1e-3, std::numeric_limits<double>::infinity(), std::nan("")}) {
    FastPathOptions f;
    f.moving_lamp_cutoff_cd_m2 = bad;
    auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 1, f);
    ASSERT_FALSE(ev.has_value()) << bad;
    EXPECT_NE(ev.error().message.find("moving_lamp_cutoff_cd_m2"), std::string::npos) << ev.error().message;
  }
}

// FastPathOptions::max_moving_lamps: beyond the budget the lamps whose bound's factor
// (K_s I_max e^{−K_t D}/D × largest colour weight) is smallest are left out of the frame: the
// image is the one with exactly those lamps switched off, bit for bit (cutoff 0 in both, so that
// nothing else depends on how many lamps are on).
TEST(AirlightImage, MovingLampBudgetLeavesOutTheDimmest) {
  const Scene scene = withDistantTraffic();
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  FastPathOptions f = scaledFastPath();
  f.moving_lamp_cutoff_cd_m2 = 0.0;
  f.max_moving_lamps = 4;
  auto budgeted = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, f);
  ASSERT_TRUE(budgeted.has_value());
  AirlightImage a;
  budgeted->evaluate(scene, surf, SubsamplingOptions{}, a);
  // The expected ranking, from the bound's factor of every measured lamp not fixed to the eye.
  std::vector<std::pair<double, std::size_t>> rank;
  for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
    const SceneLamp& l = scene.lamps[i];
    if (l.mount == LampMount::Vehicle || std::holds_alternative<IsotropicProfile>(l.lamp.profile->model())) continue;
    const double d = glm::length(l.lamp.position_m - scene.camera.position_m);
    const double c = std::max({l.lamp.color[0], l.lamp.color[1], l.lamp.color[2]});
    rank.emplace_back(AirlightBound::factor(l.lamp.profile->peak().intensity_cd * c, d, scene.fog.extinction_per_m,
                                            scene.fog.albedo),
                      i);
  }
  ASSERT_EQ(rank.size(), 11u);
  std::sort(rank.begin(), rank.end(),
            [](const auto& x, const auto& y) { return x.first > y.first || (x.first == y.first && x.second < y.second); });
  EXPECT_EQ(a.moving_dropped, rank.size() - 4);
  f.max_moving_lamps = 0;
  auto switched = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, f);
  ASSERT_TRUE(switched.has_value());
  for (std::size_t k = 4; k < rank.size(); ++k) switched->setLampEnabled(rank[k].second, false);
  AirlightImage b;
  switched->evaluate(scene, surf, SubsamplingOptions{}, b);
  EXPECT_EQ(b.moving_dropped, 0u);
  ASSERT_EQ(a.rgb.size(), b.rgb.size());
  EXPECT_TRUE(a.rgb == b.rgb) << "the budget's image is not the image with the dimmest lamps off";
  // And they were not negligible: the full image differs.
  AirlightImage all;
  auto every = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, f);
  ASSERT_TRUE(every.has_value());
  every->evaluate(scene, surf, SubsamplingOptions{}, all);
  EXPECT_FALSE(all.rgb == a.rgb);
  f.max_moving_lamps = -1;
  EXPECT_FALSE(AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 1, f).has_value());
}

// The adaptive spoke plan (PencilOptions::spoke_tolerance) against every spoke: fewer spokes,
// the same image within the plan's tolerance, and no worse against the per-ray method.
TEST(AirlightImage, AdaptiveSpokesAgainstEverySpoke) {
  const OncomingCar car;
  AirlightImage perRay, every, planned;
  car.image(MovingLampPath::PerRay, 0.0, perRay);
  car.image(MovingLampPath::Pencil, 0.0, every);
  car.image(MovingLampPath::Pencil, PencilOptions{}.spoke_tolerance, planned);
  const auto [planP95, planMax] = imageError(planned, every);
  const auto [everyRayP95, everyRayMax] = imageError(every, perRay);
  const auto [planRayP95, planRayMax] = imageError(planned, perRay);
  std::printf("spokes: %zu planned, %zu every; planned vs every p95 %.2e max %.2e; vs per ray: every p95 %.2e, "
              "planned p95 %.2e max %.2e\n",
              planned.spokes, every.spokes, planP95, planMax, everyRayP95, planRayP95, planRayMax);
  EXPECT_GT(every.spokes, 0u);
  EXPECT_LT(planned.spokes, every.spokes * 3 / 4);
  EXPECT_LE(planP95, 1e-3);
  EXPECT_LE(planRayP95, 1e-3);
  EXPECT_LE(planRayMax, 0.02);
}

// A way of interpolating moving lamps (`with`) against not doing so (`without`), both against
// every pixel evaluated: nightRoad at 512×288 with its oncoming car 80 m away, whose light is
// smooth at the lattice's super-cells (16 px, 1.9°) over most of the image, as on the traffic
// bench (32 px and 1.5° at 1280×720; closer or at 256 px, blocks split for the car's own light
// dominate). Prints and returns the (pixel, moving lamp) evaluations and the p95 errors.
struct MovingInterpolation {
  std::size_t with = 0, without = 0;
  double withP95 = 0.0, withoutP95 = 0.0;
};
MovingInterpolation compareMovingInterpolation(const char* what, const SubsamplingOptions& without,
                                               void (*edit)(SurfaceBuffers&)) {
  Scene scene = nightRoad(512, 288);
  for (std::size_t i : {2u, 3u}) scene.lamps[i].lamp.position_m.x = 80.0;
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  if (edit) edit(surf);
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, scaledFastPath());
  EXPECT_TRUE(ev.has_value());
  if (!ev) return {};
  AirlightImage full, on, off;
  ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, full);
  ev->evaluate(scene, surf, SubsamplingOptions{}, on);
  ev->evaluate(scene, surf, without, off);
  const auto [onP95, onMax] = imageError(on, full);
  const auto [offP95, offMax] = imageError(off, full);
  std::printf("%s: moving-lamp evaluations %zu with, %zu without, %zu every pixel; against every pixel p95 %.2e "
              "max %.2e with, p95 %.2e max %.2e without\n",
              what, on.moving_evaluated, off.moving_evaluated, full.moving_evaluated, onP95, onMax, offP95, offMax);
  EXPECT_GT(off.moving_evaluated, 0u);
  EXPECT_LE(onP95, 0.01);
  EXPECT_LE(onP95, offP95 + 2e-3);
  return {on.moving_evaluated, off.moving_evaluated, onP95, offP95};
}

// The moving lamps' lattice (SubsamplingOptions::moving_lattice): the car evaluated at the
// super-cells' corners and centres and interpolated where its light is smooth, against every
// coarse node and block centre evaluating it. Fewer evaluations for the same error.
TEST(AirlightImage, MovingLatticeAgainstEveryCoarseNode) {
  const MovingInterpolation m = compareMovingInterpolation("lattice", SubsamplingOptions{.moving_lattice = false}, nullptr);
  EXPECT_LT(m.with, m.without * 4 / 5);
}

// The lattice's second level (SubsamplingOptions::moving_lattice_levels = 2): cells of 4 × 4
// coarse blocks tested at their centres first, against the first level alone. Fewer
// evaluations, and the error against every pixel evaluated within the first level's + 2e-3.
TEST(AirlightImage, MovingLatticeSecondLevelAgainstTheFirstAlone) {
  const MovingInterpolation m =
      compareMovingInterpolation("lattice level 2", SubsamplingOptions{.moving_lattice_levels = 1}, nullptr);
  EXPECT_LT(m.with, m.without);
}

// Moving lamps across silhouettes (SubsamplingOptions::moving_layers): the car seen between
// posts 12 m from the eye and behind a box 30 m away (distances written into the surface buffer:
// the airlight reads nothing else), with and without interpolating its light in the centre's
// layer of blocks split across an edge.
TEST(AirlightImage, MovingLampsAcrossSilhouettes) {
  const MovingInterpolation m = compareMovingInterpolation(
      "layers", SubsamplingOptions{.moving_layers = false}, [](SurfaceBuffers& surf) {
        for (int j = 60; j < 200; ++j)
          for (int i = 0; i < 512; ++i) {
            float& d = surf.distance[static_cast<std::size_t>(j) * 512 + static_cast<std::size_t>(i)];
            if (i % 48 < 5) d = 12.0f + 0.01f * static_cast<float>(j);                        // posts
            else if (i >= 300 && i < 380 && j >= 120 && j < 170) d = std::min(d, 30.0f);  // a box
          }
      });
  EXPECT_LT(m.with, m.without * 9 / 10);
}

// A fog that changes every frame (AirlightImageEvaluator::setFog): the ego's low beams going
// per pixel through the pencil (as in a frame whose view tables are pending), the car moving.
// The evaluator kept from frame to frame shows the new fog exactly as one built for it, and the
// ego lamps' spokes, which depend on their pose relative to the eye and not on the fog, are
// kept: the second frame samples only the car's.
TEST(AirlightImage, AFogChangeKeepsTheSpokesOfLampsFixedToTheEye) {
  Scene scene = nightRoad(128, 72);
  for (SceneLamp& l : scene.lamps) l.mount = LampMount::World;  // every measured lamp per pixel
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto kept = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 0, testFastPath());
  ASSERT_TRUE(kept.has_value());
  AirlightImage first, second, fresh;
  kept->evaluate(scene, surf, SubsamplingOptions{}, first);
  // The next frame: thicker fog, the car 0.5 m nearer, the ego (eye and lamps together) 0.5 m on.
  Scene next = scene;
  next.fog.extinction_per_m *= 1.05;
  next.fog.albedo = 0.9;
  for (std::size_t i : {2u, 3u}) next.lamps[i].lamp.position_m.x -= 0.5;
  for (std::size_t i : {0u, 1u}) next.lamps[i].lamp.position_m.x += 0.5;
  next.camera.position_m.x += 0.5;
  ASSERT_TRUE(kept->setFog(next.fog));
  ASSERT_TRUE(kept->setLampPoses(next));
  kept->evaluate(next, surf, SubsamplingOptions{}, second);
  auto built = AirlightImageEvaluator::build(next, AirlightMethod::Accurate, {}, 0, testFastPath());
  ASSERT_TRUE(built.has_value());
  built->evaluate(next, surf, SubsamplingOptions{}, fresh);
  const auto [p95, mx] = imageError(second, fresh);
  std::printf("spokes: first frame %zu sampled; next frame %zu sampled, %zu kept (a new evaluator: %zu); kept vs "
              "new evaluator p95 %.2e max %.2e\n",
              first.spokes, second.spokes, second.spokes_kept, fresh.spokes, p95, mx);
  EXPECT_GT(second.spokes_kept, fresh.spokes / 3);
  EXPECT_LT(second.spokes, fresh.spokes * 2 / 3);
  EXPECT_LE(p95, 1e-5);
  EXPECT_LE(mx, 1e-4);
  // Another phase function needs other tables: refused, the evaluator unchanged.
  Medium mie = next.fog;
  mie.phase = makeHenyeyGreenstein(0.7).value();
  EXPECT_FALSE(kept->setFog(mie));
}

// How well a fog between two tabulated fogs is shown by blending their images (the way a fog
// that changes every frame could keep to table frames: docs/airlight.md, "What is left"): the
// ego's low beams and the street lamp at K_t, against tables built at K_t itself, for brackets
// K_t / √ρ and K_t √ρ (the wanted fog at the bracket's geometric middle, where a blend is worst),
// blended linearly and geometrically in ln K_t: images blended offline (the product's path, the
// fog ladder, is FogLadderReadsTwoRungsAroundTheFog).
// nightRoad's ego low beams and street lamp at 128×72 with their surfaces, and the options of
// every image's tables: at 0.5° (a quarter of the directions of 0.25°), the same for all, so that
// only the fog differs (the blend's error is the fog's, not the tables').
struct EgoLampsAndStreetLamp {
  Scene scene = nightRoad(128, 72);
  SurfaceBuffers surf;
  FastPathOptions fast = scaledFastPath();
  EgoLampsAndStreetLamp() {
    scene.lamps = {scene.lamps[0], scene.lamps[1], scene.lamps[4]};
    renderSurfacesCpu(scene, surf);
    fast.view_table_step_deg = std::max(fast.view_table_step_deg, 0.5);
  }
  /// The scene in fog of extinction k (1/m).
  [[nodiscard]] Scene at(double k) const {
    Scene s = scene;
    s.fog.extinction_per_m = k;
    return s;
  }
};

TEST(AirlightImage, FogBetweenTwoTabulatedFogs) {
  const EgoLampsAndStreetLamp rig;
  const Scene& scene = rig.scene;
  const SurfaceBuffers& surf = rig.surf;
  const FastPathOptions& fast = rig.fast;
  const double kt = scene.fog.extinction_per_m;
  auto imageAt = [&](double k, AirlightImage& img) {
    const Scene s = rig.at(k);
    auto ev = AirlightImageEvaluator::build(s, AirlightMethod::Accurate, {}, 0, fast);
    ASSERT_TRUE(ev.has_value());
    ev->evaluate(s, surf, SubsamplingOptions{.full = true}, img);
  };
  AirlightImage exact;
  imageAt(kt, exact);
  double previous = 0.0;
  for (double rho : {1.1, 1.2, 1.4}) {
    AirlightImage lo, hi, linear, geometric;
    imageAt(kt / std::sqrt(rho), lo);
    imageAt(kt * std::sqrt(rho), hi);
    linear = geometric = exact;
    for (std::size_t k = 0; k < exact.rgb.size(); ++k) {
      const double a = lo.rgb[k], b = hi.rgb[k];
      linear.rgb[k] = static_cast<float>(0.5 * (a + b));
      geometric.rgb[k] = static_cast<float>(a > 0.0 && b > 0.0 ? std::sqrt(a * b) : 0.5 * (a + b));
    }
    const auto [linP95, linMax] = imageError(linear, exact);
    const auto [geoP95, geoMax] = imageError(geometric, exact);
    const auto [loP95, loMax] = imageError(lo, exact);
    std::printf("K_t ratio %.2f between tabulated fogs: linear blend p95 %.2e max %.2e, geometric p95 %.2e max %.2e "
                "(the nearer fog alone: p95 %.2e)\n",
                rho, linP95, linMax, geoP95, geoMax, loP95);
    // Second order in ln ρ: the blend beats the nearer fog alone, and its error grows with ρ.
    EXPECT_LT(geoP95, 0.25 * loP95);
    EXPECT_GT(geoP95, previous);
    previous = geoP95;
    if (rho <= 1.1) {
      EXPECT_LE(geoP95, 2e-3);
    }
  }
}

// The fog ladder as the product reads it (setFogLadder): an evaluator whose own tables are for
// another fog, given two rungs built by buildFogTables at K_t / √1.2 and K_t √1.2, shows K_t
// from both (the wanted fog at the bracket's geometric middle, the worst place), against tables
// built at K_t itself; a rung at K_t exactly gives the own tables' image; rungs further apart than
// the ladder's ratio, or made for another pose, are not read (viewTablesReady false).
TEST(AirlightImage, FogLadderReadsTwoRungsAroundTheFog) {
  const EgoLampsAndStreetLamp rig;
  const Scene& scene = rig.scene;
  const SurfaceBuffers& surf = rig.surf;
  const FastPathOptions& fast = rig.fast;
  const double kt = scene.fog.extinction_per_m;
  auto pool = std::make_shared<ThreadPool>(0);
  AirlightImage exact;
  auto own = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, pool, fast);
  ASSERT_TRUE(own.has_value());
  own->evaluate(scene, surf, SubsamplingOptions{.full = true}, exact);
  EXPECT_EQ(exact.fog_rungs, 0);

  constexpr double kRatio = 1.2;
  auto lo = AirlightImageEvaluator::buildFogTables(rig.at(kt / std::sqrt(kRatio)), fast, pool);
  auto hi = AirlightImageEvaluator::buildFogTables(rig.at(kt * std::sqrt(kRatio)), fast, pool);
  auto at = AirlightImageEvaluator::buildFogTables(scene, fast, pool);
  ASSERT_TRUE(lo.has_value() && hi.has_value() && at.has_value());
  EXPECT_NEAR(fogTablesExtinction(**lo), kt / std::sqrt(kRatio), 1e-15);
  EXPECT_GT(fogTablesBytes(**lo), 0u);

  // An evaluator whose own tables were made at 3 K_t, then given the ladder and K_t.
  const Scene far = rig.at(3.0 * kt);
  auto ev = AirlightImageEvaluator::build(far, AirlightMethod::Accurate, {}, pool, fast);
  ASSERT_TRUE(ev.has_value());
  AirlightImage img;
  ev->evaluate(far, surf, SubsamplingOptions{.full = true}, img);
  ev->setFogLadder({*lo, *hi}, kRatio);
  ASSERT_TRUE(ev->setFog(scene.fog));
  EXPECT_TRUE(ev->viewTablesReady(scene.camera));
  ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, img);
  EXPECT_EQ(img.fog_rungs, 2);
  EXPECT_GT(img.table_seconds, 0.0);  // the rungs' merges, no build
  const auto [p95, mx] = imageError(img, exact);
  // The same two rungs subsampled, as frames are made.
  AirlightImage sub, exactSub;
  ev->evaluate(scene, surf, SubsamplingOptions{}, sub);
  own->evaluate(scene, surf, SubsamplingOptions{}, exactSub);
  const auto [subP95, subMax] = imageError(sub, exactSub);
  std::printf("K_t between rungs %.2f apart: p95 %.2e max %.2e against tables at K_t (subsampled: p95 %.2e max %.2e)\n",
              kRatio, p95, mx, subP95, subMax);
  EXPECT_LE(p95, 6e-3);  // FogBetweenTwoTabulatedFogs: 4.5e-3 for images blended offline
  EXPECT_LE(subP95, 1e-2);
  // Blending is what makes it: either rung alone is several times further off.
  {
    auto one = AirlightImageEvaluator::build(far, AirlightMethod::Accurate, {}, pool, fast);
    ASSERT_TRUE(one.has_value());
    AirlightImage loImg;
    one->evaluate(far, surf, SubsamplingOptions{.full = true}, loImg);
    one->setFogLadder({*lo}, kRatio);
    ASSERT_TRUE(one->setFog(rig.at(kt / std::sqrt(kRatio)).fog));
    one->evaluate(rig.at(kt / std::sqrt(kRatio)), surf, SubsamplingOptions{.full = true}, loImg);
    EXPECT_EQ(loImg.fog_rungs, 1);
    EXPECT_GT(imageError(loImg, exact).first, 3.0 * p95);
  }

  // A rung at K_t exactly: the own tables' image (the same tables, merged the same way).
  ev->setFogLadder({*lo, *at, *hi}, kRatio);
  ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, img);
  EXPECT_EQ(img.fog_rungs, 1);
  EXPECT_LE(imageError(img, exact).second, 1e-6);

  // Rungs further apart than the ratio: not read; nor rungs made for another pose.
  ev->setFogLadder({*lo, *hi}, 1.1);
  EXPECT_FALSE(ev->viewTablesReady(scene.camera));
  Scene turned = scene;
  turned.lamps[0].lamp.worldFromLamp = worldFromYawPitchRoll(radians(1.0), 0.0, 0.0) * turned.lamps[0].lamp.worldFromLamp;
  ev->setFogLadder({*lo, *hi}, kRatio);
  ASSERT_TRUE(ev->setLampPoses(turned));
  EXPECT_FALSE(ev->viewTablesReady(scene.camera));
  ASSERT_TRUE(ev->setLampPoses(scene));
  EXPECT_TRUE(ev->viewTablesReady(scene.camera));
  // Back at the own tables' fog: they serve again, the ladder aside.
  ASSERT_TRUE(ev->setFog(far.fog));
  ev->evaluate(far, surf, SubsamplingOptions{.full = true}, img);
  EXPECT_EQ(img.fog_rungs, 0);
  EXPECT_GT(img.table_seconds, 0.0);  // the own tables merged again, not built
  EXPECT_LT(img.table_seconds, 0.5);
}

// Bending on the ladder (setFogLadder's maxBendingDeg; docs/airlight.md, "Bending on the
// ladder"): the ego's low beams bent 2.5° (turned about their positions), shown from rungs built
// with them bent 2° and 3°, each read through its rotation and the two blended, against tables
// built at 2.5°; with a fog between two fogs too (four rungs). The rungs blended without their
// rotations would blur the cut-off: the nearer rung alone is several times further off.
TEST(AirlightImage, BendingLadderReadsTwoTurnedRungs) {
  const EgoLampsAndStreetLamp rig;
  const SurfaceBuffers& surf = rig.surf;
  const FastPathOptions& fast = rig.fast;
  const double kt = rig.scene.fog.extinction_per_m;
  auto pool = std::make_shared<ThreadPool>(0);
  auto bent = [&](double deg, double k) {
    Scene s = rig.at(k);
    for (std::size_t i : {0u, 1u})
      s.lamps[i].lamp.worldFromLamp = worldFromYawPitchRoll(radians(deg), 0.0, 0.0) * s.lamps[i].lamp.worldFromLamp;
    return s;
  };
  auto imageOf = [&](const Scene& s, AirlightImage& img) {
    auto e = AirlightImageEvaluator::build(s, AirlightMethod::Accurate, {}, pool, fast);
    ASSERT_TRUE(e.has_value());
    e->evaluate(s, surf, SubsamplingOptions{.full = true}, img);
  };
  const Scene frame = bent(2.5, kt);
  AirlightImage exact, nearer;
  imageOf(frame, exact);
  imageOf(bent(2.0, kt), nearer);
  auto rung = [&](double deg, double k) {
    auto r = AirlightImageEvaluator::buildFogTables(bent(deg, k), fast, pool);
    EXPECT_TRUE(r.has_value());
    return r ? *r : nullptr;
  };
  const auto r2 = rung(2.0, kt), r3 = rung(3.0, kt);
  ASSERT_TRUE(r2 && r3);

  // An evaluator whose own tables are for the lamps unbent.
  auto ev = AirlightImageEvaluator::build(rig.scene, AirlightMethod::Accurate, {}, pool, fast);
  ASSERT_TRUE(ev.has_value());
  AirlightImage img;
  ev->evaluate(rig.scene, surf, SubsamplingOptions{.full = true}, img);
  ev->setFogLadder({r2, r3}, 1.2, 1.0);
  ASSERT_TRUE(ev->setLampPoses(frame));
  EXPECT_TRUE(ev->viewTablesReady(frame.camera));
  ev->evaluate(frame, surf, SubsamplingOptions{.full = true}, img);
  EXPECT_EQ(img.fog_rungs, 1);
  EXPECT_EQ(img.bending_rungs, 2);
  const auto [p95, mx] = imageError(img, exact);
  const auto [nearP95, nearMax] = imageError(nearer, exact);
  std::printf("bent 2.5 deg from rungs at 2 and 3 deg: p95 %.2e max %.2e against tables at 2.5 deg (the 2 deg tables "
              "alone: p95 %.2e max %.2e)\n",
              p95, mx, nearP95, nearMax);
  EXPECT_LE(p95, 4e-3);
  EXPECT_LT(p95, 0.25 * nearP95);
  EXPECT_LT(mx, 0.5 * nearMax);

  // At a rung's own angle: that rung alone, unturned: the image of its tables.
  ASSERT_TRUE(ev->setLampPoses(bent(2.0, kt)));
  ev->evaluate(bent(2.0, kt), surf, SubsamplingOptions{.full = true}, img);
  EXPECT_EQ(img.bending_rungs, 0);
  EXPECT_EQ(img.fog_rungs, 1);
  EXPECT_LE(imageError(img, nearer).second, 1e-6);

  // Not served: rungs further apart than maxBendingDeg; a ladder without bending; rungs on one
  // side only; one lamp bent and not the other (no rotation common to both).
  ASSERT_TRUE(ev->setLampPoses(frame));
  ev->setFogLadder({r2, r3}, 1.2, 0.9);
  EXPECT_FALSE(ev->viewTablesReady(frame.camera));
  ev->setFogLadder({r2, r3}, 1.2);
  EXPECT_FALSE(ev->viewTablesReady(frame.camera));
  ev->setFogLadder({r2, rung(2.2, kt)}, 1.2, 1.0);
  EXPECT_FALSE(ev->viewTablesReady(frame.camera));
  Scene one = frame;
  one.lamps[1] = rig.scene.lamps[1];
  ev->setFogLadder({r2, r3}, 1.2, 1.0);
  ASSERT_TRUE(ev->setLampPoses(one));
  EXPECT_FALSE(ev->viewTablesReady(one.camera));

  // A fog between two rungs as well: four rungs, K_t / √1.2 and K_t √1.2 at 2° and 3°.
  const double lo = kt / std::sqrt(1.2), hi = kt * std::sqrt(1.2);
  ev->setFogLadder({rung(2.0, lo), rung(3.0, lo), rung(2.0, hi), rung(3.0, hi)}, 1.2, 1.0);
  ASSERT_TRUE(ev->setLampPoses(frame));
  EXPECT_TRUE(ev->viewTablesReady(frame.camera));
  ev->evaluate(frame, surf, SubsamplingOptions{.full = true}, img);
  EXPECT_EQ(img.fog_rungs, 2);
  EXPECT_EQ(img.bending_rungs, 2);
  const auto [p95FogBend, maxFogBend] = imageError(img, exact);
  AirlightImage sub, exactSub;
  ev->evaluate(frame, surf, SubsamplingOptions{}, sub);
  auto own = AirlightImageEvaluator::build(frame, AirlightMethod::Accurate, {}, pool, fast);
  ASSERT_TRUE(own.has_value());
  own->evaluate(frame, surf, SubsamplingOptions{}, exactSub);
  const auto [subP95, subMax] = imageError(sub, exactSub);
  std::printf("and K_t between rungs 1.2 apart: p95 %.2e max %.2e (subsampled: p95 %.2e max %.2e)\n", p95FogBend,
              maxFogBend, subP95, subMax);
  EXPECT_LE(p95FogBend, 8e-3);
  EXPECT_LE(subP95, 1e-2);
}

// An off-axis camera (one channel of a multi-screen cab) sees a window of a larger centred
// camera with the same pose and focal length; its image must be that window of the centred
// image. The window holds both vehicle lamps' images, so the view tables (whose window in the
// tangent plane now follows the principal point) and their inset rings are exercised.
double cropP95(const AirlightImage& off, const AirlightImage& big, int x0, int y0, double* maxOut = nullptr) {
  std::vector<double> rel;
  for (int j = 0; j < off.height; ++j)
    for (int i = 0; i < off.width; ++i) {
      const std::size_t k = static_cast<std::size_t>(j * off.width + i);
      const std::size_t kb = static_cast<std::size_t>((y0 + j) * big.width + x0 + i);
      for (std::size_t c = 0; c < 3; ++c) {
        const double a = big.rgb[3 * kb + c], b = off.rgb[3 * k + c];
        rel.push_back(std::abs(b - a) / std::max(a, 1e-3));
      }
    }
  std::sort(rel.begin(), rel.end());
  if (maxOut) *maxOut = rel.back();
  return rel[rel.size() * 95 / 100];
}

TEST(AirlightImage, OffAxisImageIsTheCropOfTheCentredImage) {
  // Off-axis: 256×144 with fov_x = 60° (f = 221.7 px) and the principal point at (64, 36):
  // half-angles 16.1° left, 40.9° right, 9.2° up, 26.0° down. The centred camera with the same
  // f is 384×216; the off-axis image is its window from (128, 72), which holds both ego lamps'
  // images. (The size is that of SubsampledMatchesFullWithinOnePercentP95: subsampling's error
  // grows as the image shrinks.) (Both view tables then start at the same corner of the tangent plane, so their
  // nodes coincide and the full images agree to rounding; the tolerances are the usual ones.)
  constexpr int kW = 256, kH = 144, kBigW = 384, kBigH = 216;
  Scene off = nightRoad(kW, kH);
  off.camera.principal_px = Vec2(64.0, 36.0);
  const double f = off.camera.focalLengthPixels();
  Scene big = nightRoad(kBigW, kBigH);
  big.camera.fov_x = 2.0 * std::atan(0.5 * kBigW / f);
  const int x0 = 128, y0 = 72;
  SurfaceBuffers surfOff, surfBig;
  renderSurfacesCpu(off, surfOff);
  renderSurfacesCpu(big, surfBig);
  for (int j = 0; j < kH; j += 7)
    for (int i = 0; i < kW; i += 5) {
      const float a = surfBig.distance[static_cast<std::size_t>((y0 + j) * kBigW + x0 + i)];
      const float b = surfOff.distance[static_cast<std::size_t>(j * kW + i)];
      if (std::isinf(a)) ASSERT_TRUE(std::isinf(b)) << i << "," << j;
      else ASSERT_NEAR(b, a, 1e-5f * a) << i << "," << j;
    }

  auto evBig = AirlightImageEvaluator::build(big, AirlightMethod::Accurate, {}, 0, scaledFastPath());
  ASSERT_TRUE(evBig.has_value());
  EXPECT_NE(evBig->describe().find("2 vehicle lamp(s) by view table"), std::string::npos) << evBig->describe();
  AirlightImage bigFull;
  evBig->evaluate(big, surfBig, SubsamplingOptions{.full = true}, bigFull);

  // A fresh evaluator whose first camera is the centred one with the same size and fov_x: its
  // view tables must be rebuilt when the principal point moves (ViewKey).
  Scene centred = nightRoad(kW, kH);
  auto ev = AirlightImageEvaluator::build(centred, AirlightMethod::Accurate, {}, 0, scaledFastPath());
  ASSERT_TRUE(ev.has_value());
  SurfaceBuffers surfCentred;
  renderSurfacesCpu(centred, surfCentred);
  AirlightImage centredFull, offFull, offSub;
  ev->evaluate(centred, surfCentred, SubsamplingOptions{}, centredFull);
  ev->evaluate(off, surfOff, SubsamplingOptions{.full = true}, offFull);
  EXPECT_GT(offFull.table_seconds, 0.0) << "the view tables were not rebuilt for the new principal point";
  ev->evaluate(off, surfOff, SubsamplingOptions{}, offSub);
  ASSERT_EQ(offFull.evaluated, static_cast<std::size_t>(kW * kH));

  double maxFull = 0.0, maxSub = 0.0;
  const double p95Full = cropP95(offFull, bigFull, x0, y0, &maxFull);
  const double p95Sub = cropP95(offSub, bigFull, x0, y0, &maxSub);
  std::printf("off-axis vs crop of centred: full p95 %.2e max %.2e; subsampled (%zu of %zu px) p95 %.2e max %.2e\n",
              p95Full, maxFull, offSub.evaluated, offFull.evaluated, p95Sub, maxSub);
  // Full evaluation differs only where the two cameras' view-table nodes interpolate the same
  // direction differently (their grids are offset); the subsampled image adds its own 1 %.
  EXPECT_LE(p95Full, 1e-3);
  EXPECT_LE(maxFull, 0.01);
  EXPECT_LE(p95Sub, 0.01);
}

// Tiling: with a negative tolerance every block splits (a zero one still accepts a centre that
// equals its prediction exactly, e.g. where the airlight is 0), so the subsampled image evaluates
// every pixel and must equal the full image exactly, whatever the image size against the tile size
// (128 px) and the coarse step: each pixel written once, by the tile that owns it. Odd sizes,
// one-pixel images and steps that do not divide the tile are included.
TEST(AirlightImage, SplittingEveryBlockGivesTheFullImageAtAnySize) {
  for (const auto& [w, h, step] : std::vector<std::tuple<int, int, int>>{
           {1, 1, 8}, {1, 37, 8}, {37, 1, 8}, {129, 129, 8}, {128, 128, 16}, {257, 66, 8}, {131, 70, 6}, {300, 140, 32},
           {97, 130, 128}, {140, 260, 256}}) {
    // Tiling does not depend on how lamps are evaluated: the street lamp (F table) and one
    // oncoming lamp (pencil) everywhere; the vehicle lamps' view tables (the slow part to
    // build) in one size only.
    Scene scene = nightRoad(w, h);
    if (w == 131) scene.lamps.erase(scene.lamps.begin() + 2, scene.lamps.begin() + 4);
    else scene.lamps.erase(scene.lamps.begin(), scene.lamps.begin() + 3);
    SurfaceBuffers surf;
    renderSurfacesCpu(scene, surf);
    auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 2, scaledFastPath());
    ASSERT_TRUE(ev.has_value());
    AirlightImage full, sub;
    ev->evaluate(scene, surf, SubsamplingOptions{.full = true}, full);
    SubsamplingOptions exact;
    exact.coarse_step = step;
    exact.rel_tolerance = 0.0;
    exact.abs_tolerance_cd_m2 = -1.0;
    ev->evaluate(scene, surf, exact, sub);
    const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    EXPECT_EQ(full.evaluated, n);
    // Tile borders are evaluated by both tiles that meet there: a few more than the pixels.
    EXPECT_GE(sub.evaluated, n) << w << "x" << h;
    std::size_t differ = 0;
    for (std::size_t k = 0; k < 3 * n; ++k) differ += full.rgb[k] != sub.rgb[k];
    EXPECT_EQ(differ, 0u) << w << "x" << h << " step " << step;
  }
}

// Write::Add (the service's traffic lamps onto its world and ego lamps' image): bit for bit the
// sum of the two images each evaluator writes alone, subsampled and on every pixel, at a size
// whose last tiles are partial; an image of another size is replaced, not added to.
TEST(AirlightImage, AddingAnEvaluatorsImageIsTheSumOfTheTwoImages) {
  Scene scene = nightRoad(203, 117);
  Scene street = scene, cars = scene;
  street.lamps = {scene.lamps[4]};
  cars.lamps = {scene.lamps[2], scene.lamps[3]};
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto a = AirlightImageEvaluator::build(street, AirlightMethod::Accurate, {}, 2, testFastPath());
  auto b = AirlightImageEvaluator::build(cars, AirlightMethod::Accurate, {}, 2, testFastPath());
  ASSERT_TRUE(a.has_value() && b.has_value());
  for (const bool full : {false, true}) {
    SubsamplingOptions opt;
    opt.full = full;
    AirlightImage alone, carsAlone, sum;
    a->evaluate(street, surf, opt, alone);
    b->evaluate(cars, surf, opt, carsAlone);
    a->evaluate(street, surf, opt, sum);
    b->evaluate(cars, surf, opt, sum, AirlightImageEvaluator::Write::Add);
    ASSERT_EQ(sum.rgb.size(), alone.rgb.size());
    std::size_t differ = 0, lit = 0;
    for (std::size_t k = 0; k < sum.rgb.size(); ++k) {
      differ += sum.rgb[k] != alone.rgb[k] + carsAlone.rgb[k];
      lit += carsAlone.rgb[k] > 1e-3f && alone.rgb[k] > 1e-3f;
    }
    EXPECT_EQ(differ, 0u) << (full ? "every pixel" : "subsampled");
    EXPECT_GT(lit, sum.rgb.size() / 2);  // both sets of lamps light most of the image
    EXPECT_EQ(sum.evaluated, carsAlone.evaluated);  // the figures are the second call's
  }
  AirlightImage small;
  small.width = 10;
  small.height = 10;
  small.rgb.assign(300, 7.0f);
  AirlightImage carsAlone;
  b->evaluate(cars, surf, SubsamplingOptions{}, carsAlone);
  b->evaluate(cars, surf, SubsamplingOptions{}, small, AirlightImageEvaluator::Write::Add);
  EXPECT_EQ(small.rgb, carsAlone.rgb);
}

// Vehicle lamps of one colour are read from one merged table (their frustum tables summed):
// the image with both lamps equals the sum of the images with each alone, and switching a lamp
// off and on again restores the image, i.e. the merged table follows the lamps' switching.
TEST(AirlightImage, MergedVehicleTablesFollowLampSwitching) {
  Scene scene = nightRoad(160, 90);
  scene.lamps.resize(2);  // the two ego low beams only
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  auto ev = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, {}, 2, scaledFastPath());
  ASSERT_TRUE(ev.has_value());
  const SubsamplingOptions full{.full = true};
  AirlightImage both, left, right, again;
  ev->evaluate(scene, surf, full, both);
  ev->setLampEnabled(1, false);
  ev->evaluate(scene, surf, full, left);
  ev->setLampEnabled(1, true);
  ev->setLampEnabled(0, false);
  ev->evaluate(scene, surf, full, right);
  ev->setLampEnabled(0, true);
  ev->evaluate(scene, surf, full, again);
  double worst = 0.0, peak = 0.0;
  for (std::size_t k = 0; k < both.rgb.size(); ++k) {
    const double sum = static_cast<double>(left.rgb[k]) + static_cast<double>(right.rgb[k]);
    worst = std::max(worst, std::abs(static_cast<double>(both.rgb[k]) - sum) / std::max(sum, 1e-3));
    peak = std::max(peak, sum);
    ASSERT_EQ(both.rgb[k], again.rgb[k]) << k;
  }
  std::printf("both lamps vs the sum of each alone: max relative difference %.2e (peak %.3g cd/m2)\n", worst, peak);
  ASSERT_GT(peak, 0.0);
  EXPECT_LT(worst, 1e-5);  // float rounding of the summed table
}

TEST(SurfaceCpu, RoadLitByOwnBeamMatchesLambertFormulaAndDistances) {
  Scene scene = nightRoad(160, 90);
  scene.fog.ambient_cd_m2 = 0.01;
  SurfaceBuffers surf;
  renderSurfacesCpu(scene, surf);
  // Pixel on the road: distance is the ray–plane distance, luminance the formula.
  const int i = 80, j = 70;
  const Vec3 d = scene.camera.rayDirection(i + 0.5, j + 0.5);
  const double t = -scene.camera.position_m.z / d.z;
  const auto k = static_cast<std::size_t>(j * 160 + i);
  EXPECT_NEAR(surf.distance[k], t, 1e-4 * t);
  const Vec3 x = scene.camera.position_m + t * d;
  double l = 0.0;
  for (const auto& sl : scene.lamps) l += lambertianLuminance(sl.lamp, scene.fog, x, {0, 0, 1}, 0.15);
  const double tr = std::exp(-scene.fog.extinction_per_m * t);
  EXPECT_NEAR(surf.rgb[3 * k], l * tr + 0.01 * (1 - tr), 1e-5 * l);
  // Sky above the horizon: infinite distance, ambient only.
  EXPECT_TRUE(std::isinf(surf.distance[5 * 160 + 80]));
  EXPECT_NEAR(surf.rgb[3 * (5 * 160 + 80)], 0.01, 1e-7);
}

}  // namespace
}  // namespace fogbeam
