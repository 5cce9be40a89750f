// fogbeam — the fog's scattered light on surfaces (fogbeam/render/fog_light.hpp).
#include <fogbeam/render/fog_light.hpp>

#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/render/lamp_effects.hpp>
#include <fogbeam/util/shared_cache.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include "glow_quadrature.hpp"
#include "render/view_table_cache.hpp"

#include <boost/math/quadrature/gauss.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <tuple>

namespace fogbeam {

namespace {

constexpr double kDeg = kPi / 180.0;
// T nodes 2^(kLogFirst + i / kPerOctave), i < kTNodes: 2^(−7) … 2^5.
constexpr int kPerOctave = 4, kLogFirst = -7, kTNodes = 12 * kPerOctave + 1;
// The dense table: T = 2^(−7 + i/16) for i ≤ 112 (up to 1), then 1 + (i − 112)/16 up to 32.
constexpr std::size_t kDenseLog = FogLightTable::kDenseLog, kDenseNodes = FogLightTable::kDenseNodes;
double denseT(std::size_t i) {
  return i <= kDenseLog ? std::exp2(-7.0 + static_cast<double>(i) / 16.0) : 1.0 + static_cast<double>(i - kDenseLog) / 16.0;
}
double denseIndex(double T) {  // fractional node of T (≥ 0)
  return T < 1.0 ? std::max(0.0, (std::log2(T) + 7.0) * 16.0) : static_cast<double>(kDenseLog) + (T - 1.0) * 16.0;
}

// Angles of the glow curve the moments integrate over (glowNodeAngle).
constexpr std::size_t kThetaNodes = 257;
// The annulus maps' grid: the angle α from the lamp's axis every 0.5° up to 24° (a headlamp's
// beam and cut-off lie within a few degrees of its axis, and the first bins are 3° and 5° wide:
// at 1° the first bin's harmonic was 11 % off between rows next to the axis, 0.5° quarters that),
// then every 3°; the azimuth every 3°.
constexpr double kMapFine = AnnulusMeanMap::kFineDeg * kDeg, kMapStep = AnnulusMeanMap::kStepDeg * kDeg;
constexpr int kMapFineRows = AnnulusMeanMap::kFineRows;  // rows below kMapFineEnd
constexpr double kMapFineEnd = kMapFineRows * kMapFine;
double mapAlpha(std::size_t i) {
  const double fine = static_cast<double>(std::min<std::size_t>(i, kMapFineRows)) * kMapFine;
  return i <= static_cast<std::size_t>(kMapFineRows) ? fine : kMapFineEnd + static_cast<double>(i - kMapFineRows) * kMapStep;
}
double mapRow(double alpha) {  // fractional row of α
  return alpha < kMapFineEnd ? alpha / kMapFine : kMapFineRows + (alpha - kMapFineEnd) / kMapStep;
}

// The fit's normals: μ = ±u², u uniform in [−1, 1] (81 nodes). Both the irradiance's kink and the
// dipole's step at μ = 0 are as wide as the sine of the angle the light arrives at from the
// lamp's direction (a few degrees for the first bins), so the nodes crowd there (0.0006, 0.0025,
// 0.0056, … apart), where a road seeing a lamp along it sits; 0.05 apart near ±1.
constexpr std::size_t kFitNodes = 81;
double fitNode(std::size_t j) {
  const double u = -1.0 + 2.0 * static_cast<double>(j) / static_cast<double>(kFitNodes - 1);
  return u * std::abs(u);
}

// F(μ) ≈ Σ_q c_q b_q(μ) through F(μ_j), b the symmetric or the dipole functions of fogLightBasis,
// by least squares weighted by 1 / (|F| + 0.02 scale)²: nearly relative. Gaussian elimination with
// partial pivoting on the 4 × 4 normal equations; out all zero when F is (or scale is 0).
// (The symmetric part was fitted first as κ μ⁺ + a Legendre quadratic on 41 uniform nodes: −6 to
// −22 % at μ = 0 exactly, and 0.77 of the irradiance of a road 40 m ahead of a low beam, whose μ is
// 0.016; with the smoothed ramps 1.0 there. Truncating the Funk–Hecke series of the clamped
// cosine at l = 2 instead rang: +40 % at grazing incidence and negative facing away.)
void fitBasis(const std::vector<double>& F, double scale, bool dipole, double* out) {
  for (int q = 0; q < 4; ++q) out[q] = 0.0;
  const double floor = 0.02 * scale;
  if (!(floor > 0.0)) return;
  double A[4][5] = {};
  for (std::size_t j = 0; j < F.size(); ++j) {
    double p[4];
    if (dipole) fogLightBasis(fitNode(j), static_cast<double*>(nullptr), p);
    else fogLightBasis(fitNode(j), p, static_cast<double*>(nullptr));
    const double w = 1.0 / ((std::abs(F[j]) + floor) * (std::abs(F[j]) + floor));
    for (int r = 0; r < 4; ++r) {
      A[r][4] += w * p[r] * F[j];
      for (int q = 0; q < 4; ++q) A[r][q] += w * p[r] * p[q];
    }
  }
  for (int c = 0; c < 4; ++c) {
    int piv = c;
    for (int r = c + 1; r < 4; ++r)
      if (std::abs(A[r][c]) > std::abs(A[piv][c])) piv = r;
    if (!(std::abs(A[piv][c]) > 0.0)) return;
    for (int q = 0; q < 5; ++q) std::swap(A[c][q], A[piv][q]);
    for (int r = c + 1; r < 4; ++r) {
      const double f = A[r][c] / A[c][c];
      for (int q = c; q < 5; ++q) A[r][q] -= f * A[c][q];
    }
  }
  for (int c = 3; c >= 0; --c) {
    double v = A[c][4];
    for (int q = c + 1; q < 4; ++q) v -= A[c][q] * out[q];
    out[c] = v / A[c][c];
  }
}

// Breakpoints of the order-1 quadrature in η: fine near η = 0, where the scattering angle θ + η
// of a ray next to the lamp sits in the phase function's forward peak, then every 3°.
const std::vector<double>& etaBreaks() {
  static const std::vector<double> b = [] {
    std::vector<double> v{0.0};
    for (double e = 0.05; e < 3.0; e *= 2.0) v.push_back(e * kDeg);
    for (double e = 3.0; e <= 180.0 + 1e-9; e += 3.0) v.push_back(e * kDeg);
    return v;
  }();
  return b;
}

// ∫ over [a, b] of the order-1 integrand at (T, θ), 8-point Gauss–Legendre.
double order1Piece(const Phase& phase, double T, double theta, double sinTheta, double a, double b) {
  auto f = [&](double eta) {
    const double s = std::sin(theta + eta);
    if (!(s > 0.0)) return 0.0;
    const double x = T * (std::sin(eta) + sinTheta) / s;
    return x > 700.0 ? 0.0 : evalPhase(phase, std::cos(theta + eta)) * std::exp(-x);
  };
  return boost::math::quadrature::gauss<double, 8>::integrate(f, a, b);
}

// l¹ per bin at (T, θ) into out[k] (albedo 1): every piece of the breakpoints and bin edges,
// each added to its bin.
void order1Bins(const Phase& phase, double T, double theta, const std::vector<double>& edges, double* out) {
  const std::size_t bins = edges.size() - 1;
  for (std::size_t k = 0; k < bins; ++k) out[k] = 0.0;
  const double sinTheta = std::sin(theta);
  if (!(sinTheta > 0.0) || !(T > 0.0)) return;
  const double top = kPi - theta;
  const auto& br = etaBreaks();
  std::size_t ib = 1;
  for (std::size_t k = 0; k < bins; ++k) {
    double a = edges[k];
    const double end = std::min(edges[k + 1], top);
    while (a < end) {
      while (ib < br.size() && br[ib] <= a) ++ib;
      const double b = std::min(end, ib < br.size() ? br[ib] : end);
      out[k] += order1Piece(phase, T, theta, sinTheta, a, b);
      a = b;
    }
  }
  for (std::size_t k = 0; k < bins; ++k) out[k] /= T * sinTheta;
}

}  // namespace

double hemisphereIrradiance(const std::function<double(const Vec3&)>& radiance, ThreadPool& pool,
                            std::size_t azimuths) {
  using GL = boost::math::quadrature::gauss<double, 64>;
  std::vector<double> rows(GL::abscissa().size() * 2, 0.0);  // ± abscissae (64 nodes, none at 0)
  pool.parallelFor(rows.size(), [&](std::size_t i) {
    const std::size_t a = i / 2;
    const double x = (i % 2 == 0 ? 1.0 : -1.0) * GL::abscissa()[a];
    const double u = 0.5 * (1.0 + x), sinT = std::sqrt(u), cosT = std::sqrt(1.0 - u);
    double sum = 0.0;
    for (std::size_t j = 0; j < azimuths; ++j) {
      const double phi = 2.0 * kPi * (static_cast<double>(j) + 0.5) / static_cast<double>(azimuths);
      sum += radiance(Vec3(sinT * std::cos(phi), sinT * std::sin(phi), cosT));
    }
    rows[i] = GL::weights()[a] * sum * (2.0 * kPi / static_cast<double>(azimuths));
  });
  double e = 0.0;
  for (double r : rows) e += r;
  return 0.25 * e;  // ½ du dφ, du = ½ dx
}

FogLightAzimuthal fogLightAzimuthal(double theta, double mu) noexcept {
  const double si = std::sqrt(std::max(0.0, 1.0 - mu * mu)), st = std::sin(theta), a = std::cos(theta) * mu, b = st * si;
  if (b <= std::abs(a)) return {2.0 * kPi * std::max(a, 0.0), a > 0.0 ? kPi * st : 0.0};
  const double phi0 = std::acos(std::clamp(-a / b, -1.0, 1.0));
  return {2.0 * (a * phi0 + b * std::sin(phi0)), a * std::sin(phi0) / si + st * phi0};
}

double fogLightOrder1(const Phase& phase, double opticalDistance, double theta, double eta0, double eta1) noexcept {
  const std::vector<double> edges{eta0, eta1};
  double out = 0.0;
  order1Bins(phase, opticalDistance, theta, edges, &out);
  return out;
}

Result<std::shared_ptr<const FogLightTable>> FogLightTable::build(const MultipleScatteringTable& ms, const Phase& phase,
                                                                  double albedo, ThreadPool* pool) {
  return build(&ms, ms.hasEmissionBins() ? ms.emissionEdges() : std::vector<double>{0.0, kPi}, phase, albedo, pool);
}

Result<std::shared_ptr<const FogLightTable>> FogLightTable::buildOrderOne(const std::vector<double>& edges,
                                                                          const Phase& phase, double albedo,
                                                                          ThreadPool* pool) {
  if (edges.size() < 2 || edges.front() != 0.0 || std::abs(edges.back() - kPi) > 1e-12 ||
      !std::is_sorted(edges.begin(), edges.end()))
    return Error{"fog light: emission bin edges must rise from 0 to pi"};
  return build(nullptr, edges, phase, albedo, pool);
}

Result<std::shared_ptr<const FogLightTable>> FogLightTable::build(const MultipleScatteringTable* ms,
                                                                  const std::vector<double>& edges, const Phase& phase,
                                                                  double albedo, ThreadPool* pool) {
  if (!(albedo > 0.0 && albedo <= 1.0)) return Error{"fog light: albedo must lie in (0, 1]"};
  const auto start = std::chrono::steady_clock::now();
  std::shared_ptr<FogLightTable> t(new FogLightTable());
  t->albedo_ = albedo;
  t->edges_ = edges;
  const std::size_t bins = t->bins();
  t->t_.resize(kTNodes);
  for (int i = 0; i < kTNodes; ++i)
    t->t_[static_cast<std::size_t>(i)] = std::exp2(kLogFirst + static_cast<double>(i) / kPerOctave);
  t->logEnv_.assign(kTNodes * bins, 0.0);
  t->norm_.assign(kTNodes * bins * kCoefficients, 0.0);
  std::vector<double> theta(kThetaNodes);
  for (std::size_t i = 0; i < kThetaNodes; ++i) theta[i] = glow_quadrature::glowNodeAngle(i, kThetaNodes);

  // The integrals over θ at each fit normal as weights on the θ nodes (the same for every bin and
  // T): integrateFromApex's rule times sin θ times the azimuthal integrals of the clamped cosine,
  //   E: W₀ = ∫ max(0, ω·n) dφ = 2 (A φ0 + B sin φ0),
  //   G: W₁ / √(1 − μ²), W₁ = ∫ cos φ max(0, ω·n) dφ = A sin φ0 + B φ0 (header comment),
  // with n = μ a + √(1 − μ²) x̂, A = μ cos θ, B = √(1 − μ²) sin θ, cos φ0 = −A/B where the element
  // sees part of the ring about a; where it sees all of it (A ≥ B) W₀ = 2π A, W₁ = π B; none: 0.
  std::vector<double> rule(kThetaNodes, 0.0);
  for (std::size_t i = 1; i < kThetaNodes; ++i)
    rule[i] = glow_quadrature::integrateFromApex(theta, [&](std::size_t m) { return m == i ? 1.0 : 0.0; });
  std::vector<double> wE(kFitNodes * kThetaNodes, 0.0), wG(kFitNodes * kThetaNodes, 0.0);
  for (std::size_t j = 0; j < kFitNodes; ++j)
    for (std::size_t i = 1; i < kThetaNodes; ++i) {
      const FogLightAzimuthal w = fogLightAzimuthal(theta[i], fitNode(j));
      wE[j * kThetaNodes + i] = rule[i] * w.w0 * std::sin(theta[i]);
      wG[j * kThetaNodes + i] = rule[i] * w.w1 * std::sin(theta[i]);
    }
  auto node = [&](std::size_t iT) {
    const double T = t->t_[iT];
    // L_k(θ_i) (K_t = 1 /m, 1 cd): Ω l¹_k + f share_k; L1 the dipole's radiance per unit Ī₁_k · ω̂⊥:
    // Ω l¹_k (order 1 leaves towards the scatterer's side) + f h_k (orders ≥ 2: the tables' first
    // azimuthal harmonic of the emission, MultipleScatteringTable::emissionHarmonics; 0 for tables
    // without it, the ring means alone).
    std::vector<double> L(kThetaNodes * bins, 0.0), L1(kThetaNodes * bins, 0.0), shares(bins, 1.0), o1(bins);
    std::vector<double> harmonics(bins, 0.0);
    const bool withHarmonics = ms != nullptr && ms->hasEmissionBins() && ms->hasEmissionHarmonics();
    for (std::size_t i = 1; i < kThetaNodes; ++i) {
      order1Bins(phase, T, theta[i], t->edges_, o1.data());
      const double f = ms != nullptr ? ms->value(T, theta[i], albedo) : 0.0;
      if (ms != nullptr && ms->hasEmissionBins()) ms->emissionShares(T, theta[i], shares.data());
      if (withHarmonics) ms->emissionHarmonics(T, theta[i], harmonics.data());
      for (std::size_t k = 0; k < bins; ++k) {
        L1[i * bins + k] = albedo * o1[k] + f * harmonics[k];
        L[i * bins + k] = albedo * o1[k] + f * shares[k];
      }
    }
    // E_k(μ_j) = Σ_i L_k(θ_i) wE[j][i] and G_k(μ_j) = Σ_i L¹_k(θ_i) wG[j][i] (the weights below),
    // then fitted in fogLightBasis's functions (fitBasis).
    std::vector<double> E(kFitNodes), G(kFitNodes);
    for (std::size_t k = 0; k < bins; ++k) {
      double gMax = 0.0;
      for (std::size_t j = 0; j < kFitNodes; ++j) {
        const double* we = wE.data() + j * kThetaNodes;
        const double* wg = wG.data() + j * kThetaNodes;
        double e = 0.0, g = 0.0;
        for (std::size_t i = 1; i < kThetaNodes; ++i) {
          e += L[i * bins + k] * we[i];
          g += L1[i * bins + k] * wg[i];
        }
        E[j] = e;
        G[j] = g;
        gMax = std::max(gMax, g);
      }
      double c[kCoefficients];
      fitBasis(E, E.back(), false, c);
      fitBasis(G, gMax, true, c + kSymmetric);
      // Stored as log E_k(1) (the envelope: positive, falls as e^{−T}) and the coefficients over
      // it (bounded), so that T interpolates smoothly.
      const double env = E.back();
      t->logEnv_[iT * bins + k] = std::log(std::max(env, 1e-300));
      for (std::size_t q = 0; q < kCoefficients; ++q)
        t->norm_[(iT * bins + k) * kCoefficients + q] = env > 0.0 ? c[q] / env : 0.0;
    }
  };
  parallelFor(pool, kTNodes, node);
  // The dense table the frames read: the log-linear interpolation above, resampled where linear
  // interpolation is within 0.1 % of it (T every 2^(1/16) below 1, every 1/16 above), so that a
  // look-up is a lerp of two rows, without an exp per bin.
  t->dense_.resize(kDenseNodes * bins * kCoefficients);
  std::vector<double> row(bins * kCoefficients);
  for (std::size_t i = 0; i < kDenseNodes; ++i) {
    t->smoothCoefficients(denseT(i), row.data());
    for (std::size_t q = 0; q < row.size(); ++q) t->dense_[i * row.size() + q] = static_cast<float>(row[q]);
  }
  t->denseSum_.assign(kDenseNodes * kSymmetric, 0.0f);
  for (std::size_t i = 0; i < kDenseNodes; ++i)
    for (std::size_t k = 0; k < bins; ++k)
      for (std::size_t q = 0; q < kSymmetric; ++q)
        t->denseSum_[i * kSymmetric + q] += t->dense_[(i * bins + k) * kCoefficients + q];
  t->buildSeconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return std::shared_ptr<const FogLightTable>(std::move(t));
}

namespace {
using TableCacheKey = std::tuple<const void*, PhaseIdentity, double>;
// The tables alive in this process (get() and shipped()), the 4 most recent kept regardless.
SharedCache<TableCacheKey, FogLightTable>& tableCache() {
  static SharedCache<TableCacheKey, FogLightTable> cache(4);
  return cache;
}
}  // namespace

std::string FogLightTable::toBytes() const {
  // The table cache's own layout (detail::Writer: each array's count, then its elements).
  detail::Writer w;
  w.array(std::vector<double>{albedo_});
  for (const std::vector<double>* v : {&edges_, &t_, &logEnv_, &norm_}) w.array(*v);
  w.array(dense_);
  w.array(denseSum_);
  return std::move(w.data());
}

std::shared_ptr<const FogLightTable> FogLightTable::fromBytes(std::string_view in, const std::vector<double>& wantEdges,
                                                              double albedo) {
  std::shared_ptr<FogLightTable> t(new FogLightTable());
  detail::Reader r(in.data(), in.size());
  // Each array exactly `want` long (Reader::array bounds it by want and by the bytes left).
  auto exactly = [&r](auto& v, std::size_t want) { return r.array(v, want) && v.size() == want; };
  std::vector<double> a;
  const std::size_t edges = wantEdges.size();
  if (edges < 2 || !exactly(a, 1) || a[0] != albedo) return nullptr;
  t->albedo_ = albedo;
  const std::size_t bins = edges - 1, nT = static_cast<std::size_t>(kTNodes);
  if (!exactly(t->edges_, edges) || !exactly(t->t_, nT) || !exactly(t->logEnv_, nT * bins) ||
      !exactly(t->norm_, nT * bins * kCoefficients) || !exactly(t->dense_, kDenseNodes * bins * kCoefficients) ||
      !exactly(t->denseSum_, kDenseNodes * kSymmetric) || r.at() != in.size() || t->edges_ != wantEdges)
    return nullptr;
  return t;
}

namespace {
// The shipped table is a function of the phase function alone (the embedded tables, blended
// between their g nodes): the key is the phase and the albedo; the code hash covers the shipped
// tables' files and their code.
detail::TableKey shippedKey(const Phase& phase, double albedo) {
  detail::TableKey key;
  key.add("fog-light-table").addPhase(phase).add(albedo);
  return key;
}
}  // namespace

std::shared_ptr<const FogLightTable> FogLightTable::loadShipped(const Phase& phase, double albedo,
                                                                const std::string& cacheDir) {
  const auto ms = shippedMultipleScatteringTable(phase);
  if (!ms || cacheDir.empty()) return nullptr;
  const auto t0 = std::chrono::steady_clock::now();
  std::string bytes;
  if (!detail::loadBytes(cacheDir, "fl", shippedKey(phase, albedo), bytes)) return nullptr;
  auto loaded = fromBytes(bytes, ms->hasEmissionBins() ? ms->emissionEdges() : std::vector<double>{0.0, kPi}, albedo);
  if (loaded)
    std::const_pointer_cast<FogLightTable>(loaded)->buildSeconds_ =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return loaded;
}

Result<std::shared_ptr<const FogLightTable>> FogLightTable::shipped(const Phase& phase, double albedo, ThreadPool* pool,
                                                                    const std::string& cacheDir, std::string* cacheError) {
  const auto ms = shippedMultipleScatteringTable(phase);
  if (!ms) return Error{"fog light: no shipped multiple-scattering table for this phase function"};
  if (cacheDir.empty()) return get(ms, phase, albedo, pool);
  std::string error;
  auto table = tableCache().get(
      TableCacheKey{ms.get(), phaseIdentity(phase), albedo},
      [&]() -> std::shared_ptr<const FogLightTable> {
        if (auto loaded = loadShipped(phase, albedo, cacheDir)) return loaded;
        auto built = build(*ms, phase, albedo, pool);
        if (!built) {
          error = built.error().message;
          return nullptr;
        }
        if (Status st = detail::storeBytes(cacheDir, "fl", shippedKey(phase, albedo), (*built)->toBytes());
            !st && cacheError != nullptr)
          *cacheError = st.error().message;
        return std::move(built).value();
      },
      ms);
  if (!table) return Error{error.empty() ? "fog light: table build failed" : error};
  return table;
}

Result<std::shared_ptr<const FogLightTable>> FogLightTable::get(const std::shared_ptr<const MultipleScatteringTable>& ms,
                                                                const Phase& phase, double albedo, ThreadPool* pool) {
  if (!ms) return Error{"fog light: no multiple-scattering table"};
  std::string error;
  auto table = tableCache().get(
      TableCacheKey{ms.get(), phaseIdentity(phase), albedo},
      [&]() -> std::shared_ptr<const FogLightTable> {
        auto built = build(*ms, phase, albedo, pool);
        if (!built) {
          error = built.error().message;
          return nullptr;
        }
        return std::move(built).value();
      },
      ms);
  if (!table) return Error{error.empty() ? "fog light: table build failed" : error};
  return table;
}

void FogLightTable::smoothCoefficients(double opticalDistance, double* c) const noexcept {
  const std::size_t bins = this->bins();
  const double T = opticalDistance;
  if (!(T > 0.0) || T > t_.back()) {
    for (std::size_t i = 0; i < bins * kCoefficients; ++i) c[i] = 0.0;
    return;
  }
  const double x = std::max(0.0, (std::log2(T) - kLogFirst) * kPerOctave);
  const std::size_t i0 = std::min(static_cast<std::size_t>(x), t_.size() - 2);
  const double w = std::min(x - static_cast<double>(i0), 1.0);
  const double below = T < t_.front() ? t_.front() / T : 1.0;  // ∝ 1/T below the first node
  for (std::size_t k = 0; k < bins; ++k) {
    const std::size_t a = i0 * bins + k, b = (i0 + 1) * bins + k;
    const double env = below * std::exp((1.0 - w) * logEnv_[a] + w * logEnv_[b]);
    for (std::size_t q = 0; q < kCoefficients; ++q)
      c[k * kCoefficients + q] = env * ((1.0 - w) * norm_[kCoefficients * a + q] + w * norm_[kCoefficients * b + q]);
  }
}

bool FogLightTable::denseRow(double opticalDistance, std::size_t& row, double& weight, double& below) const noexcept {
  const double T = opticalDistance;
  if (!(T > 0.0) || T > t_.back()) return false;
  const double x = denseIndex(T);
  row = std::min(static_cast<std::size_t>(x), kDenseNodes - 2);
  weight = std::min(x - static_cast<double>(row), 1.0);
  below = T < t_.front() ? t_.front() / T : 1.0;  // ∝ 1/T below the first node
  return true;
}

void FogLightTable::coefficients(double opticalDistance, double* c) const noexcept {
  const std::size_t n = bins() * kCoefficients;
  std::size_t i0 = 0;
  double w = 0.0, below = 1.0;
  if (!denseRow(opticalDistance, i0, w, below)) {
    for (std::size_t i = 0; i < n; ++i) c[i] = 0.0;
    return;
  }
  const float* a = dense_.data() + i0 * n;
  const float* b = a + n;
  for (std::size_t q = 0; q < n; ++q) c[q] = below * ((1.0 - w) * double(a[q]) + w * double(b[q]));
}

void FogLightTable::weighted(double opticalDistance, const float* binMeans, const float* binDipoles, float scale,
                             float* out) const noexcept {
  const std::size_t bins = this->bins(), n = bins * kCoefficients;
  for (std::size_t q = 0; q < kLampFloats; ++q) out[q] = 0.0f;
  std::size_t i0 = 0;
  double wd = 0.0, below = 1.0;
  if (!denseRow(opticalDistance, i0, wd, below)) return;
  const auto w = static_cast<float>(wd);
  const float s = scale * static_cast<float>(below);
  if (binMeans == nullptr) {  // an isotropic lamp: every bin's mean is 1, the rows' sums over bins
    const float* a = denseSum_.data() + i0 * kSymmetric;
    for (std::size_t q = 0; q < kSymmetric; ++q) out[q] = s * (a[q] + w * (a[q + kSymmetric] - a[q]));
    return;
  }
  // Rows blended first (one lerp per bin and coefficient), then weighed by the bins' means and
  // dipoles. Flat loops the compiler vectorises: the lerps over all bins at once, then per bin
  // the four symmetric sums and, per dipole component e, the four sums D_q,e (kept as [e][q],
  // a vector each, and written as out's [q][e] at the end). Each sum adds its bins in the same
  // order as before: the same results to the bit (this runs per node and lamp of a frame).
  const float* a = dense_.data() + i0 * n;
  const float* b = a + n;
  constexpr std::size_t kMaxBins = 64;
  if (bins > kMaxBins) return;
  float c[kMaxBins * kCoefficients];
  for (std::size_t i = 0; i < n; ++i) c[i] = a[i] + w * (b[i] - a[i]);
  float sym[kSymmetric] = {}, dip[3][kSymmetric] = {};
  for (std::size_t k = 0; k < bins; ++k) {
    const float* ck = c + k * kCoefficients;
    for (std::size_t q = 0; q < kSymmetric; ++q) sym[q] += binMeans[k] * ck[q];
  }
  if (binDipoles != nullptr)
    for (std::size_t k = 0; k < bins; ++k) {
      const float* ck = c + k * kCoefficients + kSymmetric;
      for (std::size_t e = 0; e < 3; ++e) {
        const float d = binDipoles[3 * k + e];
        for (std::size_t q = 0; q < kSymmetric; ++q) dip[e][q] += d * ck[q];
      }
    }
  for (std::size_t q = 0; q < kSymmetric; ++q) {
    out[q] = sym[q] * s;
    for (std::size_t e = 0; e < 3; ++e) out[kSymmetric + 3 * q + e] = dip[e][q] * s;
  }
}

double FogLightTable::irradiance(double opticalDistance, double mu, const double* binMeans,
                                 const double* dipoleDotN) const noexcept {
  const std::size_t bins = this->bins();
  double c[64 * kCoefficients];
  if (bins > 64) return 0.0;
  coefficients(opticalDistance, c);
  double s[kCoefficients] = {};
  for (std::size_t k = 0; k < bins; ++k)
    for (std::size_t q = 0; q < kCoefficients; ++q)
      s[q] += (q < kSymmetric ? binMeans[k] : (dipoleDotN != nullptr ? dipoleDotN[k] : 0.0)) * c[k * kCoefficients + q];
  double b[kSymmetric], bd[kSymmetric];
  fogLightBasis(mu, b, bd);
  double e = 0.0;
  for (std::size_t q = 0; q < kSymmetric; ++q) e += b[q] * s[q] + bd[q] * s[kSymmetric + q];
  return std::max(0.0, e);
}

namespace {
std::atomic<std::size_t> gMapBuilds{0};  // AnnulusMeanMap::buildsSoFar

// AnnulusMeanMap::shared's key: the profile by identity (SharedCache's owner ties the entry to
// it), frontOnly and the bin edges.
using MapKey = std::tuple<const Profile*, bool, std::vector<double>>;
SharedCache<MapKey, AnnulusMeanMap>& mapCache() {
  static SharedCache<MapKey, AnnulusMeanMap> cache(16);
  return cache;
}
}  // namespace

std::size_t AnnulusMeanMap::buildsSoFar() noexcept { return gMapBuilds.load(); }

std::shared_ptr<const AnnulusMeanMap> AnnulusMeanMap::shared(const std::shared_ptr<const Profile>& profile,
                                                             const std::vector<double>& edges, bool frontOnly,
                                                             ThreadPool* pool, const std::string& cacheDir,
                                                             std::string* cacheError) {
  return mapCache().get(
      MapKey{profile.get(), frontOnly, edges},
      [&] { return build(profile, edges, frontOnly, pool, cacheDir, cacheError); }, profile);
}

std::shared_ptr<const AnnulusMeanMap> AnnulusMeanMap::build(const std::shared_ptr<const Profile>& profile,
                                                            const std::vector<double>& edges,
                                                            bool frontOnly, ThreadPool* pool,
                                                            const std::string& cacheDir, std::string* cacheError) {
  std::shared_ptr<AnnulusMeanMap> m(new AnnulusMeanMap());
  m->bins_ = edges.size() - 1;
  m->nA_ = kMapFineRows + static_cast<int>(std::lround((kPi - kMapFineEnd) / kMapStep)) + 1;  // 0 … 180°
  m->nB_ = static_cast<int>(std::lround(2.0 * kPi / kMapStep)) + 1;  // 0 … 360°, the last = the first
  const std::size_t bins = m->bins_, nB = static_cast<std::size_t>(m->nB_);
  const std::size_t size = static_cast<std::size_t>(m->nA_) * nB * bins * kFloats;
  // What the map's values depend on besides the code (FOGBEAM_TABLE_CODE_HASH covers this file
  // and lamp_effects.cpp): the profile's data, the edges, frontOnly and the grid.
  detail::TableKey key;
  if (!cacheDir.empty()) {
    key.add("annulus-map").addProfile(*profile).add(static_cast<std::int64_t>(frontOnly ? 1 : 0));
    key.add(static_cast<std::int64_t>(m->nA_)).add(static_cast<std::int64_t>(m->nB_)).add(static_cast<std::int64_t>(kFloats));
    key.add(static_cast<std::int64_t>(edges.size()));
    for (double e : edges) key.add(e);
    if (detail::loadFloats(cacheDir, "am", key, m->v_) && m->v_.size() == size) {
      m->fromCache_ = true;
      return m;
    }
  }
  m->v_.assign(size, 0.0f);
  gMapBuilds.fetch_add(1);
  // The nodes' annuli as the glow's (cellAnnulusMeans): annuli ≥ 10° wide summed over the
  // profile's ~1.5° sphere cells, narrower ones sampled with azimuths ≤ 1.5° apart. Sampled at
  // 24 azimuths, as until 2026-11-28, a bin's mean was off by up to 38 % (high beam), 61 % (front
  // fog lamp) and 89 % (low beam) of itself plus 1 % of the largest bin, against 16 sub-annuli ×
  // 1 440 azimuths, at directions to road points 3–80 m ahead and behind a lamp; the cells, 4–5 %.
  const std::shared_ptr<const ProfileSphereCells> cells = sharedProfileSphereCells(profile);
  auto row = [&](std::size_t ia) {
    std::vector<double> out(bins);
    std::vector<Vec3> first(bins);
    const double a = mapAlpha(ia);
    for (std::size_t ib = 0; ib + 1 < nB; ++ib) {
      const double b = static_cast<double>(ib) * kMapStep;
      const Vec3 w{std::cos(a), std::sin(a) * std::cos(b), std::sin(a) * std::sin(b)};
      cellAnnulusMeans(*profile, cells.get(), w, edges.data(), bins, out.data(), frontOnly, nullptr, first.data());
      float* v = &m->v_[(ia * nB + ib) * bins * kFloats];
      for (std::size_t k = 0; k < bins; ++k) {
        v[kFloats * k] = static_cast<float>(out[k]);
        for (int e = 0; e < 3; ++e) v[kFloats * k + 1 + static_cast<std::size_t>(e)] = static_cast<float>(first[k][e]);
      }
    }
    std::copy_n(&m->v_[(ia * nB) * bins * kFloats], bins * kFloats, &m->v_[(ia * nB + nB - 1) * bins * kFloats]);
  };
  parallelFor(pool, static_cast<std::size_t>(m->nA_), row);
  if (!cacheDir.empty()) {
    if (Status st = detail::storeFloats(cacheDir, "am", key, m->v_); !st && cacheError != nullptr)
      *cacheError = st.error().message;
  }
  return m;
}

template <class T>
void AnnulusMeanMap::lookupInto(const Vec3& w, T* means, T* dipoles) const noexcept {
  const double a = fastAtan2(std::sqrt(w.y * w.y + w.z * w.z), w.x);
  double b = fastAtan2(w.z, w.y);
  if (b < 0.0) b += 2.0 * kPi;
  const double x = std::clamp(mapRow(a), 0.0, static_cast<double>(nA_ - 1));
  const double y = std::clamp(b / kMapStep, 0.0, static_cast<double>(nB_ - 1));
  const std::size_t ia = std::min(static_cast<std::size_t>(x), static_cast<std::size_t>(nA_ - 2));
  const std::size_t ib = std::min(static_cast<std::size_t>(y), static_cast<std::size_t>(nB_ - 2));
  const float u = static_cast<float>(x - static_cast<double>(ia)), v = static_cast<float>(y - static_cast<double>(ib));
  const std::size_t nB = static_cast<std::size_t>(nB_), node = bins_ * kFloats;
  const float* p00 = &v_[(ia * nB + ib) * node];
  const float* p01 = p00 + node;
  const float* p10 = p00 + nB * node;
  const float* p11 = p10 + node;
  const float w00 = (1 - u) * (1 - v), w01 = (1 - u) * v, w10 = u * (1 - v), w11 = u * v;
  // The four nodes' blocks blended in one pass over their floats (means and harmonics
  // interleaved, kFloats a bin): a loop the compiler vectorises, where one bin's four floats at a
  // time were read with a stride (the frame's fog light calls this per node and lamp). The same
  // sums in the same order as per float: the results are the same to the bit.
  constexpr std::size_t kMaxBins = 64;
  float at[kMaxBins * kFloats];
  const std::size_t nf = std::min(bins_, kMaxBins) * kFloats;
  for (std::size_t i = 0; i < nf; ++i) at[i] = w00 * p00[i] + w01 * p01[i] + w10 * p10[i] + w11 * p11[i];
  for (std::size_t k = 0; k < bins_; ++k) means[k] = k < kMaxBins ? static_cast<T>(at[kFloats * k]) : T(0);
  if (dipoles == nullptr) return;
  // The nodes' harmonics are perpendicular to their own directions: the blend's part along w
  // is the nodes' spread, not light on either side, and goes.
  for (std::size_t k = 0; k < bins_; ++k) {
    if (k >= kMaxBins) {
      for (std::size_t e = 0; e < 3; ++e) dipoles[3 * k + e] = T(0);
      continue;
    }
    const Vec3 h{at[kFloats * k + 1], at[kFloats * k + 2], at[kFloats * k + 3]};
    const Vec3 hp = h - glm::dot(h, w) * w;
    for (int e = 0; e < 3; ++e) dipoles[3 * k + static_cast<std::size_t>(e)] = static_cast<T>(hp[e]);
  }
}

void AnnulusMeanMap::lookup(const Vec3& w, float* means, float* dipoles) const noexcept { lookupInto(w, means, dipoles); }
void AnnulusMeanMap::lookup(const Vec3& w, double* means, double* dipoles) const noexcept {
  lookupInto(w, means, dipoles);
}

std::size_t FogLightFrame::floats() const noexcept {
  std::size_t n = 0;
  for (const Lamp& l : lamps) n += fogLightFloats(l);
  return n;
}

double fogLightLamp(const FogLightFrame& frame, std::size_t lamp, const Vec3& x, float* out) noexcept {
  const FogLightFrame::Lamp& L = frame.lamps[lamp];
  std::fill(out, out + fogLightFloats(L), 0.0f);
  const FogLightTable* table = frame.table;
  const Vec3 d = L.pos - x;
  const double r = glm::length(d);
  if (table == nullptr || table->bins() > 64) return r;
  const double kt = frame.extinction;
  if (!(r > 0.0) || kt * r > table->opticalDistances().back()) return r;
  const float kt2 = static_cast<float>(kt * kt);
  if (L.map != nullptr) {
    float means[64], dipoles[3 * 64];
    L.map->lookup(L.lampFromWorld * (-d / r), means, dipoles);  // from the lamp to x
    table->weighted(kt * r, means, dipoles, kt2, out);
    // The dipoles' sums are lamp-frame vectors: into the world (the camera-relative frame).
    const Mat3 worldFromLamp = glm::transpose(L.lampFromWorld);
    for (std::size_t q = 0; q < FogLightTable::kSymmetric; ++q) {
      float* v = out + FogLightTable::kSymmetric + 3 * q;
      const Vec3 wv = worldFromLamp * Vec3(v[0], v[1], v[2]);
      for (int e = 0; e < 3; ++e) v[e] = static_cast<float>(wv[e]);
    }
  } else {
    float all[kFogLightFloats];
    table->weighted(kt * r, nullptr, nullptr, kt2 * static_cast<float>(L.i0), all);
    std::copy_n(all, FogLightTable::kSymmetric, out);
  }
  return r;
}

double fogLightCoefficients(const FogLightFrame& frame, const Vec3& x, float* out) noexcept {
  double near = std::numeric_limits<double>::infinity();
  const double limit = frame.table != nullptr ? frame.table->opticalDistances().back() : 0.0;
  for (std::size_t l = 0; l < frame.lamps.size(); ++l) {
    const double r = fogLightLamp(frame, l, x, out);
    out += fogLightFloats(frame.lamps[l]);
    if (r > 0.0 && frame.extinction * r <= limit) near = std::min(near, r);
  }
  return near;
}

struct FogLightPrewarm::State {
  mutable std::mutex mutex;
  mutable std::condition_variable doneCv;
  bool done = false;
  std::atomic<bool> stop{false};  // the destructor: no map after the one in progress
  Summary summary;
  std::thread thread;
};

FogLightPrewarm::FogLightPrewarm(std::vector<Lamp> lamps, const Phase& phase, double albedo, unsigned threads,
                                 std::string cacheDir, std::function<void(const Summary&)> done)
    : state_(std::make_unique<State>()) {
  state_->thread = std::thread([st = state_.get(), lamps = std::move(lamps), phase, albedo, threads,
                                cacheDir = std::move(cacheDir), done = std::move(done)] {
    const auto start = std::chrono::steady_clock::now();
    Summary out;
    // Anything thrown here (memory) ends the prewarm, not the process: the frames then make
    // what is missing themselves, as without one.
    try {
      ThreadPool pool(threads);
      auto table = FogLightTable::shipped(phase, albedo, &pool, cacheDir, &out.error);
      if (table) {
        const std::vector<double>& edges = (*table)->edges();
        std::vector<std::pair<const Profile*, bool>> seen;
        for (const Lamp& l : lamps) {
          if (st->stop.load()) break;
          if (!l.profile || std::holds_alternative<IsotropicProfile>(l.profile->model())) continue;
          const std::pair<const Profile*, bool> key{l.profile.get(), l.frontOnly};
          if (std::find(seen.begin(), seen.end(), key) != seen.end()) continue;
          seen.push_back(key);
          out.maps.push_back(AnnulusMeanMap::shared(l.profile, edges, l.frontOnly, &pool, cacheDir, &out.error));
          if (out.maps.back()->fromCache()) ++out.loaded;
        }
      }
    } catch (const std::exception& e) {
      out.error = std::string("the prewarm stopped: ") + e.what();
    }
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (done) done(out);
    std::lock_guard lock(st->mutex);
    st->summary = std::move(out);
    st->done = true;
    st->doneCv.notify_all();
  });
}

FogLightPrewarm::~FogLightPrewarm() {
  state_->stop.store(true);
  if (state_->thread.joinable()) state_->thread.join();
}

bool FogLightPrewarm::ready() const {
  std::lock_guard lock(state_->mutex);
  return state_->done;
}

void FogLightPrewarm::wait() const {
  std::unique_lock lock(state_->mutex);
  state_->doneCv.wait(lock, [&] { return state_->done; });
}

const FogLightPrewarm::Summary& FogLightPrewarm::summary() const {
  wait();
  return state_->summary;
}

}  // namespace fogbeam
