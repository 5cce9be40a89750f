// fogbeam — the airlight kernel expanded in B-splines along the lamp's great circles
// (airlight_kernel.hpp).
#include "airlight_kernel.hpp"

#include <fogbeam/physics/math.hpp>
#include <fogbeam/util/shared_cache.hpp>

#include <algorithm>
#include <cmath>
#include <thread>

namespace fogbeam::detail {

namespace {

// Knots: 0.004 rad first, ×1.3 per step up to 0.06 rad. The forward peak of p(cos χ) at χ → 0
// (HG g = 0.85: ~0.15 rad wide; fog-mie's diffraction lobe narrower) sits at ψ = 0 for rays
// next to the lamp's image; elsewhere M changes on scales of 0.2 rad and more (prototype: 44
// to 121 functions gave the same airlight within 1e-5).
constexpr double kFirstStep = 0.004, kStepRatio = 1.3, kWidestStep = 0.06;
// Tail next to ψ = π − γ left to product integration: w = min(π − γ, kTailMax, kTailC √(h k)).
constexpr double kTailMax = 0.1, kTailC = 2.0;
// Axes: γ on A asinh(γ/γ0) + γ/Δγ, about one node per unit (480 nodes: 2e-4 rad apart at 0,
// 2 % of γ up to ~0.5 rad, never more than 0.015 rad apart: near γ = π the fitted range
// π − γ − w is short and M changes with γ on its scale; an asinh axis alone, 0.05 rad apart there,
// put a following car's low beam 4e-3 off at the 95th percentile); τ on log1p(τ/τ0) (0.025
// apart at 0, 2.5 % of τ beyond a few). 480 × 160 nodes × 63 functions: 19 MB of floats.
constexpr double kGamma0 = 0.01, kGammaLog = 50.0, kGammaStep = 0.02, kTau0 = 1.0;
constexpr int kTauNodes = 160;

const double kGL3x[3] = {-0.7745966692414834, 0.0, 0.7745966692414834};
const double kGL3w[3] = {0.5555555555555556, 0.8888888888888888, 0.5555555555555556};

double gammaAxis(double gamma) { return kGammaLog * std::asinh(gamma / kGamma0) + gamma / kGammaStep; }
int gammaNodes() { return static_cast<int>(std::ceil(gammaAxis(kPi))) + 1; }
double gammaAt(double u) {
  double lo = 0.0, hi = kPi;  // gammaAxis is increasing: bisection
  for (int i = 0; i < 64; ++i) {
    const double mid = 0.5 * (lo + hi);
    (gammaAxis(mid) < u ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}
double tauScale() { return (kTauNodes - 1) / std::log1p(KernelTable::kTauMax / kTau0); }

/// The knot index up to which node (γ, τ) is fitted (see the header: the tail next to π − γ).
int cutOf(const PsiBasis& basis, double gamma, double tau) {
  const double k = tau * std::sin(gamma);
  const double w = std::min({kPi - gamma, kTailMax, kTailC * std::sqrt(basis.widestStep() * k)});
  const double psiC = kPi - gamma - w;
  int j = 0;
  while (j < basis.intervals() && basis.knot(j + 1) <= psiC) ++j;
  return j;
}

}  // namespace

PsiBasis::PsiBasis() {
  double x = 0.0, step = kFirstStep;
  knots_.push_back(0.0);
  while (x + step < kPi - 0.5 * step) {
    x += step;
    knots_.push_back(x);
    widest_ = std::max(widest_, step);
    step = std::min(step * kStepRatio, kWidestStep);
  }
  knots_.push_back(kPi);
  widest_ = std::max(widest_, kPi - x);
  // interval()'s cells: half the smallest knot step wide, so a cell and its rounding margin
  // hold at most one knot.
  double narrowest = kPi;
  for (std::size_t k = 0; k + 1 < knots_.size(); ++k) narrowest = std::min(narrowest, knots_[k + 1] - knots_[k]);
  cellsPerRad_ = 2.0 / narrowest;
  cellStart_.resize(static_cast<std::size_t>(std::ceil(kPi * cellsPerRad_)) + 1);
  for (std::size_t c = 0; c < cellStart_.size(); ++c) cellStart_[c] = intervalSearch(static_cast<double>(c) / cellsPerRad_);
  padded_ = {0.0, 0.0, 0.0};
  padded_.insert(padded_.end(), knots_.begin(), knots_.end());
  padded_.insert(padded_.end(), {kPi, kPi, kPi});
  // Each function is one cubic per interval: its coefficients from its values at s = 0, ⅓, ⅔, 1
  // (the inverse of that Vandermonde matrix, exact), so that eval() needs no division.
  const int m = intervals();
  for (double t : knots_) {
    knotCos_.push_back(std::cos(t));
    knotSin_.push_back(std::sin(t));
  }
  invStep_.resize(static_cast<std::size_t>(m));
  poly_.assign(static_cast<std::size_t>(m) * 16, 0.0);
  for (int j = 0; j < m; ++j) {
    const double a = knots_[static_cast<std::size_t>(j)], h = knots_[static_cast<std::size_t>(j) + 1] - a;
    invStep_[static_cast<std::size_t>(j)] = 1.0 / h;
    double v[4][4];  // v[k][i]: function j + i at s = k/3
    for (int k = 0; k < 4; ++k) deBoor(j, a + h * k / 3.0, v[k]);
    for (int i = 0; i < 4; ++i) {
      const double y0 = v[0][i], y1 = v[1][i], y2 = v[2][i], y3 = v[3][i];
      double* c = poly_.data() + (static_cast<std::size_t>(j) * 4 + static_cast<std::size_t>(i)) * 4;
      c[0] = y0;
      c[1] = (-11.0 * y0 + 18.0 * y1 - 9.0 * y2 + 2.0 * y3) / 2.0;
      c[2] = 9.0 * (2.0 * y0 - 5.0 * y1 + 4.0 * y2 - y3) / 2.0;
      c[3] = 27.0 * (-y0 + 3.0 * y1 - 3.0 * y2 + y3) / 6.0;
    }
  }
}

void PsiBasis::combine(int j, const float w[4], double g[4]) const noexcept {
  const double* c = poly_.data() + static_cast<std::size_t>(j) * 16;
  for (int p = 0; p < 4; ++p) g[p] = 0.0;
  for (int i = 0; i < 4; ++i, c += 4)
    for (int p = 0; p < 4; ++p) g[p] += static_cast<double>(w[i]) * c[p];
}

int PsiBasis::intervalSearch(double psi) const noexcept {
  const auto it = std::upper_bound(knots_.begin(), knots_.end(), psi);
  const int j = static_cast<int>(it - knots_.begin()) - 1;
  return std::clamp(j, 0, intervals() - 1);
}

void PsiBasis::deBoor(int j, double psi, double b[4]) const noexcept {
  // de Boor's recurrence for the cubic B-splines on padded interval k = j + 3.
  const std::size_t k = static_cast<std::size_t>(j) + 3;
  double left[4], right[4];
  b[0] = 1.0;
  for (std::size_t d = 1; d <= 3; ++d) {
    left[d] = psi - padded_[k + 1 - d];
    right[d] = padded_[k + d] - psi;
    double saved = 0.0;
    for (std::size_t r = 0; r < d; ++r) {
      const double tmp = b[r] / (right[r + 1] + left[d - r]);
      b[r] = saved + right[r + 1] * tmp;
      saved = left[d - r] * tmp;
    }
    b[d] = saved;
  }
}

const PsiBasis& psiBasis() {
  static const PsiBasis basis;
  return basis;
}

KernelTable::Factors KernelTable::kernelFactors(const Phase& phase, double psi, double gamma) noexcept {
  const double chi = psi + gamma;
  const bool beyond = chi >= kPi - 1e-12;
  // cos γ + sin γ tan(χ/2) − 1 ≥ 0: the path lamp → point → eye less the direct one, over D.
  const double excess = beyond ? 0.0 : std::max(std::cos(gamma) + std::sin(gamma) * std::tan(0.5 * chi) - 1.0, 0.0);
  return {evalPhase(phase, std::cos(chi)), excess, beyond};
}

double KernelTable::kernel(const Phase& phase, double psi, double gamma, double tau) noexcept {
  return kernelFrom(tau, kernelFactors(phase, psi, gamma));
}

KernelTable::KernelTable(const Phase& phase) : nG_(gammaNodes()), nT_(kTauNodes) {
  const PsiBasis& basis = psiBasis();
  r_ = basis.functions();
  constexpr int kPhaseNodes = 1024;
  phaseTailMax_.assign(kPhaseNodes + 1, 0.0);
  for (int i = kPhaseNodes; i >= 0; --i) {
    const double p = evalPhase(phase, std::cos(kPi * i / kPhaseNodes));
    phaseTailMax_[static_cast<std::size_t>(i)] = std::max(p, i < kPhaseNodes ? phaseTailMax_[static_cast<std::size_t>(i) + 1] : 0.0);
  }
  coef_.assign(static_cast<std::size_t>(nG_) * static_cast<std::size_t>(nT_) * static_cast<std::size_t>(r_), 0.0f);
  cut_.assign(static_cast<std::size_t>(nG_) * static_cast<std::size_t>(nT_), 0);
  // Nodes spaced so that the last γ node lands on π and the last τ node on kTauMax.
  gScale_ = (nG_ - 1) / gammaAxis(kPi);
  tScale_ = tauScale();
  const double gS = 1.0 / gScale_, tS = tScale_;
  // One least-squares fit per node, by row of γ on every core: the normal matrix of cubic
  // B-splines is banded (3 below the diagonal), so a banded Cholesky solves it.
  auto fitRow = [&](int ig) {
    const double gamma = gammaAt(ig * gS);
    std::vector<double> band(static_cast<std::size_t>(r_) * 4), rhs(static_cast<std::size_t>(r_));
    // The fit's sample points (3-point Gauss on both halves of every knot interval), their basis
    // values and what kernel() computes there that does not depend on τ (kernelFactors). Taken
    // once per γ row instead of once per (γ, τ) node (the phase function, cos, tan per sample
    // were most of the table's build); m below is then kernel()'s value bit for bit.
    const int nInt = basis.intervals();
    const auto nSamples = static_cast<std::size_t>(nInt) * 6;
    std::vector<double> sw(nSamples), sb(nSamples * 4);
    std::vector<Factors> sf(nSamples);
    for (int j = 0; j < nInt; ++j) {
      const double a = basis.knot(j), b = basis.knot(j + 1);
      for (int sub = 0; sub < 2; ++sub) {
        const double sa = a + 0.5 * sub * (b - a), half = 0.25 * (b - a), mid = sa + half;
        for (int g = 0; g < 3; ++g) {
          const auto q = static_cast<std::size_t>(j * 6 + sub * 3 + g);
          const double x = mid + half * kGL3x[g];
          sw[q] = half * kGL3w[g];
          basis.eval(j, x, sb.data() + 4 * q);
          sf[q] = kernelFactors(phase, x, gamma);
        }
      }
    }
    for (int it = 0; it < nT_; ++it) {
      const double tau = kTau0 * std::expm1(it / tS);
      const int cut = cutOf(basis, gamma, tau);
      const std::size_t node = static_cast<std::size_t>(ig) * static_cast<std::size_t>(nT_) + static_cast<std::size_t>(it);
      cut_[node] = cut;
      if (cut == 0) continue;
      const int n = cut + 3;  // functions with data on [0, knot(cut)]
      std::fill(band.begin(), band.end(), 0.0);
      std::fill(rhs.begin(), rhs.end(), 0.0);
      for (int j = 0; j < cut; ++j) {
        for (int sg = 0; sg < 6; ++sg) {
          const auto q = static_cast<std::size_t>(j * 6 + sg);
          const double w = sw[q];
          const double* bv = sb.data() + 4 * q;
          const double m = kernelFrom(tau, sf[q]);
          for (int i = 0; i < 4; ++i) {
            const std::size_t r = static_cast<std::size_t>(j + i);
            rhs[r] += w * bv[i] * m;
            for (int d = 0; d <= i; ++d) band[r * 4 + static_cast<std::size_t>(d)] += w * bv[i] * bv[i - d];
          }
        }
      }
      // A little ridge: the last functions have data only on the first interval of their support.
      double diag = 0.0;
      for (int r = 0; r < n; ++r) diag = std::max(diag, band[static_cast<std::size_t>(r) * 4]);
      for (int r = 0; r < n; ++r) band[static_cast<std::size_t>(r) * 4] += 1e-10 * diag;
      // Banded Cholesky, L stored over the band; then forward and back substitution.
      for (int r = 0; r < n; ++r) {
        for (int d = 3; d >= 0; --d) {
          const int c = r - d;
          if (c < 0) continue;
          double s = band[static_cast<std::size_t>(r) * 4 + static_cast<std::size_t>(d)];
          for (int e = 1; e <= 3 - d && c - e >= 0; ++e)
            s -= band[static_cast<std::size_t>(r) * 4 + static_cast<std::size_t>(d + e)] *
                 band[static_cast<std::size_t>(c) * 4 + static_cast<std::size_t>(e)];
          if (d == 0) band[static_cast<std::size_t>(r) * 4] = std::sqrt(std::max(s, 1e-300));
          else band[static_cast<std::size_t>(r) * 4 + static_cast<std::size_t>(d)] = s / band[static_cast<std::size_t>(c) * 4];
        }
      }
      for (int r = 0; r < n; ++r) {
        double s = rhs[static_cast<std::size_t>(r)];
        for (int d = 1; d <= 3 && r - d >= 0; ++d)
          s -= band[static_cast<std::size_t>(r) * 4 + static_cast<std::size_t>(d)] * rhs[static_cast<std::size_t>(r - d)];
        rhs[static_cast<std::size_t>(r)] = s / band[static_cast<std::size_t>(r) * 4];
      }
      for (int r = n - 1; r >= 0; --r) {
        double s = rhs[static_cast<std::size_t>(r)];
        for (int d = 1; d <= 3 && r + d < n; ++d)
          s -= band[static_cast<std::size_t>(r + d) * 4 + static_cast<std::size_t>(d)] * rhs[static_cast<std::size_t>(r + d)];
        rhs[static_cast<std::size_t>(r)] = s / band[static_cast<std::size_t>(r) * 4];
      }
      float* out = coef_.data() + node * static_cast<std::size_t>(r_);
      for (int r = 0; r < n; ++r) out[r] = static_cast<float>(rhs[static_cast<std::size_t>(r)]);
    }
  };
  const unsigned threads = std::max(1u, std::min(16u, std::thread::hardware_concurrency()));
  std::vector<std::thread> pool;
  for (unsigned t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (int ig = static_cast<int>(t); ig < nG_; ig += static_cast<int>(threads)) fitRow(ig);
    });
  for (std::thread& th : pool) th.join();
}

double KernelTable::tauPosition(double tau) const noexcept {
  return std::clamp(std::log1p(std::max(tau, 0.0) / kTau0) * tScale_, 0.0, nT_ - 1.0);
}

double KernelTable::phaseBoundBeyond(double chi) const noexcept {
  const auto n = static_cast<double>(phaseTailMax_.size() - 1);
  const double x = std::clamp(chi / kPi * n, 0.0, n);
  return 2.0 * phaseTailMax_[static_cast<std::size_t>(x)];
}

void KernelTable::gammaPosition(double gamma, int& ig, double& fu) const noexcept {
  const double u = std::clamp(gammaAxis(std::clamp(gamma, 0.0, kPi)) * gScale_, 0.0, nG_ - 1.0);
  ig = std::min(static_cast<int>(u), nG_ - 2);
  fu = u - ig;
}

void KernelTable::sliceAt(double v, std::vector<float>& rows, std::vector<int>& cuts) const {
  const int it = std::min(static_cast<int>(v), nT_ - 2);
  const auto fv = static_cast<float>(v - it), gv = 1.0f - fv;
  const auto r = static_cast<std::size_t>(r_);
  rows.resize(static_cast<std::size_t>(nG_) * r);
  cuts.resize(static_cast<std::size_t>(nG_));
  for (int ig = 0; ig < nG_; ++ig) {
    const std::size_t node = static_cast<std::size_t>(ig) * static_cast<std::size_t>(nT_) + static_cast<std::size_t>(it);
    const float* a = coef_.data() + node * r;
    const float* b = a + r;
    float* o = rows.data() + static_cast<std::size_t>(ig) * r;
    for (std::size_t k = 0; k < r; ++k) o[k] = gv * a[k] + fv * b[k];
    cuts[static_cast<std::size_t>(ig)] = std::min(cut_[node], cut_[node + 1]);
  }
}

KernelTable::Lookup KernelTable::lookupAt(double gamma, double v) const noexcept {
  int ig = 0;
  double fu = 0.0;
  gammaPosition(gamma, ig, fu);
  const int it = std::min(static_cast<int>(v), nT_ - 2);
  const double fv = v - it;
  Lookup l{};
  int cut = psiBasis().intervals();
  for (int c = 0; c < 4; ++c) {
    const std::size_t node = static_cast<std::size_t>(ig + (c >> 1)) * static_cast<std::size_t>(nT_) +
                             static_cast<std::size_t>(it + (c & 1));
    l.row[c] = coef_.data() + node * static_cast<std::size_t>(r_);
    l.w[c] = static_cast<float>(((c >> 1) ? fu : 1.0 - fu) * ((c & 1) ? fv : 1.0 - fv));
    cut = std::min(cut, cut_[node]);
  }
  l.cut = cut;
  return l;
}

std::shared_ptr<const KernelTable> kernelTableFor(const Phase& phase) {
  // The 4 most recent stay alive while fogs alternate; one build at a time, the others wait.
  static SharedCache<PhaseIdentity, KernelTable> cache(4);
  return cache.get(phaseIdentity(phase), [&] { return std::make_shared<const KernelTable>(phase); });
}

}  // namespace fogbeam::detail
