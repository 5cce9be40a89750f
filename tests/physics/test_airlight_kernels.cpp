// The image fast path: the float tables against the accurate per-ray evaluator, and every
// compiled SIMD target against the scalar definitions (airlight_kernels.hpp).
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_kernels.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace fogbeam {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

Medium fog(double g) {
  Medium m;
  m.extinction_per_m = extinctionFromVisibility(100.0);
  m.albedo = 0.95;
  m.phase = makeHenyeyGreenstein(g).value();
  return m;
}

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

TEST(AirlightKernels, CumulativeMatchesEvaluateAtEveryDistance) {
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  ASSERT_TRUE(low.has_value());
  const std::vector<std::shared_ptr<const Profile>> profiles{
      makeProfile(IsotropicProfile{1000.0}).value(), makeProfile(SpotProfile{20000.0, radians(4.0), radians(14.0)}).value(),
      *low};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const std::vector<double> dist{0.0, 0.5, 2.0, 7.5, 20.0, 55.0, 140.0, kInf};
  int compared = 0;
  for (const auto& prof : profiles) {
    Lamp lamp;
    lamp.position_m = {2.0, 0.7, 0.65};
    lamp.worldFromLamp = worldFromYawPitchRoll(0.0, radians(0.57), 0.0);
    lamp.profile = prof;
    auto ev = AirlightEvaluator::build(lamp, fog(0.85), AirlightMethod::Accurate);
    ASSERT_TRUE(ev.has_value());
    auto ref = AirlightEvaluator::build(lamp, fog(0.85), AirlightMethod::Reference);
    ASSERT_TRUE(ref.has_value());
    for (int n = 0; n < 20; ++n) {
      const Ray ray{{0.0, 0.35, 1.2}, glm::normalize(Vec3(1.0, 0.4 * u(rng), 0.2 * u(rng))), 0.0};
      std::vector<double> cum(dist.size());
      ev->evaluateCumulative(ray, dist.data(), dist.size(), cum.data());
      for (std::size_t m = 0; m < dist.size(); ++m) {
        Ray r = ray;
        r.distance_m = dist[m];
        const double single = ev->evaluate(r), truth = ref->evaluate(r);
        // The extra breakpoints refine the accurate method's pieces: the cumulative values are
        // within the method's documented bound (1 %) of the reference, or no worse than a single call.
        EXPECT_NEAR(cum[m], truth, std::max(1e-2 * truth, 1.2 * std::abs(single - truth)) + 1e-9)
            << "distance " << dist[m];
        if (m > 0) {
          EXPECT_GE(cum[m], cum[m - 1] * (1.0 - 1e-9));
        }
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 3 * 20 * 8);
}

TEST(AirlightKernels, IsoTableMatchesAccurateEvaluator) {
  for (double g : {0.0, 0.85}) {
    const Medium m = fog(g);
    const auto table = kernels::IsoTable::get(m.phase);
    Lamp lamp;
    lamp.position_m = {30.0, -6.0, 8.0};
    lamp.profile = makeProfile(IsotropicProfile{3000.0}).value();
    auto ev = AirlightEvaluator::build(lamp, m, AirlightMethod::Accurate);
    ASSERT_TRUE(ev.has_value());
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<double> rel;
    for (int n = 0; n < 400; ++n) {
      const Vec3 dir = glm::normalize(Vec3(1.0, 0.6 * u(rng), 0.35 * u(rng)));
      const double d = n % 4 == 0 ? kInf : 5.0 + 60.0 * (1.0 + u(rng));
      const Ray ray{{0.0, 0.0, 1.2}, dir, d};
      const double want = ev->evaluate(ray);
      const RayLampGeometry geo = rayLampGeometry(ray, lamp.position_m);
      const double kt = m.extinction_per_m;
      const double fd = table->lookup(kt * geo.h, std::isinf(d) ? kInf : (d - geo.p) / geo.h);
      const double f0 = table->lookup(kt * geo.h, -geo.p / geo.h);
      const double got = m.albedo * kt * 3000.0 * std::exp(-kt * geo.p) / geo.h * (fd - f0);
      rel.push_back(std::abs(got - want) / want);
    }
    EXPECT_LT(percentile(rel, 0.95), 1e-3) << "g = " << g;
    EXPECT_LT(percentile(rel, 1.0), 1e-2) << "g = " << g;
  }
}

struct Batch {
  std::vector<float> x, y, d;
  kernels::PixelBatch view() const { return {x.data(), y.data(), d.data(), n}; }
  std::size_t n = 0;
};

Batch randomPixels(std::size_t n, int w, int h, unsigned seed) {
  Batch b;
  b.n = n;
  const std::size_t padded = kernels::paddedSize(n);
  b.x.assign(padded, 0.5f);
  b.y.assign(padded, 0.5f);
  b.d.assign(padded, 1.0f);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (std::size_t i = 0; i < n; ++i) {
    b.x[i] = std::floor(u(rng) * static_cast<float>(w)) + 0.5f;
    b.y[i] = std::floor(u(rng) * static_cast<float>(h)) + 0.5f;
    const float r = u(rng);
    b.d[i] = r < 0.2f ? std::numeric_limits<float>::infinity() : (r < 0.25f ? 0.0f : 200.0f * r * r);
  }
  return b;
}

// Compares the dispatched kernel on every compiled and supported target with the scalar
// definition (float tables, double arithmetic): relative 2e-4 plus a small absolute floor.
template <class Simd, class Scalar>
void compareAllTargets(const Batch& b, Simd simd, Scalar scalar) {
  const std::size_t padded = kernels::paddedSize(b.n);
  std::vector<float> rs(padded, 0.0f), gs(padded, 0.0f), bs(padded, 0.0f);
  scalar(b.view(), rs.data(), gs.data(), bs.data());
  double maxRef = 0.0;
  for (std::size_t i = 0; i < b.n; ++i) maxRef = std::max(maxRef, static_cast<double>(rs[i]));
  ASSERT_GT(maxRef, 0.0);
  const auto targets = kernels::availableTargets();
  ASSERT_FALSE(targets.empty());
  for (const std::string& t : targets) {
    ASSERT_TRUE(kernels::forceTarget(t));
    EXPECT_EQ(kernels::activeTarget(), t);
    std::vector<float> r(padded, 0.0f), g(padded, 0.0f), bl(padded, 0.0f);
    simd(b.view(), r.data(), g.data(), bl.data());
    std::size_t bad = 0;
    for (std::size_t i = 0; i < b.n; ++i) {
      const double ref = static_cast<double>(rs[i]);
      const double tol = 2e-4 * std::abs(ref) + 1e-6 * maxRef;
      auto off = [&](float a, float c) { return std::abs(static_cast<double>(a) - static_cast<double>(c)) > tol; };
      if (off(r[i], rs[i]) || off(g[i], gs[i]) || off(bl[i], bs[i])) {
        if (bad < 5) ADD_FAILURE() << t << " pixel " << i << ": " << r[i] << " vs scalar " << ref;
        ++bad;
      }
    }
    EXPECT_EQ(bad, 0u) << t;
    std::printf("  target %-8s %zu pixels agree with the scalar path\n", t.c_str(), b.n);
  }
  kernels::forceTarget("");
}

TEST(AirlightKernels, IsoKernelMatchesScalarOnEveryTarget) {
  const Medium m = fog(0.85);
  const auto table = kernels::IsoTable::get(m.phase);
  std::vector<kernels::IsoLamp> lamps;
  // Lamps ahead, beside and behind the eye (camera frame: x forward, y left, z up).
  for (const Vec3 p : {Vec3(25, -6, 7), Vec3(60, 6, 7), Vec3(8, 1.5, 0.5), Vec3(-3, 0.5, -0.4), Vec3(40, 0.05, 0.0)}) {
    kernels::IsoLamp l;
    for (int c = 0; c < 3; ++c) l.pos[c] = static_cast<float>(p[c]);
    l.weight[0] = 100.0f;
    l.weight[1] = 80.0f;
    l.weight[2] = 50.0f;
    l.kt = static_cast<float>(m.extinction_per_m);
    lamps.push_back(l);
  }
  const kernels::PixelGeometry geo{320.0f, 180.0f, static_cast<float>(1.0 / (320.0 / std::tan(radians(30.0))))};
  const Batch b = randomPixels(4099, 640, 360, 11);  // not a multiple of any vector length
  compareAllTargets(
      b,
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateIsoLamps(*table, lamps.data(), lamps.size(), geo, px, r, g, bl);
      },
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateIsoLampsScalar(*table, lamps.data(), lamps.size(), geo, px, r, g, bl);
      });
}

// A camera-fixed low beam: the view table against the per-ray accurate evaluator, then the
// SIMD lookup against the scalar one.
TEST(AirlightKernels, ViewTableMatchesAccurateAndScalar) {
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  ASSERT_TRUE(low.has_value());
  Camera cam;
  cam.position_m = {0.0, 0.35, 1.2};
  cam.width = 160;
  cam.height = 90;
  cam.fov_x = radians(50.0);
  Lamp lamp;
  lamp.position_m = {2.0, 0.7, 0.65};
  lamp.worldFromLamp = worldFromYawPitchRoll(0.0, radians(0.57), 0.0);
  lamp.profile = *low;
  lamp.color = {1.0, 0.9, 0.8};
  const Medium m = fog(0.85);
  auto ev = AirlightEvaluator::build(lamp, m, AirlightMethod::Accurate);
  ASSERT_TRUE(ev.has_value());
  ThreadPool pool(2);
  const kernels::ViewTable vt = kernels::ViewTable::build(*ev, cam, 0.25, 48, pool);
  ASSERT_GT(vt.nA, 10);
  const double f = cam.focalLengthPixels();
  const kernels::PixelGeometry geo{static_cast<float>(0.5 * cam.width), static_cast<float>(0.5 * cam.height),
                                   static_cast<float>(1.0 / f)};
  const Batch b = randomPixels(1500, cam.width, cam.height, 5);
  std::vector<double> rel;
  double maxWant = 0.0;
  std::vector<double> want(b.n), got(b.n);
  for (std::size_t i = 0; i < b.n; ++i) {
    const Ray ray{cam.position_m, cam.rayDirection(static_cast<double>(b.x[i]), static_cast<double>(b.y[i])),
                  static_cast<double>(b.d[i])};
    want[i] = ev->evaluate(ray);
    got[i] = vt.lookup((static_cast<double>(geo.cx) - static_cast<double>(b.x[i])) / f,
                       (static_cast<double>(geo.cy) - static_cast<double>(b.y[i])) / f, static_cast<double>(b.d[i]));
    maxWant = std::max(maxWant, want[i]);
  }
  for (std::size_t i = 0; i < b.n; ++i)
    if (want[i] > 1e-3 * maxWant) rel.push_back(std::abs(got[i] - want[i]) / want[i]);
  ASSERT_GT(rel.size(), 500u);
  const double p95 = percentile(rel, 0.95);
  std::printf("  view table vs accurate: median %.2e, p95 %.2e, max %.2e over %zu rays (build %.2f s, %.1f MB)\n",
              percentile(rel, 0.5), p95, percentile(rel, 1.0), rel.size(), vt.build_seconds,
              static_cast<double>(vt.bytes()) / 1e6);
  EXPECT_LT(p95, 0.01);
  compareAllTargets(
      b,
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateViewTable(vt, geo, px, r, g, bl);
      },
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateViewTableScalar(vt, geo, px, r, g, bl);
      });
}

}  // namespace
}  // namespace fogbeam
