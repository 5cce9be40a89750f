// fogbeam — the airlight kernel of one eye–lamp pair expanded in a fixed basis along the
// lamp's great circles (private; used by PencilAirlight, airlight_pencil.hpp).
//
// Within the plane through the eye, the lamp and a view ray (a "spoke"), eq. (3) of Lecocq
// et al. 2001 reads, with ψ the angle at the lamp from the direction of the eye and γ the
// ray's angle from the eye→lamp direction (D = |S − O|, τ = K_t D, h = D sin γ, χ = ψ + γ the
// scattering angle, θ = ψ + γ − π/2):
//
//     L(ψd) = Ω K_t e^{−τ} / h · ∫_0^{ψd} M(ψ; γ, τ) I_s(ψ) dψ,
//     M(ψ; γ, τ) = exp(−τ (cos γ + sin γ tan(χ/2) − 1)) · p(cos χ),
//
// (e^{−τ(cos γ + sin γ tan(χ/2))} is the transmittance along lamp → point → eye, at least
// e^{−τ}). I_s(ψ), the profile along the spoke's circle, is the same for every ray of the spoke;
// M depends only on the ray's (γ, τ) and the phase function, not on the lamp, its pose or the
// fog's density beyond τ. So M is expanded once per phase function in cubic B-splines β_r(ψ)
// on fixed knots (dense at ψ = 0, where the forward peak of p sits when γ is small),
// M ≈ Σ_r u_r(γ, τ) β_r, tabulated over (γ, τ); each spoke projects its I_s on the basis once
// (∫ β_r I_s dψ), and a ray costs one short dot product instead of ~50–90 cumulative G-moment
// look-ups. Near ψ = π − γ (the ray's far end) M falls as e^{−2k/s}, s = π − γ − ψ,
// k = τ sin γ, a drop no fixed knot spacing resolves for small k; the expansion is therefore
// fitted and used only up to a knot ψc ≤ π − γ − w, w = min(π − γ, 0.1, 2 √(h k)) (h the
// widest knot step), and the rest is product-integrated as before.
//
// Measured against the per-ray accurate method (prototype, 400 rays of a 60° × 34° view, HG
// g = 0.85 and fog-mie, 30–300 m visibility, measured low beam oncoming at 8–150 m, behind the
// eye, and at the driver's own headlamp 2.2 m ahead): the expansion with this tail agrees with
// exact M to 1e-5 relative; the whole error is the spoke sampling's.
//
// Thread-safety: both classes are immutable once built.
#pragma once

#include <fogbeam/physics/medium.hpp>

#include <cmath>
#include <cstddef>
#include <memory>
#include <vector>

namespace fogbeam::detail {

/// Cubic B-splines on ψ ∈ [0, π], clamped at both ends; knots from 0.004 rad growing by 1.3×
/// up to steps of 0.06 rad (~60 functions).
class PsiBasis {
 public:
  PsiBasis();
  [[nodiscard]] int intervals() const noexcept { return static_cast<int>(knots_.size()) - 1; }
  [[nodiscard]] int functions() const noexcept { return intervals() + 3; }
  [[nodiscard]] double knot(int j) const noexcept { return knots_[static_cast<std::size_t>(j)]; }
  [[nodiscard]] double widestStep() const noexcept { return widest_; }
  [[nodiscard]] double knotCos(int j) const noexcept { return knotCos_[static_cast<std::size_t>(j)]; }
  [[nodiscard]] double knotSin(int j) const noexcept { return knotSin_[static_cast<std::size_t>(j)]; }
  /// The interval j with knot(j) ≤ ψ < knot(j + 1), clamped to [0, intervals() − 1].
  /// Inline: a few times per ray of the pencil (a binary search over ~60 knots was ~2 % of a
  /// traffic frame). A table holds the interval at the start of each of equal cells of [0, π),
  /// half the smallest knot step wide, so the answer is that entry or one either side of it.
  [[nodiscard]] int interval(double psi) const noexcept {
    if (psi >= 0.0 && psi < kPiCells) {
      const auto c = static_cast<std::size_t>(psi * cellsPerRad_);
      if (c < cellStart_.size()) {
        int j = cellStart_[c];  // off by one at most, also where ψ · cellsPerRad_ rounds across a cell
        if (psi >= knots_[static_cast<std::size_t>(j) + 1]) ++j;
        else if (psi < knots_[static_cast<std::size_t>(j)]) --j;
        return j < intervals() ? j : intervals() - 1;
      }
    }
    return intervalSearch(psi);
  }
  /// The values at ψ of the four functions j, j + 1, j + 2, j + 3 that live on interval j.
  /// Inline: the pencil's spoke projection calls it three times per piece and interval.
  void eval(int j, double psi, double b[4]) const noexcept {
    const double s = local(j, psi);
    const double* c = poly_.data() + static_cast<std::size_t>(j) * 16;
    for (int i = 0; i < 4; ++i, c += 4) b[i] = c[0] + s * (c[1] + s * (c[2] + s * c[3]));
  }
  /// Σ_i w[i] β_{j+i} on interval j as one cubic in s = (ψ − t_j)/(t_{j+1} − t_j):
  /// g[p] the coefficient of s^p.
  void combine(int j, const float w[4], double g[4]) const noexcept;
  /// s of ψ on interval j (for combine()'s cubic).
  [[nodiscard]] double local(int j, double psi) const noexcept {
    return (psi - knots_[static_cast<std::size_t>(j)]) * invStep_[static_cast<std::size_t>(j)];
  }

 private:
  void deBoor(int j, double psi, double b[4]) const noexcept;
  [[nodiscard]] int intervalSearch(double psi) const noexcept;
  static constexpr double kPiCells = 3.141592653589793;  // the cells cover [0, π)

  std::vector<int> cellStart_;  // interval(c / cellsPerRad_) for each cell c
  double cellsPerRad_ = 0.0;

  std::vector<double> knots_;   // t_0 = 0 < … < t_m = π
  std::vector<double> padded_;  // three 0s, the knots, three πs
  std::vector<double> invStep_; // 1 / (t_{j+1} − t_j)
  std::vector<double> knotCos_, knotSin_;
  // On interval j the four functions are cubics in s = (ψ − t_j)/(t_{j+1} − t_j):
  // poly_[(j · 4 + i) · 4 + p] is the coefficient of s^p of function j + i.
  std::vector<double> poly_;
  double widest_ = 0.0;
};

/// The one basis every table and spoke uses.
[[nodiscard]] const PsiBasis& psiBasis();

/// u_r(γ, τ) of M above, per phase function, on γ ∈ [0, π] (asinh axis, dense at 0) × τ ∈
/// [0, kTauMax] (log1p axis); bilinear.
class KernelTable {
 public:
  /// Beyond this optical eye–lamp distance a lamp's airlight is below e^{−50} of its
  /// intensity: rays fall back to product integration (which also covers them).
  static constexpr double kTauMax = 50.0;
  explicit KernelTable(const Phase& phase);

  struct Lookup {
    const float* row[4];  ///< the four nodes' coefficient rows (functions() floats each)
    float w[4];           ///< their bilinear weights
    int cut;              ///< the expansion holds on [0, knot(cut)] (the smallest of the four nodes')
    /// u_r at the looked-up (γ, τ): the nodes' rows blended.
    [[nodiscard]] float coefficient(int r) const noexcept {
      return w[0] * row[0][r] + w[1] * row[1][r] + w[2] * row[2][r] + w[3] * row[3][r];
    }
  };
  [[nodiscard]] Lookup lookup(double gamma, double tau) const noexcept { return lookupAt(gamma, tauPosition(tau)); }
  /// τ's position on the table's axis (a pencil's rays share one τ: computed once).
  [[nodiscard]] double tauPosition(double tau) const noexcept;
  [[nodiscard]] Lookup lookupAt(double gamma, double tauPos) const noexcept;

  /// The table at one τ (a pencil's rays share it): the bilinear blend split into its τ part,
  /// done once per pencil, and its γ part, per ray. rows[iγ · functions() + r] = the τ-blend of
  /// that γ node's two rows, cuts[iγ] = the smaller of their cuts: a ray then reads two rows of
  /// this 120 KB slice instead of four of the 19 MB table (the same values up to float
  /// rounding: bilinear interpolation is separable). `tauPos` from tauPosition(); the vectors'
  /// memory is reused.
  void sliceAt(double tauPos, std::vector<float>& rows, std::vector<int>& cuts) const;
  /// γ's position on the table's axis: node ig (≤ gammaNodes() − 2) and weight fu of ig + 1.
  void gammaPosition(double gamma, int& ig, double& fu) const noexcept;
  [[nodiscard]] int gammaNodeCount() const noexcept { return nG_; }
  /// An upper bound of the phase function over scattering angles [χ, π] (χ in radians; the
  /// largest sample at or beyond the node below χ, 1 024 nodes, doubled for what lies
  /// between nodes): bounds the light a ray's tail can hold (PencilAirlight).
  [[nodiscard]] double phaseBoundBeyond(double chi) const noexcept;
  [[nodiscard]] std::size_t bytes() const noexcept { return coef_.size() * sizeof(float) + cut_.size() * sizeof(int); }
  /// M of the header, for tests.
  [[nodiscard]] static double kernel(const Phase& phase, double psi, double gamma, double tau) noexcept;
  /// M's factors at (ψ, γ), none of which depends on τ: the phase function at χ = ψ + γ, the
  /// path excess max(cos γ + sin γ tan(χ/2) − 1, 0) (0 beyond χ = π) and whether χ is there.
  /// kernel() is exactly kernelFrom(τ, kernelFactors(ψ, γ)): a fit over many τ takes these once.
  struct Factors {
    double phase;
    double excess;
    bool beyond;
  };
  [[nodiscard]] static Factors kernelFactors(const Phase& phase, double psi, double gamma) noexcept;
  [[nodiscard]] static double kernelFrom(double tau, const Factors& f) noexcept {
    return tau <= 0.0 ? f.phase : f.beyond ? 0.0 : std::exp(-tau * f.excess) * f.phase;
  }

 private:
  int nG_ = 0, nT_ = 0, r_ = 0;
  double gScale_ = 0.0, tScale_ = 0.0;  // node index per unit of the γ and τ axes (lookup())
  std::vector<float> coef_;  // [(iγ · nT + iτ) · R + r]
  std::vector<int> cut_;     // [iγ · nT + iτ]
  std::vector<double> phaseTailMax_;  // [i]: max of p over nodes i … end (χ_i = π i / 1024)
};

/// The table of `phase`, built on first use (~0.5 s on 2 cores) and shared while someone holds
/// it (the most recent few are kept).
[[nodiscard]] std::shared_ptr<const KernelTable> kernelTableFor(const Phase& phase);

}  // namespace fogbeam::detail
