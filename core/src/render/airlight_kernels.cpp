// fogbeam — the airlight tables of the image fast path and their scalar definitions
// (airlight_kernels.hpp). The SIMD versions are in airlight_kernels_simd.cpp.
#include <fogbeam/render/airlight_kernels.hpp>
#include <fogbeam/util/shared_cache.hpp>

#include <boost/math/quadrature/gauss.hpp>
#include <boost/math/quadrature/gauss_kronrod.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <tuple>

namespace fogbeam::kernels {

namespace {

constexpr double kHalfPi = 0.5 * kPi;
// The tables are float (for the SIMD kernels); the scalar definitions compute in double.
constexpr double dbl(float v) noexcept { return static_cast<double>(v); }

// ζ ↔ q = tan θ (airlight_kernels.hpp): ζ = sgn q (1 − (1 + |q|)^{−1/2}).
double zetaOfQ(double q) {
  if (std::isinf(q)) return q > 0 ? 1.0 : -1.0;
  return std::copysign(1.0 - 1.0 / std::sqrt(1.0 + std::abs(q)), q);
}
double thetaOfZeta(double z) {
  const double e = 1.0 - std::abs(z);
  if (e <= 0.0) return std::copysign(kHalfPi, z);
  return std::atan(std::copysign(1.0 / (e * e) - 1.0, z));
}
double hermite(double t, double f0, double m0, double f1, double m1) {
  const double t2 = t * t, t3 = t2 * t;
  const double h01 = 3 * t2 - 2 * t3;
  return (1 - h01) * f0 + (t3 - 2 * t2 + t) * m0 + h01 * f1 + (t3 - t2) * m1;
}

void cell(double g, int n, int& i, double& t) {
  const double gc = std::clamp(g, 0.0, static_cast<double>(n - 1));
  const double fl = std::min(std::floor(gc), static_cast<double>(n - 2));
  i = static_cast<int>(fl);
  t = gc - fl;
}

using PhaseKey = std::tuple<PhaseIdentity, int, int, double>;

}  // namespace

std::shared_ptr<const IsoTable> IsoTable::get(const Phase& phase, int nK, int nZ, double kMax) {
  // The most recent tables stay alive when no evaluator holds them: evaluators built per frame
  // (traffic, frames while view tables are built) would otherwise build the table (~0.2 s) on
  // every frame whose longer-lived evaluator has no isotropic lamp.
  static SharedCache<PhaseKey, IsoTable> cache(4);
  return cache.get(PhaseKey{phaseIdentity(phase), nK, nZ, kMax}, [&] { return build(phase, nK, nZ, kMax); });
}

std::shared_ptr<const IsoTable> IsoTable::build(const Phase& phase, int nK, int nZ, double kMax) {
  auto t = std::make_shared<IsoTable>();
  t->phase = phase;
  t->nK = nK;
  t->nZ = nZ;
  t->kMax = static_cast<float>(kMax);
  // k0: the log axis is linear below ~k0 (k = K_t h ≈ 0 for rays grazing a lamp) and
  // logarithmic above, where F changes by a similar fraction per decade.
  const double k0 = 0.01;
  t->k0 = static_cast<float>(k0);
  const double logSpan = pseudoLog2(1.0 + kMax / k0);
  t->uScale = static_cast<float>((nK - 1) / logSpan);
  t->data.assign(static_cast<std::size_t>(nK) * static_cast<std::size_t>(nZ), 0.0f);
  const double dz = 2.0 / (nZ - 1);
  using GL = boost::math::quadrature::gauss<double, 8>;
  // G's k-independent factors (integrandGFactors) at every abscissa the quadrature asks for,
  // recorded once in the order it asks; each k row replays them, so that it needs one exp per
  // abscissa instead of a phase function, a sine and a tangent as well. The sums are bit for bit
  // those of integrandG (same arguments, same order).
  std::vector<double> theta(static_cast<std::size_t>(nZ));
  for (int j = 0; j < nZ; ++j) theta[static_cast<std::size_t>(j)] = thetaOfZeta(-1.0 + j * dz);
  std::vector<GFactors> factors;
  for (int j = 1; j < nZ; ++j) {
    const double a = theta[static_cast<std::size_t>(j - 1)], b = theta[static_cast<std::size_t>(j)];
    if (b > a)
      (void)GL::integrate([&](double x) { factors.push_back(integrandGFactors(phase, x)); return 0.0; }, a, b);
  }
  for (int i = 0; i < nK; ++i) {
    const double k = k0 * (pseudoExp2(static_cast<double>(i) / (nK - 1) * logSpan) - 1.0);
    float* row = t->data.data() + static_cast<std::size_t>(i) * static_cast<std::size_t>(nZ);
    double sum = 0.0, thPrev = -kHalfPi;
    std::size_t next = 0;
    for (int j = 0; j < nZ; ++j) {
      const double th = theta[static_cast<std::size_t>(j)];
      // ∫ G dθ over the node interval (G is smooth there: the θ nodes are dense where it peaks).
      if (j > 0 && th > thPrev)
        sum += GL::integrate(
            [&](double) { return integrandGFrom(k, factors[next++]); },
            thPrev, th);
      thPrev = th;
      row[j] = static_cast<float>(sum);
    }
  }
  t->quads.assign(static_cast<std::size_t>(nK - 1) * static_cast<std::size_t>(nZ) * 4, 0.0f);
  for (int i = 0; i + 1 < nK; ++i)
    for (int j = 0; j + 1 < nZ; ++j) {
      const std::size_t at = static_cast<std::size_t>(i) * static_cast<std::size_t>(nZ) + static_cast<std::size_t>(j);
      float* q = t->quads.data() + 4 * at;
      q[0] = t->data[at];
      q[1] = t->data[at + 1];
      q[2] = t->data[at + static_cast<std::size_t>(nZ)];
      q[3] = t->data[at + static_cast<std::size_t>(nZ) + 1];
    }
  return t;
}

double IsoTable::tailIntegral(double k, double theta) const {
  if (!(theta < kHalfPi)) return 0.0;
  if (!(k > 0.0)) {  // no extinction along the ray: the phase function alone
    using GL = boost::math::quadrature::gauss<double, 15>;
    return GL::integrate([&](double x) { return evalPhase(phase, -std::sin(x)); }, theta, kHalfPi);
  }
  // θ' = π/2 − 2 atan(k/t), so −sin θ' = (k² − t²)/(k² + t²); dθ' = 2k/(k² + t²) dt;
  // G = e^{−t} p(−sin θ'). The table is float: 1e-7 is tolerance enough.
  auto f = [&](double t) {
    const double s = k * k + t * t;
    return std::exp(-t) * evalPhase(phase, (k * k - t * t) / s) * 2.0 * k / s;
  };
  using GK = boost::math::quadrature::gauss_kronrod<double, 31>;
  return GK::integrate(f, k * std::tan(0.25 * kPi + 0.5 * theta), std::numeric_limits<double>::infinity(), 15, 1e-7);
}

double IsoTable::lookup(double k, double q) const noexcept {
  int iu = 0, iz = 0;
  double tu = 0.0, tz = 0.0;
  cell(pseudoLog2(1.0 + k / dbl(k0)) * dbl(uScale), nK, iu, tu);
  cell((zetaOfQ(q) + 1.0) * 0.5 * (nZ - 1), nZ, iz, tz);
  auto at = [&](int row) {
    const float* c = data.data() + static_cast<std::size_t>(row) * static_cast<std::size_t>(nZ) +
                     static_cast<std::size_t>(iz);
    return dbl(c[0]) + tz * (dbl(c[1]) - dbl(c[0]));
  };
  const double a = at(iu), b = at(iu + 1);
  return a + tu * (b - a);
}

double pseudoLog2(double y) noexcept {
  int e = 0;
  const double m = std::frexp(y, &e);  // y = m · 2^e, m ∈ [0.5, 1)
  return static_cast<double>(e - 1) + (2.0 * m - 1.0);
}

double pseudoExp2(double u) noexcept {
  const double e = std::floor(u);
  return std::ldexp(1.0 + (u - e), static_cast<int>(e));
}

namespace {
constexpr double kSqrtHalf = 0.70710678118654752440;
// Node coordinate of half-chord x in an IsoSky half table.
constexpr double kSkyNodeScale = (kIsoSkyNodes - 1) / kSqrtHalf;
// Behind the lamp, x = cos γ/2 below this (γ within 2.9° of π) is integrated directly.
constexpr double kAwaySkyX = 0.025;
}  // namespace

namespace {
double isoDistance(const IsoLamp& lamp) {
  const double px = dbl(lamp.pos[0]), py = dbl(lamp.pos[1]), pz = dbl(lamp.pos[2]);
  return std::sqrt(px * px + py * py + pz * pz);
}
}  // namespace

void setIsoDirection(IsoLamp& lamp) noexcept {
  const double D = isoDistance(lamp);
  for (int c = 0; c < 3; ++c) lamp.dir[c] = static_cast<float>(dbl(lamp.pos[c]) / D);
}

void buildIsoSky(const IsoTable& table, IsoLamp& lamp, float* out) {
  setIsoDirection(lamp);
  const double D = isoDistance(lamp);
  const double kt = dbl(lamp.kt);
  const double fInf = std::numeric_limits<double>::infinity();
  for (int half = 0; half < 2; ++half)
    for (int i = 0; i < kIsoSkyNodes; ++i) {
      // x = sin γ/2 in front (cos γ/2 behind): cos γ = ±(1 − 2x²), sin γ = 2x √(1 − x²).
      const double x = static_cast<double>(i) / kSkyNodeScale;
      const double cosG = (half == 0 ? 1.0 : -1.0) * (1.0 - 2.0 * x * x);
      const double sinG = 2.0 * x * std::sqrt(1.0 - x * x);
      const double p = D * cosG, h = D * sinG;
      const double k = kt * h;
      // F(k, π/2) − F(k, θ0), θ0 = γ − π/2 (q0 = tan θ0 = −p/h, −∞ on the lamp's own direction):
      // from the table, or integrated directly within 3° of straight away from the lamp, where
      // the difference of table values loses its precision (IsoTable::tailIntegral).
      double tail = 0.0;
      if (half == 1 && x < kAwaySkyX)
        tail = x > 0.0 ? table.tailIntegral(k, kHalfPi - 2.0 * std::asin(x)) : 0.0;
      else
        tail = table.lookup(k, fInf) - table.lookup(k, h > 0.0 ? -p / h : -fInf);
      out[half * kIsoSkyNodes + i] = static_cast<float>(std::max(std::exp(-kt * p) / D * tail, 0.0));
    }
}

namespace {
// L_m / (Ω K_t I) of a sky ray from the lamp's IsoSky table (the SIMD kernel's steps in double).
double isoSkyScalar(const IsoLamp& L, double wx, double wy, double wz) {
  const double ex = dbl(L.dir[0]), ey = dbl(L.dir[1]), ez = dbl(L.dir[2]);
  const bool behind = wx * ex + wy * ey + wz * ez < 0.0;
  const double sg = behind ? -1.0 : 1.0;
  const double vx = wx - sg * ex, vy = wy - sg * ey, vz = wz - sg * ez;
  const double x = 0.5 * std::sqrt(vx * vx + vy * vy + vz * vz);
  int i = 0;
  double t = 0.0;
  cell(x * kSkyNodeScale, kIsoSkyNodes, i, t);
  const float* row = L.sky + (behind ? kIsoSkyNodes : 0) + i;
  const double v = dbl(row[0]) + t * (dbl(row[1]) - dbl(row[0]));
  const double sinG = std::max(2.0 * x * std::sqrt(std::max(1.0 - x * x, 0.0)), 1e-7);
  return v / sinG;
}
}  // namespace

void accumulateIsoLampsScalar(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                              const PixelBatch& px, float* r, float* gr, float* b) {
  for (std::size_t i = 0; i < px.n; ++i) {
    const double a = (dbl(g.cx) - dbl(px.x[i])) * dbl(g.invF);
    const double bb = (dbl(g.cy) - dbl(px.y[i])) * dbl(g.invF);
    const double invLen = 1.0 / std::sqrt(1.0 + a * a + bb * bb);
    const double dist = dbl(px.d[i]);
    for (std::size_t l = 0; l < nLamps; ++l) {
      const IsoLamp& L = lamps[l];
      if (!(dist > 0.0)) continue;
      if (std::isinf(dist) && L.sky) {
        const double lm = isoSkyScalar(L, invLen, a * invLen, bb * invLen);
        r[i] += static_cast<float>(lm * dbl(L.weight[0]));
        gr[i] += static_cast<float>(lm * dbl(L.weight[1]));
        b[i] += static_cast<float>(lm * dbl(L.weight[2]));
        continue;
      }
      const double lx = dbl(L.pos[0]), ly = dbl(L.pos[1]), lz = dbl(L.pos[2]);
      const double p = (lx + a * ly + bb * lz) * invLen;  // (S − O)·ω
      const double cx = ly * bb - lz * a, cy = lz - lx * bb, cz = lx * a - ly;  // (S − O) × (1, a, b)
      const double h = std::max(std::sqrt(cx * cx + cy * cy + cz * cz) * invLen, 1e-6);
      const double k = dbl(L.kt) * h;
      const double f0 = table.lookup(k, -p / h);
      const double fd = table.lookup(k, std::isinf(dist) ? std::numeric_limits<double>::infinity() : (dist - p) / h);
      const double lm = std::max(0.0, std::exp(-dbl(L.kt) * p) / h * (fd - f0));
      r[i] += static_cast<float>(lm * dbl(L.weight[0]));
      gr[i] += static_cast<float>(lm * dbl(L.weight[1]));
      b[i] += static_cast<float>(lm * dbl(L.weight[2]));
    }
  }
}

// ---------------------------------------------------------------------------------------------
double ViewTable::defaultDistanceScale(double kt, double lampDistance) noexcept {
  return std::clamp(0.3 / kt, 2.0 * lampDistance + 1.0, 200.0);
}

bool ViewTable::sameGrid(const ViewTable& o) const noexcept {
  return a0 == o.a0 && b0 == o.b0 && invStep == o.invStep && nA == o.nA && nB == o.nB && nX == o.nX &&
         distanceScale == o.distanceScale && data.size() == o.data.size();
}

void ViewTable::add(const ViewTable& o) {
  for (std::size_t i = 0; i < data.size(); ++i) data[i] += o.data[i];
  finish();
}

void ViewTable::finish() {
  const auto na = static_cast<std::size_t>(nA), nb = static_cast<std::size_t>(nB);
  const std::size_t last = 2 * static_cast<std::size_t>(nX - 1);
  auto sky = [&](std::size_t ia, std::size_t ib) {
    return data[(std::min(ib, nb - 1) * na + std::min(ia, na - 1)) * 2 * static_cast<std::size_t>(nX) + last];
  };
  skyQuads.assign(4 * na * nb, 0.0f);
  for (std::size_t ib = 0; ib < nb; ++ib)
    for (std::size_t ia = 0; ia < na; ++ia) {
      float* q = skyQuads.data() + 4 * (ib * na + ia);
      q[0] = sky(ia, ib);
      q[1] = sky(ia + 1, ib);
      q[2] = sky(ia, ib + 1);
      q[3] = sky(ia + 1, ib + 1);
    }
}

ViewTableUse ViewTableUse::of(const ViewTable& t) noexcept {
  ViewTableUse u;
  for (int c = 0; c < 3; ++c) u.weight[c] = t.weight[c];
  u.guardA = t.guardA;
  u.guardB = t.guardB;
  u.innerR2 = t.innerR2;
  u.outerR2 = t.outerR2;
  return u;
}

ViewTable ViewTable::build(const AirlightEvaluator& lamp, const Camera& camera, double stepDeg, int nX,
                           ThreadPool& pool, double distanceScale, const PencilAirlight* pencil) {
  // The window of the tangent plane the frustum spans, a ∈ [aLo, aHi], b ∈ [bLo, bHi]. Centred:
  // ±tan(fov_x/2) and ±that × H/W (square pixels). Off-axis: pixel x ∈ [0, W] maps to
  // a = (cx − x)/f ∈ [(cx − W)/f, cx/f] = [−tan right, tan left] and y ∈ [0, H] to
  // b = (cy − y)/f ∈ [(cy − H)/f, cy/f] = [−tan down, tan up] (PixelGeometry).
  double aLo, aHi, bLo, bHi;
  if (camera.isCentred()) {
    aHi = std::tan(0.5 * camera.fov_x);
    bHi = aHi * camera.height / camera.width;
    aLo = -aHi;
    bLo = -bHi;
  } else {
    const double f = camera.focalLengthPixels();
    const Vec2 c = camera.principalPoint();
    aLo = (c.x - camera.width) / f;
    aHi = c.x / f;
    bLo = (c.y - camera.height) / f;
    bHi = c.y / f;
  }
  const double step = viewTableStep(stepDeg, aHi - aLo, bHi - bLo);
  // One node of margin beyond the frustum on each side, so that edge pixels interpolate.
  return buildWindow(lamp, camera, aLo - step, bLo - step, static_cast<int>(std::ceil((aHi - aLo) / step)) + 3,
                     static_cast<int>(std::ceil((bHi - bLo) / step)) + 3, step, nX, pool, distanceScale, pencil);
}

double ViewTable::viewTableStep(double stepDeg, double spanA, double spanB) noexcept {
  // The nodes are uniform in the tangent plane, so their angular spacing at an angle θ from the
  // view axis is step · cos² θ: a view 120° wide at 16:9 needs 9× the nodes of one 60° wide for
  // the same spacing at the centre, and one 170° wide ~400× (24 million directions, 9 GB at
  // 48 distances: the build never ended). Past kMaxDirections the step grows until the table
  // holds that many (~230 MB a lamp): views up to ~120° wide at 16:9 keep stepDeg.
  double step = std::tan(radians(stepDeg));
  const double n = (spanA / step) * (spanB / step);
  if (n > static_cast<double>(kMaxDirections)) step *= std::sqrt(n / static_cast<double>(kMaxDirections));
  return step;
}

ViewTable ViewTable::buildWindow(const AirlightEvaluator& lamp, const Camera& camera, double a0, double b0, int nA,
                                 int nB, double step, int nX, ThreadPool& pool, double distanceScale,
                                 const PencilAirlight* pencil) {
  const auto t0 = std::chrono::steady_clock::now();
  ViewTable vt;
  vt.nA = std::max(nA, 2);
  vt.nB = std::max(nB, 2);
  vt.a0 = static_cast<float>(a0);
  vt.b0 = static_cast<float>(b0);
  vt.invStep = static_cast<float>(1.0 / step);
  vt.nX = std::max(nX, 4);
  // D: half the cumulative's growth happens within a few scattering lengths; 0.3/K_t puts
  // about a third of the nodes inside the first 0.3 mean free paths and keeps D at least
  // twice the lamp's distance from the eye, where the near-lamp peak sits.
  const Medium& m = lamp.medium();
  const double D = distanceScale > 0.0
                       ? distanceScale
                       : defaultDistanceScale(m.extinction_per_m,
                                              glm::length(lamp.lamp().position_m - camera.position_m));
  vt.distanceScale = static_cast<float>(D);
  for (int c = 0; c < 3; ++c) vt.weight[c] = static_cast<float>(lamp.lamp().color[c]);
  const auto nDir = static_cast<std::size_t>(vt.nA) * static_cast<std::size_t>(vt.nB);
  vt.data.assign(nDir * static_cast<std::size_t>(vt.nX) * 2, 0.0f);

  std::vector<double> dist(static_cast<std::size_t>(vt.nX)), dddx(static_cast<std::size_t>(vt.nX));
  const double dx = 1.0 / (vt.nX - 1);
  for (int k = 0; k < vt.nX; ++k) {
    const double x = k * dx;
    dist[static_cast<std::size_t>(k)] = k + 1 == vt.nX ? std::numeric_limits<double>::infinity() : D * x / (1 - x);
    dddx[static_cast<std::size_t>(k)] = k + 1 == vt.nX ? 0.0 : D / ((1 - x) * (1 - x));
  }
  const Lamp& L = lamp.lamp();
  const Mat3 lampFromWorld = glm::transpose(L.worldFromLamp);
  const double kt = m.extinction_per_m;
  // Built once per lamp and fog, not per frame: the closure may allocate.
  pool.parallelFor(static_cast<std::size_t>(vt.nB), [&](std::size_t jb) {
    ViewTable& t = vt;
    const std::size_t nXs = static_cast<std::size_t>(t.nX);
    std::vector<double> out(nXs);
    for (int ia = 0; ia < t.nA; ++ia) {
      const double a = dbl(t.a0) + ia * step, b = dbl(t.b0) + static_cast<double>(jb) * step;
      const Vec3 local = glm::normalize(Vec3(1.0, a, b));
      const Ray ray{camera.position_m, glm::normalize(camera.worldFromCamera * local), 0.0};
      if (pencil) pencil->evaluateCumulative(ray.direction, dist.data(), nXs, out.data());
      else lamp.evaluateCumulative(ray, dist.data(), nXs, out.data());
      float* cellp = t.data.data() + (jb * static_cast<std::size_t>(t.nA) + static_cast<std::size_t>(ia)) * nXs * 2;
      for (std::size_t k = 0; k < nXs; ++k) {
        // dL/dd: the in-scattering integrand at distance d (the integrand of L_m in airlight.hpp).
        double slope = 0.0;
        const double dk = dist[k];
        if (!std::isinf(dk)) {
          const Vec3 s = ray.origin + dk * ray.direction - L.position_m;
          const double r2 = glm::dot(s, s), r = std::sqrt(r2);
          if (r > 1e-9) {
            const Vec3 w = s / r;
            const double f = m.albedo * kt * std::exp(-kt * (dk + r)) * evalPhase(m.phase, -glm::dot(w, ray.direction)) *
                             L.profile->intensity(lampFromWorld * w) / r2;
            slope = f * dddx[k] * dx;
          }
        }
        cellp[2 * k] = static_cast<float>(out[k]);
        cellp[2 * k + 1] = static_cast<float>(slope);
      }
    }
  });
  vt.finish();
  vt.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return vt;
}

bool ViewTable::covers(double a, double b) const noexcept {
  const double da = a - dbl(guardA), db = b - dbl(guardB);
  const double r2 = da * da + db * db;
  return r2 > dbl(innerR2) && r2 <= dbl(outerR2);
}

double ViewTable::lookup(double a, double b, double d) const noexcept {
  if (!covers(a, b)) return 0.0;
  return lookupAnywhere(a, b, d);
}

double ViewTable::lookupAnywhere(double a, double b, double d) const noexcept {
  if (!(d > 0.0)) return 0.0;
  int ia = 0, ib = 0, ix = 0;
  double ta = 0.0, tb = 0.0, tx = 0.0;
  cell((a - dbl(a0)) * dbl(invStep), nA, ia, ta);
  cell((b - dbl(b0)) * dbl(invStep), nB, ib, tb);
  const double x = std::isinf(d) ? 1.0 : d / (d + dbl(distanceScale));
  cell(x * (nX - 1), nX, ix, tx);
  auto at = [&](int i, int j) {
    const float* c = data.data() + ((static_cast<std::size_t>(j) * static_cast<std::size_t>(nA) +
                                     static_cast<std::size_t>(i)) * static_cast<std::size_t>(nX) +
                                    static_cast<std::size_t>(ix)) * 2;
    return hermite(tx, dbl(c[0]), dbl(c[1]), dbl(c[2]), dbl(c[3]));
  };
  const double l0 = at(ia, ib) + ta * (at(ia + 1, ib) - at(ia, ib));
  const double l1 = at(ia, ib + 1) + ta * (at(ia + 1, ib + 1) - at(ia, ib + 1));
  return std::max(0.0, l0 + tb * (l1 - l0));
}

void accumulateViewTableScalar(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r,
                               float* gr, float* b) {
  accumulateViewTableScalar(table, ViewTableUse::of(table), g, px, r, gr, b);
}

void accumulateViewTableScalar(const ViewTable& table, const ViewTableUse& use, const PixelGeometry& g,
                               const PixelBatch& px, float* r, float* gr, float* b) {
  for (std::size_t i = 0; i < px.n; ++i) {
    const double a = (dbl(g.cx) - dbl(px.x[i])) * dbl(g.invF);
    const double bb = (dbl(g.cy) - dbl(px.y[i])) * dbl(g.invF);
    const double da = a - dbl(use.guardA), db = bb - dbl(use.guardB);
    const double r2 = da * da + db * db;
    if (!(r2 > dbl(use.innerR2) && r2 <= dbl(use.outerR2))) continue;
    double ta = a, tb = bb;
    bool turn = use.rotated;
    for (int k = 0; k < use.nKeep && turn; ++k) {
      const double ka = a - dbl(use.keepA[k]), kb = bb - dbl(use.keepB[k]);
      turn = ka * ka + kb * kb > dbl(use.keepR2[k]);
    }
    if (turn) {
      const float* m = use.rot;
      const double x = dbl(m[0]) + dbl(m[1]) * a + dbl(m[2]) * bb;
      if (!(x > 0.0)) continue;
      ta = (dbl(m[3]) + dbl(m[4]) * a + dbl(m[5]) * bb) / x;
      tb = (dbl(m[6]) + dbl(m[7]) * a + dbl(m[8]) * bb) / x;
    }
    const double lm = table.lookupAnywhere(ta, tb, dbl(px.d[i]));
    r[i] += static_cast<float>(lm * dbl(use.weight[0]));
    gr[i] += static_cast<float>(lm * dbl(use.weight[1]));
    b[i] += static_cast<float>(lm * dbl(use.weight[2]));
  }
}

}  // namespace fogbeam::kernels
