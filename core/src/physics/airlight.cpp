#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/util/shared_cache.hpp>

#include "airlight_tables.hpp"

#include <boost/math/quadrature/gauss_kronrod.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <tuple>
#include <vector>

namespace fogbeam {

namespace {

constexpr double kHalfPi = 0.5 * kPi;
// Beyond this optical distance between eye and lamp the airlight is below e^{−700} of any
// representable value: u + r ≥ |S − O| for every point of the ray (triangle inequality).
constexpr double kMaxOpticalDistance = 700.0;

double tanHalfAngleSum(double theta) {
  // (1 + sin θ)/cos θ = tan(π/4 + θ/2): finite at θ = −π/2 (→ 0), +∞ at θ = +π/2.
  return std::tan(0.25 * kPi + 0.5 * theta);
}

// ---- caches: tables are shared between evaluators with the same phase or profile ----------
using PhaseKey = std::tuple<PhaseIdentity, int, int, double>;
PhaseKey phaseKey(const Phase& ph, int a, int b, double c) { return {phaseIdentity(ph), a, b, c}; }

// make() of a cache, its build time added to `seconds` (only when the cache builds).
template <class Make>
auto timed(double& seconds, Make make) {
  return [&seconds, make]() {
    const auto t0 = std::chrono::steady_clock::now();
    auto sp = make();
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return sp;
  };
}

// Tables shared by every evaluator of the same phase function or profile; the 8 most recent
// stay alive, so that evaluators built one after another for the same fog (validate, scene
// reloads) reuse them.
SharedCache<PhaseKey, detail::GMomentTable>& gCache() {
  static SharedCache<PhaseKey, detail::GMomentTable> c(8);
  return c;
}
SharedCache<PhaseKey, detail::SeedCoefficients>& seedCache() {
  static SharedCache<PhaseKey, detail::SeedCoefficients> c(8);
  return c;
}
using ProfileKey = std::pair<const Profile*, double>;
SharedCache<ProfileKey, detail::GreatCircleMoments>& circleCache() {
  static SharedCache<ProfileKey, detail::GreatCircleMoments> c(8);
  return c;
}

double forwardWidth(const Phase& phase) {
  // Angular width (rad) of the forward peak of p, ≈ (1 − g) for HG; 0 = no peak.
  double g = 0.0;
  if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&phase)) g = hg->g;
  if (const auto* fm = std::get_if<FogMiePhase>(&phase)) g = std::max(fm->g_hg, fm->g_d);
  return g > 0.05 ? 1.0 - g : 0.0;
}

}  // namespace

std::string_view toString(AirlightMethod m) {
  switch (m) {
    case AirlightMethod::Reference: return "reference";
    case AirlightMethod::Seed: return "seed";
    case AirlightMethod::Accurate: return "accurate";
  }
  return "?";
}

Result<AirlightMethod> parseAirlightMethod(std::string_view s) {
  if (s == "reference") return AirlightMethod::Reference;
  if (s == "seed") return AirlightMethod::Seed;
  if (s == "accurate") return AirlightMethod::Accurate;
  return Error{"unknown airlight method '" + std::string(s) + "' (expected seed, accurate or reference)"};
}

RayLampGeometry rayLampGeometry(const Ray& ray, const Vec3& lampPosition) noexcept {
  RayLampGeometry g{};
  const Vec3& w = ray.direction;
  g.p = glm::dot(lampPosition - ray.origin, w);
  const Vec3 foot = ray.origin + g.p * w;
  Vec3 v = foot - lampPosition;
  g.h = glm::length(v);
  if (g.h < 1e-9) {
    // The ray passes through the lamp: any n ⟂ ω will do, the integral diverges like 1/h.
    const Vec3 a = std::abs(w.x) < 0.9 ? Vec3(1, 0, 0) : Vec3(0, 1, 0);
    v = glm::normalize(glm::cross(w, a)) * 1e-9;
    g.h = 1e-9;
  }
  g.n = v / g.h;
  g.theta0 = std::atan2(-g.p, g.h);
  g.thetaD = std::isinf(ray.distance_m) ? kHalfPi : std::atan2(ray.distance_m - g.p, g.h);
  return g;
}

GFactors integrandGFactors(const Phase& phase, double theta) noexcept {
  return {evalPhase(phase, -std::sin(theta)), tanHalfAngleSum(theta)};
}

double integrandG(const Phase& phase, double k, double theta) noexcept {
  return integrandGFrom(k, integrandGFactors(phase, theta));
}

Result<AirlightEvaluator> AirlightEvaluator::build(const Lamp& lamp, const Medium& medium, AirlightMethod method,
                                                   const AirlightOptions& options) {
  if (Status s = medium.validate(); !s) return s.error();
  if (!lamp.profile) return Error{"lamp has no intensity profile"};
  AirlightEvaluator e;
  e.lamp_ = lamp;
  e.medium_ = medium;
  e.method_ = method;
  e.options_ = options;
  e.lampFromWorld_ = glm::transpose(lamp.worldFromLamp);
  auto tables = std::make_shared<detail::AirlightTables>();
  double seconds = 0.0;
  if (method == AirlightMethod::Accurate) {
    const PhaseKey key = phaseKey(medium.phase, options.g_table_theta, options.g_table_k, options.g_table_k_max);
    tables->g = gCache().get(key, timed(seconds, [&] {
      return std::make_shared<const detail::GMomentTable>(medium.phase, options.g_table_theta, options.g_table_k,
                                                          options.g_table_k_max);
    }));
    e.stats_.bytes += tables->g->bytes();
  } else if (method == AirlightMethod::Seed) {
    const PhaseKey key = phaseKey(medium.phase, options.seed_k_nodes, 0, options.g_table_k_max);
    tables->seed = seedCache().get(key, timed(seconds, [&] {
      return std::make_shared<const detail::SeedCoefficients>(medium.phase, options.seed_k_nodes, options.g_table_k_max);
    }));
    e.stats_.bytes += tables->seed->bytes();
    if (!std::holds_alternative<IsotropicProfile>(lamp.profile->model())) {
      tables->circles = circleCache().get(ProfileKey{lamp.profile.get(), options.seed_circle_step_deg}, timed(seconds, [&] {
        return std::make_shared<const detail::GreatCircleMoments>(*lamp.profile, options.seed_circle_step_deg);
      }), std::weak_ptr<const void>(lamp.profile));
      e.stats_.bytes += tables->circles->bytes();
    }
  }
  e.stats_.build_seconds = seconds;
  e.tables_ = std::move(tables);
  return e;
}

namespace {

struct Context {
  const Profile& profile;
  const Phase& phase;
  double kt, k, p;
  Vec3 n, t;  // lamp frame
  double intensity(double theta) const noexcept {
    return profile.intensity(std::cos(theta) * n + std::sin(theta) * t);
  }
};

// ∫ e^{−K_t p} G(k, θ) I(w(θ)) dθ by adaptive Gauss–Kronrod on each kink-free piece.
// e^{−K_t p} is folded into the exponent (K_t (p + h s(θ)) = K_t (u + r) ≥ 0) so that it
// cannot overflow for lamps far behind the eye.
double referenceIntegral(const Context& c, double th0, double thD, double relTol) {
  std::vector<double> bp{th0, thD};
  c.profile.appendKinks(c.n, c.t, th0, thD, bp);
  if (const double w = forwardWidth(c.phase); w > 0.0) {
    for (double f : {0.25, 0.5, 1.0, 2.0, 4.0}) {
      const double th = -kHalfPi + f * w;
      if (th > th0 && th < thD) bp.push_back(th);
    }
  }
  std::sort(bp.begin(), bp.end());
  auto f = [&](double th) {
    const double s = tanHalfAngleSum(th);
    const double expo = c.k == 0.0 ? c.kt * c.p : c.kt * c.p + c.k * s;
    if (!std::isfinite(expo)) return 0.0;
    return std::exp(-expo) * evalPhase(c.phase, -std::sin(th)) * c.intensity(th);
  };
  // Towards θ = π/2 G = e^{−k cot(s/2)} p, s = π/2 − θ, has an essential singularity at s = 0
  // that Gauss rules approach slowly (seconds per ray for a ray looking 0.01° from straight away
  // from the lamp, where the whole range lies next to it). Pieces that start where the exponent
  // t = k cot(s/2) is already ≥ 0.1 are integrated in t: θ = π/2 − 2 atan(k/t),
  // dθ = 2k/(k² + t²) dt, a smooth integrand e^{−t} … over [t(θa), t(θb)] (t(π/2) = ∞). (Where
  // t is still small at the piece's start, 2k/(k² + t²) spans many scales in t and θ is better.)
  auto ft = [&](double t) {
    if (!(t > 0.0)) return 0.0;
    const double th = kHalfPi - 2.0 * std::atan(c.k / t);
    return std::exp(-c.kt * c.p - t) * evalPhase(c.phase, -std::sin(th)) * c.intensity(th) * 2.0 * c.k /
           (c.k * c.k + t * t);
  };
  using GK = boost::math::quadrature::gauss_kronrod<double, 31>;
  auto piece = [&](double a, double b, unsigned depth, double tol, double* err, double* l1) {
    if (c.k > 0.0 && a > 0.0 && c.k * tanHalfAngleSum(a) >= 0.1)
      return GK::integrate(ft, c.k * tanHalfAngleSum(a),
                           b >= kHalfPi ? std::numeric_limits<double>::infinity() : c.k * tanHalfAngleSum(b), depth, tol,
                           err, l1);
    return GK::integrate(f, a, b, depth, tol, err, l1);
  };
  // Two passes: a 31-point estimate of every piece gives the integral's scale, then each piece
  // is refined to an absolute tolerance relTol × |total| (a piece-relative tolerance would
  // chase rounding noise on negligible pieces, e.g. near θ → π/2 where e^{−k s} underflows).
  std::vector<double> l1(bp.size(), 0.0);
  double total = 0.0;
  for (std::size_t i = 1; i < bp.size(); ++i) {
    if (bp[i] - bp[i - 1] < 1e-13) continue;
    double err = 0.0;
    piece(bp[i - 1], bp[i], 0, 0.0, &err, &l1[i]);
    total += l1[i];
  }
  if (!(total > 0.0)) return 0.0;
  double sum = 0.0;
  for (std::size_t i = 1; i < bp.size(); ++i) {
    if (bp[i] - bp[i - 1] < 1e-13 || l1[i] == 0.0) continue;
    const double tol = std::min(0.1, relTol * total / l1[i]);
    double err = 0.0;
    sum += piece(bp[i - 1], bp[i], 20, tol, &err, nullptr);
  }
  return sum;
}

// Accurate method: product integration. I is replaced by its piecewise quadratic interpolant
// through samples at the ends and middle of each piece; G is integrated exactly against it
// through the tabulated cumulative moments T_q(k, θ) (so the forward phase peak and the
// exponential are never sampled). Pieces start at the profile's own breakpoints.
//
// `cum` (optional): ascending angles θ_m at which the running integral ∫_{θ0}^{θ_m} is also
// wanted (written to cumOut; 0 below θ0, the total above θD). They become breakpoints, so
// one pass yields the integral up to every one of them.
struct CumulativeRequest {
  const double* theta = nullptr;
  double* out = nullptr;
  std::size_t n = 0;
};

double accurateIntegral(const Context& c, const detail::GMomentTable& g, double th0, double thD,
                        const AirlightOptions& opt, CumulativeRequest cum = {}) {
  const auto& model = c.profile.model();
  const detail::GMomentTable::KWeights kw = g.kWeights(c.k);
  if (const auto* iso = std::get_if<IsotropicProfile>(&model)) {
    const auto ta = g.cumulative(kw, th0), tb = g.cumulative(kw, thD);
    for (std::size_t m = 0; m < cum.n; ++m) {
      const double th = std::clamp(cum.theta[m], th0, thD);
      cum.out[m] = iso->intensity_cd * (g.cumulative(kw, th)[0] - ta[0]);
    }
    return iso->intensity_cd * (tb[0] - ta[0]);
  }
  // Per-thread scratch kept between calls: the image evaluator calls this per pixel from its
  // pool threads and must not allocate per frame (256 covers the kinks of every shipped
  // profile; more only grows the buffer once).
  thread_local std::vector<double> bp;
  thread_local std::vector<char> live;
  bp.reserve(256 + cum.n);
  live.reserve(256 + cum.n);
  bp.clear();
  bp.push_back(th0);
  bp.push_back(thD);
  for (std::size_t m = 0; m < cum.n; ++m)
    if (cum.theta[m] > th0 && cum.theta[m] < thD) bp.push_back(cum.theta[m]);
  const bool tabulated = std::holds_alternative<TabulatedProfile>(model);
  if (!tabulated) {
    c.profile.appendKinks(c.n, c.t, th0, thD, bp);
  } else {
    // Clip to the profile's support cone: outside it I = 0.
    const double sup = c.profile.supportHalfAngle();
    if (sup < kPi) {
      const double x = c.n.x, y = c.t.x, r = std::hypot(x, y);
      const double cs = std::cos(sup);
      if (r > 1e-15 && std::abs(cs) <= r) {
        const double centre = std::atan2(y, x), half = std::acos(cs / r);
        for (double base : {centre - half, centre + half})
          for (int kk = -1; kk <= 1; ++kk) {
            const double th = base + kk * 2.0 * kPi;
            if (th > th0 && th < thD) bp.push_back(th);
          }
      }
    }
    c.profile.appendFeatureKinks(c.n, c.t, th0, thD, bp);
  }
  std::sort(bp.begin(), bp.end());

  // Intervals between breakpoints where I is not identically zero, and their total length
  // (tabulated profiles share their pieces out over it). Spot: between cone crossings I is 0,
  // constant or a ramp, so the midpoint decides. Tabulated: the support cone decides.
  live.assign(bp.size(), 0);
  double liveLength = 0.0;
  const double cosSupport = std::cos(c.profile.supportHalfAngle());
  for (std::size_t i = 1; i < bp.size(); ++i) {
    const double a = bp[i - 1], b = bp[i];
    if (b - a < 1e-13) continue;
    const double mid = 0.5 * (a + b);
    const bool isLive = tabulated ? (std::cos(mid) * c.n.x + std::sin(mid) * c.t.x) >= cosSupport
                                  : c.intensity(mid) > 0.0;
    if (!isLive) continue;
    live[i] = 1;
    liveLength += b - a;
  }

  // Tabulated data: every sample of the pieces below is known before the walk (each live
  // interval's ends just inside it and its pieces' middles and joints, in walk order), so they
  // are taken in one batch along the circle (Profile::intensitiesOnCircle: the file angles a
  // SIMD vector at a time; the per-sample trigonometry was ~60 % of a view table's build).
  auto piecesOf = [&](double a, double b) {
    return std::max(1, static_cast<int>(std::lround(opt.accurate_segments * (b - a) / liveLength)));
  };
  thread_local std::vector<double> samplePsi, sampleValue;
  std::size_t nextSampleValue = 0;
  if (tabulated) {
    samplePsi.clear();
    for (std::size_t i = 1; i < bp.size(); ++i) {
      if (!live[i]) continue;
      const double a = bp[i - 1], b = bp[i];
      const int pieces = piecesOf(a, b);
      const double hw = 0.5 * (b - a) / pieces;
      samplePsi.push_back(a + 1e-12 * (b - a));
      for (int m = 1; m < 2 * pieces; ++m) samplePsi.push_back(a + m * hw);
      samplePsi.push_back(b - 1e-12 * (b - a));
    }
    sampleValue.resize(samplePsi.size());
    c.profile.intensitiesOnCircle(c.n, c.t, samplePsi.data(), samplePsi.size(), sampleValue.data());
  }

  double sum = 0.0;
  std::size_t nextOut = 0;
  auto emit = [&](double upTo) {
    while (nextOut < cum.n && cum.theta[nextOut] <= upTo) cum.out[nextOut++] = sum;
  };
  emit(th0);
  for (std::size_t i = 1; i < bp.size(); ++i) {
    if (!live[i]) {
      emit(bp[i]);
      continue;
    }
    const double a = bp[i - 1], b = bp[i];
    int pieces = 1;
    if (!tabulated) {
      const double ia = c.intensity(a + 1e-12), im = c.intensity(0.5 * (a + b)), ib = c.intensity(b - 1e-12);
      const bool constant = ia == im && im == ib;
      pieces = constant ? 1 : opt.accurate_spot_segments;
    } else {
      pieces = piecesOf(a, b);
    }
    const double width = (b - a) / pieces, hw = 0.5 * width;
    auto tPrev = g.cumulative(kw, a);
    // End samples just inside the interval: at a kink I is continuous for spot edges, but
    // tabulated data may drop to 0 at the edge of the covered range.
    double iPrev = tabulated ? sampleValue[nextSampleValue++] : c.intensity(a + 1e-12 * (b - a));
    // Interior samples sit at a + m·hw; their directions cos θ n + sin θ t follow by rotating
    // (cos, sin) through hw each step instead of calling sincos per sample (tabulated data:
    // from the batch above, in the same order).
    const double cd = tabulated ? 0.0 : std::cos(hw), sd = tabulated ? 0.0 : std::sin(hw);
    double cs = tabulated ? 0.0 : std::cos(a + hw), sn = tabulated ? 0.0 : std::sin(a + hw);
    auto nextSample = [&] {
      if (tabulated) return sampleValue[nextSampleValue++];
      const double v = c.profile.intensity(cs * c.n + sn * c.t);
      const double cs2 = cs * cd - sn * sd;
      sn = sn * cd + cs * sd;
      cs = cs2;
      return v;
    };
    for (int s = 0; s < pieces; ++s) {
      const double pa = a + s * width, pb = (s + 1 == pieces) ? b : pa + width;
      const double pm = 0.5 * (pa + pb);
      const auto tNext = g.cumulative(kw, pb);
      const double im = nextSample();
      // The last piece ends just inside the interval (b − ε), not at the next joint.
      double iNext = (s + 1 == pieces && !tabulated) ? c.intensity(b - 1e-12 * (b - a)) : nextSample();
      const double d0 = tNext[0] - tPrev[0], d1 = tNext[1] - tPrev[1], d2 = tNext[2] - tPrev[2];
      // Moments about the piece centre: ∫ G (θ − pm)^q dθ.
      const double m0 = d0, m1 = d1 - pm * d0, m2 = d2 - 2 * pm * d1 + pm * pm * d0;
      if (hw < 1e-9) {
        sum += im * m0;
      } else {
        // Lagrange quadratic through (pa, iPrev), (pm, im), (pb, iNext) in x = θ − pm.
        const double c1 = (iNext - iPrev) / (2 * hw);
        const double c2 = (iPrev - 2 * im + iNext) / (2 * hw * hw);
        sum += im * m0 + c1 * m1 + c2 * m2;
      }
      tPrev = tNext;
      iPrev = iNext;
    }
    emit(b);
  }
  while (nextOut < cum.n) cum.out[nextOut++] = sum;
  return sum;
}

}  // namespace

double AirlightEvaluator::evaluate(const Ray& ray) const noexcept {
  const double kt = medium_.extinction_per_m;
  if (kt * glm::length(lamp_.position_m - ray.origin) > kMaxOpticalDistance) return 0.0;
  const RayLampGeometry geo = rayLampGeometry(ray, lamp_.position_m);
  if (!(geo.thetaD > geo.theta0)) return 0.0;
  const Context c{*lamp_.profile, medium_.phase, kt, kt * geo.h, geo.p,
                  lampFromWorld_ * geo.n, lampFromWorld_ * ray.direction};
  const double scale = medium_.albedo * kt / geo.h;
  switch (method_) {
    case AirlightMethod::Reference:
      return scale * referenceIntegral(c, geo.theta0, geo.thetaD, options_.reference_rel_tol);
    case AirlightMethod::Accurate: {
      // Beyond the table (rare: h > k_max / K_t) or looking (nearly) straight away from the lamp
      // (detail::kAwayConeRad): integrate directly.
      if (c.k > tables_->g->kMax() || geo.theta0 > kHalfPi - detail::kAwayConeRad)
        return scale * referenceIntegral(c, geo.theta0, geo.thetaD, 1e-6);
      return scale * std::exp(-kt * geo.p) * accurateIntegral(c, *tables_->g, geo.theta0, geo.thetaD, options_);
    }
    case AirlightMethod::Seed: {
      // Lecocq et al. 2001, eq. (4).
      const auto cc = tables_->seed->at(c.k);
      std::array<double, 3> m{};
      if (const auto* iso = std::get_if<IsotropicProfile>(&c.profile.model())) {
        const double a = geo.theta0, b = geo.thetaD;
        m = {iso->intensity_cd * (b - a), iso->intensity_cd * (b * b - a * a) / 2,
             iso->intensity_cd * (b * b * b - a * a * a) / 3};
      } else {
        m = tables_->circles->moments(c.n, c.t, geo.theta0, geo.thetaD);
      }
      return scale * std::exp(-kt * geo.p) * (cc[0] * m[0] + cc[1] * m[1] + cc[2] * m[2]);
    }
  }
  return 0.0;
}

GMomentTexels gMomentTexels(const Phase& phase, const AirlightOptions& options) {
  double seconds = 0.0;
  const PhaseKey key = phaseKey(phase, options.g_table_theta, options.g_table_k, options.g_table_k_max);
  const auto g = gCache().get(key, timed(seconds, [&] {
    return std::make_shared<const detail::GMomentTable>(phase, options.g_table_theta, options.g_table_k,
                                                        options.g_table_k_max);
  }));
  GMomentTexels t;
  t.nTheta = g->thetaNodes();
  t.nK = g->kNodes();
  t.k0 = g->k0();
  t.logSpan = g->logSpan();
  t.kMax = g->kMax();
  auto split = [](double v, std::vector<float>& hi, std::vector<float>& lo) {
    const auto h = static_cast<float>(v);
    hi.push_back(h);
    lo.push_back(static_cast<float>(v - static_cast<double>(h)));
  };
  for (double th : g->thetaGrid()) split(th, t.theta, t.thetaLo);
  t.texels.reserve(static_cast<std::size_t>(t.nK) * static_cast<std::size_t>(t.nTheta) * 4);
  t.texelsLo.reserve(t.texels.capacity());
  for (int i = 0; i < t.nK; ++i)
    for (int j = 0; j < t.nTheta; ++j)
      for (int q = 0; q < 4; ++q) split(g->cell(i, j)[q], t.texels, t.texelsLo);
  return t;
}

void AirlightEvaluator::setPose(const Vec3& position_m, const Mat3& worldFromLamp) noexcept {
  lamp_.position_m = position_m;
  lamp_.worldFromLamp = worldFromLamp;
  lampFromWorld_ = glm::transpose(worldFromLamp);
}

Status AirlightEvaluator::setMedium(const Medium& medium) {
  if (Status s = medium.validate(); !s) return s.error();
  if (!(phaseIdentity(medium.phase) == phaseIdentity(medium_.phase)))
    return Error{"setMedium: another phase function needs other tables (build a new evaluator)"};
  medium_ = medium;
  return Ok{};
}

void AirlightEvaluator::evaluateCumulative(const Ray& ray, const double* distances, std::size_t n,
                                           double* out) const {
  const double kt = medium_.extinction_per_m;
  Ray r = ray;
  r.distance_m = std::numeric_limits<double>::infinity();
  const RayLampGeometry geo = rayLampGeometry(r, lamp_.position_m);
  const bool negligible = kt * glm::length(lamp_.position_m - ray.origin) > kMaxOpticalDistance;
  if (negligible || method_ != AirlightMethod::Accurate || kt * geo.h > tables_->g->kMax() ||
      geo.theta0 > kHalfPi - detail::kAwayConeRad) {
    for (std::size_t m = 0; m < n; ++m) {
      r.distance_m = distances[m];
      out[m] = negligible ? 0.0 : evaluate(r);
    }
    return;
  }
  // θ of each distance (eq. 3: d − p = h tan θ), ascending with the distances.
  std::vector<double> theta(n);
  for (std::size_t m = 0; m < n; ++m)
    theta[m] = std::isinf(distances[m]) ? kHalfPi : std::atan2(distances[m] - geo.p, geo.h);
  const Context c{*lamp_.profile, medium_.phase, kt, kt * geo.h, geo.p,
                  lampFromWorld_ * geo.n, lampFromWorld_ * ray.direction};
  const double scale = medium_.albedo * kt / geo.h * std::exp(-kt * geo.p);
  accurateIntegral(c, *tables_->g, geo.theta0, kHalfPi, options_, CumulativeRequest{theta.data(), out, n});
  for (std::size_t m = 0; m < n; ++m) out[m] = distances[m] <= 0.0 ? 0.0 : scale * out[m];
}

}  // namespace fogbeam
