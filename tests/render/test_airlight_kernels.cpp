// The image fast path: the float tables against the accurate per-ray evaluator, and every
// compiled SIMD target against the scalar definitions (airlight_kernels.hpp).
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/render/airlight_kernels.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdint>
#include <random>
#include <string>
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
      const double vz = u(rng), vy = u(rng);  // one draw each, in a defined order (not within one call)
      const Ray ray{{0.0, 0.35, 1.2}, glm::normalize(Vec3(1.0, 0.4 * vy, 0.2 * vz)), 0.0};
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
      const double vz = u(rng), vy = u(rng);  // one draw each, in a defined order (not within one call)
      const Vec3 dir = glm::normalize(Vec3(1.0, 0.6 * vy, 0.35 * vz));
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
    std::printf("  F table (%d x %d) vs accurate, g = %.2f: median %.2e, p95 %.2e, max %.2e\n", table->nK, table->nZ, g,
                percentile(rel, 0.5), percentile(rel, 0.95), percentile(rel, 1.0));
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
  const std::vector<Vec3> at{Vec3(25, -6, 7), Vec3(60, 6, 7), Vec3(8, 1.5, 0.5), Vec3(-3, 0.5, -0.4), Vec3(40, 0.05, 0.0)};
  std::vector<float> sky(2 * kernels::kIsoSkyNodes * at.size());
  for (const Vec3 p : at) {
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
  // Sky rays through the F table (no sky tables), then through the lamps' sky tables.
  for (bool withSky : {false, true}) {
    if (withSky)
      for (std::size_t l = 0; l < lamps.size(); ++l) {
        kernels::buildIsoSky(*table, lamps[l], sky.data() + 2 * kernels::kIsoSkyNodes * l);
        lamps[l].sky = sky.data() + 2 * kernels::kIsoSkyNodes * l;
      }
    compareAllTargets(
        b,
        [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
          kernels::accumulateIsoLamps(*table, lamps.data(), lamps.size(), geo, px, r, g, bl);
        },
        [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
          kernels::accumulateIsoLampsScalar(*table, lamps.data(), lamps.size(), geo, px, r, g, bl);
        });
  }
}

// The sky table of an isotropic lamp (IsoSky: one function of the angle γ between ray and lamp)
// against the F-table formula it is made from and against the accurate evaluator, on sky rays
// all round the lamp: within a few degrees of its direction (the 1/γ peak), across the whole
// sphere, and within a few degrees of the opposite direction (where sin γ → 0 again).
TEST(AirlightKernels, IsoSkyTableMatchesTheFTableAndTheAccurateMethod) {
  // A lamp ahead of the camera and one behind it (its opposite direction is then in view).
  for (const auto& [g, lampPos] : std::vector<std::pair<double, Vec3>>{
           {0.0, Vec3(30.0, -6.0, 8.0)}, {0.85, Vec3(30.0, -6.0, 8.0)}, {0.85, Vec3(-25.0, 4.0, -3.0)}}) {
    const Medium m = fog(g);
    const auto table = kernels::IsoTable::get(m.phase);
    Lamp lamp;
    lamp.position_m = lampPos;
    lamp.profile = makeProfile(IsotropicProfile{3000.0}).value();
    auto ev = AirlightEvaluator::build(lamp, m, AirlightMethod::Accurate);
    ASSERT_TRUE(ev.has_value());
    kernels::IsoLamp L;
    for (int c = 0; c < 3; ++c) L.pos[c] = static_cast<float>(lampPos[c]);
    L.kt = static_cast<float>(m.extinction_per_m);
    L.weight[0] = L.weight[1] = L.weight[2] = 1.0f;
    std::vector<float> sky(2 * kernels::kIsoSkyNodes);
    kernels::buildIsoSky(*table, L, sky.data());
    L.sky = sky.data();
    const Vec3 e = glm::normalize(lampPos);
    const Vec3 u = glm::normalize(glm::cross(e, Vec3(0, 0, 1))), v = glm::cross(u, e);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    std::vector<double> vsTable, vsAccurate;
    for (int n = 0; n < 600; ++n) {
      // γ: a third near the lamp (0.01°–3°), a third anywhere, a third near the opposite pole.
      const double r = uni(rng);
      const double gamma = n % 3 == 0 ? radians(0.01 + 3.0 * r) : n % 3 == 1 ? kPi * r : kPi - radians(0.01 + 3.0 * r);
      const double phi = 2.0 * kPi * uni(rng);
      const Vec3 dir = std::cos(gamma) * e + std::sin(gamma) * (std::cos(phi) * u + std::sin(phi) * v);
      // One pixel whose ray is `dir`: camera frame x forward (a = y/x, b = z/x) needs x > 0;
      // rays behind the camera go through the scalar definition directly.
      const double kt = m.extinction_per_m;
      const RayLampGeometry geo = rayLampGeometry(Ray{{0, 0, 0}, dir, kInf}, lampPos);
      const double formula = std::exp(-kt * geo.p) / geo.h *
                             (table->lookup(kt * geo.h, kInf) - table->lookup(kt * geo.h, -geo.p / geo.h));
      double got = 0.0;
      if (dir.x > 1e-3) {
        const float pxX = 0.5f, pxY = 0.5f, d = std::numeric_limits<float>::infinity();
        const kernels::PixelGeometry pg{static_cast<float>(0.5 + dir.y / dir.x), static_cast<float>(0.5 + dir.z / dir.x), 1.0f};
        float rr = 0.0f, gg = 0.0f, bb = 0.0f;
        kernels::accumulateIsoLampsScalar(*table, &L, 1, pg, {&pxX, &pxY, &d, 1}, &rr, &gg, &bb);
        got = static_cast<double>(rr);
      } else {
        continue;
      }
      // Within a few degrees of the direction away from the lamp the F-table formula itself
      // loses accuracy (F(k, π/2) − F(k, θ0) at small k is a small difference of large table
      // values: 24 % off at 179.95°, where the sky table, whose nodes sit exactly at γ = π, is
      // within 1 %); it is compared elsewhere.
      if (gamma < radians(170.0)) vsTable.push_back(std::abs(got - formula) / formula);
      const double want = ev->evaluate(Ray{{0, 0, 0}, dir, kInf}) / (m.albedo * kt * 3000.0);
      vsAccurate.push_back(std::abs(got - want) / want);
    }
    ASSERT_GT(vsAccurate.size(), 190u);
    std::printf("  sky table, lamp %s, g = %.2f: vs F-table formula p95 %.2e max %.2e; vs accurate p95 %.2e max %.2e (%zu rays)\n",
                lampPos.x > 0 ? "ahead" : "behind", g,
                percentile(vsTable, 0.95), percentile(vsTable, 1.0), percentile(vsAccurate, 0.95),
                percentile(vsAccurate, 1.0), vsAccurate.size());
    EXPECT_LT(percentile(vsTable, 0.95), 1e-3) << g;
    EXPECT_LT(percentile(vsTable, 1.0), 5e-3) << g;
    EXPECT_LT(percentile(vsAccurate, 0.95), 1e-3) << g;
    EXPECT_LT(percentile(vsAccurate, 1.0), 5e-3) << g;
  }
}

// The F table's k axis: pseudoLog2 is the float-bits logarithm, exact at powers of two,
// continuous and increasing, with pseudoExp2 its inverse.
TEST(AirlightKernels, PseudoLogAxisIsMonotoneAndInvertible) {
  for (int e = 0; e < 20; ++e) EXPECT_EQ(kernels::pseudoLog2(std::ldexp(1.0, e)), static_cast<double>(e));
  double prev = -1.0;
  for (double y = 1.0; y < 5000.0; y *= 1.0137) {
    const double u = kernels::pseudoLog2(y);
    EXPECT_GT(u, prev);
    EXPECT_NEAR(kernels::pseudoExp2(u), y, 1e-12 * y);
    EXPECT_LE(std::abs(u - std::log2(y)), 0.0861);  // max of log2(1 + m) − m over m ∈ [0, 1)
    prev = u;
  }
}

// The tile kernels of the subsampled image on every target: distance-edge bits against the
// per-pixel mask, the bilinear fill of leaves against a scalar fill, and the RGB interleave.
TEST(AirlightKernels, TileKernelsMatchScalarOnEveryTarget) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const std::size_t n = 203, pad = 32;
  // Three rows of 1/d with steps (silhouettes), smooth ramps and zeros (sky), padded both sides.
  std::vector<float> rows(3 * (n + 2 * pad), 0.0f);
  for (int r = 0; r < 3; ++r)
    for (std::size_t i = 0; i < n; ++i) {
      float q = 0.02f + 0.0001f * static_cast<float>(i);
      if ((i / 17) % 3 == 0) q = 0.0f;
      if ((i / 29) % 4 == 1) q = 0.08f + 0.01f * u(rng);
      rows[static_cast<std::size_t>(r) * (n + 2 * pad) + pad + i] = q;
    }
  const float* up = rows.data() + pad;
  const float* c = up + (n + 2 * pad);
  const float* dn = c + (n + 2 * pad);
  // The definition: a second difference beyond 2 % of the largest value, which exceeds the floor;
  // along the row for inner entries, across the rows for all.
  auto edge = [](float a, float b, float m, float floor) {
    const float top = std::max(std::max(a, b), m);
    return std::abs(a + b - 2 * m) > 0.02f * top && top > floor;
  };
  std::size_t edges = 0;
  for (const std::string& t : kernels::availableTargets()) {
    ASSERT_TRUE(kernels::forceTarget(t));
    for (float floor : {0.0f, 0.05f}) {
      for (bool across : {true, false}) {
        std::vector<std::uint64_t> bits((n + 63) / 64 + 1, ~std::uint64_t{0});
        kernels::distanceEdgeBits(across ? up : nullptr, c, across ? dn : nullptr, n, 0.02f, floor, bits.data());
        for (std::size_t i = 0; i < n; ++i) {
          const bool got = (bits[i / 64] >> (i % 64)) & 1u;
          const bool want = (i > 0 && i + 1 < n && edge(c[i - 1], c[i + 1], c[i], floor)) ||
                            (across && edge(up[i], dn[i], c[i], floor));
          edges += want;
          ASSERT_EQ(got, want) << t << " floor " << floor << " across " << across << " pixel " << i;
        }
        EXPECT_EQ(bits[(n + 63) / 64], 0u) << t;
      }
    }
    // Fill: planes of 40 × 20 with a stride of 64, random values. Evaluated pixels, as the tiles
    // make them: every corner and centre, and some of each leaf's first row and column.
    const std::size_t stride = 64;
    std::vector<float> planes(3 * stride * 21);
    for (float& v : planes) v = u(rng);
    std::vector<std::uint8_t> done(stride * 21, 0);
    const std::vector<kernels::FillBlock> blocks{{0, 0, 8, 8, 7, 7}, {8, 0, 16, 8, 23, 7}, {24, 0, 1, 1, 24, 0},
                                                 {0, 8, 4, 12, 4, 19}, {30, 10, 9, 9, 39, 19}, {25, 0, 5, 9, 29, 8}};
    for (const auto& bl : blocks) {
      auto mark = [&](int i, int j) { done[static_cast<std::size_t>(j) * stride + static_cast<std::size_t>(i)] = 1; };
      for (int i : {bl.i0, bl.i0 + bl.w})
        for (int j : {bl.j0, bl.j0 + bl.h}) mark(i, j);
      mark(bl.i0 + bl.w / 2, bl.j0 + bl.h / 2);
      for (int i = bl.i0; i <= bl.iEnd; ++i)
        if (u(rng) < 0.3f) mark(i, bl.j0);
      for (int j = bl.j0; j <= bl.jEnd; ++j)
        if (u(rng) < 0.3f) mark(bl.i0, j);
    }
    std::vector<float> want = planes, got = planes;
    for (const auto& bl : blocks)
      for (int j = bl.j0; j <= bl.jEnd; ++j)
        for (int i = bl.i0; i <= bl.iEnd; ++i) {
          const std::size_t at = static_cast<std::size_t>(j) * stride + static_cast<std::size_t>(i);
          if (done[at]) continue;
          const float fu = static_cast<float>(i - bl.i0) / static_cast<float>(bl.w);
          const float fv = static_cast<float>(j - bl.j0) / static_cast<float>(bl.h);
          for (int p = 0; p < 3; ++p) {
            const float* pl = planes.data() + static_cast<std::size_t>(p) * stride * 21;
            auto cv = [&](int ii, int jj) { return pl[static_cast<std::size_t>(jj) * stride + static_cast<std::size_t>(ii)]; };
            const float left = cv(bl.i0, bl.j0) + fv * (cv(bl.i0, bl.j0 + bl.h) - cv(bl.i0, bl.j0));
            const float right = cv(bl.i0 + bl.w, bl.j0) + fv * (cv(bl.i0 + bl.w, bl.j0 + bl.h) - cv(bl.i0 + bl.w, bl.j0));
            want[static_cast<std::size_t>(p) * stride * 21 + at] = left + fu * (right - left);
          }
        }
    kernels::fillBlocks(blocks.data(), blocks.size(), got.data(), got.data() + stride * 21, got.data() + 2 * stride * 21,
                        done.data(), stride);
    for (std::size_t k = 0; k < got.size(); ++k) ASSERT_NEAR(got[k], want[k], 2e-6f) << t << " at " << k;
    std::vector<float> rgb(3 * 37, -1.0f);
    kernels::interleaveRgb(planes.data(), planes.data() + 100, planes.data() + 200, 37, rgb.data());
    kernels::flushStreams();
    for (std::size_t i = 0; i < 37; ++i) {
      ASSERT_EQ(rgb[3 * i], planes[i]) << t;
      ASSERT_EQ(rgb[3 * i + 1], planes[100 + i]) << t;
      ASSERT_EQ(rgb[3 * i + 2], planes[200 + i]) << t;
    }
  }
  kernels::forceTarget("");
  EXPECT_GT(edges, 100u);  // the rows hold silhouettes
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

  // The same table with its rays through the pencil (FastPathOptions::pencil_view_tables, the
  // renderer's default): node by node against the per-ray table (the pencil's own error: its
  // spokes and the kernel expansion), then looked up against the accurate method per ray.
  PencilOptions po;
  po.spoke_tolerance = 0.0;
  auto pencil = PencilAirlight::build(*ev, cam.position_m, po);
  ASSERT_TRUE(pencil.has_value());
  const kernels::ViewTable vp = kernels::ViewTable::build(*ev, cam, 0.25, 48, pool, 0.0, &*pencil);
  ASSERT_TRUE(vp.sameGrid(vt));
  double maxNode = 0.0;
  for (std::size_t k = 0; k < vt.data.size(); k += 2) maxNode = std::max(maxNode, static_cast<double>(vt.data[k]));
  std::vector<double> nodeRel;
  for (std::size_t k = 0; k < vt.data.size(); k += 2) {
    const double a = vt.data[k], c = vp.data[k];
    ASSERT_EQ(vt.data[k + 1], vp.data[k + 1]);  // the slopes are the integrand itself, not the pencil's
    if (a > 1e-3 * maxNode) nodeRel.push_back(std::abs(c - a) / a);
  }
  ASSERT_GT(nodeRel.size(), 10000u);
  std::vector<double> relP;
  for (std::size_t i = 0; i < b.n; ++i) {
    if (!(want[i] > 1e-3 * maxWant)) continue;
    const double gp = vp.lookup((static_cast<double>(geo.cx) - static_cast<double>(b.x[i])) / f,
                                (static_cast<double>(geo.cy) - static_cast<double>(b.y[i])) / f,
                                static_cast<double>(b.d[i]));
    relP.push_back(std::abs(gp - want[i]) / want[i]);
  }
  std::printf("  pencil's table: nodes vs the per-ray table p95 %.2e, max %.2e (%zu nodes); looked up vs accurate "
              "median %.2e, p95 %.2e, max %.2e (build %.2f s against %.2f s)\n",
              percentile(nodeRel, 0.95), percentile(nodeRel, 1.0), nodeRel.size(), percentile(relP, 0.5),
              percentile(relP, 0.95), percentile(relP, 1.0), vp.build_seconds, vt.build_seconds);
  EXPECT_LT(percentile(nodeRel, 0.95), 2e-3);
  EXPECT_LT(percentile(relP, 0.95), 0.01);

  compareAllTargets(
      b,
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateViewTable(vt, geo, px, r, g, bl);
      },
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateViewTableScalar(vt, geo, px, r, g, bl);
      });

  // Read through a rotation (the bending ladder: a rung made for the lamp turned by 1.5° about
  // the camera's vertical, ViewTableUse::rotated), with the rotation off in a disc around a
  // point of the view (a lamp's image): every target against the scalar definition; and the
  // scalar read against the table looked up at the turned direction by hand.
  kernels::ViewTableUse turned = kernels::ViewTableUse::of(vt);
  turned.rotated = true;
  const Mat3 qT = glm::transpose(worldFromYawPitchRoll(radians(1.5), 0.0, 0.0));
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) turned.rot[3 * row + col] = static_cast<float>(qT[col][row]);
  turned.nKeep = 1;
  turned.keepA[0] = 0.1f;
  turned.keepB[0] = -0.1f;
  turned.keepR2[0] = 0.01f;
  compareAllTargets(
      b,
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateViewTable(vt, turned, geo, px, r, g, bl);
      },
      [&](const kernels::PixelBatch& px, float* r, float* g, float* bl) {
        kernels::accumulateViewTableScalar(vt, turned, geo, px, r, g, bl);
      });
  std::vector<float> z(kernels::paddedSize(b.n), 0.0f), rr = z, gg = z, bb = z;
  kernels::accumulateViewTableScalar(vt, turned, geo, b.view(), rr.data(), gg.data(), bb.data());
  int inside = 0, outside = 0;
  for (std::size_t i = 0; i < b.n; ++i) {
    const double a = (static_cast<double>(geo.cx) - static_cast<double>(b.x[i])) / f;
    const double c = (static_cast<double>(geo.cy) - static_cast<double>(b.y[i])) / f;
    const Vec3 dir = qT * Vec3(1.0, a, c);
    const bool keep = (a - 0.1) * (a - 0.1) + (c + 0.1) * (c + 0.1) <= 0.01;
    const double read = keep ? vt.lookupAnywhere(a, c, static_cast<double>(b.d[i]))
                             : vt.lookupAnywhere(dir.y / dir.x, dir.z / dir.x, static_cast<double>(b.d[i]));
    (keep ? inside : outside) += 1;
    EXPECT_NEAR(rr[i], read * static_cast<double>(turned.weight[0]), 1e-4 * read + 1e-9) << "pixel " << i;
  }
  EXPECT_GT(inside, 10);
  EXPECT_GT(outside, 500);
}

// Wide views (fogbeam render of a 170° camera never finished, one of 179.999° ran out of memory:
// the nodes are uniform in the tangent plane, 24 million directions at 0.2°): the frustum table
// keeps at most kMaxDirections directions, coarser where it must (viewTableStep). A view 120°
// wide keeps 0.2°; one 150° wide gets ~0.42° at the centre and is checked against the accurate
// method per ray (the figure docs/airlight.md gives).
TEST(AirlightKernels, WideViewsKeepTheViewTableBounded) {
  using kernels::ViewTable;
  // Views up to ~100° wide at 16:9 keep the step asked for.
  EXPECT_EQ(ViewTable::viewTableStep(0.2, 2.0 * std::tan(radians(30.0)), 2.0 * std::tan(radians(30.0)) * 9.0 / 16.0),
            std::tan(radians(0.2)));
  const double t60 = std::tan(radians(60.0));
  EXPECT_EQ(ViewTable::viewTableStep(0.2, 2.0 * t60, 2.0 * t60 * 9.0 / 16.0), std::tan(radians(0.2)));  // 120°
  auto low = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");
  ASSERT_TRUE(low.has_value());
  Lamp lamp;
  lamp.position_m = {2.0, 0.7, 0.65};
  lamp.worldFromLamp = worldFromYawPitchRoll(0.0, radians(0.57), 0.0);
  lamp.profile = *low;
  auto ev = AirlightEvaluator::build(lamp, fog(0.85), AirlightMethod::Accurate);
  ASSERT_TRUE(ev.has_value());
  ThreadPool pool(2);
  auto camera = [](int w, int h, double fovDeg) {
    Camera c;
    c.position_m = {0.0, 0.35, 1.2};
    c.width = w;
    c.height = h;
    c.fov_x = radians(fovDeg);
    return c;
  };
  // 170° and 179.999° wide, and 2 × 1000 px at 60° (179.6° high): a few distances suffice to
  // show the size; the nodes are those of any table of that view.
  PencilOptions po;
  po.spoke_tolerance = 0.0;
  auto pencil = PencilAirlight::build(*ev, camera(1, 1, 60.0).position_m, po);  // every camera's eye
  ASSERT_TRUE(pencil.has_value());
  for (const Camera& cam : {camera(320, 180, 170.0), camera(320, 180, 179.999), camera(2, 1000, 60.0)}) {
    const ViewTable vt = ViewTable::build(*ev, cam, 0.2, 4, pool, 0.0, &*pencil);
    const std::size_t dirs = static_cast<std::size_t>(vt.nA) * static_cast<std::size_t>(vt.nB);
    // The bound less the nodes of margin (3 a side): at most a quarter more where one side is narrow.
    EXPECT_LE(dirs, ViewTable::kMaxDirections * 5 / 4) << cam.width << "x" << cam.height << " at " << cam.fov_x;
    EXPECT_GT(dirs, ViewTable::kMaxDirections / 2);
    for (float v : vt.data) ASSERT_TRUE(std::isfinite(v));
  }
  // 150° at 16:9: 2.6 million directions at 0.2°, kMaxDirections at the spacing it gets.
  const Camera cam = camera(320, 180, 150.0);
  const ViewTable vt = ViewTable::build(*ev, cam, 0.2, 48, pool, 0.0, &*pencil);
  const double stepDeg = degrees(std::atan(1.0 / static_cast<double>(vt.invStep)));
  EXPECT_GT(stepDeg, 0.35);
  EXPECT_LT(stepDeg, 0.5);
  const double f = cam.focalLengthPixels();
  const Batch b = randomPixels(12000, cam.width, cam.height, 11);
  std::vector<double> want(b.n), rel;
  for (std::size_t i = 0; i < b.n; ++i) {
    const Ray ray{cam.position_m, cam.rayDirection(static_cast<double>(b.x[i]), static_cast<double>(b.y[i])),
                  static_cast<double>(b.d[i])};
    want[i] = ev->evaluate(ray);
  }
  // Over the pixels above 1 % of the 99.5th percentile, outside the disc of 15 steps about the
  // lamp's image, where the renderer reads insets and rays instead (buildLampViewTables).
  const Vec3 lampInCam = glm::transpose(cam.worldFromCamera) * (lamp.position_m - cam.position_m);
  const double la = lampInCam.y / lampInCam.x, lb = lampInCam.z / lampInCam.x, guard = 15.0 / static_cast<double>(vt.invStep);
  const double p995 = percentile(want, 0.995);
  for (std::size_t i = 0; i < b.n; ++i) {
    if (!(want[i] > 1e-2 * p995)) continue;
    const double a = (0.5 * cam.width - static_cast<double>(b.x[i])) / f, bb = (0.5 * cam.height - static_cast<double>(b.y[i])) / f;
    if ((a - la) * (a - la) + (bb - lb) * (bb - lb) <= guard * guard) continue;
    rel.push_back(std::abs(vt.lookup(a, bb, static_cast<double>(b.d[i])) - want[i]) / want[i]);
  }
  ASSERT_GT(rel.size(), 300u);
  std::printf("  150 deg view: step %.3f deg at the centre, %d x %d directions; vs accurate median %.2e, p95 %.2e, "
              "max %.2e over %zu rays (build %.2f s, %.1f MB)\n",
              stepDeg, vt.nA, vt.nB, percentile(rel, 0.5), percentile(rel, 0.95), percentile(rel, 1.0), rel.size(),
              vt.build_seconds, static_cast<double>(vt.bytes()) / 1e6);
  EXPECT_LT(percentile(rel, 0.95), 0.02);
}

}  // namespace
}  // namespace fogbeam
