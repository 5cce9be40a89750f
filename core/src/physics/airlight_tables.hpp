// fogbeam — precomputed tables behind the Seed and Accurate airlight methods (private).
//
// Two kinds, both built once and shared through shared_ptr:
//  * GMomentTable (per phase function): cumulative moments of G(k, θ) of eq. (3),
//        T_q(k, θ) = ∫_{−π/2}^{θ} θ'^q G(k, θ') dθ',  q = 0, 1, 2,
//    on a (k, θ) grid. G depends on the phase function only (not on K_t or Ω), so one
//    table serves every lamp in a given fog. Used by Accurate (exact phase peak) and, for
//    its Taylor coefficients c_q(k), by Seed.
//  * Great-circle tables (per profile): cumulative moments of I along great circles of
//    the lamp's direction sphere, the seed's "precomputed tables" (Lecocq et al. 2001).
#pragma once

#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/physics/profile.hpp>

#include <array>
#include <memory>
#include <vector>

namespace fogbeam::detail {

/// Cumulative G moments, cubic Hermite in θ (dT_q/dθ = θ^q G is stored too) and
/// Catmull-Rom in the k coordinate u = log1p(k/k0)/log1p(kmax/k0).
/// Rays whose whole integration range lies within this angle of θ = π/2 (the ray looks within
/// this angle of straight away from the lamp) are integrated directly, not from GMomentTable:
/// there T_q(θd) − T_q(θ0) is a small difference of large table values whose interpolation in
/// k (G changes with k on the scale k ≈ cos θ) it cannot resolve. Measured before this rule,
/// isotropic lamp 25.9 m behind the eye, HG g = 0.85, 100 m fog: accurate against reference
/// 3e-5 at 178° from the lamp, 1.9e-4 at 179°, 1.1e-3 at 179.5°, 29 % at 179.9°, 544 % at
/// 179.95°. The cone is kept narrow: direct integration costs 10–140 µs a ray.
inline constexpr double kAwayConeRad = 0.0175;  // 1°

class GMomentTable {
 public:
  GMomentTable(const Phase& phase, int nTheta, int nK, double kMax);

  /// Interpolation weights of the 4 k rows around k: computed once per ray, since every
  /// lookup along one ray shares its k = K_t h.
  struct KWeights {
    int row[4];
    double w[4];
  };
  [[nodiscard]] KWeights kWeights(double k) const noexcept;

  /// T_0, T_1, T_2 at (k, θ); k ∈ [0, kMax], θ ∈ [−π/2, π/2].
  [[nodiscard]] std::array<double, 3> cumulative(const KWeights& kw, double theta) const noexcept;
  [[nodiscard]] std::array<double, 3> cumulative(double k, double theta) const noexcept {
    return cumulative(kWeights(k), theta);
  }
  [[nodiscard]] double kMax() const noexcept { return kMax_; }
  [[nodiscard]] std::size_t bytes() const noexcept { return data_.size() * sizeof(double); }
  [[nodiscard]] int thetaNodes() const noexcept { return nTheta_; }
  [[nodiscard]] int kNodes() const noexcept { return nK_; }
  [[nodiscard]] double k0() const noexcept { return k0_; }
  [[nodiscard]] double logSpan() const noexcept { return logSpan_; }
  [[nodiscard]] const std::vector<double>& thetaGrid() const noexcept { return theta_; }
  /// T_0, T_1, T_2, G at (k row i, θ node j).
  [[nodiscard]] const double* cell(int i, int j) const noexcept {
    return data_.data() + (static_cast<std::size_t>(i) * static_cast<std::size_t>(nTheta_) + static_cast<std::size_t>(j)) * 4;
  }

 private:
  [[nodiscard]] double thetaAt(int j) const noexcept;

  int nTheta_, nK_;
  double kMax_, k0_, logSpan_;
  std::vector<double> theta_;  // grid nodes
  // data_[(i * nTheta + j) * 4 + {0,1,2,3}] = T0, T1, T2, G at (k_i, θ_j)
  std::vector<double> data_;
};

/// Seed: Taylor coefficients c0, c1, c2 of G(k, θ) at θ = 0, tabulated in k (linear).
class SeedCoefficients {
 public:
  SeedCoefficients(const Phase& phase, int nK, double kMax);
  [[nodiscard]] std::array<double, 3> at(double k) const noexcept;
  [[nodiscard]] std::size_t bytes() const noexcept { return c_.size() * sizeof(double); }

 private:
  int nK_;
  double kMax_;
  std::vector<double> c_;  // 3 per node
};

/// Moments ∫ θ^q I(w(θ)) dθ, q = 0..2, over [θ0, θd] along the circle w(θ) = cosθ n + sinθ t
/// (lamp frame), from cumulative tables. Symmetric profiles (spot) use a 2D table over the
/// circle's closest approach to the axis; general profiles a 3D table over plane orientation.
class GreatCircleMoments {
 public:
  GreatCircleMoments(const Profile& profile, double stepDeg);
  [[nodiscard]] std::array<double, 3> moments(const Vec3& n, const Vec3& t, double theta0,
                                              double thetaD) const noexcept;
  [[nodiscard]] std::size_t bytes() const noexcept { return data_.size() * sizeof(double); }

 private:
  // Moments ∫_a^b (φ − β)^q I dφ from the cumulative row `row` (φ ∈ [−π, π]), handling
  // ranges that leave [−π, π] by periodic wrap.
  [[nodiscard]] std::array<double, 3> rowMoments(const double* row, double a, double b, double beta) const noexcept;
  [[nodiscard]] std::array<double, 3> rowMomentsInside(const double* row, double a, double b, double beta) const noexcept;

  bool symmetric_ = false;
  int nPhi_ = 0;       // along-circle nodes (cells + 1) over [−π, π]
  int nA_ = 0, nB_ = 0;  // symmetric: nA_ = δ nodes; general: nA_ = ϑ nodes, nB_ = ϕ nodes
  double step_ = 0.0;  // radians
  std::vector<double> data_;  // rows of nPhi_ × 3 cumulative values
};

/// The tables an AirlightEvaluator holds (shared with other evaluators of the same fog or
/// profile); which are set depends on the method.
struct AirlightTables {
  std::shared_ptr<const GMomentTable> g;
  std::shared_ptr<const SeedCoefficients> seed;
  std::shared_ptr<const GreatCircleMoments> circles;
};

}  // namespace fogbeam::detail
