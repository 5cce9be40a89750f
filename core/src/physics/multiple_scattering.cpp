// fogbeam — multiple-scattering tables (fogbeam/physics/multiple_scattering.hpp; method and
// checks in docs/physics.md, "Multiple scattering tables").
#include <fogbeam/physics/multiple_scattering.hpp>

#include "physics/airlight_tables.hpp"

#include <fogbeam/physics/path_tracer.hpp>

#include "table_text.hpp"
#include <fogbeam/util/thread_pool.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

namespace fogbeam {

namespace {

constexpr double kHalfPi = 0.5 * kPi;
constexpr double kDeg = kPi / 180.0;
// A lamp farther than this (optical depths) from a vertex gets nothing from it: the segment's
// integral is below e^{−35} p_max π / h (every point's lamp → point → vertex path is ≥ D long).
constexpr double kReach = 35.0;
// G-moment table resolution: the accurate method's defaults (AirlightOptions).
constexpr int kGTheta = 1024, kGK = 192;
constexpr double kGKMax = 2000.0;

double tanHalfAngleSum(double theta) { return std::tan(0.25 * kPi + 0.5 * theta); }

// The single-scattering integral of a unit isotropic lamp along the whole ray from a vertex
// (K_t = 1, Ω = 1): e^{−p}/h ∫_{θ0}^{π/2} e^{−h s(θ)} p(−sin θ) dθ, s = tan(π/4 + θ/2)
// (eq. 3 of docs/physics.md), from the cumulative G moments; rays within 1° of straight away from
// the lamp (θ0 near π/2, where the table difference is imprecise: detail::kAwayConeRad) by a
// 16-point Gauss–Legendre rule in θ with e^{−p} folded into the exponent (backscatter, smooth).
struct SegmentIntegral {
  const detail::GMomentTable& g;
  const Phase& phase;

  double operator()(double p, double h, double theta0) const noexcept {
    if (theta0 > kHalfPi - detail::kAwayConeRad) {
      static constexpr std::array<double, 8> x{0.0950125098376374, 0.2816035507792589, 0.4580167776572274,
                                               0.6178762444026438, 0.7554044083550030, 0.8656312023878318,
                                               0.9445750230732326, 0.9894009349916499};
      static constexpr std::array<double, 8> w{0.1894506104550685, 0.1826034150449236, 0.1691565193950025,
                                               0.1495959888165767, 0.1246289712555339, 0.0951585116824928,
                                               0.0622535239386479, 0.0271524594117541};
      const double a = theta0, b = kHalfPi, mid = 0.5 * (a + b), half = 0.5 * (b - a);
      double sum = 0.0;
      for (std::size_t i = 0; i < x.size(); ++i)
        for (double sgn : {-1.0, 1.0}) {
          const double th = mid + sgn * half * x[i];
          const double expo = p + h * tanHalfAngleSum(th);
          sum += w[i] * std::exp(-expo) * evalPhase(phase, -std::sin(th));
        }
      return half * sum / h;
    }
    const auto kw = g.kWeights(h);
    const double full = g.cumulative(kw, kHalfPi)[0], part = g.cumulative(kw, theta0)[0];
    return std::exp(-p) / h * std::max(full - part, 0.0);
  }

  // The same integral split by the emission angle η at the lamp: the point at angle θ of the ray
  // receives the light the lamp emits along u(θ) = n cos θ + ω sin θ (n the unit vector from the
  // lamp to the ray's foot point), so cos η(θ) = u · e = ne cos θ + we sin θ = A cos(θ − φ0),
  // e the direction from the lamp to the eye. The range [θ0, π/2] is cut where cos η crosses a
  // bin edge (θ = φ0 ± acos(c/A)) and each piece goes to its bin. `cosEdges` descending (η
  // ascending), bins = cosEdges.size() − 1; `out` gets += per bin; returns the total.
  //
  // `outH` (if not null) gets += per bin the same light weighted by cos Δφ, the cosine of the
  // azimuth of u about e from that of d, a unit vector ⊥ e (the camera ray's side of the
  // lamp–eye line): cos Δφ = u · d / √(1 − (u · e)²) = (nd cos θ + wd sin θ) / sin η, taken at each
  // piece's G-weighted mean angle θ̄ = ∫ θ G / ∫ G (the cumulative moments T_1 / T_0), where its
  // linear variation integrates to nothing. The first azimuthal harmonic of the emission
  // (MultipleScatteringTable::emissionHarmonics).
  double binned(double p, double h, double theta0, double ne, double we, const std::vector<double>& cosEdges,
                double* out, double nd = 0.0, double wd = 0.0, double* outH = nullptr) const noexcept {
    const std::size_t bins = cosEdges.size() - 1;
    auto binOf = [&](double c) {
      std::size_t k = 0;
      while (k + 1 < bins && c < cosEdges[k + 1]) ++k;
      return k;
    };
    auto cosAzimuth = [&](double th) {
      const double c = ne * std::cos(th) + we * std::sin(th), sinEta = std::sqrt(std::max(0.0, 1.0 - c * c));
      return sinEta > 1e-9 ? std::clamp((nd * std::cos(th) + wd * std::sin(th)) / sinEta, -1.0, 1.0) : 0.0;
    };
    if (theta0 > kHalfPi - detail::kAwayConeRad) {
      // Backscatter within 1° of straight away: the whole (short, smooth) range to the bin of its middle.
      const double v = (*this)(p, h, theta0);
      const double mid = 0.5 * (theta0 + kHalfPi);
      const std::size_t k = binOf(ne * std::cos(mid) + we * std::sin(mid));
      out[k] += v;
      if (outH != nullptr) outH[k] += v * cosAzimuth(mid);
      return v;
    }
    std::array<double, 40> cuts{};
    std::size_t m = 0;
    cuts[m++] = theta0;
    const double A = std::hypot(ne, we), phi0 = std::atan2(we, ne);
    for (std::size_t k = 1; k < bins && m + 3 < cuts.size(); ++k) {
      if (!(std::abs(cosEdges[k]) < A)) continue;
      const double d = std::acos(cosEdges[k] / A);
      for (double t : {phi0 - d, phi0 + d}) {
        if (t <= -kPi) t += 2.0 * kPi;
        if (t > kPi) t -= 2.0 * kPi;
        if (t > theta0 && t < kHalfPi) cuts[m++] = t;
      }
    }
    std::sort(cuts.begin() + 1, cuts.begin() + static_cast<std::ptrdiff_t>(m));
    cuts[m++] = kHalfPi;
    const auto kw = g.kWeights(h);
    const double scale = std::exp(-p) / h;
    const auto first = g.cumulative(kw, theta0);
    double prev = first[0], prev1 = first[1], total = 0.0;
    for (std::size_t i = 1; i < m; ++i) {
      const auto curAll = g.cumulative(kw, cuts[i]);
      const double cur = curAll[0], d0 = cur - prev, d1 = curAll[1] - prev1;
      const double v = scale * std::max(d0, 0.0);
      prev = cur;
      prev1 = curAll[1];
      if (!(v > 0.0)) continue;
      const double mid = 0.5 * (cuts[i - 1] + cuts[i]);
      const std::size_t k = binOf(ne * std::cos(mid) + we * std::sin(mid));
      out[k] += v;
      if (outH != nullptr) {
        const double mean = d0 > 0.0 ? std::clamp(d1 / d0, cuts[i - 1], cuts[i]) : mid;
        outH[k] += v * cosAzimuth(mean);
      }
      total += v;
    }
    return total;
  }
};

Status checkNodes(const std::vector<double>& v, const char* what, double lo, double hi, bool loOpen) {
  if (v.empty()) return Error{std::string("multiple-scattering table: no ") + what + " nodes"};
  for (std::size_t i = 0; i < v.size(); ++i) {
    const bool inRange = std::isfinite(v[i]) && (loOpen ? v[i] > lo : v[i] >= lo) && v[i] <= hi;
    if (!inRange || (i > 0 && !(v[i] > v[i - 1])))
      return Error{std::string("multiple-scattering table: ") + what + " node " + std::to_string(i) + " (" +
                   std::to_string(v[i]) + ") must be ascending in " + (loOpen ? "(" : "[") + std::to_string(lo) +
                   ", " + std::to_string(hi) + "]"};
  }
  return Ok{};
}

// Position of x among ascending nodes: the cell i (nodes i, i+1) and the fraction in it, clamped.
std::pair<std::size_t, double> locate(const std::vector<double>& nodes, double x) noexcept {
  if (nodes.size() < 2) return {0, 0.0};
  if (x <= nodes.front()) return {0, 0.0};
  if (x >= nodes.back()) return {nodes.size() - 2, 1.0};
  const auto it = std::upper_bound(nodes.begin(), nodes.end(), x);
  const auto i = static_cast<std::size_t>(it - nodes.begin()) - 1;
  return {i, (x - nodes[i]) / (nodes[i + 1] - nodes[i])};
}

}  // namespace

MultipleScatteringOptions MultipleScatteringOptions::defaults() {
  MultipleScatteringOptions o;
  // Below 0.25 at steps of 2: a driver's own lamps light fog at K_t R ~ 0.1 (the eye ~2 m
  // behind them), where orders ≥ 2 are small beside order 1 but not flat in T.
  o.optical_distances = {0.03125, 0.0625, 0.125};
  for (int i = 0; i <= 12; ++i) o.optical_distances.push_back(0.25 * std::pow(std::sqrt(2.0), i));
  for (double d : {0.1, 0.2, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 2.8, 4.0, 5.6, 8.0, 11.3, 16.0, 22.6, 32.0, 45.0, 64.0, 90.0,
                   120.0, 150.0, 180.0})
    o.angles_rad.push_back(d * kDeg);
  o.albedos = {0.7, 0.8, 0.85, 0.9, 0.94, 0.97, 0.99, 1.0};
  o.emission_edges_deg = {0.0, 3.0, 8.0, 15.0, 30.0, 60.0, 100.0, 140.0, 160.0, 170.0, 176.0, 180.0};
  return o;
}

std::string multipleScatteringTableName(const Phase& phase) {
  char buf[64];
  if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&phase)) {
    std::snprintf(buf, sizeof buf, "hg-%.3f", hg->g);
    return buf;
  }
  if (const auto* fm = std::get_if<FogMiePhase>(&phase)) {
    std::snprintf(buf, sizeof buf, "fog-mie-%.1fum", fm->diameter_um);
    return buf;
  }
  return "isotropic";
}

Result<MultipleScatteringTable> MultipleScatteringTable::build(const Phase& phase, const MultipleScatteringOptions& options,
                                                               ThreadPool* pool) {
  MultipleScatteringOptions o = options;
  const MultipleScatteringOptions d = MultipleScatteringOptions::defaults();
  if (o.optical_distances.empty()) o.optical_distances = d.optical_distances;
  if (o.angles_rad.empty()) o.angles_rad = d.angles_rad;
  if (o.albedos.empty()) o.albedos = d.albedos;
  if (!o.emission_edges_deg.empty()) {
    const auto& e = o.emission_edges_deg;
    bool okEdges = e.size() >= 2 && e.front() == 0.0 && e.back() == 180.0;
    for (std::size_t k = 1; k < e.size(); ++k) okEdges = okEdges && e[k] > e[k - 1];
    if (!okEdges || e.size() > 17)
      return Error{"multiple-scattering table: emission_edges_deg must ascend from 0 to 180 (at most 16 bins)"};
  }
  if (Status s = checkNodes(o.optical_distances, "optical distance", 0.0, kReach, true); !s) return s.error();
  if (Status s = checkNodes(o.angles_rad, "angle", 0.0, kPi, true); !s) return s.error();
  if (Status s = checkNodes(o.albedos, "albedo", 0.0, 1.0, true); !s) return s.error();
  if (o.paths < 2) return Error{"multiple-scattering table: at least 2 paths (the standard error needs two)"};
  if (o.max_order < 2) return Error{"multiple-scattering table: max_order must be at least 2"};
  if (o.batch_size < 1) return Error{"multiple-scattering table: batch_size must be at least 1"};
  const auto t0 = std::chrono::steady_clock::now();

  // The phase sampler of the path tracer (exact for HG and isotropic, inverse-CDF table with the
  // weight p/pdf for fog-mie); its lamp is not used.
  Medium unit{1.0, 1.0, phase, 0.0};
  Lamp dummy;
  auto iso = makeProfile(IsotropicProfile{1.0});
  if (!iso) return iso.error();
  dummy.profile = *iso;
  auto tracer = PathTracer::build({dummy}, unit);
  if (!tracer) return tracer.error();
  const detail::GMomentTable g(phase, kGTheta, kGK, kGKMax);
  const SegmentIntegral segment{g, phase};
  const bool tabulated = std::holds_alternative<FogMiePhase>(phase);

  MultipleScatteringTable t;
  t.phase_ = phase;
  t.t_ = o.optical_distances;
  t.theta_ = o.angles_rad;
  t.albedo_ = o.albedos;
  t.paths_ = o.paths;
  for (double e : o.emission_edges_deg) t.edges_.push_back(e * kDeg);
  t.seed_ = o.seed;
  t.maxOrder_ = o.max_order;
  const std::size_t nT = t.t_.size(), nTh = t.theta_.size(), nA = t.albedo_.size(), nL = nT * nTh;
  std::vector<Vec3> lamps(nL);
  for (std::size_t i = 0; i < nT; ++i)
    for (std::size_t j = 0; j < nTh; ++j)
      lamps[i * nTh + j] = t.t_[i] * Vec3(std::sin(t.theta_[j]), 0.0, std::cos(t.theta_[j]));
  const double reach = t.t_.back();
  // Emission bins (the Ω = 1 node's light split by the angle η at the lamp from its direction to
  // the eye): cos of the edges, descending; the unit direction from each lamp to the eye.
  const std::size_t nK = t.edges_.empty() ? 0 : t.edges_.size() - 1;
  std::vector<double> cosEdges;
  for (double e : t.edges_) cosEdges.push_back(std::cos(e));
  if (nK > 0) {
    cosEdges.front() = 2.0;  // η = 0 and 180° exactly: every cos η falls inside
    cosEdges.back() = -2.0;
  }
  std::vector<Vec3> toEye(nL);
  for (std::size_t l = 0; l < nL; ++l) toEye[l] = -glm::normalize(lamps[l]);
  // The camera ray's side of each lamp–eye line: the unit part of +z perpendicular to it (the
  // lamp at T (sin θ, 0, cos θ): (−cos θ, 0, sin θ)), the reference of the emission's azimuth.
  std::vector<Vec3> side(nL);
  for (std::size_t l = 0; l < nL; ++l) {
    const double th = t.theta_[l % nTh];
    side[l] = Vec3(-std::cos(th), 0.0, std::sin(th));
  }

  const std::uint64_t batches = (o.paths + o.batch_size - 1) / o.batch_size;
  // Per batch: Σ x and Σ x² per (albedo, lamp), and the events.
  std::vector<double> sums(batches * nA * nL * 2, 0.0);
  std::vector<double> binSums(batches * nL * std::max<std::size_t>(nK, 1), 0.0);
  std::vector<double> harmSums(batches * nL * std::max<std::size_t>(nK, 1), 0.0);  // the same × cos Δφ
  std::vector<std::uint64_t> events(batches, 0);
  auto runBatch = [&](std::size_t b) {
    double* sum = sums.data() + b * nA * nL * 2;
    double* sq = sum + nA * nL;
    std::vector<double> acc(nA * nL);
    double* binAcc = binSums.data() + b * nL * std::max<std::size_t>(nK, 1);
    double* harmAcc = harmSums.data() + b * nL * std::max<std::size_t>(nK, 1);
    std::vector<double> segBins(std::max<std::size_t>(nK, 1)), tmpBins(std::max<std::size_t>(nK, 1));
    std::vector<double> segHarm(std::max<std::size_t>(nK, 1)), tmpHarm(std::max<std::size_t>(nK, 1));
    std::vector<double> wA(nA);
    const std::uint64_t first = b * o.batch_size, last = std::min<std::uint64_t>(o.paths, first + o.batch_size);
    for (std::uint64_t s = first; s < last; ++s) {
      PathRng rng(o.seed, 0, s);
      std::fill(acc.begin(), acc.end(), 0.0);
      {
        Vec3 x(0.0), w(0.0, 0.0, 1.0);  // the eye, looking along the camera ray
        double beta = 1.0;
        for (int n = 1; n < o.max_order; ++n) {
          // The n-th scattering vertex: free flight, then a new direction from the phase function.
          x += -std::log1p(-rng.uniform()) * w;
          const Vec3 wIn = w;
          const PathTracer::PhaseDraw draw = tracer->samplePhase(wIn, rng);
          w = draw.direction;
          const double cosP = glm::dot(wIn, w), sinP = glm::length(glm::cross(wIn, w));
          const double fP = evalPhase(phase, cosP), pdfP = tabulated ? tracer->phaseSamplingPdf(cosP, sinP) : fP;
          const double betaIn = beta;
          beta *= draw.weight;
          ++events[b];
          // The segment leaving vertex n carries order n + 1: weight Ω^{n+1} per albedo node.
          for (std::size_t a = 0; a < nA; ++a) wA[a] = betaIn * std::pow(t.albedo_[a], n + 1);
          // Per lamp, the segment's lamp integral S(ω) weighted by the phase function is estimated
          // by two samples combined by the balance heuristic (Veach 1997), as the path tracer's
          // lamp-guided NEE: the phase-sampled ω_P (which also continues the path) and ω_G drawn
          // towards this lamp with ψ, its angle from the lamp's direction, uniform in [0, π/2]
          // (pdf 1/(π² sin ψ)). A segment passing at h from a lamp carries ∝ 1/h; phase sampling
          // alone gives it a logarithmically infinite variance, the mixture a bounded one.
          for (std::size_t l = 0; l < nL; ++l) {
            const Vec3 v = lamps[l] - x;
            const double d2 = glm::dot(v, v);
            if (d2 > kReach * kReach) continue;
            const double D = std::sqrt(d2);
            double val = 0.0;
            const Vec3& e = toEye[l];
            const Vec3& dp = side[l];
            std::fill(segBins.begin(), segBins.end(), 0.0);
            std::fill(segHarm.begin(), segHarm.end(), 0.0);
            {  // the phase-sampled direction
              const double p = glm::dot(v, w);
              const double h = std::sqrt(std::max(d2 - p * p, 1e-18));
              const double pG = p > 0.0 ? 1.0 / (kPi * kPi * (h / D)) : 0.0;
              const double mis = fP / (pdfP + pG);
              if (nK == 0) {
                const double seg = segment(p, h, std::atan2(-p, h));
                if (seg > 0.0) val += mis * seg;
              } else {
                // n: from the lamp to the ray's foot point x + p ω.
                const Vec3 foot = (x + p * w - lamps[l]) / h;
                tmpBins.assign(nK, 0.0);
                tmpHarm.assign(nK, 0.0);
                val += mis * segment.binned(p, h, std::atan2(-p, h), glm::dot(foot, e), glm::dot(w, e), cosEdges,
                                            tmpBins.data(), glm::dot(foot, dp), glm::dot(w, dp), tmpHarm.data());
                for (std::size_t k = 0; k < nK; ++k) {
                  segBins[k] += mis * tmpBins[k];
                  segHarm[k] += mis * tmpHarm[k];
                }
              }
            }
            {  // the guided direction: only its angles matter. The segment's lamp integral depends
               // on (D, ψ): p = D cos ψ, h = D sin ψ, θ0 = ψ − π/2; the phase function on the angle
               // from the incoming direction, cos = cos ψ c + sin ψ √(1 − c²) cos φ, c = ω_in · u.
              const double psi = kHalfPi * rng.uniform(), phi = 2.0 * kPi * rng.uniform();
              const double cpsi = std::cos(psi), spsi = std::max(std::sin(psi), 1e-12);
              const double c = glm::dot(wIn, v) / D;
              const double cosG =
                  std::clamp(cpsi * c + spsi * std::sqrt(std::max(0.0, 1.0 - c * c)) * std::cos(phi), -1.0, 1.0);
              const double fG = evalPhase(phase, cosG);
              const double pdfG =
                  tabulated ? tracer->phaseSamplingPdf(cosG, std::sqrt(std::max(0.0, 1.0 - cosG * cosG))) : fG;
              const double mis = fG / (pdfG + 1.0 / (kPi * kPi * spsi));
              if (nK == 0) {
                const double seg = segment(D * cpsi, D * spsi, psi - kHalfPi);
                if (seg > 0.0) val += mis * seg;
              } else {
                // ω_G = cos ψ u + sin ψ v, v ⊥ u at azimuth φ from the projection of ω_in; then
                // n = −sin ψ u + cos ψ v. With ue = u·e and v·e = |e⊥| cos(φ − φ_e), φ_e the
                // azimuth of e's projection from ω_in's about u.
                const Vec3 u = v / D;
                const double ue = glm::dot(u, e);
                const Vec3 ePerp = e - ue * u, inPerp = wIn - c * u;
                const double ePerpLen = glm::length(ePerp), inPerpLen = glm::length(inPerp);
                double ve = 0.0;
                if (ePerpLen > 1e-12) {
                  if (inPerpLen > 1e-12) {
                    const double cosPhiE = glm::dot(inPerp, ePerp) / (inPerpLen * ePerpLen);
                    const double sinPhiE = glm::dot(u, glm::cross(inPerp, ePerp)) / (inPerpLen * ePerpLen);
                    ve = ePerpLen * (std::cos(phi) * cosPhiE + std::sin(phi) * sinPhiE);
                  } else {
                    ve = ePerpLen * std::cos(phi);  // ω_in along u: any azimuth reference will do
                  }
                }
                const double ne = -spsi * ue + cpsi * ve, we = cpsi * ue + spsi * ve;
                // The same for the side vector: v = cos φ â + sin φ (u × â), â the unit part of ω_in
                // ⊥ u (else of e, else any), as ve above.
                Vec3 a0 = inPerpLen > 1e-12 ? inPerp / inPerpLen : (ePerpLen > 1e-12 ? ePerp / ePerpLen : Vec3(0.0));
                if (!(inPerpLen > 1e-12) && !(ePerpLen > 1e-12)) {
                  const Vec3 any = std::abs(u.x) < 0.9 ? Vec3(1.0, 0.0, 0.0) : Vec3(0.0, 1.0, 0.0);
                  a0 = glm::normalize(any - glm::dot(any, u) * u);
                }
                const double ud = glm::dot(u, dp);
                const double vd = std::cos(phi) * glm::dot(a0, dp) + std::sin(phi) * glm::dot(glm::cross(u, a0), dp);
                const double nd = -spsi * ud + cpsi * vd, wd = cpsi * ud + spsi * vd;
                tmpBins.assign(nK, 0.0);
                tmpHarm.assign(nK, 0.0);
                val += mis * segment.binned(D * cpsi, D * spsi, psi - kHalfPi, ne, we, cosEdges, tmpBins.data(), nd, wd,
                                            tmpHarm.data());
                for (std::size_t k = 0; k < nK; ++k) {
                  segBins[k] += mis * tmpBins[k];
                  segHarm[k] += mis * tmpHarm[k];
                }
              }
            }
            if (!(val > 0.0)) continue;
            for (std::size_t a = 0; a < nA; ++a) acc[a * nL + l] += wA[a] * val;
            for (std::size_t k = 0; k < nK; ++k) {
              binAcc[l * nK + k] += wA[nA - 1] * segBins[k];
              harmAcc[l * nK + k] += wA[nA - 1] * segHarm[k];
            }
          }
          // Russian roulette on the importance 1/(1 + ρ), ρ the vertex's distance beyond the
          // farthest lamp (a weight window: below half of the target weight 1 + ρ a path survives
          // with probability β/(1 + ρ) and then carries 1 + ρ; unbiased). Paths that wander off
          // end; inside the lamps' sphere none is ended before max_order. Splitting paths as they
          // move out towards the far lamps (importance (1 + r)^a) was tried: a = 1 cost 7× the
          // events for 1.5–2× less σ at T = 8, no better than more paths.
          const double target = 1.0 + std::max(0.0, glm::length(x) - reach);
          if (n >= 3 && beta < 0.5 * target) {
            if (rng.uniform() >= beta / target) break;
            beta = target;
          }
        }
      }
      for (std::size_t k = 0; k < acc.size(); ++k) {
        sum[k] += acc[k];
        sq[k] += acc[k] * acc[k];
      }
    }
  };
  if (pool != nullptr)
    pool->parallelFor(batches, runBatch);
  else
    for (std::size_t b = 0; b < batches; ++b) runBatch(b);

  t.mean_.assign(nA * nL, 0.0);
  t.stderr_.assign(nA * nL, 0.0);
  std::vector<double> sq(nA * nL, 0.0);
  std::uint64_t allEvents = 0;
  for (std::uint64_t b = 0; b < batches; ++b) {
    const double* s = sums.data() + b * nA * nL * 2;
    for (std::size_t k = 0; k < nA * nL; ++k) {
      t.mean_[k] += s[k];
      sq[k] += s[nA * nL + k];
    }
    allEvents += events[b];
  }
  const double N = static_cast<double>(o.paths);
  for (std::size_t k = 0; k < nA * nL; ++k) {
    const double m = t.mean_[k] / N;
    const double var = std::max(0.0, sq[k] / N - m * m) * N / (N - 1.0);
    t.mean_[k] = m;
    t.stderr_[k] = std::sqrt(var / N);
  }
  t.meanEvents_ = static_cast<double>(allEvents) / N;
  // Emission fractions per (T, θ) node at the largest albedo: each bin's share of the node's light.
  // The harmonics over the same total (MultipleScatteringTable::emissionHarmonics).
  if (nK > 0) {
    t.fractions_.assign(nL * nK, 0.0);
    t.harmonics_.assign(nL * nK, 0.0);
    for (std::uint64_t b = 0; b < batches; ++b)
      for (std::size_t k = 0; k < nL * nK; ++k) {
        t.fractions_[k] += binSums[b * nL * nK + k];
        t.harmonics_[k] += harmSums[b * nL * nK + k];
      }
    for (std::size_t l = 0; l < nL; ++l) {
      double sum = 0.0;
      for (std::size_t k = 0; k < nK; ++k) sum += t.fractions_[l * nK + k];
      for (std::size_t k = 0; k < nK; ++k) {
        t.fractions_[l * nK + k] = sum > 0.0 ? t.fractions_[l * nK + k] / sum : 1.0 / static_cast<double>(nK);
        t.harmonics_[l * nK + k] = sum > 0.0 ? t.harmonics_[l * nK + k] / sum : 0.0;
      }
    }
  }
  for (double v : t.t_) t.logT_.push_back(std::log(v));
  for (double v : t.theta_) t.logTheta_.push_back(std::log(v));
  t.buildSeconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return t;
}

double MultipleScatteringTable::valueAtAlbedo(std::size_t a, double T, double theta) const noexcept {
  const double lt = std::log(std::max(T, t_.front())), lth = std::log(std::max(theta, theta_.front()));
  const auto [i, fi] = locate(logT_, lt);
  const auto [j, fj] = locate(logTheta_, lth);
  const std::size_t i1 = std::min(i + 1, t_.size() - 1), j1 = std::min(j + 1, theta_.size() - 1);
  const double v00 = mean_[index(a, i, j)], v01 = mean_[index(a, i, j1)], v10 = mean_[index(a, i1, j)],
               v11 = mean_[index(a, i1, j1)];
  double v;
  if (v00 > 0.0 && v01 > 0.0 && v10 > 0.0 && v11 > 0.0) {
    v = std::exp((1 - fi) * ((1 - fj) * std::log(v00) + fj * std::log(v01)) +
                 fi * ((1 - fj) * std::log(v10) + fj * std::log(v11)));
  } else {
    v = (1 - fi) * ((1 - fj) * v00 + fj * v01) + fi * ((1 - fj) * v10 + fj * v11);
  }
  // Below the first T node: the first node's value (T is clamped above). f = L / (I K_t²) does not
  // vanish as the lamp nears the eye: the multiply scattered light about a lamp grows slowly as
  // one comes closer (the path tracer, HG 0.85, from T = 0.25 to 0.05: +3 % at θ = 3°, +19 % at
  // 20°, +64 % at 90°), hence the shipped tables' nodes down to T = 1/32 (a driver's own lamps);
  // a T² fall-off (before 2026-11-26) took 96 % of it away at T = 0.05
  // (SmallOpticalDistancesFollowThePathTracer).
  return std::max(v, 0.0);
}

void MultipleScatteringTable::binsAt(const std::vector<double>& perBin, double opticalDistance, double theta,
                                     double* out) const noexcept {
  const std::size_t nK = edges_.size() - 1;
  const double lt = std::log(std::max(opticalDistance, t_.front())), lth = std::log(std::max(theta, theta_.front()));
  const auto [i, fi] = locate(logT_, lt);
  const auto [j, fj] = locate(logTheta_, lth);
  const std::size_t i1 = std::min(i + 1, t_.size() - 1), j1 = std::min(j + 1, theta_.size() - 1);
  const std::size_t nTh = theta_.size();
  for (std::size_t k = 0; k < nK; ++k)
    out[k] = (1 - fi) * ((1 - fj) * perBin[(i * nTh + j) * nK + k] + fj * perBin[(i * nTh + j1) * nK + k]) +
             fi * ((1 - fj) * perBin[(i1 * nTh + j) * nK + k] + fj * perBin[(i1 * nTh + j1) * nK + k]);
}

void MultipleScatteringTable::emissionShares(double opticalDistance, double theta, double* out) const noexcept {
  if (fractions_.empty()) return;
  const std::size_t nK = edges_.size() - 1;
  binsAt(fractions_, opticalDistance, theta, out);
  double sum = 0.0;
  for (std::size_t k = 0; k < nK; ++k) sum += out[k];
  for (std::size_t k = 0; k < nK; ++k) out[k] = sum > 0.0 ? out[k] / sum : 1.0 / static_cast<double>(nK);
}

void MultipleScatteringTable::emissionHarmonics(double opticalDistance, double theta, double* out) const noexcept {
  if (!harmonics_.empty()) binsAt(harmonics_, opticalDistance, theta, out);
}

double MultipleScatteringTable::value(double opticalDistance, double theta, double albedo) const noexcept {
  if (!(opticalDistance > 0.0) || mean_.empty()) return 0.0;
  const auto [a, fa] = locate(albedo_, albedo);
  if (albedo_.size() < 2) return valueAtAlbedo(0, opticalDistance, theta);
  const double v0 = valueAtAlbedo(a, opticalDistance, theta), v1 = valueAtAlbedo(a + 1, opticalDistance, theta);
  if (fa == 0.0) return v0;
  if (fa == 1.0) return v1;
  return v0 > 0.0 && v1 > 0.0 ? std::exp((1 - fa) * std::log(v0) + fa * std::log(v1)) : (1 - fa) * v0 + fa * v1;
}

// ---- text form ----------------------------------------------------------------------------
// fogbeam-multiple-scattering 1
// phase <describe(phase)>            (informational; the identity below is what load checks)
// phase_identity <kind> <a> <b> <c>
// paths <N> seed <S> max_order <M> mean_events <E>
// optical_distances <n> v…
// angles_deg <n> v…
// albedos <n> v…
// emission_edges_deg <n> v…          (n = 0: no emission bins)
// then n_albedo × n_T × n_θ lines "mean stderr" in (albedo, T, θ) order; with bins the line
// "emission_shares" and n_T × n_θ lines of one share per bin, then (optional) the line
// "emission_harmonics" and n_T × n_θ lines of one harmonic per bin.

Status MultipleScatteringTable::save(const std::filesystem::path& path) const {
  std::ofstream f(path);
  if (!f) return Error{"cannot write " + path.string()};
  f.precision(17);
  f << "fogbeam-multiple-scattering 1\n";
  detail::writePhase(f, phase_);
  f << "paths " << paths_ << " seed " << seed_ << " max_order " << maxOrder_ << " mean_events " << meanEvents_ << "\n";
  auto list = [&](const char* name, const std::vector<double>& v, double scale) { detail::writeList(f, name, v, scale); };
  list("optical_distances", t_, 1.0);
  list("angles_deg", theta_, 180.0 / kPi);
  list("albedos", albedo_, 1.0);
  list("emission_edges_deg", edges_, 180.0 / kPi);
  // 8 significant digits: the nodes' standard errors are ≥ 1e-4 of their values.
  f.precision(8);
  for (std::size_t k = 0; k < mean_.size(); ++k) f << mean_[k] << ' ' << stderr_[k] << "\n";
  if (!fractions_.empty()) {
    const std::size_t nK = edges_.size() - 1;
    f << "emission_shares\n";
    f.precision(6);
    for (std::size_t l = 0; l < fractions_.size() / nK; ++l) {
      for (std::size_t k = 0; k < nK; ++k) f << (k ? " " : "") << fractions_[l * nK + k];
      f << "\n";
    }
    if (!harmonics_.empty()) {
      f << "emission_harmonics\n";
      for (std::size_t l = 0; l < harmonics_.size() / nK; ++l) {
        for (std::size_t k = 0; k < nK; ++k) f << (k ? " " : "") << harmonics_[l * nK + k];
        f << "\n";
      }
    }
  }
  if (!f) return Error{"error writing " + path.string()};
  return Ok{};
}

Result<MultipleScatteringTable> MultipleScatteringTable::load(const std::filesystem::path& path) {
  auto text = detail::readTextFile(path, "multiple-scattering table");
  if (!text) return text.error();
  return parse(*text, path.string());
}

Result<MultipleScatteringTable> MultipleScatteringTable::parse(std::string_view text, const std::string& source) {
  detail::TableText in(text, source);
  auto fail = [&](const std::string& what) { return in.fail(what); };
  auto phase = in.headerAndPhase("fogbeam-multiple-scattering");
  if (!phase) return phase.error();
  MultipleScatteringTable t;
  t.phase_ = *phase;
  std::string k1, k2, k3;
  if (!in.next("paths") || !(in.words() >> t.paths_ >> k1 >> t.seed_ >> k2 >> t.maxOrder_ >> k3 >> t.meanEvents_) ||
      k1 != "seed" || k2 != "max_order" || k3 != "mean_events")
    return fail("expected 'paths <N> seed <S> max_order <M> mean_events <E>'");
  auto list = [&](const char* key, std::vector<double>& v, double scale, bool mayBeEmpty = false) {
    return in.list(key, v, scale, mayBeEmpty);
  };
  if (Status s = list("optical_distances", t.t_, 1.0); !s) return s.error();
  if (Status s = list("angles_deg", t.theta_, kPi / 180.0); !s) return s.error();
  if (Status s = list("albedos", t.albedo_, 1.0); !s) return s.error();
  if (Status s = list("emission_edges_deg", t.edges_, kPi / 180.0, true); !s) return s.error();
  if (!t.edges_.empty()) {
    bool okEdges = t.edges_.size() >= 2 && t.edges_.size() <= 17 && t.edges_.front() == 0.0 &&
                   std::abs(t.edges_.back() - kPi) < 1e-9;
    for (std::size_t k = 1; k < t.edges_.size(); ++k) okEdges = okEdges && t.edges_[k] > t.edges_[k - 1];
    if (!okEdges) return fail("emission_edges_deg: expected 2 to 17 edges ascending from 0 to 180");
    t.edges_.back() = kPi;
  }
  // Rounding of the degree values may put 180° a hair past π.
  t.theta_.back() = std::min(t.theta_.back(), kPi);
  if (Status s = checkNodes(t.t_, "optical distance", 0.0, kReach, true); !s) return fail(s.error().message);
  if (Status s = checkNodes(t.theta_, "angle", 0.0, kPi, true); !s) return fail(s.error().message);
  if (Status s = checkNodes(t.albedo_, "albedo", 0.0, 1.0, true); !s) return fail(s.error().message);
  const std::size_t n = t.t_.size() * t.theta_.size() * t.albedo_.size();
  t.mean_.resize(n);
  t.stderr_.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    if (!in.nextLine()) return in.failMissing("expected " + std::to_string(n) + " node lines, found " + std::to_string(k));
    std::istringstream& ls = in.words();
    if (!(ls >> t.mean_[k] >> t.stderr_[k]) || !std::isfinite(t.mean_[k]) || !(t.stderr_[k] >= 0.0) || t.mean_[k] < 0.0)
      return fail("expected '<mean ≥ 0> <standard error ≥ 0>'");
  }
  if (!t.edges_.empty()) {
    const std::size_t nK = t.edges_.size() - 1, nL = t.t_.size() * t.theta_.size();
    if (!in.nextLine()) return in.failMissing("expected 'emission_shares' (the table has emission bins)");
    if (in.line() != "emission_shares") return fail("expected 'emission_shares' (the table has emission bins)");
    // nL lines of nK numbers each, every one accepted by `ok(value, index)` (`bound` says how).
    auto binLines = [&](std::vector<double>& v, const std::string& what, const char* bound, auto ok) -> Status {
      v.resize(nL * nK);
      for (std::size_t l = 0; l < nL; ++l) {
        if (!in.nextLine())
          return in.failMissing("expected " + std::to_string(nL) + " " + what + " lines, found " + std::to_string(l));
        std::istringstream& ls = in.words();
        for (std::size_t k = 0; k < nK; ++k)
          if (!(ls >> v[l * nK + k]) || !ok(v[l * nK + k], l * nK + k))
            return fail("expected " + std::to_string(nK) + " " + what + "s, each " + bound);
      }
      return Ok{};
    };
    if (Status s = binLines(t.fractions_, "emission share", "in [0, 1]",
                            [](double x, std::size_t) { return x >= 0.0 && x <= 1.0 + 1e-9; });
        !s)
      return s.error();
    // Optional (tables from before 2026-11-27 have none): the emission's first azimuthal harmonic,
    // each |value| at most its share (a mean of the share's light times a cosine).
    while (in.nextLine()) {
      const std::string& line = in.line();
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      if (line != "emission_harmonics") return fail("expected 'emission_harmonics' or the end of the table");
      if (Status s = binLines(t.harmonics_, "emission harmonic", "within ± its share",
                              [&](double h, std::size_t i) {
                                return std::isfinite(h) && std::abs(h) <= t.fractions_[i] + 1e-5;
                              });
          !s)
        return s.error();
      break;
    }
    while (in.nextLine())
      if (in.line().find_first_not_of(" \t\r") != std::string::npos) return fail("unexpected text after the table");
  }
  for (double v : t.t_) t.logT_.push_back(std::log(v));
  for (double v : t.theta_) t.logTheta_.push_back(std::log(v));
  return t;
}

}  // namespace fogbeam

namespace fogbeam {

Result<MultipleScatteringTable> MultipleScatteringTable::blend(const MultipleScatteringTable& a,
                                                               const MultipleScatteringTable& b, double w,
                                                               const Phase& phase) {
  if (a.t_ != b.t_ || a.theta_ != b.theta_ || a.albedo_ != b.albedo_)
    return Error{"multiple-scattering tables: blending needs the same nodes"};
  MultipleScatteringTable t = a;
  t.phase_ = phase;
  for (std::size_t k = 0; k < t.mean_.size(); ++k) {
    t.mean_[k] = (1.0 - w) * a.mean_[k] + w * b.mean_[k];
    t.stderr_[k] = std::hypot((1.0 - w) * a.stderr_[k], w * b.stderr_[k]);
  }
  if (a.fractions_.size() == b.fractions_.size() && a.edges_ == b.edges_) {
    for (std::size_t k = 0; k < t.fractions_.size(); ++k)
      t.fractions_[k] = (1.0 - w) * a.fractions_[k] + w * b.fractions_[k];
    if (a.harmonics_.size() == b.harmonics_.size()) {
      for (std::size_t k = 0; k < t.harmonics_.size(); ++k)
        t.harmonics_[k] = (1.0 - w) * a.harmonics_[k] + w * b.harmonics_[k];
    } else {
      t.harmonics_.clear();  // one of them has none: the blend has none
    }
  } else {
    t.fractions_.clear();  // one of them has no bins: the blend has none
    t.harmonics_.clear();
    t.edges_.clear();
  }
  t.paths_ = std::min(a.paths_, b.paths_);
  t.meanEvents_ = (1.0 - w) * a.meanEvents_ + w * b.meanEvents_;
  return t;
}

namespace detail {
extern const EmbeddedTable kEmbeddedMultipleScatteringTables[];
extern const std::size_t kEmbeddedMultipleScatteringTableCount;
}  // namespace detail

std::vector<std::string> shippedMultipleScatteringTableNames() {
  std::vector<std::string> names;
  for (std::size_t i = 0; i < detail::kEmbeddedMultipleScatteringTableCount; ++i)
    names.emplace_back(detail::kEmbeddedMultipleScatteringTables[i].name);
  return names;
}

std::shared_ptr<const MultipleScatteringTable> shippedMultipleScatteringTable(const Phase& phase) {
  return detail::shippedTable<MultipleScatteringTable>(phase, detail::kEmbeddedMultipleScatteringTables,
                                                       detail::kEmbeddedMultipleScatteringTableCount, ".msc",
                                                       multipleScatteringTableName);
}

}  // namespace fogbeam
