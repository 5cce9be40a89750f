#include <fogbeam/physics/glow.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace fogbeam {

Result<Apsf> Apsf::build(double opticalDistance, double q, double tolerance, int maxTerms) {
  if (!(opticalDistance >= minOpticalDistance()) || !std::isfinite(opticalDistance))
    return Error{"APSF: optical distance " + std::to_string(opticalDistance) + " below " +
                 std::to_string(minOpticalDistance()) + " (the series diverges as T^-m for T < 1)"};
  if (!(q >= 0.0 && q < 1.0)) return Error{"APSF: forward-scattering parameter q must be in [0, 1), got " + std::to_string(q)};
  Apsf a;
  a.t_ = opticalDistance;
  a.q_ = q;
  const double T = opticalDistance, lnT = std::log(T);
  // g_m = exp(−β_m T − (m + 1) ln T), β_m = (2m + 1)/m (1 − q^{m−1}); g_0 = 0.
  auto g = [&](int m) {
    if (m == 0) return 0.0;
    const double beta = (2.0 * m + 1.0) / m * (1.0 - std::pow(q, m - 1));
    return std::exp(-beta * T - (m + 1) * lnT);
  };
  double sum = 0.0, gm = g(0);
  for (int m = 0; m < maxTerms; ++m) {
    const double gm1 = g(m + 1);
    const double c = gm + gm1;
    a.coef_.push_back(c);
    sum += c;
    // The coefficients fall as T^{−m} once q^{m−1} is small: stop when the next ones cannot
    // matter (P_m is bounded by 1 in magnitude).
    if (m > 2 && c < tolerance * sum && gm1 < gm) return a;
    gm = gm1;
  }
  return Error{"APSF: the series did not converge in " + std::to_string(maxTerms) + " terms at T = " +
               std::to_string(T) + ", q = " + std::to_string(q)};
}

double Apsf::series(double cosTheta) const noexcept {
  // Σ c_m P_m(μ) with the three-term recurrence (m + 1) P_{m+1} = (2m + 1) μ P_m − m P_{m−1}.
  const double mu = std::clamp(cosTheta, -1.0, 1.0);
  double pPrev = 1.0, p = mu, sum = coef_.empty() ? 0.0 : coef_[0];
  for (std::size_t m = 1; m < coef_.size(); ++m) {
    sum += coef_[m] * p;
    const double md = static_cast<double>(m);
    const double pNext = ((2.0 * md + 1.0) * mu * p - md * pPrev) / (md + 1.0);
    pPrev = p;
    p = pNext;
  }
  return sum;
}

double Apsf::netFluxRatio() const noexcept { return coef_.size() > 1 ? coef_[1] * t_ * t_ : 0.0; }

double veilingLuminancePerLux(double angle_deg, double age_years, double pigmentation) noexcept {
  const double th = std::clamp(angle_deg, 0.1, 100.0);
  const double ageFactor = 1.0 + std::pow(age_years / 62.5, 4.0);
  return 10.0 / (th * th * th) + (5.0 / (th * th) + 0.1 * pigmentation / th) * ageFactor + 0.0025 * pigmentation;
}

}  // namespace fogbeam
