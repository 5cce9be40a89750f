#include <fogbeam/physics/airlight_bound.hpp>
#include <fogbeam/physics/math.hpp>

#include <boost/math/quadrature/gauss.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

namespace fogbeam {

namespace {
// Relative headroom on every tabulated value: the quadrature of a smooth phase function over
// intervals of 0.044° is exact to rounding, so this only keeps rounding on the safe side.
constexpr double kSlack = 1.0 + 1e-9;
}  // namespace

AirlightBound::AirlightBound(const Phase& phase) : suffix_(kIntervals + 1, 0.0) {
  constexpr std::size_t n = kIntervals;
  const double step = kPi / static_cast<double>(n);
  auto at = [step](std::size_t j) { return static_cast<double>(j) * step; };
  auto p = [&](double alpha) { return evalPhase(phase, std::cos(alpha)); };
  // Interval integrals of p in the scattering angle, summed from π down: P at every node.
  std::vector<double> tail(n + 1, 0.0);
  for (std::size_t j = n; j-- > 0;)
    tail[j] = tail[j + 1] + boost::math::quadrature::gauss<double, 10>::integrate(p, at(j), at(j + 1));
  // Per interval j, a bound of P(γ)/sin γ over [γ_j, γ_{j+1}], t = γ_{j+1} − γ ∈ [0, Δ]:
  // P(γ) ≤ P(γ_{j+1}) + p̄_j t (p̄_j the largest p on the interval) and sin γ ≥ the chord
  // sin γ_{j+1} + t (sin γ_j − sin γ_{j+1})/Δ (sin is concave on [0, π]). The ratio of two
  // linear functions of t is monotone, so its largest value is at t = 0 or t = Δ. (P(γ_j)/sin γ_{j+1}
  // instead doubles the bound next to π, where both vanish.) p̄_j: the largest of 9 samples
  // with 0.1 % headroom (p changes by far less over 0.044°).
  std::vector<double> q(n, 0.0);
  for (std::size_t j = 0; j < n; ++j) {
    double pMax = 0.0;
    for (int s = 0; s <= 8; ++s) pMax = std::max(pMax, p(at(j) + step * s / 8.0));
    pMax *= 1.001;
    const double sinLo = std::sin(at(j)), sinHi = j + 1 == n ? 0.0 : std::sin(at(j + 1));
    const double atLo = sinLo > 0.0 ? (tail[j + 1] + pMax * step) / sinLo : std::numeric_limits<double>::infinity();
    const double atHi = sinHi > 0.0 ? tail[j + 1] / sinHi : 0.0;  // j = n − 1: 0/0, the t = Δ end decides
    q[j] = kSlack * std::max(atLo, atHi);
  }
  // Suffix maxima: the bound for every γ from node k on (P/sin γ rises again towards π for a
  // phase function that scatters back).
  suffix_[n] = 0.0;
  suffix_[n - 1] = q[n - 1];
  for (std::size_t k = n - 1; k-- > 0;) suffix_[k] = std::max(q[k], suffix_[k + 1]);
}

double AirlightBound::factor(double peakCd, double distance_m, double kt, double albedo) noexcept {
  if (!(distance_m > 0.0)) return std::numeric_limits<double>::infinity();
  return albedo * kt * peakCd * std::exp(-kt * distance_m) / distance_m;
}

double AirlightBound::scale(double gamma) const noexcept {
  if (!(gamma > 0.0)) return suffix_[0];
  const double k = std::floor(gamma / (kPi / kIntervals));
  if (k >= kIntervals - 1) return suffix_[std::size_t{kIntervals} - 1];
  return suffix_[static_cast<std::size_t>(k)];
}

double AirlightBound::coneHalfAngle(double factor, double limit) const noexcept {
  constexpr double kNever = kPi + 1.0;
  if (!(limit > 0.0) || !(factor < std::numeric_limits<double>::infinity())) return kNever;
  if (!(factor > 0.0)) return kPi / kIntervals;
  if (factor * suffix_[std::size_t{kIntervals} - 1] > limit) return kNever;
  // suffix_ does not rise: the first node from which the bound holds, by bisection.
  int lo = 1, hi = kIntervals - 1;  // suffix_[hi] passes
  while (lo < hi) {
    const int mid = (lo + hi) / 2;
    if (factor * suffix_[static_cast<std::size_t>(mid)] <= limit) hi = mid;
    else lo = mid + 1;
  }
  return hi * (kPi / kIntervals);
}

}  // namespace fogbeam
