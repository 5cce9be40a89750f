// fogbeam — the all-orders reference path tracer (fogbeam/physics/path_tracer.hpp; method and
// estimators in docs/physics.md, "All-orders reference: the path tracer").
#include <fogbeam/physics/path_tracer.hpp>

#include <fogbeam/util/thread_pool.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace fogbeam {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// SplitMix64's output function (Steele, Lea & Flood, OOPSLA 2014): a bijective 64-bit mix.
std::uint64_t mix64(std::uint64_t z) noexcept {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// Orthonormal basis around a unit n (Duff et al., JCGT 2017): no branch on a "least axis".
void basis(const Vec3& n, Vec3& b1, Vec3& b2) noexcept {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z);
  const double b = n.x * n.y * a;
  b1 = Vec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
  b2 = Vec3(b, sign + n.y * n.y * a, -n.y);
}

Vec3 aroundAxis(const Vec3& axis, double cosTheta, double sinTheta, double phi) noexcept {
  Vec3 b1, b2;
  basis(axis, b1, b2);
  return glm::normalize(sinTheta * std::cos(phi) * b1 + sinTheta * std::sin(phi) * b2 + cosTheta * axis);
}

Vec3 aroundAxis(const Vec3& axis, double cosTheta, double phi) noexcept {
  return aroundAxis(axis, cosTheta, std::sqrt(std::max(0.0, 1.0 - cosTheta * cosTheta)), phi);
}

}  // namespace

PathRng::PathRng(std::uint64_t seed, std::uint64_t stream, std::uint64_t sample) noexcept
    : state_(mix64(mix64(mix64(seed) ^ (stream + 0x632be59bd9b4e019ULL)) ^ (sample + 0x9e3779b97f4a7c15ULL))) {}

std::uint64_t PathRng::next() noexcept {
  state_ += 0x9e3779b97f4a7c15ULL;
  return mix64(state_);
}

// Inverse CDF of the scattering angle θ ∈ [0, π] for a phase function p: the density of θ is
// 2π p(cos θ) sin θ. Nodes θ_i = π (i/(n−1))² crowd the forward peak (fog-mie at 50 µm is a few
// milliradians wide). Within an interval θ is drawn uniformly, so the sampled pdf is piecewise
// constant in θ; the weight p / pdf corrects the tabulation error exactly (it stays in [0, ~2]
// next to θ = 0, where sin θ → 0 but so does the interval's mass per radian).
// The interval [x_i, x_{i+1}) holding a (clamped to [0, π]) of nodes x_i = π (i/n)², i = 0 … n
// (`nodes`: n + 1 of them, n ≥ 1): i = ⌊n √(a/π)⌋ at most n − 1, then settled on the bracket, since
// rounding of the root can put a node's own angle one interval off. PhaseTable and AngleTable.
namespace {
std::size_t squareNodeInterval(const std::vector<double>& nodes, double a) noexcept {
  a = std::clamp(a, 0.0, kPi);
  const double n = static_cast<double>(nodes.size() - 1);
  auto i = static_cast<std::size_t>(std::min(std::sqrt(a / kPi) * n, n - 1.0));
  while (i > 0 && a < nodes[i]) --i;
  while (i + 2 < nodes.size() && a >= nodes[i + 1]) ++i;
  return i;
}
}  // namespace

struct PathTracer::PhaseTable {
  std::vector<double> theta, cdf;

  PhaseTable(const Phase& phase, int n) {
    theta.resize(static_cast<std::size_t>(n));
    cdf.assign(static_cast<std::size_t>(n), 0.0);
    auto density = [&](double t) { return 2.0 * kPi * evalPhase(phase, std::cos(t)) * std::sin(t); };
    for (int i = 0; i < n; ++i) {
      const double u = static_cast<double>(i) / (n - 1);
      theta[static_cast<std::size_t>(i)] = kPi * u * u;
    }
    for (std::size_t i = 1; i < theta.size(); ++i) {
      const double a = theta[i - 1], b = theta[i];
      cdf[i] = cdf[i - 1] + (b - a) / 6.0 * (density(a) + 4.0 * density(0.5 * (a + b)) + density(b));  // Simpson
    }
    const double total = cdf.back();
    for (double& c : cdf) c /= total;
    cdf.back() = 1.0;
  }

  // θ and its sampled density per radian.
  void sample(double xi, double& th, double& pdfTheta) const noexcept {
    auto it = std::upper_bound(cdf.begin(), cdf.end(), xi);
    std::size_t i = static_cast<std::size_t>(std::max<std::ptrdiff_t>(1, it - cdf.begin())) - 1;
    i = std::min(i, cdf.size() - 2);
    const double width = cdf[i + 1] - cdf[i];
    const double dt = theta[i + 1] - theta[i];
    const double f = width > 0.0 ? std::clamp((xi - cdf[i]) / width, 0.0, 1.0) : 0.5;
    th = theta[i] + f * dt;
    pdfTheta = width / dt;
  }

  // The sampled density per radian at θ (the interval's, as sample() draws it): nodes are
  // θ_i = π (i/(n−1))², so the interval of θ is ⌊(n−1) √(θ/π)⌋.
  [[nodiscard]] double pdf(double th) const noexcept {
    const std::size_t i = squareNodeInterval(theta, th);
    return (cdf[i + 1] - cdf[i]) / (theta[i + 1] - theta[i]);
  }
};

// The scattering angle α of a lamp connection along a segment, for the phase-angle half of NEE's
// mixture (segmentNee): on the segment x + t ω the lamp at S is seen at θ = atan((t − δ)/h) from
// the closest approach (h its distance, δ where it is), and the light the lamp sends to the point
// scatters towards −ω by α = π/2 + θ (cos α = −sin θ). The integrand holds p(cos α) dt and
// dt = (r²/h) dα, so drawing α ∝ p(cos α) over the segment's window [π/2 + θ_a, π/2 + θ_b] puts
// samples where the phase function's forward peak meets the segment (light running back along
// it from a lamp ahead): fog-mie's diffraction peak (~1° wide, p(1) of several hundred per sr) is
// missed by the equiangular point, which spreads its samples uniformly in θ (docs/physics.md,
// "Variance near lamps": σ in fog-mie's rings 2–5× smaller at the same paths).
// Density piecewise constant in α on cells α_i = π (i/n)² (crowding the peak); C(α) its integral.
struct PathTracer::AngleTable {
  static constexpr int kCells = 4096;
  std::vector<double> alpha, cdf, density;  // nodes (kCells + 1), C at nodes, p per cell

  explicit AngleTable(const Phase& phase) {
    alpha.resize(kCells + 1);
    cdf.assign(kCells + 1, 0.0);
    density.resize(kCells);
    for (int i = 0; i <= kCells; ++i) {
      const double u = static_cast<double>(i) / kCells;
      alpha[static_cast<std::size_t>(i)] = kPi * u * u;
    }
    for (std::size_t i = 0; i < density.size(); ++i) {
      const double a = alpha[i], b = alpha[i + 1];
      // The cell's mean of p (Simpson), so that C is the integral of p to within the fit.
      density[i] = (evalPhase(phase, std::cos(a)) + 4.0 * evalPhase(phase, std::cos(0.5 * (a + b))) +
                    evalPhase(phase, std::cos(b))) / 6.0;
      cdf[i + 1] = cdf[i] + density[i] * (b - a);
    }
  }
  [[nodiscard]] std::size_t cell(double a) const noexcept { return squareNodeInterval(alpha, a); }
  [[nodiscard]] double integral(double a) const noexcept {
    a = std::clamp(a, 0.0, kPi);
    const std::size_t i = cell(a);
    return cdf[i] + density[i] * (a - alpha[i]);
  }
  [[nodiscard]] double at(double a) const noexcept { return density[cell(a)]; }
  // α with C(α) = c (C(0) ≤ c ≤ C(π)).
  [[nodiscard]] double inverse(double c) const noexcept {
    auto it = std::upper_bound(cdf.begin(), cdf.end(), c);
    std::size_t i = static_cast<std::size_t>(std::max<std::ptrdiff_t>(1, it - cdf.begin())) - 1;
    i = std::min(i, density.size() - 1);
    return density[i] > 0.0 ? std::clamp(alpha[i] + (c - cdf[i]) / density[i], alpha[i], alpha[i + 1]) : alpha[i];
  }
};

Result<PathTracer> PathTracer::build(std::vector<Lamp> lamps, const Medium& medium,
                                     std::optional<GroundPlane> ground, const PathTracerOptions& options) {
  if (auto st = medium.validate(); !st) return st.error();
  if (!(medium.extinction_per_m > 0.0) || !std::isfinite(medium.extinction_per_m))
    return Error{"path tracer: extinction_per_m must be finite and > 0"};
  if (ground && (!(ground->reflectance >= 0.0 && ground->reflectance <= 1.0) || !std::isfinite(ground->height_m)))
    return Error{"path tracer: ground reflectance must lie in [0, 1] and its height be finite"};
  if (options.max_order < 1) return Error{"path tracer: max_order must be >= 1"};
  if (options.roulette_start < 1) return Error{"path tracer: roulette_start must be >= 1"};
  if (!(options.roulette_fraction >= 0.0 && options.roulette_fraction < 1.0))
    return Error{"path tracer: roulette_fraction must lie in [0, 1)"};
  if (options.phase_table_nodes < 16) return Error{"path tracer: phase_table_nodes must be >= 16"};
  if (options.batch_size < 1) return Error{"path tracer: batch_size must be >= 1"};
  PathTracer t;
  for (std::size_t i = 0; i < lamps.size(); ++i) {
    if (!lamps[i].profile) return Error{"path tracer: lamp " + std::to_string(i) + " has no profile"};
    t.lampFromWorld_.push_back(glm::transpose(lamps[i].worldFromLamp));
    t.lampFlux_.push_back(lamps[i].profile->totalFlux());
    t.lampLit_.push_back(!ground || lamps[i].position_m.z > ground->height_m ? 1 : 0);
    if (t.lampLit_.back() && t.lampFlux_.back() > 0.0) ++t.guidedLamps_;
  }
  t.lamps_ = std::move(lamps);
  t.medium_ = medium;
  t.ground_ = ground;
  t.options_ = options;
  // An isotropic phase function's angle density is the equiangular one: no table, NEE's point
  // stays equiangular (and the path streams as they were before the mixture).
  if (!std::holds_alternative<IsotropicPhase>(medium.phase)) t.angleTable_ = std::make_shared<const AngleTable>(medium.phase);
  if (options.tabulate_all_phases || std::holds_alternative<FogMiePhase>(medium.phase)) {
    t.phaseKind_ = 2;
    t.phaseTable_ = std::make_shared<const PhaseTable>(medium.phase, options.phase_table_nodes);
  } else if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&medium.phase)) {
    t.phaseKind_ = 1;
    t.hgG_ = hg->g;
  } else {
    t.phaseKind_ = 0;
  }
  // Diffusion constants (the P1 approximation): D = 1 / (3 (K_a + K_s (1 − g))) with K_a =
  // (1 − Ω) K_t, K_s = Ω K_t; diffusion length L = √(D / K_a).
  const double kt = medium.extinction_per_m;
  t.diffusionD_ = 1.0 / (3.0 * kt * (1.0 - medium.albedo * meanCosine(medium.phase)));
  t.diffusionInvL_ = std::sqrt(kt * (1.0 - medium.albedo) / t.diffusionD_);
  return t;
}

double PathTracer::diffusionRadiance(const Vec3& x) const noexcept {
  double sum = 0.0;
  for (std::size_t l = 0; l < lamps_.size(); ++l) {
    if (!lampLit_[l]) continue;
    const double r = glm::length(x - lamps_[l].position_m);
    // Φ e^{−r/L} / (4π D r): the fluence of an isotropic point source of flux Φ (lm) in the
    // diffusion approximation; r is held at ≥ 1/K_t (one mean free path), inside which the
    // approximation means nothing (the uncollided light dominates) and 1/r would blow up.
    sum += lampFlux_[l] * std::exp(-r * diffusionInvL_) /
           (4.0 * kPi * diffusionD_ * std::max(r, 1.0 / medium_.extinction_per_m));
  }
  return sum * kInvFourPi;
}

PathTracer::PhaseDraw PathTracer::samplePhase(const Vec3& forward, PathRng& rng) const noexcept {
  const double xi = rng.uniform();
  const double phi = 2.0 * kPi * rng.uniform();
  switch (phaseKind_) {
    case 0:
      return {aroundAxis(forward, 1.0 - 2.0 * xi, phi), 1.0};
    case 1: {
      // Inverse CDF of HG in μ = cos α (e.g. pbrt-v4, SampleHenyeyGreenstein; sign as p(μ) with
      // μ = +1 forward): μ = (1 + g² − ((1 − g²)/(1 − g + 2gξ))²) / (2g).
      const double g = hgG_;
      double mu;
      if (std::abs(g) < 1e-3) {
        mu = 1.0 - 2.0 * xi;
      } else {
        const double s = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
        mu = (1.0 + g * g - s * s) / (2.0 * g);
      }
      return {aroundAxis(forward, std::clamp(mu, -1.0, 1.0), phi), 1.0};
    }
    default: {
      double th = 0.0, pdfTheta = 1.0;
      phaseTable_->sample(xi, th, pdfTheta);
      const double mu = std::cos(th);
      const double w = pdfTheta > 0.0 ? evalPhase(medium_.phase, mu) * 2.0 * kPi * std::sin(th) / pdfTheta : 0.0;
      return {aroundAxis(forward, mu, phi), w};
    }
  }
}

double PathTracer::phasePdf(const Vec3& forward, const Vec3& w) const noexcept {
  // θ from the cross and dot products: accurate at the forward peak, where acos is not.
  return phaseSamplingPdf(glm::dot(forward, w), glm::length(glm::cross(forward, w)));
}

double PathTracer::phaseSamplingPdf(double cosAngle, double sinAngle) const noexcept {
  switch (phaseKind_) {
    case 0:
      return kInvFourPi;
    case 1:
      return std::abs(hgG_) < 1e-3 ? kInvFourPi : evalPhase(medium_.phase, cosAngle);
    default: {
      const double th = std::atan2(sinAngle, cosAngle);
      return sinAngle > 0.0 ? phaseTable_->pdf(th) / (2.0 * kPi * sinAngle) : 0.0;
    }
  }
}

double PathTracer::guideWeight(std::size_t l, const Vec3& x) const noexcept {
  if (!lampLit_[l]) return 0.0;
  const double r = glm::length(x - lamps_[l].position_m);
  return lampFlux_[l] * std::exp(-r * diffusionInvL_) / std::max(r, 1.0 / medium_.extinction_per_m);
}

double PathTracer::guidePdf(const Vec3& x, const Vec3& w, double weightSum) const noexcept {
  double sum = 0.0;
  for (std::size_t l = 0; l < lamps_.size(); ++l) {
    const double c = guideWeight(l, x);
    if (!(c > 0.0)) continue;
    const Vec3 a = lamps_[l].position_m - x;
    if (!(glm::dot(a, w) > 0.0)) continue;  // the cone is the hemisphere towards the lamp
    const double s = glm::length(glm::cross(w, a)) / glm::length(a);  // sin ψ
    // Exactly at the lamp (sin ψ rounds to 0) the density is infinite: the sample's balance
    // weight is 0. Skipping the lamp instead left p_G = 0 there, and the segment through the lamp
    // (h at its 1e-9 m floor) gave one path 4.4e8 cd/m² in a frame whose mean is 0.6 (fog-mie,
    // 1 000 000 paths: docs/physics.md).
    if (!(s > 0.0)) return kInf;
    sum += c / (kPi * kPi * s);
  }
  return sum / weightSum;
}

double PathTracer::guideWeightSum(const Vec3& x) const noexcept {
  double weightSum = 0.0;
  for (std::size_t l = 0; l < lamps_.size(); ++l) weightSum += guideWeight(l, x);
  return weightSum;
}

double PathTracer::guideDensity(const Vec3& x, const Vec3& w) const noexcept {
  const double weightSum = guideWeightSum(x);
  return weightSum > 0.0 ? guidePdf(x, w, weightSum) : 0.0;
}

Vec3 PathTracer::sampleGuide(const Vec3& x, double weightSum, PathRng& rng) const noexcept {
  // Lamp ℓ with probability c_ℓ / Σ c, then ψ uniform in [0, π/2] and φ uniform about the
  // direction from x to it: pdf g_ℓ(ω) = 1 / (π² sin ψ) on that hemisphere.
  const double target = rng.uniform() * weightSum;
  double acc = 0.0;
  std::size_t pick = lamps_.size();
  for (std::size_t l = 0; l < lamps_.size(); ++l) {
    const double c = guideWeight(l, x);
    if (!(c > 0.0)) continue;
    pick = l;
    acc += c;
    if (target < acc) break;
  }
  const Vec3 a = glm::normalize(lamps_[pick].position_m - x);
  const double psi = 0.5 * kPi * rng.uniform();
  // sin ψ as drawn, not from cos ψ: below ψ ≈ 1e-8 cos ψ rounds to 1 and the direction would be
  // the lamp's own, whose segment passes through the lamp (guidePdf then has sin ψ = 0).
  return aroundAxis(a, std::cos(psi), std::sin(psi), 2.0 * kPi * rng.uniform());
}

PathSample PathTracer::trace(const Ray& ray, PathRng& rng) const {
  PathSample out;
  const double kt = medium_.extinction_per_m;
  const double omega = medium_.albedo;
  const double zGround = ground_ ? ground_->height_m : -kInf;
  if (ground_ && !(ray.origin.z > zGround)) return out;  // the eye is in or under the ground
  const bool guiding = options_.lamp_guiding && guidedLamps_ > 0;

  // Distance from x along unit dir to the ground plane (+inf when the ray does not go down).
  auto groundDistance = [&](const Vec3& x, const Vec3& dir) {
    if (!ground_ || !(dir.z < 0.0)) return kInf;
    return std::max(0.0, (zGround - x.z) / dir.z);
  };

  // The lamp term at a point y of a segment whose ray direction is dir, per unit length and per
  // unit path weight: e^{−K_t t} Ω K_t p(cos α) I(w) e^{−K_t r} / r², cos α = w · (−dir)
  // (docs/physics.md, "Along one view ray"; t the distance from the segment's start).
  auto lampTerm = [&](std::size_t l, const Vec3& y, const Vec3& dir, double t) {
    const Vec3 v = y - lamps_[l].position_m;
    const double r2 = glm::dot(v, v);
    const double r = std::sqrt(r2);
    if (!(r > 0.0)) return 0.0;
    const Vec3 w = v / r;
    const double intensity = lamps_[l].profile->intensity(lampFromWorld_[l] * w);
    if (intensity <= 0.0) return 0.0;
    return std::exp(-kt * (t + r)) * omega * kt * evalPhase(medium_.phase, -glm::dot(w, dir)) * intensity / r2;
  };

  auto addOrder = [&](int order, std::size_t l, double value) {
    if (order == 1) out.single += value;
    else out.multiple += value;
    out.rgb += value * lamps_[l].color;
  };

  // NEE along the segment x + t dir, t ∈ [0, T), per lamp: two samples combined by the balance
  // heuristic (Veach 1997; Kulla & Fajardo 2012), the collision point t_C (density pdfC(t);
  // present when `collided`) and a point t_M drawn from an even mixture of two densities over
  // the segment's window (one-sample MIS over the mixture): the equiangular density
  // p_A = h / ((θ_b − θ_a) r²), which cancels the 1/r² of a lamp near the segment, and the
  // phase-angle density p_P = p̃(α) h / (ΔC r²) (α ∝ p(cos α): AngleTable), which follows the
  // phase function's forward peak where the lamp's light runs back along the segment. Each point
  // gives f(t) / (q(t) + p_C(t)), q = ½ p_A + ½ p_P; their sum is an unbiased estimate of
  // ∫_0^T f dt. Scaled by `weight`. (Both densities as separate points, three lamp terms a
  // segment, had about the same variance and cost 1.7× per path: docs/physics.md.)
  const AngleTable* angles = angleTable_.get();  // null for the isotropic phase: p_P = p_A
  auto segmentNee = [&](const Vec3& x, const Vec3& dir, double T, bool collided, double tc, auto&& pdfC, int order,
                        double weight) {
    for (std::size_t l = 0; l < lamps_.size(); ++l) {
      if (!lampLit_[l]) continue;
      const Vec3& s = lamps_[l].position_m;
      const double delta = glm::dot(s - x, dir);
      const double h = std::max(glm::length(x + delta * dir - s), 1e-9);
      const double ta = std::atan2(-delta, h);
      const double tb = std::isfinite(T) ? std::atan2(T - delta, h) : 0.5 * kPi;
      const double span = tb - ta;
      if (!(span > 0.0)) continue;
      const double cA = angles ? angles->integral(0.5 * kPi + ta) : 0.0;
      const double mass = angles ? angles->integral(0.5 * kPi + tb) - cA : 0.0;
      const double shareA = mass > 0.0 ? 0.5 : 1.0, shareP = 1.0 - shareA;
      // q(t), both densities carrying h / r²; θ = atan((t − δ)/h) where known (NaN: computed).
      auto pdfMix = [&](double t, double theta) {
        const double dt = t - delta, r2 = h * h + dt * dt;
        if (!(shareP > 0.0)) return h / (span * r2);
        if (std::isnan(theta)) theta = std::atan2(dt, h);
        return (shareA / span + shareP * angles->at(0.5 * kPi + theta) / mass) * h / r2;
      };
      auto sampleAt = [&](double t, double theta) {
        const double f = lampTerm(l, x + t * dir, dir, t);
        if (f > 0.0) addOrder(order, l, weight * f / (pdfMix(t, theta) + pdfC(t)));
      };
      const double tMax = std::isfinite(T) ? std::nextafter(T, 0.0) : kInf;
      // One uniform picks the density and places the point in it (the stream stays one draw a
      // segment and lamp, as with the equiangular point alone).
      const double xi = rng.uniform();
      const double theta = xi < shareA ? ta + (xi / shareA) * span
                                       : angles->inverse(cA + ((xi - shareA) / shareP) * mass) - 0.5 * kPi;
      const double tRaw = delta + h * std::tan(theta);
      const double tM = std::clamp(tRaw, 0.0, tMax);
      // θ again only where the clamp moved the point (rounding at the window's ends).
      const double unknown = std::numeric_limits<double>::quiet_NaN();
      if (std::isfinite(tM)) sampleAt(tM, tM == tRaw ? theta : unknown);
      if (collided) sampleAt(tc, unknown);
    }
  };

  // Lamp-guided NEE at a vertex x (docs/physics.md, "Variance near lamps"). The next order's
  // lamp connections along the segment leaving x are ∫ f_s(ω) S(ω) dω (f_s the phase function
  // about `forward`, or cos θ/π off the ground; S(ω) the segment's connections per unit weight).
  // Two strategies estimate it, combined by the balance heuristic: the phase-sampled ω_P that
  // continues the path (its segment's connections are scaled by p_P / (p_P + q p_G), returned),
  // and a guided ω_G drawn here (pdf p_G, ∝ 1/sin ψ about a lamp) whose segment is connected at
  // once with weight β f_s(ω_G) / (p_P(ω_G) + q p_G(ω_G)), q = 1 the guided samples per vertex.
  // S(ω) ∝ 1/h for a segment passing at h from a lamp, p_G ∝ 1/sin ψ ∝ 1/h: their ratio stays
  // bounded (the phase sample alone has a logarithmically infinite variance). (Guiding only
  // near lamps, q = min(1, e^{1 − K_t r}), is as unbiased and cheaper, but measured worse far
  // from the lamp, where the tail is relative to a small mean: docs/physics.md.) The guided
  // segment is connected through the medium by its equiangular sample alone (bounded by itself:
  // the pdf cancels the 1/r²); the ground connection at a segment's end keeps the phase sample
  // alone (it has no 1/h).
  auto guidedNee = [&](const Vec3& x, const Vec3& forward, bool ground, const Vec3& wP, double beta, int order) {
    const double weightSum = guideWeightSum(x);
    if (!(weightSum > 0.0)) return 1.0;
    constexpr double q = 1.0;  // one guided sample per vertex (see above)
    auto pdfP = [&](const Vec3& w) { return ground ? std::max(0.0, w.z) / kPi : phasePdf(forward, w); };
    {
      const Vec3 wG = sampleGuide(x, weightSum, rng);
      const double fG = ground ? std::max(0.0, wG.z) / kPi : evalPhase(medium_.phase, glm::dot(forward, wG));
      const double T = groundDistance(x, wG);
      const double pdf = pdfP(wG) + q * guidePdf(x, wG, weightSum);
      if (fG > 0.0 && T > 0.0 && pdf > 0.0 && std::isfinite(pdf))
        segmentNee(x, wG, T, false, 0.0, [](double) { return 0.0; }, order, beta * fG / pdf);
    }
    const double pP = pdfP(wP);
    const double pG = guidePdf(x, wP, weightSum);
    return pP > 0.0 ? pP / (pP + q * pG) : 0.0;
  };

  Vec3 x = ray.origin;
  Vec3 dir = ray.direction;
  double beta = 1.0;  // path weight (dimensionless)
  double mis = 1.0;   // the segment's connections' MIS weight against the guided sample
  double bestImportance = 0.0;
  int events = 0;
  const int maxOrder = options_.max_order;

  for (;;) {
    // ---- one segment: from x along dir up to T (the camera ray: the visible surface or ground).
    const bool camera = events == 0;
    const double tGround = groundDistance(x, dir);
    const double T = camera ? std::min(ray.distance_m, tGround) : tGround;
    if (!(T > 0.0)) break;
    const int order = events + 1;

    // Free-flight distance. The camera ray is forced to scatter in [0, T): the truncated
    // exponential pdf K_t e^{−K_t t} / (1 − e^{−K_t T}), whose normaliser enters the weight, so
    // order 1 estimates exactly ∫_0^d of the airlight integrand. Later segments sample the plain
    // exponential; passing T means reaching the ground with probability e^{−K_t T} (weight 1).
    const double forcedMass = camera ? -std::expm1(-kt * T) : 1.0;  // 1 − e^{−K_t T}
    const double xi = rng.uniform();
    double tc = -std::log1p(-xi * forcedMass) / kt;
    bool collided = true;
    if (camera) {
      tc = std::min(tc, std::nextafter(T, 0.0));
    } else {
      collided = tc < T;
    }
    segmentNee(x, dir, T, collided, tc, [&](double t) { return kt * std::exp(-kt * t) / forcedMass; }, order,
               beta * mis);

    // ---- the next vertex.
    if (collided) {
      x += tc * dir;
      beta *= omega * forcedMass;  // Ω: the share scattered (absorption as a weight); forced mass
      ++events;
      if (events >= maxOrder) {
        out.remainder = beta * diffusionRadiance(x);
        break;
      }
      const PhaseDraw d = samplePhase(dir, rng);
      mis = guiding ? guidedNee(x, dir, false, d.direction, beta, events + 1) : 1.0;
      dir = d.direction;
      beta *= d.weight;
    } else {
      // The ground (T finite, not the camera ray): Lambertian, ρ/π. NEE to each lamp above it:
      // β ρ/π cos θ_i I(w) e^{−K_t r} / r² (order = events + 1, the ground being that event).
      x += T * dir;
      x.z = zGround;
      const double rho = ground_->reflectance;
      for (std::size_t l = 0; l < lamps_.size(); ++l) {
        if (!lampLit_[l]) continue;
        const Vec3 v = lamps_[l].position_m - x;
        const double r = glm::length(v);
        if (!(r > 0.0)) continue;
        const double cosI = v.z / r;
        const double intensity = lamps_[l].profile->intensity(lampFromWorld_[l] * (-v / r));
        if (cosI > 0.0 && intensity > 0.0)
          addOrder(order, l, beta * rho / kPi * cosI * intensity * std::exp(-kt * r) / (r * r));
      }
      ++events;
      beta *= rho;  // cosine-weighted reflection: (ρ/π) cos / (cos/π)
      if (!(beta > 0.0)) break;
      if (events >= maxOrder) {
        out.remainder = beta * diffusionRadiance(x);
        break;
      }
      const double u1 = rng.uniform(), phi = 2.0 * kPi * rng.uniform();
      const double sr = std::sqrt(u1);
      const Vec3 next(sr * std::cos(phi), sr * std::sin(phi), std::sqrt(std::max(0.0, 1.0 - u1)));
      mis = guiding ? guidedNee(x, Vec3(0.0, 0.0, 1.0), true, next, beta, events + 1) : 1.0;
      dir = next;
    }
    if (!(beta > 0.0)) break;

    // Russian roulette by weight windows: β·ψ(x), ψ the diffusion estimate of the radiance the
    // path can still collect here, against the largest value met along this path. Below a
    // fraction of it the path survives with q = β ψ / (fraction · max) and carries β / q: the
    // expectation is unchanged (unbiased), paths that wander far from every lamp stop early.
    const double importance = beta * diffusionRadiance(x);
    bestImportance = std::max(bestImportance, importance);
    if (events >= options_.roulette_start) {
      const double threshold = options_.roulette_fraction * bestImportance;
      if (importance < threshold) {
        const double q = importance / threshold;
        if (!(rng.uniform() < q)) break;
        beta /= q;
      }
    }
  }
  out.events = events;
  return out;
}

namespace {

struct Sums {
  double s[5] = {0, 0, 0, 0, 0};
  double s2[5] = {0, 0, 0, 0, 0};
  Vec3 rgb{0.0};
  double events = 0.0;
  std::uint64_t n = 0;

  void add(const PathSample& p) {
    const double v[5] = {p.single, p.multiple, p.single + p.multiple, p.remainder, p.single + p.multiple + p.remainder};
    for (int k = 0; k < 5; ++k) {
      s[k] += v[k];
      s2[k] += v[k] * v[k];
    }
    rgb += p.rgb;
    events += p.events;
    ++n;
  }
  void add(const Sums& o) {
    for (int k = 0; k < 5; ++k) {
      s[k] += o.s[k];
      s2[k] += o.s2[k];
    }
    rgb += o.rgb;
    events += o.events;
    n += o.n;
  }
};

McEstimate finish(double s, double s2, std::uint64_t n) {
  if (n == 0) return {};
  const double nn = static_cast<double>(n);
  const double mean = s / nn;
  const double var = n > 1 ? std::max(0.0, (s2 - s * mean) / (nn - 1.0)) : 0.0;
  return {mean, std::sqrt(var / nn)};
}

std::vector<RadianceEstimate> run(std::uint64_t streams, std::uint64_t samples, std::uint64_t seed,
                                  std::uint64_t streamOffset, std::uint32_t batch, ThreadPool* pool,
                                  const PathTracer::PathFunction& path) {
  const std::uint64_t batches = (samples + batch - 1) / batch;
  std::vector<Sums> partial(static_cast<std::size_t>(streams * batches));
  // Each work item sums its batch in sample order; the reduction below walks the batches in
  // order: the floating-point result does not depend on which thread ran which item.
  auto item = [&](std::size_t k) {
    const std::uint64_t s = k / batches, b = k % batches;
    Sums sums;
    const std::uint64_t end = std::min(samples, (b + 1) * batch);
    for (std::uint64_t i = b * batch; i < end; ++i) {
      PathRng rng(seed, streamOffset + s, i);
      sums.add(path(s, i, rng));
    }
    partial[k] = sums;
  };
  if (pool != nullptr) {
    pool->parallelFor(partial.size(), item);
  } else {
    for (std::size_t k = 0; k < partial.size(); ++k) item(k);
  }
  std::vector<RadianceEstimate> out(static_cast<std::size_t>(streams));
  for (std::uint64_t s = 0; s < streams; ++s) {
    Sums total;
    for (std::uint64_t b = 0; b < batches; ++b) total.add(partial[static_cast<std::size_t>(s * batches + b)]);
    RadianceEstimate& e = out[static_cast<std::size_t>(s)];
    McEstimate* q[5] = {&e.single, &e.multiple, &e.all, &e.remainder, &e.total};
    for (int k = 0; k < 5; ++k) *q[k] = finish(total.s[k], total.s2[k], total.n);
    e.samples = total.n;
    if (total.n > 0) {
      e.rgb = total.rgb / static_cast<double>(total.n);
      e.mean_events = total.events / static_cast<double>(total.n);
    }
  }
  return out;
}

}  // namespace

std::vector<RadianceEstimate> PathTracer::radiance(std::span<const Ray> rays, std::uint64_t samples,
                                                   std::uint64_t seed, ThreadPool* pool,
                                                   std::uint64_t first_stream) const {
  return run(rays.size(), samples, seed, first_stream, options_.batch_size, pool,
             [&](std::uint64_t s, std::uint64_t, PathRng& rng) { return trace(rays[s], rng); });
}

std::vector<RadianceEstimate> PathTracer::estimate(std::uint64_t streams, std::uint64_t samples, std::uint64_t seed,
                                                   ThreadPool* pool, const PathFunction& path) const {
  return run(streams, samples, seed, 0, options_.batch_size, pool, path);
}

}  // namespace fogbeam
