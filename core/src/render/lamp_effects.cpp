#include <fogbeam/render/lamp_effects.hpp>

#include <fogbeam/physics/glow.hpp>
#include <fogbeam/physics/ground_correction.hpp>
#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/render/airlight_kernels.hpp>

#include <fogbeam/util/shared_cache.hpp>

#include "glow_quadrature.hpp"
#include "ground_veil.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

namespace fogbeam {

namespace {

// Radial tables over the half-chord s = |ω − e|/2 = sin(θ/2) between a pixel's ray ω and the
// lamp's direction e: nodes s_i = (i / (n − 1))², dense near the lamp (θ of the first node: 2e-5
// rad at n = 512), every θ up to π.
using lamp_fx::kNodes;
double sOfNode(int i) {
  const double u = static_cast<double>(i) / (kNodes - 1);
  return u * u;
}
double thetaOfS(double s) { return 2.0 * std::asin(std::min(s, 1.0)); }

double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

using glow_quadrature::glowNodeAngle;
using glow_quadrature::integrateFromApex;

// Φ[L] R² / (2π) pieces: 2π ∫ L cos θ sin θ dθ (integrateFromApex). cos θ sin θ is kept per
// thread for the last nodes: a moving lamp's curves, every frame on the same nodes, would
// otherwise spend ~2 000 sines and cosines a frame each here (the rule reads each node twice).
double fluxOver(const std::vector<double>& theta, const std::vector<double>& L) {
  thread_local std::vector<double> lastTheta, cs;
  if (theta != lastTheta) {
    lastTheta = theta;
    cs.resize(theta.size());
    for (std::size_t i = 0; i < theta.size(); ++i) cs[i] = std::cos(theta[i]) * std::sin(theta[i]);
  }
  return 2.0 * kPi * integrateFromApex(theta, [&](std::size_t i) { return L[i] * cs[i]; });
}

// A glow curve's fixed nodes for a table's angle nodes: θ_i (glowNodeAngle), and where each
// falls among the table's angles (j_i, and its log-linear weight w_i). A moving lamp computes its
// curve every frame; these do not change with it (only with `nodes` and the table), and their
// asin and logs per node were most of the curve's cost. Per thread, rebuilt when either changes.
struct CurveNodes {
  std::vector<double> angles;  // the table's angle nodes they were made for
  std::vector<double> theta, w;
  std::vector<std::size_t> j;
};
const CurveNodes& curveNodes(const std::vector<double>& angles, std::size_t n) {
  thread_local CurveNodes c;
  if (c.theta.size() == n && c.angles == angles) return c;
  c.angles = angles;
  c.theta.resize(n);
  c.w.resize(n);
  c.j.resize(n);
  std::size_t j = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double theta = glowNodeAngle(i, n);
    c.theta[i] = theta;
    if (angles.size() < 2) continue;
    const double th = std::max(theta, angles.front());
    while (j + 2 < angles.size() && th > angles[j + 1]) ++j;
    c.j[i] = j;
    c.w[i] = std::clamp(std::log(th / angles[j]) / std::log(angles[j + 1] / angles[j]), 0.0, 1.0);
  }
  return c;
}

// S₁ for the sky ray at θ from an isotropic source of 1 cd at R (eq. 3 with the F table, Ω = 1):
// K_t e^{−K_t R cos θ} / h · [F(k, π/2) − F(k, θ0)], h = R sin θ, k = K_t h, θ0 = θ − π/2.
// Rays looking away from the source (θ0 > 0): the tail integral directly (the table's
// difference of two O(1) values would be amplified by e^{K_t R |cos θ|}).
// At θ = 0 (towards the source) S₁ ~ 1/θ: +inf; at θ = π it is finite and weighs nothing
// in the flux (sin θ = 0) nor on screen: 0.
double singleAt(const kernels::IsoTable& table, double kt, double R, double theta) {
  const double cosT = std::cos(theta), sinT = std::sin(theta);
  double single = theta < 0.5 * kPi ? std::numeric_limits<double>::infinity() : 0.0;
  if (sinT > 1e-12) {
    const double h = R * sinT, k = kt * h, th0 = theta - 0.5 * kPi;
    const double bracket = th0 > 0.0 ? table.tailIntegral(k, th0)
                                     : table.lookup(k, std::numeric_limits<double>::infinity()) -
                                           table.lookup(k, -cosT / sinT);
    single = kt * std::exp(-kt * R * cosT) / h * std::max(bracket, 0.0);
  }
  return single;
}

}  // namespace

double singleScatteredFlux(const kernels::IsoTable& table, double opticalDistance, int nodes) {
  // On every 4th node of the glow curve's angles (S₁ is smooth there but for its 1/θ peak,
  // which the first interval's rule takes: fluxOver), with K_t = 1 /m and R = T m.
  thread_local std::vector<double> th4, s4;
  th4.clear();
  s4.clear();
  const auto n = static_cast<std::size_t>(std::max(nodes, 16));
  for (std::size_t i = 0; i < n; i += 4) {
    th4.push_back(glowNodeAngle(i, n));
    s4.push_back(singleAt(table, 1.0, opticalDistance, th4.back()));
  }
  return opticalDistance * opticalDistance * fluxOver(th4, s4);
}

Result<GlowCurve> glowCurveFromTable(const MultipleScatteringTable& ms, const kernels::IsoTable& table, const Medium& fog,
                                     double distance_m, int nodes, bool withSingleFlux) {
  const double kt = fog.extinction_per_m, R = distance_m, T = kt * R;
  if (nodes < 16) return Error{"glow: at least 16 nodes"};
  if (!(kt > 0.0 && R > 0.0)) return Error{"glow: extinction and distance must be > 0"};
  GlowCurve c;
  const auto n = static_cast<std::size_t>(nodes);
  c.theta.resize(n);
  c.glow.resize(n);
  // Orders ≥ 2 of a 1 cd source (multiple_scattering.hpp): K_t² f(K_t R, θ, Ω), albedo included.
  // f at the table's own angle nodes (its interpolation in T and Ω, once), then log-linear in θ
  // between them for every curve node: the table's interpolation (log-multilinear), done in
  // ~25 look-ups instead of one per node (a moving lamp recomputes its curve every frame).
  const auto& angles = ms.angles();
  thread_local std::vector<double> logF;
  logF.resize(angles.size());
  bool positive = true;
  for (std::size_t j = 0; j < angles.size(); ++j) {
    const double f = ms.value(T, angles[j], fog.albedo);
    positive = positive && f > 0.0;
    logF[j] = f > 0.0 ? std::log(f) : 0.0;
  }
  const CurveNodes& nodesOf = curveNodes(angles, n);
  std::copy(nodesOf.theta.begin(), nodesOf.theta.end(), c.theta.begin());
  for (std::size_t i = 0; i < n; ++i) {
    if (!positive) {
      c.glow[i] = ms.radiance(1.0, kt, R, c.theta[i], fog.albedo);
      continue;
    }
    const std::size_t j = nodesOf.j[i];
    const double w = nodesOf.w[i];
    c.glow[i] = kt * kt * std::exp((1.0 - w) * logF[j] + w * logF[j + 1]);
  }
  // The report's shares: the flux of the single-scattering part through the sphere of radius R
  // (singleScatteredFlux), the multiple part's on every node.
  c.scale = 1.0;
  c.single_flux = withSingleFlux ? fog.albedo * singleScatteredFlux(table, T, nodes) : 0.0;
  c.multiple_flux = R * R * fluxOver(c.theta, c.glow);
  return c;
}

Result<ScatteredIrradiance> scatteredIrradiance(const MultipleScatteringTable& ms, const kernels::IsoTable& table,
                                                const Medium& fog, double distance_m, double cosIncidence, int nodes) {
  auto curve = glowCurveFromTable(ms, table, fog, distance_m, nodes, false);
  if (!curve) return curve.error();
  const double kt = fog.extinction_per_m, R = distance_m;
  const double ci = std::clamp(cosIncidence, -1.0, 1.0), si = std::sqrt(std::max(0.0, 1.0 - ci * ci));
  // The azimuthal integral about the source direction e of max(0, ω·n) at angle θ from e:
  // ω·n = a + b cos φ, a = cos θ cos i, b = sin θ sin i ≥ 0; ∫ max(0, a + b cos φ) dφ is 2π a⁺
  // where b ≤ |a|, else 2 (a φ₀ + b sin φ₀), cos φ₀ = −a/b.
  auto azimuthal = [&](double theta) {
    const double a = std::cos(theta) * ci, b = std::sin(theta) * si;
    if (b <= std::abs(a)) return 2.0 * kPi * std::max(a, 0.0);
    const double phi0 = std::acos(std::clamp(-a / b, -1.0, 1.0));
    return 2.0 * (a * phi0 + b * std::sin(phi0));
  };
  // E = ∫ L(θ) W(θ) sin θ dθ over the glow curve's nodes (dense near the source): integrateFromApex.
  const std::vector<double>& th = curve->theta;
  ScatteredIrradiance out;
  auto integrate = [&](auto&& L) {
    return integrateFromApex(th, [&](std::size_t i) { return L(i) * azimuthal(th[i]) * std::sin(th[i]); });
  };
  out.single = fog.albedo * integrate([&](std::size_t i) {
    const double v = singleAt(table, kt, R, th[i]);
    return std::isfinite(v) ? v : 0.0;
  });
  out.multiple = integrate([&](std::size_t i) { return curve->glow[i]; });
  return out;
}

Result<GlowCurve> glowCurve(const kernels::IsoTable& table, const Medium& fog, double distance_m, int nodes) {
  const double kt = fog.extinction_per_m, R = distance_m, T = kt * R;
  if (nodes < 16) return Error{"glow: at least 16 nodes"};
  const double q = std::clamp(meanCosine(fog.phase), 0.0, 0.99);
  auto apsf = Apsf::build(T, q);
  if (!apsf) return apsf.error();
  GlowCurve c;
  c.terms = apsf->terms();
  const auto n = static_cast<std::size_t>(nodes);
  c.theta.resize(n);
  c.single.resize(n);
  c.apsf.resize(n);
  c.glow.assign(n, 0.0);
  std::vector<double> excess(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    const double theta = glowNodeAngle(i, n);
    c.theta[i] = theta;
    const double single = singleAt(table, kt, R, theta);
    c.single[i] = single;
    c.apsf[i] = apsf->radiance(std::cos(theta), 1.0, kt);
    excess[i] = std::max(0.0, c.apsf[i] - single);
  }
  // Energy (header comment): R² Φ[S₁ + λ·excess] = 1 − e^{−T} for 1 cd; the multiple part then
  // × Ω², the single part × Ω (as the airlight layer has it).
  const double R2 = R * R;
  const double singleFlux1 = R2 * fluxOver(c.theta, c.single);
  const double excessFlux = R2 * fluxOver(c.theta, excess);
  const double multipleFlux1 = (1.0 - std::exp(-T)) - singleFlux1;
  const double omega = fog.albedo;
  c.single_flux = omega * singleFlux1;
  if (multipleFlux1 > 0.0 && excessFlux > 0.0) {
    c.scale = multipleFlux1 / excessFlux;
    for (std::size_t i = 0; i < n; ++i) c.glow[i] = omega * omega * c.scale * excess[i];
    c.multiple_flux = omega * omega * multipleFlux1;
  }
  return c;
}

double glowSourceIntensity(const Lamp& lamp, const Vec3& eye, double opticalDistance, double q) {
  const Vec3 d = eye - lamp.position_m;
  const double len = glm::length(d);
  if (!(len > 0.0)) return 0.0;
  // An isotropic lamp's mean over any cone is its intensity (a moving street lamp asks every frame).
  if (const auto* iso = std::get_if<IsotropicProfile>(&lamp.profile->model())) return iso->intensity_cd;
  const Mat3 lampFromWorld = glm::transpose(lamp.worldFromLamp);
  const Vec3 axis = lampFromWorld * (d / len);  // towards the eye, lamp frame
  const double cosPsi = std::max(std::pow(std::clamp(q, 0.0, 1.0), opticalDistance), 0.5);
  // Equal solid angles: 8 bands uniform in cos ψ' × 16 azimuths, one sample at each band's
  // middle (a lamp's profile is smooth on this scale; the cone is ≥ 6° wide for T ≥ 1.1, q ≤ 0.99).
  const Vec3 helper = std::abs(axis.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
  const Vec3 u = glm::normalize(glm::cross(axis, helper)), v = glm::cross(axis, u);
  constexpr int kBands = 8, kAzimuths = 16;
  // cos φ and sin φ of the azimuths, even bands then odd bands (offset by half a step).
  static const std::array<std::array<double, 2>, 2 * kAzimuths> kDirs = [] {
    std::array<std::array<double, 2>, 2 * kAzimuths> t{};
    for (int odd = 0; odd < 2; ++odd)
      for (int a = 0; a < kAzimuths; ++a) {
        const double phi = 2.0 * kPi * (static_cast<double>(a) + 0.5 * odd) / kAzimuths;
        t[static_cast<std::size_t>(odd * kAzimuths + a)] = {std::cos(phi), std::sin(phi)};
      }
    return t;
  }();
  double sum = 0.0;
  for (int b = 0; b < kBands; ++b) {
    const double c = 1.0 - (static_cast<double>(b) + 0.5) / kBands * (1.0 - cosPsi);
    const double sn = std::sqrt(std::max(0.0, 1.0 - c * c));
    for (int a = 0; a < kAzimuths; ++a) {
      const auto& cs = kDirs[static_cast<std::size_t>((b & 1) * kAzimuths + a)];
      sum += lamp.profile->intensity(c * axis + sn * (cs[0] * u + cs[1] * v));
    }
  }
  return sum / (kBands * kAzimuths);
}

void annulusMeans(const Profile& profile, const Vec3& axis, const double* edges, std::size_t bins, double* out,
                  bool frontOnly, int narrowBands, Vec3* harmonic, double* bandMeans, int azimuths) {
  const Vec3 helper = std::abs(axis.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
  const Vec3 u = glm::normalize(glm::cross(axis, helper)), v = glm::cross(axis, u);
  // Equal solid angles within each annulus: 4 bands uniform in cos η (`narrowBands` for annuli
  // narrower than 10°) × 24 azimuths (staggered), one sample at each cell's middle.
  const int kAzimuths = std::max(1, azimuths);
  constexpr double kNarrow = 10.0 * kPi / 180.0;
  for (std::size_t k = 0; k < bins; ++k) {
    const double c0 = std::cos(edges[k]), c1 = std::cos(edges[k + 1]);
    const int bands = edges[k + 1] - edges[k] < kNarrow ? narrowBands : 4;
    double sum = 0.0;
    Vec3 first{0.0};  // Σ I ê(φ), ê the unit direction of the azimuth φ about the axis
    for (int b = 0; b < bands; ++b) {
      const double c = c0 + (static_cast<double>(b) + 0.5) / bands * (c1 - c0);
      const double sn = std::sqrt(std::max(0.0, 1.0 - c * c));
      double band = 0.0;
      for (int a = 0; a < kAzimuths; ++a) {
        const double phi = 2.0 * kPi * (static_cast<double>(a) + 0.5 * (b & 1)) / kAzimuths;
        const Vec3 e = std::cos(phi) * u + std::sin(phi) * v;
        const Vec3 w = c * axis + sn * e;
        if (!frontOnly || w.x >= 0.0) {
          const double i = profile.intensity(w);
          band += i;
          first += i * e;
        }
      }
      sum += band;
      if (bandMeans != nullptr && b < kGlowBands) bandMeans[k * kGlowBands + static_cast<std::size_t>(b)] = band / kAzimuths;
    }
    out[k] = sum / (bands * kAzimuths);
    // I ≈ Ī + Ī₁ · ê on the annulus: Ī₁ = 2 ⟨I ê⟩ (⟨cos² φ⟩ = ½).
    if (harmonic != nullptr) harmonic[k] = first * (2.0 / (bands * kAzimuths));
  }
}

// A profile's light on cells of ~1.5° of the direction sphere (lamp frame), for the glow's wide
// emission bins. Sampling such an annulus (4 bands × 24 azimuths: 15° apart at η = 90°) aliases a
// narrow beam: a high beam seen from the side (σ 1.8° across the annulus) fell between the
// azimuths of two bands and on those of the other two, and the bins' means were off by 10–30 %
// (measured against 32 bands × 720 azimuths). Summing cells instead costs a dot product per cell
// and frame, not a profile look-up: each cell holds its mean intensity (4 × 4 look-ups, equal
// solid angles, once per profile) and its solid angle, and goes to the bin and band of its
// centre; a bin's mean is Σ I Ω / Σ Ω over its cells (exact for a uniform profile).
struct ProfileSphereCells {
  std::vector<float> x, y, z;   // unit centre, lamp frame
  std::vector<double> iOmega;   // mean I × Ω, cd·sr
  std::vector<double> omega;    // sr (double: a uniform profile's means come out exact)
  std::vector<std::uint32_t> lit;  // the cells with I > 0 (a headlamp's file leaves much of the sphere dark)
};

std::shared_ptr<const ProfileSphereCells> profileSphereCells(const Profile& profile) {
  auto cells = std::make_shared<ProfileSphereCells>();
  constexpr double kCell = 1.5 * kPi / 180.0;
  constexpr int kSub = 4;
  const int rings = static_cast<int>(std::lround(kPi / kCell));
  for (int r = 0; r < rings; ++r) {
    // Rings about the lamp's axis (+x), cells uniform in cos θ and φ within each.
    const double t0 = kPi * r / rings, t1 = kPi * (r + 1) / rings;
    const double c0 = std::cos(t0), c1 = std::cos(t1);
    const int az = std::max(1, static_cast<int>(std::lround(2.0 * kPi * std::sin(0.5 * (t0 + t1)) / kCell)));
    const double dPhi = 2.0 * kPi / az, cellOmega = (c0 - c1) * dPhi;
    for (int a = 0; a < az; ++a) {
      double sum = 0.0;
      for (int i = 0; i < kSub; ++i) {
        const double c = c0 + (i + 0.5) / kSub * (c1 - c0), sn = std::sqrt(std::max(0.0, 1.0 - c * c));
        for (int j = 0; j < kSub; ++j) {
          const double phi = (a + (j + 0.5) / kSub) * dPhi;
          sum += profile.intensity(Vec3(c, sn * std::cos(phi), sn * std::sin(phi)));
        }
      }
      const double c = 0.5 * (c0 + c1), sn = std::sqrt(std::max(0.0, 1.0 - c * c)), phi = (a + 0.5) * dPhi;
      cells->x.push_back(static_cast<float>(c));
      cells->y.push_back(static_cast<float>(sn * std::cos(phi)));
      cells->z.push_back(static_cast<float>(sn * std::sin(phi)));
      if (sum > 0.0) cells->lit.push_back(static_cast<std::uint32_t>(cells->x.size() - 1));
      cells->iOmega.push_back(sum / (kSub * kSub) * cellOmega);
      cells->omega.push_back(cellOmega);
    }
  }
  return cells;
}

std::shared_ptr<const ProfileSphereCells> sharedProfileSphereCells(const std::shared_ptr<const Profile>& profile) {
  // Kept while a lamp holds its profile (SharedCache's owner), the 16 last alive regardless.
  static SharedCache<const Profile*, ProfileSphereCells> cache(16);
  return cache.get(profile.get(), [&] { return profileSphereCells(*profile); }, profile);
}

namespace {

// Emission bins at least this wide are summed from the sphere cells (their bands ≥ 2.3° across,
// 1.5 cells); narrower ones, whose annuli are small around the axis or its opposite, are sampled
// (annulusMeans) with azimuths at most kArc apart along the annulus.
constexpr double kWideBin = 10.0 * kPi / 180.0 - 1e-9;
constexpr double kArc = 1.5 * kPi / 180.0;

}  // namespace

void glowAnnulusMeans(const Lamp& lamp, const Vec3& eye, const double* edges, std::size_t bins, double* out,
                      bool frontOnly, double* bandMeans) {
  const Vec3 d = eye - lamp.position_m;
  const double len = glm::length(d);
  if (!(len > 0.0)) {
    for (std::size_t k = 0; k < bins; ++k) out[k] = 0.0;
    if (bandMeans != nullptr) std::fill(bandMeans, bandMeans + bins * kGlowBands, 0.0);
    return;
  }
  const Mat3 lampFromWorld = glm::transpose(lamp.worldFromLamp);
  const Vec3 axis = lampFromWorld * (d / len);  // towards the eye
  bool anyWide = false;
  for (std::size_t k = 0; k < bins; ++k) anyWide = anyWide || edges[k + 1] - edges[k] >= kWideBin;
  cellAnnulusMeans(*lamp.profile, anyWide ? sharedProfileSphereCells(lamp.profile).get() : nullptr, axis, edges, bins, out, frontOnly,
                   bandMeans);
}

void cellAnnulusMeans(const Profile& profile, const ProfileSphereCells* cells, const Vec3& axis, const double* edges,
                      std::size_t bins, double* out, bool frontOnly, double* bandMeans, Vec3* harmonic) {
  for (std::size_t k = 0; k < bins; ++k) out[k] = 0.0;
  if (bandMeans != nullptr) std::fill(bandMeans, bandMeans + bins * kGlowBands, 0.0);
  if (harmonic != nullptr) std::fill(harmonic, harmonic + bins, Vec3(0.0));
  auto wide = [&](std::size_t k) { return edges[k + 1] - edges[k] >= kWideBin; };
  bool anyWide = false;
  for (std::size_t k = 0; k < bins; ++k) {
    if (wide(k)) {
      anyWide = true;
      continue;
    }
    // Around the axis (or its opposite) the annulus is short: azimuths kArc apart along its
    // outer edge (at least 24).
    const double outer = edges[k + 1] <= 0.5 * kPi ? std::sin(edges[k + 1]) : edges[k] >= 0.5 * kPi ? std::sin(edges[k]) : 1.0;
    const int az = std::max(24, static_cast<int>(std::ceil(2.0 * kPi * outer / kArc)));
    annulusMeans(profile, axis, edges + k, 1, out + k, frontOnly, kGlowBands,
                 harmonic != nullptr ? harmonic + k : nullptr, bandMeans != nullptr ? bandMeans + k * kGlowBands : nullptr,
                 az);
  }
  if (!anyWide || cells == nullptr) return;
  // Per bin its edges' cosines, descending; per wide bin and band Σ I Ω and Σ Ω.
  constexpr std::size_t kMaxBins = 64;
  if (bins > kMaxBins) return;
  double ce[kMaxBins + 1];
  for (std::size_t k = 0; k <= bins; ++k) ce[k] = std::cos(edges[k]);
  // Each of kSlices slices of cos η ∈ [−1, 1] goes to the (bin, band) of its middle, wide bins
  // only (kDrop: a narrow bin's, sampled above): a cell's cos η then picks its sums with one
  // look-up, no branch (the cells' order about the lamp's axis is not the annuli's; branches
  // mispredicted ~2 a cell, 10 ns). A slice is 1/2048 of cos η wide: 0.03° at η = 90°, 0.11° at
  // 15° and 165° (the wide bins' extremes), far below the cells' own 1.5°.
  constexpr int kSlices = 4096;
  constexpr std::size_t kDrop = kMaxBins * kGlowBands;
  // Per thread, for the last edges it was made for (the frame's table's: made once). With the
  // slice's 1 / sin η at its middle for the harmonic (wide bins lie within 15–170°, where that
  // is within 0.8 % of the cell's own).
  thread_local std::vector<double> sliceEdges;
  thread_local std::vector<std::uint16_t> sliceCode;
  thread_local std::vector<float> sliceInvSin;
  if (!std::equal(edges, edges + bins + 1, sliceEdges.begin(), sliceEdges.end())) {
    sliceEdges.assign(edges, edges + bins + 1);
    sliceCode.resize(kSlices);
    sliceInvSin.resize(kSlices);
    for (int q = 0; q < kSlices; ++q) {
      const double c = -1.0 + 2.0 * (q + 0.5) / kSlices;
      std::size_t k = 0;
      while (k + 1 < bins && c < ce[k + 1]) ++k;
      std::size_t code = kDrop;
      if (wide(k) && ce[k] > ce[k + 1]) {
        const double t = (ce[k] - c) / (ce[k] - ce[k + 1]) * kGlowBands;
        code = k * kGlowBands + std::min<std::size_t>(kGlowBands - 1, static_cast<std::size_t>(std::max(0.0, t)));
      }
      sliceCode[static_cast<std::size_t>(q)] = static_cast<std::uint16_t>(code);
      sliceInvSin[static_cast<std::size_t>(q)] = static_cast<float>(1.0 / std::sqrt(std::max(1e-12, 1.0 - c * c)));
    }
  }
  // Per (bin, band) slot Σ I Ω and Σ Ω. With the harmonic also Σ I Ω ê, ê the unit direction of
  // the cell's centre c about the axis: Σ (I Ω / sin η) c − axis · Σ (I Ω / sin η) cos η
  // (annulusMeans' Ī₁ = 2 ⟨I ê⟩).
  double iw[kDrop + 1] = {}, w[kDrop + 1] = {};
  const auto ax = static_cast<float>(axis.x), ay = static_cast<float>(axis.y), az = static_cast<float>(axis.z);
  const std::size_t n = cells->x.size();
  const float *cx = cells->x.data(), *cy = cells->y.data(), *cz = cells->z.data();
  const double *ci = cells->iOmega.data(), *co = cells->omega.data();
  const std::uint16_t* code = sliceCode.data();
  auto sliceOf = [&](float c) { return static_cast<std::size_t>(std::clamp(static_cast<int>((c + 1.0f) * (0.5f * kSlices)), 0, kSlices - 1)); };
  // Σ Ω over every cell, Σ I Ω (and the harmonic's sums) over the lit ones. Neighbouring cells
  // mostly fall in one slot: each run of them is summed in registers and added to its slot once
  // (adding every cell to memory chained each addition on the store before: ~6 ns a cell).
  {
    std::size_t cur = kDrop;
    double run = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const auto slot = static_cast<std::size_t>(code[sliceOf(ax * cx[i] + ay * cy[i] + az * cz[i])]);
      if (slot != cur) {
        w[cur] += run;
        run = 0.0;
        cur = slot;
      }
      run += co[i];
    }
    w[cur] += run;
  }
  const std::uint32_t* lit = cells->lit.data();
  const std::size_t nLit = cells->lit.size();
  if (harmonic == nullptr) {
    std::size_t cur = kDrop;
    double run = 0.0;
    for (std::size_t j = 0; j < nLit; ++j) {
      const std::size_t i = lit[j];
      const auto slot = static_cast<std::size_t>(code[sliceOf(ax * cx[i] + ay * cy[i] + az * cz[i])]);
      if (slot != cur) {
        iw[cur] += run;
        run = 0.0;
        cur = slot;
      }
      // frontOnly: the cells behind the lamp count as dark (their area stays in the annulus).
      run += frontOnly && cx[i] < 0.0f ? 0.0 : ci[i];
    }
    iw[cur] += run;
  } else {
    double hx[kDrop + 1] = {}, hy[kDrop + 1] = {}, hz[kDrop + 1] = {}, hc[kDrop + 1] = {};
    const float* invSin = sliceInvSin.data();
    std::size_t cur = kDrop;
    double r0 = 0.0, rx = 0.0, ry = 0.0, rz = 0.0, rc = 0.0;
    auto flush = [&] {
      iw[cur] += r0;
      hx[cur] += rx;
      hy[cur] += ry;
      hz[cur] += rz;
      hc[cur] += rc;
      r0 = rx = ry = rz = rc = 0.0;
    };
    for (std::size_t j = 0; j < nLit; ++j) {
      const std::size_t i = lit[j];
      const float c = ax * cx[i] + ay * cy[i] + az * cz[i];
      const std::size_t q = sliceOf(c);
      const auto slot = static_cast<std::size_t>(code[q]);
      if (slot != cur) {
        flush();
        cur = slot;
      }
      const double l = frontOnly && cx[i] < 0.0f ? 0.0 : ci[i];
      const double e = l * static_cast<double>(invSin[q]);
      r0 += l;
      rx += e * static_cast<double>(cx[i]);
      ry += e * static_cast<double>(cy[i]);
      rz += e * static_cast<double>(cz[i]);
      rc += e * static_cast<double>(c);
    }
    flush();
    for (std::size_t k = 0; k < bins; ++k) {
      if (!wide(k)) continue;
      Vec3 h{0.0};
      double hcs = 0.0, sw = 0.0;
      for (std::size_t b = 0; b < kGlowBands; ++b) {
        const std::size_t sl = k * kGlowBands + b;
        h += Vec3(hx[sl], hy[sl], hz[sl]);
        hcs += hc[sl];
        sw += w[sl];
      }
      harmonic[k] = sw > 0.0 ? (h - hcs * axis) * (2.0 / sw) : Vec3(0.0);
    }
  }
  for (std::size_t k = 0; k < bins; ++k) {
    if (!wide(k)) continue;
    double si = 0.0, sw = 0.0;
    for (std::size_t b = 0; b < kGlowBands; ++b) {
      si += iw[k * kGlowBands + b];
      sw += w[k * kGlowBands + b];
    }
    out[k] = sw > 0.0 ? si / sw : 0.0;
    if (bandMeans == nullptr) continue;
    for (std::size_t b = 0; b < kGlowBands; ++b) {
      // A band no cell centre fell in (a cell wider than it): the bin's mean.
      const double bw = w[k * kGlowBands + b];
      bandMeans[k * kGlowBands + b] = bw > 0.0 ? iw[k * kGlowBands + b] / bw : out[k];
    }
  }
}

void emissionBandWeights(const double* shares, const double* edges, std::size_t bins, double* weights) {
  std::fill(weights, weights + bins * kGlowBands, 1.0);
  if (bins < 2) return;
  // Per bin: the middle in cos η, its η, and the log of the share per unit cos η (−inf for 0).
  constexpr std::size_t kMaxBins = 64;
  if (bins > kMaxBins) return;
  double mid[kMaxBins], logDensity[kMaxBins];
  for (std::size_t k = 0; k < bins; ++k) {
    const double c0 = std::cos(edges[k]), c1 = std::cos(edges[k + 1]);
    mid[k] = std::acos(std::clamp(0.5 * (c0 + c1), -1.0, 1.0));
    const double d = c0 - c1 > 0.0 ? shares[k] / (c0 - c1) : 0.0;
    logDensity[k] = d > 0.0 ? std::log(d) : -std::numeric_limits<double>::infinity();
  }
  for (std::size_t k = 0; k < bins; ++k) {
    const double c0 = std::cos(edges[k]), c1 = std::cos(edges[k + 1]);
    double w[kGlowBands];
    bool ok = std::isfinite(logDensity[k]);
    for (int b = 0; b < kGlowBands && ok; ++b) {
      const double eta = std::acos(std::clamp(c0 + (b + 0.5) / kGlowBands * (c1 - c0), -1.0, 1.0));
      // The pair of bin middles around η (the nearest two at the ends).
      std::size_t lo = eta < mid[k] ? (k > 0 ? k - 1 : 0) : (k + 1 < bins ? k : bins - 2);
      const std::size_t hi = lo + 1;
      if (!std::isfinite(logDensity[lo]) || !std::isfinite(logDensity[hi]) || !(mid[hi] > mid[lo])) {
        ok = false;
        break;
      }
      const double t = (eta - mid[k]) / (mid[hi] - mid[lo]);
      w[b] = t * (logDensity[hi] - logDensity[lo]);  // log of the density relative to the bin's middle
    }
    if (!ok) continue;
    double mean = 0.0;
    for (double& x : w) {
      x = std::exp(x);
      mean += x / kGlowBands;
    }
    for (int b = 0; b < kGlowBands; ++b) weights[k * kGlowBands + static_cast<std::size_t>(b)] = w[b] / mean;
  }
}

struct LampEffects::Tables {
  std::shared_ptr<const kernels::IsoTable> iso;  // single scattering of the glow's isotropic source
  // The glow's multiple-scattering table for the frame's phase (GlowModel::Table; nullptr: the APSF).
  std::shared_ptr<const MultipleScatteringTable> ms;
  // The ground's factor on it for the frame's phase (GlowOptions::ground_reflectance ≥ 0; nullptr:
  // none, or no shipped factor for this phase: the glow of infinite fog).
  std::shared_ptr<const GroundCorrectionTable> ground;
  PhaseIdentity msPhase{};
  bool msLooked = false;
  std::vector<float> cieGlare;                   // CIE 146 L_v/E per node, (cd/m²)/lux
  struct Radial {
    float e[3] = {1, 0, 0};      // lamp direction, camera frame
    float color[3] = {1, 1, 1};  // glow: colour × table; glare: colour × E
    // The glow's occlusion weight clamp((d − from)/(to − from), 0, 1) at a pixel whose surface is
    // d away (LampEffects::evaluate: R/2 … R for a lamp in the scene, 0 … 2/K_t for the driver's own).
    float weightFrom = 0.0f, weightTo = 0.0f;
    const float* table = nullptr;
  };
  std::vector<Radial> glow, glare;
  std::vector<float> glowTables;  // kNodes per glowing lamp
  // Per scene lamp: its glow curve for the last (R, fog) it was computed for. The curve (an APSF
  // series and the F table at 512 angles, ~0.1 ms and a few allocations) depends on nothing else,
  // so a lamp that keeps its distance in a steady fog reuses it (steady frames allocate nothing).
  struct CurveCache {
    bool valid = false, ok = false;
    double R = 0.0, kt = 0.0, albedo = 0.0, groundH = 0.0;
    PhaseIdentity phase{};
    bool fromTable = false;
    double scale = 0.0, single_flux = 0.0, multiple_flux = 0.0;
    int terms = 0;
    std::vector<double> glow;  // kNodes
    // Measured lamps with the tables' emission bins: per table angle node j the shares of each
    // bin (j × bins + k), and per glow node i the table node below it and the weight of the one
    // above (log θ).
    std::vector<double> shares;
    std::vector<double> bandWeights;  // (j × bins + k) × kGlowBands + b: emissionBandWeights
    std::vector<int> node;
    std::vector<double> nodeWeight;
    bool measured = false;
    // The measured lamp's effective intensity per table angle (I_eff, below) and what it was
    // made for: the lamp-frame direction to the eye, the profile, frontOnly. A lamp fixed to the
    // eye (the driver's own) keeps that direction, so its ~0.13 ms a frame of annulus sums is
    // spent once; so is a parked car's. Cleared with the curve (its shares change).
    std::vector<double> effective;
    Vec3 effectiveAxis{0.0};
    std::shared_ptr<const Profile> effectiveProfile;  // held: no other profile takes its address
    bool effectiveOwn = false, effectiveValid = false;
  };
  // The report's single-scattered flux (singleScatteredFlux) of the tables' glow, tabulated in
  // log T for the IsoTable it was computed with: a moving lamp's curve would otherwise spend
  // ~128 single-scattering look-ups a frame (most of its cost) on a report figure.
  // Held (not a raw pointer): a new table allocated at a freed one's address must not match.
  std::shared_ptr<const kernels::IsoTable> fluxIso;
  std::vector<double> logFlux;  // log of the flux at T = 2^(kFluxLog2Min + i / kFluxPerOctave)
  static constexpr double kFluxLog2Min = -10.0, kFluxLog2Max = 6.0, kFluxPerOctave = 4.0;
  double singleFlux(double T) {
    const double x = (std::log2(T) - kFluxLog2Min) * kFluxPerOctave;
    if (!(x >= 0.0) || x > static_cast<double>(logFlux.size() - 1) || logFlux.empty())
      return singleScatteredFlux(*iso, T, kNodes);  // outside the table: computed (rare)
    const auto i = std::min(static_cast<std::size_t>(x), logFlux.size() - 2);
    const double w = x - static_cast<double>(i);
    return std::exp((1.0 - w) * logFlux[i] + w * logFlux[i + 1]);
  }
  void tabulateFlux() {
    if (fluxIso == iso) return;
    fluxIso = iso;
    const auto n = static_cast<std::size_t>((kFluxLog2Max - kFluxLog2Min) * kFluxPerOctave) + 1;
    logFlux.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      logFlux[i] = std::log(std::max(
          singleScatteredFlux(*iso, std::exp2(kFluxLog2Min + static_cast<double>(i) / kFluxPerOctave), kNodes), 1e-300));
  }
  // Scratch of the per-frame emission-bin means (steady frames allocate nothing).
  std::vector<double> annulus, bands;
  std::vector<CurveCache> curves;
  // The fast path's buffers of one layer (grown only: steady frames allocate nothing).
  struct Layer {
    std::vector<lamp_fx::KernelLamp> lamps;
    std::vector<float> grid, hmid, vmid, centre;  // per lamp gw × gh: nodes, edge midpoints, cell centres
    // Partial sums over lamps of colour × grid (lamp_fx::LayerRow::prefix): 3 planes per m.
    std::vector<float> prefix;
    bool prefixAll = false;
    std::vector<std::size_t> order;               // lamps' indices, nearest first (glow)
    std::vector<float> floor;                     // per lamp: the check's absolute floor (table units)
    std::vector<std::uint8_t> exact;              // tiles × lamps (lamp_fx::TileMode)
    std::vector<std::int32_t> fineFirst;          // per tile: its first lamp not kTileBilinear (nl: none)
    std::vector<std::array<std::size_t, 3>> modes;  // per tile row: its (tile, lamp) pairs by TileMode
    std::vector<float> imageX, imageY;            // per lamp: its image point, pixels (centre coordinates)
    std::vector<float> weightTo, weightFrom;      // per lamp (LayerRow::weight_to, weight_from), kCell past the last
    bool fromSorted = false;
    int gw = 0, gh = 0;
  };
  Layer glowLayer, glareLayer;
  // The veil of the road lit by the driver's own lamps (ground_veil.hpp): per node of a coarse
  // grid over the image (every kVeilNodeDeg, denser rows about the horizon), its light along the
  // node's ray (addVeil blends it per pixel). Kept while what it depends on holds (`key`: the own
  // lamps, camera and ground relative to the eye, turned by the camera's yaw, within
  // kVeilKeyTolerance; K_t within ±kVeilKtTolerance): a drive on the flat road reads it, a fog or
  // lamp change makes it anew.
  struct Veil {
    std::vector<double> key;
    std::size_t keyExact = 0;  // the key's entries compared exactly (veilKey)
    double kt = 0.0;           // K_t it was made for (made anew beyond ±kVeilKtTolerance)
    std::vector<float> value;  // per node (row-major, nx per row): the veil's channel mean along its ray
    std::vector<float> rows;   // the node rows' pixel y (ascending, 0 … height): 3° apart, 0.5° about the horizon
    std::vector<float> lines;  // per pixel row (height × nx): the nodes blended at its centre's y
    float color[3] = {1, 1, 1};  // the channels ÷ their mean (the own lamps' colours, one mix)
    int nx = 0, ny = 0;
    bool valid = false;
  } veil;
  std::vector<ground_veil::Lamp> veilLamps;
  std::vector<double> veilKey;  // this frame's key (veilKey), compared with veil.key
};

namespace {

// The fast path's accuracy control (docs/airlight.md, "Cost of glow and glare"). A tile (the
// kCell × kCell pixels between four grid nodes) interpolates lamp i bilinearly unless
//  * the lamp's image point lies within kNearCells cells of it (the glare's 1/θ³ and the
//    tables' steep first nodes: no smoothness to rely on), or
//  * the interpolation misses the lamp's table, evaluated exactly at the tile's centre and its
//    four edge midpoints, by more than kCheckTolerance × max(the smallest of those values and
//    the four corners', floor_i). For a smooth function the bilinear error is largest at the
//    centre, (h²/8)(F_xx + F_yy), and at the edge midpoints it is each direction's part
//    (h²/8) F_xx, so the check measures the error itself, not a bound; near a kink of the glow
//    curve (where it leaves 0, 7–8° from a lamp) it sees the interpolant's spill-over.
// A tile that fails the check (not for nearness) is tried on its four half-cells: the grid's
// edge midpoints and centre are their corners, and the same check at their own centres and
// edge midpoints (16 more values of the table) decides. Passed, the lamp is interpolated
// bilinearly on the half-cells (lamp_fx::kTileHalf), else evaluated per pixel (kTileExact).
// The error falls as h², so tiles a few cells from a lamp's image, where the glow and glare
// curves bend too much for 16 px, mostly pass at 8 px: on the bench's dozen lamps at 1280 × 720
// 1 712 (tile, lamp) pairs take their half-cells and 518 go per pixel, where all 2 230 went
// per pixel before (docs/airlight.md, "Cost of glow and glare").
// Every lamp's share is ≥ 0 and so is every weight, so a relative error ≤ τ per lamp is ≤ τ of
// the sum at every pixel. floor_i: the glare has none (its table is > 0 at every angle: the
// check is relative everywhere); the glow's is kGlowFloor × the lamp's peak (its curve is 0
// near the lamp, where only an absolute error makes sense).
constexpr float kCheckTolerance = 2.5e-3f;
constexpr float kGlowFloor = 1e-4f;

// The road veil's grid (Tables::Veil): a node every kVeilNodeDeg at the image centre (and on
// the last row and column), kVeilSteps steps along each node's ray, kVeilAngles × kVeilAzimuths
// directions to the road per step (ground_veil.hpp). The veil is a broad light (the road lit
// 5–60 m ahead, seen through 10–40 m of fog), so coarse nodes follow it: on the validate case
// (docs/airlight.md "The ground") this grid gives 0.96–0.98 of the veil of nodes 8 px apart with
// 60 steps and 28 × 24 directions in the rings 0.5–16°; against each pixel's own ray, finely,
// within 13 % at 1280×720 (LampEffectsLayers.TheRoadLitByTheOwnLampsVeilsTheView).
constexpr double kVeilNodeDeg = 3.0;
constexpr double kVeilHorizonDeg = 0.5;
constexpr int kVeilSteps = 12;
constexpr int kVeilAngles = 12;
constexpr int kVeilAzimuths = 12;
// Made anew when K_t moves by more than this fraction from the K_t it was made for (a fog that
// thickens every frame would otherwise make it every frame: 26–32 ms at 1280×720 on 2 cores),
// or when the key moves by more than kVeilKeyTolerance (m for positions, matrix entries for
// rotations: ~0.5°; a lamp that bends by less keeps its veil).
constexpr double kVeilKtTolerance = 0.05;
constexpr double kVeilKeyTolerance = 0.01;

// What the road veil depends on besides K_t, turned about the vertical by the camera's yaw and
// taken relative to the eye (a car that drives or turns on the flat road sees the same veil).
// The first `exact` entries must match exactly (sizes, fog, phase, ρ, profiles, colours); the
// rest (the camera's and lamps' rotations, positions, the eye's height) within kVeilKeyTolerance.
void veilKey(const Scene& scene, const std::vector<ground_veil::Lamp>& lamps, const GlowOptions& glow,
             std::vector<double>& k, std::size_t& exact) {
  const Camera& cam = scene.camera;
  const Vec3 fwd = cam.worldFromCamera[0];
  const double yaw = std::atan2(fwd.y, fwd.x);
  const Mat3 unyaw = glm::transpose(worldFromYawPitchRoll(yaw, 0.0, 0.0));
  k.clear();  // its capacity kept: steady frames allocate nothing
  const Vec2 pp = cam.principalPoint();
  for (double v : {cam.focalLengthPixels(), pp.x, pp.y, static_cast<double>(cam.width), static_cast<double>(cam.height),
                   glow.ground_reflectance, scene.fog.albedo, static_cast<double>(lamps.size()),
                   glow.surfaces ? 1.0 : 0.0})
    k.push_back(v);
  const auto [kind, a, b, cc] = phaseIdentity(scene.fog.phase);
  for (double v : {static_cast<double>(kind), a, b, cc}) k.push_back(v);
  for (const ground_veil::Lamp& l : lamps)
    for (double v : {l.color[0], l.color[1], l.color[2], static_cast<double>(reinterpret_cast<std::uintptr_t>(l.profile.get()))})
      k.push_back(v);
  exact = k.size();
  auto mat = [&k](const Mat3& m) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) k.push_back(m[i][j]);
  };
  mat(unyaw * cam.worldFromCamera);
  k.push_back(cam.position_m.z - glow.ground_height_m);
  for (const ground_veil::Lamp& l : lamps) {
    const Vec3 rel = unyaw * (l.position_m - cam.position_m);
    for (double v : {rel.x, rel.y, rel.z}) k.push_back(v);
    mat(unyaw * glm::transpose(l.lampFromWorld));
  }
}

bool veilKeyHolds(const std::vector<double>& a, const std::vector<double>& b, std::size_t exact) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double tol = i < exact ? 1e-12 * (1.0 + std::abs(a[i])) : kVeilKeyTolerance;
    if (!(std::abs(a[i] - b[i]) <= tol)) return false;
  }
  return true;
}

// The veil's nodes for the frame (Tables::Veil), on the pool.
void buildVeil(LampEffects::Tables::Veil& v, const Scene& scene, const std::vector<ground_veil::Lamp>& lamps,
               const GlowOptions& glow, ThreadPool& pool) {
  const Camera& cam = scene.camera;
  const ground_veil::Ground ground{glow.ground_height_m, glow.ground_reflectance};
  // The road's light holds the fog's scattered light on it where the surface layer shows that
  // (`[glow] surfaces`, fog_light.hpp: the same table and the lamps' annulus means, front only as
  // the own lamps' glow): the veil scatters the road as the image shows it. Measured against the
  // path tracer (the own low beam over a road of ρ = 0.1, docs/airlight.md): 8–16° about the lamp
  // 0.86 of it with the direct light alone, 0.92 with the fog light too.
  std::shared_ptr<const FogLightTable> fogLight;
  std::vector<ground_veil::Lamp> lit = lamps;
  if (glow.surfaces && scene.fog.albedo > 0.0) {
    if (auto table = FogLightTable::shipped(scene.fog.phase, scene.fog.albedo, &pool)) {
      fogLight = std::move(table).value();
      for (ground_veil::Lamp& l : lit)
        if (l.profile && !std::holds_alternative<IsotropicProfile>(l.profile->model()))
          // Made at the service's start (FogLightPrewarm) or by the surface layer: shared.
          l.annuli = AnnulusMeanMap::shared(l.profile, fogLight->edges(), true, &pool);
    }
  }
  const ground_veil::RoadMap road =
      ground_veil::roadMap(lit, scene.fog, ground, cam.position_m, 96, 180, &pool, fogLight.get());
  const double step = std::max(4.0, cam.focalLengthPixels() * std::tan(radians(kVeilNodeDeg)));
  v.nx = std::max(2, static_cast<int>(std::ceil(cam.width / step)) + 1);
  // Rows: kVeilNodeDeg apart, and kVeilHorizonDeg apart from 2° above the horizon to 6° below it,
  // where rays stop reaching far along the lit road and the veil bends (linear between rows
  // 3° apart it was 25 % high 2–3° below the horizon).
  const int coarseRows = std::max(2, static_cast<int>(std::ceil(cam.height / step)) + 1);
  v.rows.clear();
  for (int r = 0; r < coarseRows; ++r) v.rows.push_back(static_cast<float>(r * static_cast<double>(cam.height) / (coarseRows - 1)));
  const Vec3 fwd = cam.worldFromCamera[0], up = cam.worldFromCamera[2];
  if (std::abs(up.z) > 1e-6) {
    const double f = cam.focalLengthPixels(), cy = cam.principalPoint().y;
    const double horizon = cy + fwd.z * f / up.z;  // w.z = 0 on the image's vertical through the centre (no roll)
    const double fine = std::max(1.0, f * std::tan(radians(kVeilHorizonDeg)));
    for (double y = horizon - 2.0 * f * std::tan(radians(2.0)); y <= horizon + f * std::tan(radians(6.0)); y += fine)
      if (y > 0.0 && y < cam.height) v.rows.push_back(static_cast<float>(y));
  }
  std::sort(v.rows.begin(), v.rows.end());
  v.rows.erase(std::unique(v.rows.begin(), v.rows.end(), [](float a, float b) { return b - a < 0.5f; }), v.rows.end());
  v.rows.back() = static_cast<float>(cam.height);
  v.ny = static_cast<int>(v.rows.size());
  const std::size_t nodes = static_cast<std::size_t>(v.nx) * static_cast<std::size_t>(v.ny);
  std::vector<double> rgb(3 * nodes, 0.0);
  const double kt = scene.fog.extinction_per_m;
  pool.parallelFor(nodes, [&](std::size_t n) {
    const int ix = static_cast<int>(n % static_cast<std::size_t>(v.nx));
    const int iy = static_cast<int>(n / static_cast<std::size_t>(v.nx));
    const Vec3 w = cam.rayDirection(ix * static_cast<double>(cam.width) / (v.nx - 1),
                                    static_cast<double>(v.rows[static_cast<std::size_t>(iy)]));
    ground_veil::alongRay(road, scene.fog, ground, cam.position_m, w, kVeilSteps, &rgb[3 * n], kVeilAngles,
                          kVeilAzimuths);
  });
  double total[3] = {0.0, 0.0, 0.0};
  for (std::size_t n = 0; n < nodes; ++n)
    for (int k = 0; k < 3; ++k) total[k] += rgb[3 * n + static_cast<std::size_t>(k)];
  const double mean = (total[0] + total[1] + total[2]) / 3.0;
  for (int k = 0; k < 3; ++k) v.color[k] = mean > 0.0 ? static_cast<float>(total[k] / mean) : 1.0f;
  v.value.resize(nodes);
  for (std::size_t n = 0; n < nodes; ++n)
    v.value[n] = static_cast<float>((rgb[3 * n] + rgb[3 * n + 1] + rgb[3 * n + 2]) / 3.0);
  // Per pixel row, the node rows blended at its y (addVeil then blends along x only).
  const auto nxs = static_cast<std::size_t>(v.nx);
  v.lines.resize(static_cast<std::size_t>(cam.height) * nxs);
  for (int j = 0; j < cam.height; ++j) {
    const float y = static_cast<float>(j) + 0.5f;
    const float* rows = v.rows.data();
    const int iy = std::clamp(static_cast<int>(std::upper_bound(rows, rows + v.ny, y) - rows) - 1, 0, v.ny - 2);
    const float ty = std::clamp((y - rows[iy]) / (rows[iy + 1] - rows[iy]), 0.0f, 1.0f);
    const float* r0 = v.value.data() + static_cast<std::size_t>(iy) * nxs;
    const float* r1 = r0 + nxs;
    float* line = v.lines.data() + static_cast<std::size_t>(j) * nxs;
    for (std::size_t i = 0; i < nxs; ++i) line[i] = r0[i] + ty * (r1[i] - r0[i]);
  }
  v.kt = kt;
}

// Adds the veil to the glow layer (3 floats per pixel): per pixel the blend of its nodes (rows
// through Veil::rows, columns evenly spaced) times min(1, ramp(d) / ramp(U)), d the pixel's
// surface distance and U where its own ray meets the road (+inf above the horizon), the ramp
// clamp(K_t x / 2, 0, 1): 1 where the pixel sees the road or the sky, less where a surface
// stands in front of the road (a car, a wall). Rows on the pool, each from its line of the
// nodes blended at its y (Veil::lines), branch-free. Both paths (Fast, Exact) add it alike.
void addVeil(const LampEffects::Tables::Veil& v, const Camera& cam, const float* distance, double kt,
             double eyeHeight, float* out, ThreadPool& pool) {
  // The job by pointer: a lambda capturing more than std::function keeps inline would allocate
  // (steady frames allocate nothing).
  struct Job {
    const LampEffects::Tables::Veil* v;
    const float* distance;
    float* out;
    int w;
    float cx, cy, ff0, zf, zl, zu, hk, hkH;
  };
  const double f = cam.focalLengthPixels();
  const Vec2 c = cam.principalPoint();
  const Job job{&v,
                distance,
                out,
                cam.width,
                static_cast<float>(c.x),
                static_cast<float>(c.y),
                static_cast<float>(f) * static_cast<float>(f),  // as FillRow
                static_cast<float>(cam.worldFromCamera[0].z * f),
                static_cast<float>(cam.worldFromCamera[1].z),
                static_cast<float>(cam.worldFromCamera[2].z),
                static_cast<float>(0.5 * kt),
                static_cast<float>(0.5 * kt * eyeHeight)};
  const Job* jp = &job;
  pool.parallelFor(static_cast<std::size_t>(cam.height), [jp](std::size_t j) {
    const Job& J = *jp;
    const LampEffects::Tables::Veil& V = *J.v;
    const float y = static_cast<float>(j) + 0.5f;
    const float* line = V.lines.data() + j * static_cast<std::size_t>(V.nx);
    // w.z of the pixel's ray: (z_f f + z_l (c_x − x) + z_u (c_y − y)) / |(f, c_x − x, c_y − y)|.
    const float b = J.cy - y;
    const float n0 = J.zf + J.zu * b, ff = J.ff0 + b * b;
    const float sx = static_cast<float>(V.nx - 1) / static_cast<float>(J.w);
    const float* dist = J.distance + static_cast<std::size_t>(J.w) * j;
    float* row = J.out + 3 * static_cast<std::size_t>(J.w) * j;
    for (int i = 0; i < J.w; ++i) {
      const float x = static_cast<float>(i) + 0.5f;
      const float fx = x * sx;
      const int ix = std::min(static_cast<int>(fx), V.nx - 2);
      const float tx = fx - static_cast<float>(ix);
      const auto k = static_cast<std::size_t>(ix);
      const float val = line[k] + tx * (line[k + 1] - line[k]);
      const float a = J.cx - x;
      const float num = n0 + J.zl * a;  // w.z × |ray|: < 0 below the horizon
      const float rampU = std::min(1.0f, J.hkH * std::sqrt(ff + a * a) / std::max(-num, 1e-12f));
      const float rampD = std::min(1.0f, J.hk * dist[i]);  // +inf (sky): 1
      const float weight = std::min(1.0f, rampD / std::max(rampU, 1e-3f)) * val;
      row[3 * i] += weight * V.color[0];
      row[3 * i + 1] += weight * V.color[1];
      row[3 * i + 2] += weight * V.color[2];
    }
  });
}

constexpr float kNearCells = 2.0f;

struct FastJob {
  LampEffects::Tables::Layer* layer;
  const float* distance;  // nullptr: weights 1 (glare)
  float* out;
  int width, height;
  float f, cx, cy;
  // The road veil (glow; veil = nullptr: none) and addVeil's constants, per pixel in FillRow.
  const LampEffects::Tables::Veil* veil = nullptr;
  float veilZf = 0.0f, veilZl = 0.0f, veilZu = 0.0f, veilHk = 0.0f, veilHkh = 0.0f;
};

// Pass 1, grid row r: each lamp's table at the nodes, edge midpoints and cell centres of row
// r, and the nodes' colour-weighted partial sums over the lamps (LayerRow::prefix).
void gridRow(const FastJob& J, std::size_t r) {
  using lamp_fx::kCell;
  auto& L = *J.layer;
  const std::size_t gw = static_cast<std::size_t>(L.gw), plane = gw * static_cast<std::size_t>(L.gh);
  const float y0 = static_cast<float>(kCell * r) + 0.5f, y1 = y0 + 0.5f * kCell;
  const int count = L.gw;
  const std::size_t nl = L.lamps.size();
  const int n = static_cast<int>(nl);
  const std::size_t o = r * gw;
  lamp_fx::radialRow(L.lamps.data(), n, plane, J.f, J.cx, J.cy, 0.5f, kCell, y0, count, L.grid.data() + o);
  lamp_fx::radialRow(L.lamps.data(), n, plane, J.f, J.cx, J.cy, 0.5f + 0.5f * kCell, kCell, y0, count, L.hmid.data() + o);
  lamp_fx::radialRow(L.lamps.data(), n, plane, J.f, J.cx, J.cy, 0.5f, kCell, y1, count, L.vmid.data() + o);
  lamp_fx::radialRow(L.lamps.data(), n, plane, J.f, J.cx, J.cy, 0.5f + 0.5f * kCell, kCell, y1, count,
                     L.centre.data() + o);
  for (int ch = 0; ch < 3; ++ch) {
    // Running sums: slot m − 1 holds lamps 0 … m − 1 when all are kept, else one slot
    // accumulates in place.
    const float* prev = nullptr;
    for (std::size_t l = 0; l < nl; ++l) {
      const float col = L.lamps[l].color[ch];
      const float* g = L.grid.data() + l * plane + r * gw;
      float* dst = L.prefix.data() + ((L.prefixAll ? l : 0) * 3 + static_cast<std::size_t>(ch)) * plane + r * gw;
      if (prev == nullptr) {
        for (std::size_t c = 0; c < gw; ++c) dst[c] = 0.0f + col * g[c];
      } else {
        for (std::size_t c = 0; c < gw; ++c) dst[c] = prev[c] + col * g[c];
      }
      prev = dst;
    }
  }
}

// The check of one cell, shared by the tiles (tileRow) and their half-cells (halfCellsPass):
// the lamp's table at the cell's corners c00, c10, c01, c11, its centre and its edge midpoints;
// true when the bilinear prediction misses the centre or a midpoint by more than the tolerance
// relative to the smallest of the nine samples or the lamp's floor. Plain comparisons, no
// initializer lists: tileRow's loop over a row of tiles stays vectorised.
inline bool cellFails(float c00, float c10, float c01, float c11, float ctr, float top, float bottom, float left,
                      float right, float floorL) {
  auto maxf = [](float x, float y) { return x > y ? x : y; };
  auto minf = [](float x, float y) { return x < y ? x : y; };
  float err = std::abs(ctr - 0.25f * (c00 + c10 + c01 + c11));
  err = maxf(err, std::abs(top - 0.5f * (c00 + c10)));
  err = maxf(err, std::abs(bottom - 0.5f * (c01 + c11)));
  err = maxf(err, std::abs(left - 0.5f * (c00 + c01)));
  err = maxf(err, std::abs(right - 0.5f * (c10 + c11)));
  const float lo = minf(minf(minf(c00, c10), minf(c01, c11)), minf(minf(minf(top, bottom), minf(left, right)), ctr));
  return err > kCheckTolerance * maxf(lo, floorL);
}

// Whether lamp l's table is interpolated within the tolerance on each of the four half-cells
// of the tile whose top-left node is at (x0, y0) (pixel-centre coordinates), N its 3 × 3 nodes:
// the check of tileRow (centre and edge midpoints against the bilinear prediction, relative to
// the smallest of the half-cell's nine samples or the lamp's floor) at half the spacing.
bool halfCellsPass(const FastJob& J, std::size_t l, float x0, float y0, const float (&N)[3][3]) {
  using lamp_fx::kCell;
  constexpr float q = 0.25f * kCell;  // a quarter of the tile
  // Points: the half-cells' centres C[b][a], the midpoints H[b][a] of their horizontal edges
  // (rows b = 0, 1, 2 at x = q, 3q) and V[b][a] of their vertical edges (columns a = 0, 1, 2 at
  // y = q, 3q).
  float xs[16], ys[16], v[16];
  int k = 0;
  for (int b = 0; b < 2; ++b)
    for (int a = 0; a < 2; ++a, ++k) xs[k] = x0 + q * static_cast<float>(2 * a + 1), ys[k] = y0 + q * static_cast<float>(2 * b + 1);
  for (int b = 0; b < 3; ++b)
    for (int a = 0; a < 2; ++a, ++k) xs[k] = x0 + q * static_cast<float>(2 * a + 1), ys[k] = y0 + 2.0f * q * static_cast<float>(b);
  for (int b = 0; b < 2; ++b)
    for (int a = 0; a < 3; ++a, ++k) xs[k] = x0 + 2.0f * q * static_cast<float>(a), ys[k] = y0 + q * static_cast<float>(2 * b + 1);
  const auto& L = *J.layer;
  lamp_fx::radialPoints(L.lamps[l], J.f, J.cx, J.cy, xs, ys, 16, v);
  const float* C = v;       // C[b * 2 + a]
  const float* H = v + 4;   // H[b * 2 + a], b = 0 … 2
  const float* V = v + 10;  // V[b * 3 + a], a = 0 … 2
  for (int b = 0; b < 2; ++b)
    for (int a = 0; a < 2; ++a) {
      if (cellFails(N[b][a], N[b][a + 1], N[b + 1][a], N[b + 1][a + 1], C[b * 2 + a], H[b * 2 + a], H[(b + 1) * 2 + a],
                    V[b * 3 + a], V[b * 3 + a + 1], L.floor[l]))
        return false;
    }
  return true;
}

// Pass 2, tile row r: the tiles' flags (above), then the pixel rows kCell·r … kCell·(r + 1) − 1.
void tileRow(const FastJob& J, std::size_t r) {
  using lamp_fx::kCell;
  auto& L = *J.layer;
  const std::size_t gw = static_cast<std::size_t>(L.gw), plane = gw * static_cast<std::size_t>(L.gh);
  const std::size_t nl = L.lamps.size(), tilesW = gw - 1;
  const float margin = kNearCells * kCell;
  const float yLo = static_cast<float>(kCell * r) + 0.5f, yHi = yLo + kCell - 1.0f;
  // Lamp by lamp over the row's tiles, kChunk at a time: the check's arithmetic on contiguous
  // nodes (vectorised by the compiler: a scalar pass tile by tile cost ~13 % of a frame of a dozen
  // lamps), its verdicts in a stack buffer (steady frames allocate nothing, on any thread).
  constexpr std::size_t kChunk = 64;
  std::uint8_t bad[kChunk];
  for (std::size_t l = 0; l < nl; ++l) {
    const std::size_t o = l * plane + r * gw;
    const float* g0 = L.grid.data() + o;
    const float* g1 = g0 + gw;
    const float* h0 = L.hmid.data() + o;
    const float* h1 = h0 + gw;
    const float* v0 = L.vmid.data() + o;
    const float* ce = L.centre.data() + o;
    const float floorL = L.floor[l];
    const float ix = L.imageX[l], iy = L.imageY[l];
    const bool nearRow = iy >= yLo - margin && iy <= yHi + margin;
    for (std::size_t c0 = 0; c0 < tilesW; c0 += kChunk) {
      const std::size_t n = std::min(kChunk, tilesW - c0);
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t c = c0 + i;
        // The tile's corners, edge midpoints and centre (the 3 × 3 nodes of its half-cells).
        bad[i] = cellFails(g0[c], g0[c + 1], g1[c], g1[c + 1], ce[c], h0[c], h1[c], v0[c], v0[c + 1], floorL) ? 1 : 0;
      }
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t c = c0 + i;
        std::uint8_t& flag = L.exact[(r * tilesW + c) * nl + l];
        const float xLo = static_cast<float>(kCell * c) + 0.5f, xHi = xLo + kCell - 1.0f;
        if (nearRow && ix >= xLo - margin && ix <= xHi + margin) {
          flag = lamp_fx::kTileExact;
        } else if (!bad[i]) {
          flag = lamp_fx::kTileBilinear;
        } else {
          // The same check on the four half-cells (the bilinear error falls as the square of the
          // spacing, so most tiles a few cells from a lamp's image pass it): the table at their
          // centres and edge midpoints, 16 points, against each half-cell's corners among the
          // tile's 3 × 3 nodes N[b][a] (a along x, b along y, kCell / 2 apart).
          const float N[3][3] = {{g0[c], h0[c], g0[c + 1]}, {v0[c], ce[c], v0[c + 1]}, {g1[c], h1[c], g1[c + 1]}};
          flag = halfCellsPass(J, l, xLo, yLo, N) ? lamp_fx::kTileHalf : lamp_fx::kTileExact;
        }
      }
    }
  }
  std::array<std::size_t, 3>& modes = L.modes[r];
  modes = {0, 0, 0};
  for (std::size_t c = 0; c < tilesW; ++c) {
    const std::uint8_t* flags = L.exact.data() + (r * tilesW + c) * nl;
    std::size_t first = 0;
    while (first < nl && flags[first] == lamp_fx::kTileBilinear) ++first;
    L.fineFirst[r * tilesW + c] = static_cast<std::int32_t>(first);
    modes[lamp_fx::kTileBilinear] += first;
    for (std::size_t l = first; l < nl; ++l) ++modes[flags[l]];
  }
  lamp_fx::LayerRow row;
  row.lamps = L.lamps.data();
  row.fine_first = L.fineFirst.data();
  row.nLamps = static_cast<int>(nl);
  row.prefix = L.prefix.data();
  row.prefix_all = L.prefixAll;
  row.weight_to = L.weightTo.data();
  row.weight_from = L.weightFrom.data();
  row.from_sorted = L.fromSorted;
  row.exact = L.exact.data();
  row.gw = L.gw;
  row.gh = L.gh;
  row.width = J.width;
  row.f = J.f;
  row.cx = J.cx;
  row.cy = J.cy;
  const int j1 = std::min(static_cast<int>(kCell * (r + 1)), J.height);
  for (int j = static_cast<int>(kCell * r); j < j1; ++j) {
    const std::size_t off = static_cast<std::size_t>(j) * static_cast<std::size_t>(J.width);
    row.j = j;
    row.distance = J.distance ? J.distance + off : nullptr;
    row.out = J.out + 3 * off;
    if (J.veil != nullptr) {
      row.veil_line = J.veil->lines.data() + static_cast<std::size_t>(j) * static_cast<std::size_t>(J.veil->nx);
      row.veil_nx = J.veil->nx;
      for (int k = 0; k < 3; ++k) row.veil_color[k] = J.veil->color[k];
      row.veil_zf = J.veilZf;
      row.veil_zl = J.veilZl;
      row.veil_zu = J.veilZu;
      row.veil_hk = J.veilHk;
      row.veil_hkh = J.veilHkh;
    }
    lamp_fx::fillRow(row);
  }
}

// The fast path for one layer (header comment): grid, flags and rows on the pool.
void fastFill(ThreadPool& pool, LampEffects::Tables::Layer& L, const std::vector<LampEffects::Tables::Radial>& lamps,
              const Camera& cam, double f, const Vec2& c, const float* distance, float floorFraction,
              std::vector<float>& out, LampEffectsReport::Tiles& tiles, const LampEffects::Tables::Veil* veil = nullptr,
              double kt = 0.0, double eyeHeight = 0.0) {
  using lamp_fx::kCell;
  const std::size_t n = static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height);
  out.resize(3 * n);  // every pixel is written below
  if (lamps.empty() || n == 0) {
    std::fill(out.begin(), out.end(), 0.0f);
    if (veil != nullptr && n > 0) addVeil(*veil, cam, distance, kt, eyeHeight, out.data(), pool);
    return;
  }
  L.gw = (cam.width - 1) / kCell + 2;
  L.gh = (cam.height - 1) / kCell + 2;
  const std::size_t nl = lamps.size(), plane = static_cast<std::size_t>(L.gw) * static_cast<std::size_t>(L.gh);
  L.lamps.resize(nl);
  L.grid.resize(nl * plane);
  L.hmid.resize(nl * plane);
  L.vmid.resize(nl * plane);
  L.centre.resize(nl * plane);
  // Glow: the lamps nearest first, and every partial sum kept (a segment of pixels whose
  // surfaces are at least as far as its m nearest lamps takes their sum from one grid).
  L.prefixAll = distance != nullptr;
  L.prefix.resize((L.prefixAll ? nl : 1) * 3 * plane);
  L.order.resize(nl);
  for (std::size_t l = 0; l < nl; ++l) L.order[l] = l;
  if (L.prefixAll)  // std::sort: no buffer (steady frames allocate nothing); ties by index
    std::sort(L.order.begin(), L.order.end(), [&lamps](std::size_t a, std::size_t b) {
      return lamps[a].weightTo < lamps[b].weightTo || (lamps[a].weightTo == lamps[b].weightTo && a < b);
    });
  L.floor.resize(nl);
  L.imageX.resize(nl);
  L.imageY.resize(nl);
  L.exact.resize(static_cast<std::size_t>(L.gw - 1) * static_cast<std::size_t>(L.gh - 1) * nl);
  L.fineFirst.resize(static_cast<std::size_t>(L.gw - 1) * static_cast<std::size_t>(L.gh - 1));
  L.modes.resize(static_cast<std::size_t>(L.gh - 1));
  for (std::size_t l = 0; l < nl; ++l) {
    const LampEffects::Tables::Radial& rad = lamps[L.order[l]];
    lamp_fx::KernelLamp& k = L.lamps[l];
    for (int a = 0; a < 3; ++a) {
      k.e[a] = rad.e[a];
      k.color[a] = rad.color[a];
    }
    k.weight_from = rad.weightFrom;
    k.weight_to = rad.weightTo;
    k.weight_scale = rad.weightTo > rad.weightFrom ? 1.0f / (rad.weightTo - rad.weightFrom) : 0.0f;
    k.table = rad.table;
    k.grid = L.grid.data() + l * plane;
    k.hmid = L.hmid.data() + l * plane;
    k.vmid = L.vmid.data() + l * plane;
    k.centre = L.centre.data() + l * plane;
    L.floor[l] = floorFraction * *std::max_element(rad.table, rad.table + kNodes);
    // Image point (pixel-centre coordinates, as the evaluation's i + ½): x = c_x − f e_y/e_x.
    const bool ahead = rad.e[0] > 0.0f;
    L.imageX[l] = ahead ? static_cast<float>(c.x - f * static_cast<double>(rad.e[1] / rad.e[0])) : -1e30f;
    L.imageY[l] = ahead ? static_cast<float>(c.y - f * static_cast<double>(rad.e[2] / rad.e[0])) : -1e30f;
  }
  // FillRow loads a vector from any lamp index below nl: kCell readable entries past the last.
  const std::size_t padded = nl + lamp_fx::kCell;
  L.weightTo.assign(padded, std::numeric_limits<float>::infinity());  // the padding is masked out
  L.weightFrom.assign(padded, std::numeric_limits<float>::infinity());
  L.fromSorted = true;
  for (std::size_t l = 0; l < nl; ++l) {
    L.weightTo[l] = L.lamps[l].weight_to;
    L.weightFrom[l] = L.lamps[l].weight_from;
    L.fromSorted = L.fromSorted && (l == 0 || L.weightFrom[l] >= L.weightFrom[l - 1]);
  }
  FastJob job{&L, distance, out.data(), cam.width, cam.height, static_cast<float>(f), static_cast<float>(c.x),
              static_cast<float>(c.y)};
  if (veil != nullptr) {
    job.veil = veil;
    job.veilZf = static_cast<float>(cam.worldFromCamera[0].z * f);
    job.veilZl = static_cast<float>(cam.worldFromCamera[1].z);
    job.veilZu = static_cast<float>(cam.worldFromCamera[2].z);
    job.veilHk = static_cast<float>(0.5 * kt);
    job.veilHkh = static_cast<float>(0.5 * kt * eyeHeight);
  }
  const FastJob* jp = &job;
  pool.parallelFor(static_cast<std::size_t>(L.gh), [jp](std::size_t r) { gridRow(*jp, r); });
  pool.parallelFor(static_cast<std::size_t>(L.gh - 1), [jp](std::size_t r) { tileRow(*jp, r); });
  for (const auto& m : L.modes) {
    tiles.bilinear += m[lamp_fx::kTileBilinear];
    tiles.half += m[lamp_fx::kTileHalf];
    tiles.exact += m[lamp_fx::kTileExact];
  }
}

}  // namespace

Result<LampEffects> LampEffects::build(const Scene& scene, const GlowOptions& glow, const GlareOptions& glare,
                                       std::shared_ptr<ThreadPool> pool) {
  if (glow.enabled && !(glow.fade_in >= Apsf::minOpticalDistance()))
    return Error{"glow: fade_in must be at least " + std::to_string(Apsf::minOpticalDistance())};
  if (glare.enabled && !(glare.age_years >= 0.0 && glare.age_years <= 120.0))
    return Error{"glare: age_years must be in [0, 120]"};
  if (glare.enabled && !(glare.pigmentation >= 0.0 && glare.pigmentation <= 1.0))
    return Error{"glare: pigmentation must be in [0, 1]"};
  LampEffects fx;
  fx.glow_ = glow;
  fx.glare_ = glare;
  fx.pool_ = std::move(pool);
  fx.enabled_.assign(scene.lamps.size(), 1);
  fx.tables_ = std::make_shared<Tables>();
  if (glow.enabled) fx.tables_->iso = kernels::IsoTable::get(scene.fog.phase);
  if (glare.enabled) {
    fx.tables_->cieGlare.resize(kNodes);
    for (int i = 0; i < kNodes; ++i)
      fx.tables_->cieGlare[static_cast<std::size_t>(i)] = static_cast<float>(
          veilingLuminancePerLux(thetaOfS(sOfNode(i)) * 180.0 / kPi, glare.age_years, glare.pigmentation));
  }
  fx.tables_->glowTables.resize(static_cast<std::size_t>(kNodes) * scene.lamps.size());
  fx.tables_->glow.reserve(scene.lamps.size());
  fx.tables_->glare.reserve(scene.lamps.size());
  return fx;
}

void LampEffects::setLampEnabled(std::size_t index, bool on) {
  if (index < enabled_.size()) enabled_[index] = on ? 1 : 0;
}

void LampEffects::evaluate(const Scene& scene, const SurfaceBuffers& surface, std::vector<float>& glowOut,
                           std::vector<float>& glareOut, LampEffectsReport& report) {
  Tables& t = *tables_;
  const Camera& cam = scene.camera;
  const Medium& fog = scene.fog;
  const double kt = fog.extinction_per_m;
  const std::size_t n = static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height);
  const Mat3 camFromWorld = glm::transpose(cam.worldFromCamera);
  const double f = cam.focalLengthPixels();
  const Vec2 c = cam.principalPoint();
  std::size_t nReport = 0;  // report.lamps' elements are reused (their names keep their storage)
  report.eye_illuminance_lx = report.veiling_luminance_cd_m2 = 0.0;
  report.glow_seconds = report.glare_seconds = 0.0;
  report.glow_tiles = report.glare_tiles = {};
  t.glow.clear();
  t.glare.clear();
  const double q = std::clamp(meanCosine(fog.phase), 0.0, 0.99);
  // The single-scattering table of the frame's phase function (the fog may change between
  // frames): IsoTable::get returns the cached one while the phase stays (a map look-up), and
  // builds a new one (~0.2 s) when it changes.
  if (glow_.enabled) t.iso = kernels::IsoTable::get(fog.phase);
  if (glow_.enabled && glow_.model == GlowModel::Table && !(t.msLooked && t.msPhase == phaseIdentity(fog.phase))) {
    t.ms = shippedMultipleScatteringTable(fog.phase);
    t.ground = glow_.ground_reflectance >= 0.0 ? shippedGroundCorrection(fog.phase) : nullptr;
    t.msPhase = phaseIdentity(fog.phase);
    t.msLooked = true;
  }
  if (glow_.model != GlowModel::Table) t.ms = nullptr;

  // The scene may hold more lamps than at build() (traffic arriving): they start switched on;
  // the buffers grow only then, so a steady scene allocates nothing per frame.
  if (enabled_.size() < scene.lamps.size()) enabled_.resize(scene.lamps.size(), 1);
  if (t.glowTables.size() < static_cast<std::size_t>(kNodes) * scene.lamps.size())
    t.glowTables.resize(static_cast<std::size_t>(kNodes) * scene.lamps.size());
  if (t.curves.size() < scene.lamps.size()) t.curves.resize(scene.lamps.size());

  // Per lamp: where it is, whether a surface hides it, its light towards the eye.
  const auto tGlow = std::chrono::steady_clock::now();
  for (std::size_t li = 0; li < scene.lamps.size(); ++li) {
    if (!enabled_[li]) continue;
    const SceneLamp& sl = scene.lamps[li];
    // The driver's own lamps (mount = vehicle) sit ahead of and below the eye, behind the
    // bonnet and inside their housings: their direct light does not reach the eye, so they have
    // no glare, and their single-scattered veil is the airlight layer's. Their multiply
    // scattered light fills the fog ahead like any lamp's: with the tables they glow (never
    // hidden: the bonnet hides the lamp, not the fog its light fills), from their light forward
    // of the lamp only (a measured file's rear hemisphere would otherwise count: housing and
    // body take it). The APSF (a lamp in view at K_t R ≥ 1.1) has nothing for them.
    const bool own = sl.mount == LampMount::Vehicle;
    if (own && !(glow_.enabled && t.ms != nullptr)) continue;
    const Lamp& lamp = sl.lamp;
    const Vec3 toLamp = lamp.position_m - cam.position_m;
    const double R = glm::length(toLamp);
    if (!(R > 1e-6)) continue;
    const Vec3 eCam = camFromWorld * (toLamp / R);
    if (nReport == report.lamps.size()) report.lamps.emplace_back();
    LampEffectsReport::Lamp& rep = report.lamps[nReport++];
    {
      std::string name = std::move(rep.name);
      rep = LampEffectsReport::Lamp{};
      rep.name = std::move(name);
      rep.name.assign(sl.name);
    }
    rep.distance_m = R;
    rep.optical_distance = kt * R;
    rep.own = own;
    // The layers carry colour × the profile's values; the report gives luminous figures, the
    // profile's × the colour's mean (1 for white; the point lamps of an aperture carry their
    // quadrature weight in the colour, so theirs add up to the lamp's).
    const double luminous = (lamp.color.x + lamp.color.y + lamp.color.z) / 3.0;
    const double intensity = lamp.profile->intensity(glm::transpose(lamp.worldFromLamp) * (-toLamp / R));
    const double illuminance = intensity * std::exp(-kt * R) / (R * R);  // profile's, lux
    rep.intensity_cd = own ? 0.0 : luminous * intensity;  // the driver's own: none reaches the eye
    rep.eye_illuminance_lx = own ? 0.0 : luminous * illuminance;
    // Hidden: its image is in the frame and the surfaces there are nearer than the lamp. The
    // 2 × 2 pixels around the image point are read, and one that reaches the lamp keeps it
    // visible: a distant lamp is smaller than a pixel, whose centre ray may meet the road just
    // in front of it (at 104 m a 320 px wide, 60° view's pixel spans 0.34 m, half a low beam's
    // height above the road), and a single pixel made lamps flicker between hidden and seen.
    bool visible = eCam.x > 0.0 && !own, hidden = false;
    if (visible) {
      const double x = c.x - f * eCam.y / eCam.x, y = c.y - f * eCam.z / eCam.x;
      if (x >= 0.0 && y >= 0.0 && x < cam.width && y < cam.height) {
        const int i0 = std::clamp(static_cast<int>(std::floor(x - 0.5)), 0, cam.width - 1);
        const int j0 = std::clamp(static_cast<int>(std::floor(y - 0.5)), 0, cam.height - 1);
        bool reaches = false;
        for (int j = j0; j <= std::min(j0 + 1, cam.height - 1); ++j)
          for (int i = i0; i <= std::min(i0 + 1, cam.width - 1); ++i) {
            const std::size_t k = static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
            reaches = reaches || !(static_cast<double>(surface.distance[k]) < 0.98 * R);
          }
        visible = reaches;
        hidden = !reaches;
      }
    }
    rep.visible = visible && intensity > 0.0;
    Tables::Radial rad;
    for (int k = 0; k < 3; ++k) rad.e[k] = static_cast<float>(eCam[k]);
    // The glow's occlusion weight: a lamp's multiply scattered light along a view ray gathers
    // about the lamp, so surfaces nearer than R/2 see none of it and surfaces beyond R all of it.
    // The driver's own lamps too (R ≈ 2 m): checked against the path tracer over a black road
    // (the own low beam 0.65 m over it, 2 m ahead of the eye, 50 m fog; docs/airlight.md "The
    // ground"), single + glow is 0.96–1.01 of it in the rings 0.5–16° with this weight, and
    // 0.78–0.96 with the ramp 0 … 2/K_t the own lamps had before (light gathered over mean free
    // paths: road pixels 4–30 m away lost up to 80 % of their glow).
    rad.weightFrom = static_cast<float>(0.5 * R);
    rad.weightTo = static_cast<float>(R);
    if (rep.visible) report.eye_illuminance_lx += rep.eye_illuminance_lx;
    if (glare_.enabled && rep.visible) {
      for (int k = 0; k < 3; ++k) rad.color[k] = static_cast<float>(lamp.color[k] * illuminance);
      rad.table = t.cieGlare.data();
      t.glare.push_back(rad);
      // At the image centre: the camera's +x.
      report.veiling_luminance_cd_m2 += rep.eye_illuminance_lx *
                                        veilingLuminancePerLux(std::acos(std::clamp(eCam.x, -1.0, 1.0)) * 180.0 / kPi,
                                                               glare_.age_years, glare_.pigmentation);
    }
    // Which lamps glow. The tables (model = table): every lamp not hidden behind a surface,
    // whether in the frame, beside it or behind the eye, and whatever its intensity towards the
    // eye: multiply scattered light fills the fog around it in every direction (up to θ = π).
    // The APSF: lamps in view only, from K_t R = 1.1 (the series' limit).
    const bool fromTable = t.ms != nullptr;
    const bool glows = fromTable ? !hidden : rep.visible && rep.optical_distance >= Apsf::minOpticalDistance();
    if (glow_.enabled && glows) {
      Tables::CurveCache& cc = t.curves[li];
      const PhaseIdentity phaseId = phaseIdentity(fog.phase);
      // The ground factor's optical height: the eye's and the lamp's mean over the ground (0: none).
      const double groundH = t.ground && !own
                                 ? kt * std::max(0.5 * ((cam.position_m.z - glow_.ground_height_m) +
                                                        (lamp.position_m.z - glow_.ground_height_m)),
                                                 0.0)
                                 : 0.0;
      if (!(cc.valid && cc.R == R && cc.kt == kt && cc.groundH == groundH && cc.albedo == fog.albedo && cc.phase == phaseId &&
            cc.fromTable == fromTable)) {
        if (fromTable) t.tabulateFlux();
        auto curve = fromTable ? glowCurveFromTable(*t.ms, *t.iso, fog, R, kNodes, false) : glowCurve(*t.iso, fog, R, kNodes);
        if (curve && fromTable) curve->single_flux = fog.albedo * t.singleFlux(kt * R);
        if (curve && fromTable && t.ground && !own) {
          // The ground (GlowOptions::ground_reflectance): the path tracer's factor on the tables'
          // light at this optical distance, angle by angle; the report's flux follows it. Not
          // the driver's own lamps: at K_t R ~ 0.1 the factor is 1 (GroundCorrectionTable::factor).
          thread_local std::vector<double> groundFactor;
          groundFactor.resize(curve->glow.size());
          t.ground->factors(kt * R, glow_.ground_reflectance, groundH, curve->theta.data(), curve->theta.size(),
                            groundFactor.data());
          for (std::size_t i = 0; i < curve->glow.size(); ++i) curve->glow[i] *= groundFactor[i];
          curve->multiple_flux = R * R * fluxOver(curve->theta, curve->glow);
        }
        cc.valid = true;
        cc.R = R;
        cc.kt = kt;
        cc.groundH = groundH;
        cc.albedo = fog.albedo;
        cc.phase = phaseId;
        cc.fromTable = fromTable;
        cc.ok = static_cast<bool>(curve);
        cc.measured = false;
        cc.effectiveValid = false;
        if (curve && fromTable && t.ms->hasEmissionBins() &&
            !std::holds_alternative<IsotropicProfile>(lamp.profile->model())) {
          // The emission shares at the table's angle nodes for this T, and where each glow node
          // falls among those nodes (multiple_scattering.hpp, emissionShares).
          const auto& angles = t.ms->angles();
          const std::size_t nK = t.ms->emissionEdges().size() - 1;
          cc.shares.resize(angles.size() * nK);
          cc.bandWeights.resize(angles.size() * nK * kGlowBands);
          for (std::size_t j = 0; j < angles.size(); ++j) {
            t.ms->emissionShares(rep.optical_distance, angles[j], cc.shares.data() + j * nK);
            emissionBandWeights(cc.shares.data() + j * nK, t.ms->emissionEdges().data(), nK,
                                cc.bandWeights.data() + j * nK * kGlowBands);
          }
          cc.node.resize(static_cast<std::size_t>(kNodes));
          cc.nodeWeight.resize(static_cast<std::size_t>(kNodes));
          for (std::size_t i = 0; i < static_cast<std::size_t>(kNodes); ++i) {
            const double th = std::max(curve->theta[i], angles.front());
            std::size_t j = 0;
            while (j + 2 < angles.size() && th > angles[j + 1]) ++j;
            cc.node[i] = static_cast<int>(j);
            cc.nodeWeight[i] = std::clamp(std::log(th / angles[j]) / std::log(angles[j + 1] / angles[j]), 0.0, 1.0);
          }
          cc.measured = true;
        }
        if (curve) {
          cc.glow = curve->glow;
          cc.terms = curve->terms;
          cc.scale = curve->scale;
          cc.single_flux = curve->single_flux;
          cc.multiple_flux = curve->multiple_flux;
        }
      }
      if (cc.ok) {
        rep.apsf_terms = cc.terms;
        rep.glow_scale = cc.scale;
        const double total = cc.single_flux + cc.multiple_flux;
        rep.glow_share = total > 0.0 ? cc.multiple_flux / total : 0.0;
        // The source: isotropic lamps their intensity; measured lamps with the tables' emission
        // bins the mean intensity of each bin's annulus about the direction to the eye, weighted
        // per angle by the bins' shares (I_eff(θ)); otherwise the cone stand-in.
        const bool measured = cc.measured;
        double source = 0.0;
        if (measured) {
          const auto& edges = t.ms->emissionEdges();
          const std::size_t nK = edges.size() - 1, nA = t.ms->angles().size();
          // The direction to the eye in the lamp's frame, as glowAnnulusMeans takes it; within
          // 1e-6 rad (2e-4°, rounding of a rig that moves with the eye) of the last one's, the
          // last I_eff serves.
          const Vec3 toEye = cam.position_m - lamp.position_m;
          const double toEyeLen = glm::length(toEye);
          const Vec3 axis = toEyeLen > 0.0 ? glm::transpose(lamp.worldFromLamp) * (toEye / toEyeLen) : Vec3(0.0);
          const bool same = cc.effectiveValid && cc.effectiveProfile == lamp.profile && cc.effectiveOwn == own &&
                            cc.effective.size() == nA && glm::length(axis - cc.effectiveAxis) < 1e-6;
          if (!same) {
            t.annulus.resize(nK);
            t.bands.resize(nK * kGlowBands);
            cc.effective.resize(nA);
            glowAnnulusMeans(lamp, cam.position_m, edges.data(), nK, t.annulus.data(), own, t.bands.data());
            // Each bin's share spread over its bands (emissionBandWeights): Σ_k s_k · mean_b(w_kb Ī_kb).
            for (std::size_t j = 0; j < nA; ++j) {
              double e = 0.0;
              const double* wj = cc.bandWeights.data() + j * nK * kGlowBands;
              for (std::size_t k = 0; k < nK; ++k) {
                double in = 0.0;
                for (std::size_t b = 0; b < kGlowBands; ++b) in += wj[k * kGlowBands + b] * t.bands[k * kGlowBands + b];
                e += cc.shares[j * nK + k] * in / kGlowBands;
              }
              cc.effective[j] = e;
            }
            cc.effectiveAxis = axis;
            cc.effectiveProfile = lamp.profile;
            cc.effectiveOwn = own;
            cc.effectiveValid = true;
          }
          source = cc.effective.front();
        } else {
          source = glowSourceIntensity(lamp, cam.position_m, rep.optical_distance, q);
        }
        rep.glow_source_cd = luminous * source;
        rep.glow_from_table = fromTable;
        const double fade = fromTable ? 1.0
                                      : std::clamp((rep.optical_distance - Apsf::minOpticalDistance()) /
                                                       (glow_.fade_in - Apsf::minOpticalDistance() + 1e-12),
                                                   0.0, 1.0);
        float* table = t.glowTables.data() + static_cast<std::size_t>(kNodes) * li;
        for (int i = 0; i < kNodes; ++i) {
          const auto ui = static_cast<std::size_t>(i);
          double src = source;
          if (measured) {
            const auto j = static_cast<std::size_t>(cc.node[ui]);
            src = (1.0 - cc.nodeWeight[ui]) * cc.effective[j] + cc.nodeWeight[ui] * cc.effective[j + 1];
          }
          const double g = fade * src * cc.glow[ui];
          table[i] = static_cast<float>(g);
          rep.glow_peak_cd_m2 = std::max(rep.glow_peak_cd_m2, luminous * g);
        }
        for (int k = 0; k < 3; ++k) rad.color[k] = static_cast<float>(lamp.color[k]);
        rad.table = table;
        t.glow.push_back(rad);
      }
    }
  }
  report.lamps.resize(nReport);

  // The exact path (LampEffectsPath::Exact; the layers before the coarse grid, the reference of
  // the fast path's tests): per pixel, Σ over lamps of the radial tables at the pixel's
  // half-chord to each lamp.
  auto fill = [&](const std::vector<Tables::Radial>& lamps, bool occlusion, std::vector<float>& out) {
    out.assign(3 * n, 0.0f);
    if (lamps.empty()) return;
    struct Job {
      const std::vector<Tables::Radial>* lamps;
      const SurfaceBuffers* surf;
      std::vector<float>* out;
      int w;
      double f, cx, cy;
      bool occlusion;
    } job{&lamps, &surface, &out, cam.width, f, c.x, c.y, occlusion};
    const Job* jp = &job;
    pool_->parallelFor(static_cast<std::size_t>(cam.height), [jp](std::size_t j) {
      const auto w = static_cast<std::size_t>(jp->w);
      float* row = jp->out->data() + 3 * w * j;
      const float* dist = jp->surf->distance.data() + w * j;
      const double b = (jp->cy - (static_cast<double>(j) + 0.5)) / jp->f;
      for (std::size_t i = 0; i < w; ++i) {
        const double a = (jp->cx - (static_cast<double>(i) + 0.5)) / jp->f;
        const double inv = 1.0 / std::sqrt(1.0 + a * a + b * b);
        const float wx = static_cast<float>(inv), wy = static_cast<float>(a * inv), wz = static_cast<float>(b * inv);
        for (const Tables::Radial& L : *jp->lamps) {
          float weight = 1.0f;
          if (jp->occlusion) {
            const float d = dist[i];
            weight = std::isinf(d) ? 1.0f
                                   : std::clamp((d - L.weightFrom) / (L.weightTo - L.weightFrom), 0.0f, 1.0f);
            if (weight <= 0.0f) continue;
          }
          const float vx = wx - L.e[0], vy = wy - L.e[1], vz = wz - L.e[2];
          const float s = 0.5f * std::sqrt(vx * vx + vy * vy + vz * vz);
          const float g = std::sqrt(std::min(s, 1.0f)) * static_cast<float>(kNodes - 1);
          const int k0 = std::min(static_cast<int>(g), kNodes - 2);
          const float tt = g - static_cast<float>(k0);
          const float v = weight * (L.table[k0] + tt * (L.table[k0 + 1] - L.table[k0]));
          row[3 * i] += v * L.color[0];
          row[3 * i + 1] += v * L.color[1];
          row[3 * i + 2] += v * L.color[2];
        }
      }
    });
  };
  // The road lit by the driver's own lamps, seen through the fog (ground_veil.hpp): with the
  // tables' glow (the own lamps glow only with them) and a ground of ρ > 0, added to the glow
  // layer after its lamps (addVeil).
  report.ground_veil = false;
  report.ground_veil_build_seconds = 0.0;
  if (glow_.enabled && t.ms != nullptr && glow_.ground_reflectance > 0.0 && kt > 0.0) {
    t.veilLamps.clear();
    for (std::size_t li = 0; li < scene.lamps.size(); ++li) {
      const SceneLamp& sl = scene.lamps[li];
      if (!enabled_[li] || sl.mount != LampMount::Vehicle || !sl.lamp.profile) continue;
      ground_veil::Lamp l;
      l.position_m = sl.lamp.position_m;
      l.lampFromWorld = glm::transpose(sl.lamp.worldFromLamp);
      l.profile = sl.lamp.profile;
      for (int k = 0; k < 3; ++k) l.color[k] = sl.lamp.color[k];
      t.veilLamps.push_back(l);
    }
    if (!t.veilLamps.empty()) {
      std::size_t exact = 0;
      veilKey(scene, t.veilLamps, glow_, t.veilKey, exact);
      if (!t.veil.valid || t.veil.keyExact != exact || !veilKeyHolds(t.veilKey, t.veil.key, exact) ||
          !(std::abs(kt / t.veil.kt - 1.0) <= kVeilKtTolerance)) {
        const auto tb = std::chrono::steady_clock::now();
        buildVeil(t.veil, scene, t.veilLamps, glow_, *pool_);
        t.veil.key = t.veilKey;
        t.veil.keyExact = exact;
        t.veil.valid = true;
        report.ground_veil_build_seconds = since(tb);
      }
      report.ground_veil = true;
    }
  }
  const bool fast = path_ == LampEffectsPath::Fast;
  if (!glow_.enabled) glowOut.clear();
  else if (fast)
    fastFill(*pool_, t.glowLayer, t.glow, cam, f, c, surface.distance.data(), kGlowFloor, glowOut, report.glow_tiles,
             report.ground_veil ? &t.veil : nullptr, kt, cam.position_m.z - glow_.ground_height_m);
  else fill(t.glow, true, glowOut);
  if (report.ground_veil && !fast)  // the fast path adds it in its rows (FillRow)
    addVeil(t.veil, cam, surface.distance.data(), kt, cam.position_m.z - glow_.ground_height_m, glowOut.data(), *pool_);
  report.glow_seconds = since(tGlow);
  const auto tGlare = std::chrono::steady_clock::now();
  if (!glare_.enabled) glareOut.clear();
  else if (fast) fastFill(*pool_, t.glareLayer, t.glare, cam, f, c, nullptr, 0.0f, glareOut, report.glare_tiles);
  else fill(t.glare, false, glareOut);
  report.glare_seconds = since(tGlare);
}

}  // namespace fogbeam
