// PencilAirlight (the accurate method shared over the planes through eye and lamp) against the
// accurate method per ray, for measured and spot lamps seen from a driver's eye.
#include <fogbeam/physics/airlight_pencil.hpp>
#include <fogbeam/physics/photometry_io.hpp>

#include <gtest/gtest.h>

#include "airlight_kernel.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

namespace fogbeam {
namespace {

Medium fog100() {
  Medium m;
  m.extinction_per_m = std::log(20.0) / 100.0;  // 100 m visibility
  m.albedo = 1.0;
  m.phase = HenyeyGreensteinPhase{0.85};
  return m;
}

std::shared_ptr<const Profile> shipped(const char* name) {
  auto p = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/" + name);
  EXPECT_TRUE(p.has_value()) << name;
  return p.value();
}

// An oncoming car's lamp: facing −x (towards the eye), dipped by `pitchDeg`.
Lamp oncoming(const Vec3& pos, std::shared_ptr<const Profile> profile, double yawDeg = 180.0, double pitchDeg = 1.0) {
  Lamp l;
  l.position_m = pos;
  l.worldFromLamp = worldFromYawPitchRoll(radians(yawDeg), radians(pitchDeg), 0.0);
  l.profile = std::move(profile);
  return l;
}

struct Stats {
  double p50 = 0, p95 = 0;
  double max = 0;  // relative to max(the ray's value, 0.01 cd/m²)
  double usPencil = 0, usExact = 0;
};

// Rays over a 60° × 34° view plus a third of them within 3° of the lamp's direction, each up
// to 24 distances (the view tables' spacing) and +inf; errors relative to the ray's value at
// the farthest distance (the scale a pixel sees), floored at 1e-4 cd/m² so that rays the lamp
// does not light do not count as relative noise; the largest error relative to the ray's value
// or 0.01 cd/m², whichever is larger (a ray grazing a spot's hard cone edge gets a blend of a
// spoke inside and one outside it: 4e-4 cd/m² where the exact value is 0).
Stats compare(const AirlightEvaluator& ev, const Vec3& eye, int rays, const PencilOptions& po = {}) {
  auto pencil = PencilAirlight::build(ev, eye, po);
  EXPECT_TRUE(pencil.has_value());
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Vec3 toLamp = glm::normalize(ev.lamp().position_m - eye);
  std::vector<Vec3> dirs;
  for (int i = 0; i < rays; ++i) {
    if (i % 3 == 0) {
      // One draw per statement: the order of draws within one call's arguments is unspecified
      // (GCC goes right to left, clang left to right), and the rays must be the same whatever
      // compiles the test. This order is the one GCC gave the figures in docs/airlight.md.
      const double jz = u(rng), jy = u(rng), jx = u(rng);
      const Vec3 j(jx, jy, jz);
      dirs.push_back(glm::normalize(toLamp + 0.05 * j));
    } else {
      const double vz = u(rng), vy = u(rng);
      dirs.push_back(glm::normalize(Vec3(1.0, std::tan(radians(30.0)) * vy, std::tan(radians(17.0)) * vz)));
    }
  }
  constexpr int nX = 24;
  std::vector<double> dist(nX);
  const double D = 40.0;
  for (int k = 0; k < nX; ++k) {
    const double x = static_cast<double>(k) / (nX - 1);
    dist[static_cast<std::size_t>(k)] = k + 1 == nX ? HUGE_VAL : D * x / (1 - x);
  }
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  std::vector<double> a(static_cast<std::size_t>(rays) * nX), b(a.size());
  for (int i = 0; i < rays; ++i)
    pencil->evaluateCumulative(dirs[static_cast<std::size_t>(i)], dist.data(), nX, a.data() + static_cast<std::size_t>(i) * nX);
  const auto t1 = Clock::now();
  for (int i = 0; i < rays; ++i)
    ev.evaluateCumulative(Ray{eye, dirs[static_cast<std::size_t>(i)], 0.0}, dist.data(), nX,
                          b.data() + static_cast<std::size_t>(i) * nX);
  const auto t2 = Clock::now();
  std::vector<double> err;
  double maxRel = 0.0;
  for (int i = 0; i < rays; ++i) {
    const double* pa = a.data() + static_cast<std::size_t>(i) * nX;
    const double* pb = b.data() + static_cast<std::size_t>(i) * nX;
    const double scale = std::max(pb[nX - 1], 1e-4);
    for (int k = 1; k < nX; ++k) {
      const double e = std::abs(pa[k] - pb[k]);
      err.push_back(e / scale);
      maxRel = std::max(maxRel, e / std::max(pb[nX - 1], 1e-2));
    }
  }
  std::sort(err.begin(), err.end());
  Stats s;
  s.p50 = err[err.size() / 2];
  s.p95 = err[err.size() * 95 / 100];
  s.max = maxRel;
  s.usPencil = std::chrono::duration<double, std::micro>(t1 - t0).count() / rays;
  s.usExact = std::chrono::duration<double, std::micro>(t2 - t1).count() / rays;
  return s;
}

void report(const char* what, const Stats& s) {
  std::printf("%-34s error p50 %.1e p95 %.1e max %.1e; %.2f µs/ray (spokes included) vs %.2f µs exact\n", what,
              s.p50, s.p95, s.max, s.usPencil, s.usExact);
}

TEST(PencilAirlight, MatchesTheAccurateMethodForOncomingMeasuredLamps) {
  const Medium m = fog100();
  const Vec3 eye(1.3, 0.37, 1.2);
  struct Case {
    const char* file;
    Vec3 pos;
    double yaw;
  } cases[] = {{"low_beam.ies", {40.0, 3.5, 0.65}, 180.0},
               {"low_beam.ies", {12.0, 3.0, 0.65}, 185.0},
               {"high_beam.ies", {80.0, 4.0, 0.65}, 180.0},
               {"low_beam.ies", {-15.0, 1.0, 0.65}, 0.0}};  // a following car's lamp, behind the eye
  for (const Case& c : cases) {
    auto ev = AirlightEvaluator::build(oncoming(c.pos, shipped(c.file), c.yaw), m, AirlightMethod::Accurate);
    ASSERT_TRUE(ev.has_value());
    const Stats s = compare(*ev, eye, 900);
    char what[96];
    std::snprintf(what, sizeof what, "%s at (%.0f, %.1f) yaw %.0f", c.file, c.pos.x, c.pos.y, c.yaw);
    report(what, s);
    EXPECT_LT(s.p95, 2e-3) << what;
    EXPECT_LT(s.max, 5e-2) << what;
  }
}

TEST(PencilAirlight, MatchesTheAccurateMethodForASpot) {
  Medium m = fog100();
  auto spot = makeProfile(SpotProfile{20000.0, radians(4.0), radians(14.0)});
  ASSERT_TRUE(spot.has_value());
  auto ev = AirlightEvaluator::build(oncoming({30.0, -3.0, 4.0}, spot.value(), 160.0, 20.0), m, AirlightMethod::Accurate);
  ASSERT_TRUE(ev.has_value());
  const Stats s = compare(*ev, Vec3(0, 0, 1.2), 900);
  report("spot 4°/14° at (30, -3, 4)", s);
  EXPECT_LT(s.p95, 2e-3);
  EXPECT_LT(s.max, 5e-2);
}

TEST(PencilAirlight, FewerSpokesMoveRaysFurther) {
  // The nearest-spoke approximation is the only one besides the accurate method's own: with
  // few spokes it must show, with the default it must not.
  const Medium m = fog100();
  auto ev = AirlightEvaluator::build(oncoming({40.0, 3.5, 0.65}, shipped("low_beam.ies")), m, AirlightMethod::Accurate);
  ASSERT_TRUE(ev.has_value());
  const Stats coarse = compare(*ev, Vec3(1.3, 0.37, 1.2), 600, PencilOptions{16, 1.5});
  const Stats fine = compare(*ev, Vec3(1.3, 0.37, 1.2), 600, PencilOptions{});
  report("16 spokes", coarse);
  report("default spokes", fine);
  EXPECT_GT(coarse.p95, 5.0 * fine.p95);
}

TEST(PencilAirlight, TheKernelExpansionAgreesWithProductIntegration) {
  // The same spokes, rays integrated two ways: through the kernel's B-spline expansion
  // (core/src/physics/airlight_kernel.hpp, the default) and piece by piece against the G
  // moments. Cases that stress it: the forward peak (rays at the lamp's image, fog-mie's
  // narrow diffraction lobe), the far-end drop for rays close to a near lamp (the driver's own
  // headlamp, 2.2 m ahead, its beam along the rays), lamps behind the eye, dense and thin fog.
  struct Case {
    const char* what;
    Lamp lamp;
    Medium fog;
    Vec3 eye;
  };
  Medium mie = fog100();
  mie.phase = makeFogMie(10.0).value();
  Medium dense = fog100();
  dense.extinction_per_m = std::log(20.0) / 30.0;
  Medium thin = fog100();
  thin.extinction_per_m = std::log(20.0) / 300.0;
  const Vec3 eye(0.0, 0.37, 1.2);
  const std::vector<Case> cases{
      {"oncoming low beam 40 m, HG 0.85", oncoming({40.0, 3.5, 0.65}, shipped("low_beam.ies")), fog100(), eye},
      {"oncoming high beam 150 m, 300 m fog", oncoming({150.0, 4.0, 0.65}, shipped("high_beam.ies")), thin, eye},
      {"oncoming low beam 25 m, fog-mie", oncoming({25.0, 3.5, 0.65}, shipped("low_beam.ies")), mie, eye},
      {"own low beam 2.2 m ahead, 30 m fog", oncoming({2.2, 0.7, 0.65}, shipped("low_beam.ies"), 0.0, 0.0), dense, eye},
      {"own low beam, fog-mie", oncoming({2.2, 0.7, 0.65}, shipped("low_beam.ies"), 0.0, 0.0), mie, eye},
      {"following car's low beam 15 m behind", oncoming({-15.0, 0.5, 0.65}, shipped("low_beam.ies"), 0.0), fog100(), eye},
  };
  for (const Case& c : cases) {
    auto ev = AirlightEvaluator::build(c.lamp, c.fog, AirlightMethod::Accurate);
    ASSERT_TRUE(ev.has_value());
    PencilOptions withKernel, without;
    without.kernel_expansion = false;
    const auto tb = std::chrono::steady_clock::now();
    auto a = PencilAirlight::build(*ev, c.eye, withKernel);  // the first of a phase builds its kernel table
    const double buildMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - tb).count();
    auto b = PencilAirlight::build(*ev, c.eye, without);
    ASSERT_TRUE(a && b);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const Vec3 toLamp = glm::normalize(c.lamp.position_m - c.eye);
    std::vector<Vec3> dirs;
    std::vector<double> dists;
    for (int i = 0; i < 3000; ++i) {
      const double vz = u(rng), vy = u(rng), jz = u(rng), jy = u(rng), jx = u(rng), r = u(rng);
      dirs.push_back(i % 3 == 0 ? glm::normalize(toLamp + 0.05 * Vec3(jx, jy, jz))
                                : glm::normalize(Vec3(1.0, std::tan(radians(30.0)) * vy, std::tan(radians(17.0)) * vz)));
      // Sky, or a surface 1–200 m away (the road's distances).
      dists.push_back(r < -0.5 ? HUGE_VAL : std::exp(std::log(1.0) + (r + 1.0) / 2.0 * std::log(200.0)));
    }
    std::vector<double> va(dirs.size()), vb(dirs.size());
    using Clock = std::chrono::steady_clock;
    for (std::size_t i = 0; i < dirs.size(); ++i) va[i] = a->evaluate(dirs[i], dists[i]);  // samples the spokes
    for (std::size_t i = 0; i < dirs.size(); ++i) vb[i] = b->evaluate(dirs[i], dists[i]);
    const auto t0 = Clock::now();
    for (std::size_t i = 0; i < dirs.size(); ++i) va[i] = a->evaluate(dirs[i], dists[i]);
    const auto t1 = Clock::now();
    for (std::size_t i = 0; i < dirs.size(); ++i) vb[i] = b->evaluate(dirs[i], dists[i]);
    const auto t2 = Clock::now();
    // Relative error over rays above 1 % of the 99.5th percentile (the bench's measure).
    std::vector<double> sorted = vb;
    std::sort(sorted.begin(), sorted.end());
    const double floor = 0.01 * sorted[sorted.size() * 995 / 1000];
    std::vector<double> err;
    for (std::size_t i = 0; i < dirs.size(); ++i)
      if (vb[i] > floor) err.push_back(std::abs(va[i] - vb[i]) / vb[i]);
    ASSERT_GT(err.size(), 100u) << c.what;
    std::sort(err.begin(), err.end());
    const double p95 = err[err.size() * 95 / 100], mx = err.back();
    const double us = [](auto d) { return std::chrono::duration<double, std::micro>(d).count(); }(t1 - t0);
    const double usB = std::chrono::duration<double, std::micro>(t2 - t1).count();
    std::printf("%-40s expansion vs pieces: p95 %.1e max %.1e over %zu rays; %.2f vs %.2f µs a ray (build %.0f ms)\n",
                c.what, p95, mx, err.size(), us / static_cast<double>(dirs.size()), usB / static_cast<double>(dirs.size()),
                buildMs);
    EXPECT_LT(p95, 1e-3) << c.what;
    EXPECT_LT(mx, 1e-2) << c.what;
  }
}

TEST(PencilAirlight, RefusesOtherMethodsAndBadOptions) {
  const Medium m = fog100();
  auto ref = AirlightEvaluator::build(oncoming({40.0, 3.5, 0.65}, shipped("low_beam.ies")), m, AirlightMethod::Reference);
  ASSERT_TRUE(ref.has_value());
  EXPECT_FALSE(PencilAirlight::build(*ref, Vec3(0.0)).has_value());
  auto acc = AirlightEvaluator::build(oncoming({40.0, 3.5, 0.65}, shipped("low_beam.ies")), m, AirlightMethod::Accurate);
  ASSERT_TRUE(acc.has_value());
  EXPECT_FALSE(PencilAirlight::build(*acc, Vec3(0.0), PencilOptions{4, 1.5}).has_value());
  EXPECT_FALSE(PencilAirlight::build(*acc, Vec3(0.0), PencilOptions{720, 0.0}).has_value());
}

// PsiBasis::interval reads a table of cells (the interval at each cell's start, one step either
// way) instead of searching the knots: the same answer everywhere, at the knots, a rounding step
// either side of each, and anywhere in and around [0, π].
TEST(PsiBasis, IntervalIsTheOneHoldingPsi) {
  const detail::PsiBasis& basis = detail::psiBasis();
  const int m = basis.intervals();
  auto expected = [&](double psi) {
    int j = 0;
    while (j + 1 <= m && basis.knot(j + 1) <= psi) ++j;
    return std::clamp(j, 0, m - 1);
  };
  std::vector<double> probes;
  for (int j = 0; j <= m; ++j) {
    const double t = basis.knot(j);
    for (double x : {t, std::nextafter(t, -1.0), std::nextafter(t, 10.0), t - 1e-12, t + 1e-12})
      probes.push_back(x);
    if (j < m) probes.push_back(0.5 * (t + basis.knot(j + 1)));
  }
  std::mt19937_64 rng(15);
  std::uniform_real_distribution<double> any(-0.1, 3.3);
  for (int k = 0; k < 200000; ++k) probes.push_back(any(rng));
  int wrong = 0;
  for (double x : probes)
    if (basis.interval(x) != expected(x) && ++wrong <= 5) ADD_FAILURE() << "psi " << x << ": " << basis.interval(x) << " against " << expected(x);
  EXPECT_EQ(wrong, 0) << "of " << probes.size() << " probes";
}

}  // namespace
}  // namespace fogbeam
