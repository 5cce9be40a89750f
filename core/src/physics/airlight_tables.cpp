#include "airlight_tables.hpp"

#include <fogbeam/physics/airlight.hpp>  // integrandG

#include <boost/math/quadrature/gauss.hpp>

#include <algorithm>
#include <cmath>

namespace fogbeam::detail {

namespace {

constexpr double kHalfPi = 0.5 * kPi;
constexpr double kTwoPi = 2.0 * kPi;
// k coordinate: u = log1p(k/k0) / log1p(kmax/k0). k0 sets where the grid turns from linear to
// logarithmic; 0.02 resolves lamps close to the ray in thin fog (K_t h ≈ 0.001…0.1).
constexpr double kK0 = 0.02;

// Integrates f over [a, b] with 8-point Gauss–Legendre (Boost's nodes); the callers apply it
// to grid cells small enough that the integrand is smooth on each.
template <class F>
void gaussCell(double a, double b, F&& f) {
  using GL = boost::math::quadrature::gauss<double, 8>;
  const auto& x = GL::abscissa();
  const auto& w = GL::weights();
  const double c = 0.5 * (a + b), r = 0.5 * (b - a);
  for (std::size_t i = 0; i < x.size(); ++i) {
    f(c - r * x[i], r * w[i]);
    f(c + r * x[i], r * w[i]);
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
GMomentTable::GMomentTable(const Phase& phase, int nTheta, int nK, double kMax)
    : nTheta_(nTheta), nK_(nK), kMax_(kMax), k0_(kK0), logSpan_(std::log1p(kMax / kK0)) {
  // θ nodes cluster at both ends (Chebyshev-like): the forward phase peak sits at θ → −π/2 and
  // the exponential e^{−k s(θ)} falls off fastest at θ → +π/2.
  theta_.resize(static_cast<std::size_t>(nTheta_));
  for (int j = 0; j < nTheta_; ++j) theta_[static_cast<std::size_t>(j)] = thetaAt(j);
  data_.assign(static_cast<std::size_t>(nK_) * static_cast<std::size_t>(nTheta_) * 4, 0.0);
  // The quadrature's samples (gaussCell's 8 per cell, in its order) and G's k-independent factors
  // there and at the nodes, once: each k row then needs one exp per sample, not a phase function,
  // a sine and a tangent as well (integrandG, bit for bit: GFactors). 73 → 21 ms for HG 0.85.
  struct Sample {
    double x, w;
    GFactors f;
  };
  std::vector<Sample> samples;
  samples.reserve(static_cast<std::size_t>(nTheta_) * 8);
  std::vector<GFactors> nodeF(static_cast<std::size_t>(nTheta_));
  for (int j = 0; j < nTheta_; ++j) {
    const double th = theta_[static_cast<std::size_t>(j)];
    if (j > 0)
      gaussCell(theta_[static_cast<std::size_t>(j - 1)], th,
                [&](double x, double w) { samples.push_back({x, w, integrandGFactors(phase, x)}); });
    nodeF[static_cast<std::size_t>(j)] = integrandGFactors(phase, th);
  }
  const std::size_t perCell = samples.size() / static_cast<std::size_t>(std::max(nTheta_ - 1, 1));
  for (int i = 0; i < nK_; ++i) {
    const double u = static_cast<double>(i) / (nK_ - 1);
    const double k = k0_ * std::expm1(u * logSpan_);
    double* row = data_.data() + static_cast<std::size_t>(i) * static_cast<std::size_t>(nTheta_) * 4;
    double t0 = 0.0, t1 = 0.0, t2 = 0.0;
    const Sample* smp = samples.data();
    for (int j = 0; j < nTheta_; ++j) {
      if (j > 0) {
        for (std::size_t q = 0; q < perCell; ++q, ++smp) {
          const double gw = integrandGFrom(k, smp->f) * smp->w;
          t0 += gw;
          t1 += gw * smp->x;
          t2 += gw * smp->x * smp->x;
        }
      }
      double* cell = row + 4 * j;
      cell[0] = t0;
      cell[1] = t1;
      cell[2] = t2;
      cell[3] = integrandGFrom(k, nodeF[static_cast<std::size_t>(j)]);
    }
  }
}

double GMomentTable::thetaAt(int j) const noexcept {
  const double tau = static_cast<double>(j) / (nTheta_ - 1);
  return -kHalfPi + kHalfPi * (1.0 - std::cos(kPi * tau));
}

GMomentTable::KWeights GMomentTable::kWeights(double k) const noexcept {
  const double u = std::log1p(std::max(k, 0.0) / k0_) / logSpan_ * (nK_ - 1);
  int i = std::clamp(static_cast<int>(u), 0, nK_ - 2);
  const double t = std::clamp(u - i, 0.0, 1.0);
  // Catmull-Rom: cubic in u through 4 neighbouring rows (clamped at the ends).
  const double t2 = t * t, t3 = t2 * t;
  KWeights kw{};
  const double w[4] = {0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2), 0.5 * (-3 * t3 + 4 * t2 + t),
                       0.5 * (t3 - t2)};
  for (int r = 0; r < 4; ++r) {
    kw.row[r] = std::clamp(i - 1 + r, 0, nK_ - 1);
    kw.w[r] = w[r];
  }
  return kw;
}

std::array<double, 3> GMomentTable::cumulative(const KWeights& kw, double theta) const noexcept {
  theta = std::clamp(theta, -kHalfPi, kHalfPi);
  const double x = std::clamp(1.0 - 2.0 * (theta + kHalfPi) / kPi, -1.0, 1.0);
  // The cell: node j = acos(x)/π · (n − 1) (thetaAt). acos is ~20 ns, a large part of a ray's
  // tail (this is called per cut and per distance): Abramowitz & Stegun 4.4.45,
  // acos(x) = √(1 − x) · P7(x) on [0, 1] within 2e-8 rad (~1e-5 of a cell at 2 048 nodes), gives
  // the cell or a neighbour, and the comparisons with the nodes that follow make it exact (the
  // value is then the same as with std::acos but at cell boundaries, where both agree to rounding).
  const double ax = std::abs(x);
  double ac = std::sqrt(1.0 - ax) *
              (1.5707963050 +
               ax * (-0.2145988016 +
                     ax * (0.0889789874 +
                           ax * (-0.0501743046 +
                                 ax * (0.0308918810 + ax * (-0.0170881256 + ax * (0.0066700901 - ax * 0.0012624911)))))));
  if (x < 0.0) ac = kPi - ac;
  int j = std::clamp(static_cast<int>(ac / kPi * (nTheta_ - 1)), 0, nTheta_ - 2);
  while (j > 0 && theta < theta_[static_cast<std::size_t>(j)]) --j;
  while (j < nTheta_ - 2 && theta >= theta_[static_cast<std::size_t>(j + 1)]) ++j;
  const double a = theta_[static_cast<std::size_t>(j)], b = theta_[static_cast<std::size_t>(j + 1)];
  const double dt = b - a;
  const double s = std::clamp((theta - a) / dt, 0.0, 1.0);
  // Cubic Hermite basis in θ; the derivative of T_q is θ^q G. Four lanes per row, (T_0, T_1,
  // T_2, G) as stored, so that the compiler keeps each row's sum in vector registers: lane 3
  // carries a value nobody reads. (Written as three scalar sums with the derivatives formed
  // per row, this took ~70 ns a call, most of a view table's build and of an ego lamp's tail.)
  const double s2 = s * s, s3 = s2 * s;
  const double h00 = 2 * s3 - 3 * s2 + 1, h10 = (s3 - 2 * s2 + s) * dt, h01 = -2 * s3 + 3 * s2,
               h11 = (s3 - s2) * dt;
  const double pa[4] = {1.0, a, a * a, 0.0}, pb[4] = {1.0, b, b * b, 0.0};
  double acc[4] = {0.0, 0.0, 0.0, 0.0};
  for (int r = 0; r < 4; ++r) {
    const double* c0 = data_.data() + (static_cast<std::size_t>(kw.row[r]) * static_cast<std::size_t>(nTheta_) +
                                       static_cast<std::size_t>(j)) * 4;
    const double* c1 = c0 + 4;
    const double ga = h10 * c0[3], gb = h11 * c1[3], wr = kw.w[r];
    for (int q = 0; q < 4; ++q) acc[q] += wr * (h00 * c0[q] + h01 * c1[q] + ga * pa[q] + gb * pb[q]);
  }
  return {acc[0], acc[1], acc[2]};
}

// ---------------------------------------------------------------------------------------------
SeedCoefficients::SeedCoefficients(const Phase& phase, int nK, double kMax) : nK_(nK), kMax_(kMax) {
  // Lecocq et al. 2001, eq. (4): G(k, θ) ≈ c0 + c1 θ + c2 θ², the Taylor expansion at θ = 0.
  // Central differences with δ = 1e-4 rad: truncation error δ² ≈ 1e-8 relative.
  constexpr double d = 1e-4;
  c_.resize(static_cast<std::size_t>(nK_) * 3);
  for (int i = 0; i < nK_; ++i) {
    const double k = kK0 * std::expm1(static_cast<double>(i) / (nK_ - 1) * std::log1p(kMax_ / kK0));
    const double gm = integrandG(phase, k, -d), g0 = integrandG(phase, k, 0.0), gp = integrandG(phase, k, d);
    c_[static_cast<std::size_t>(3 * i)] = g0;
    c_[static_cast<std::size_t>(3 * i + 1)] = (gp - gm) / (2 * d);
    c_[static_cast<std::size_t>(3 * i + 2)] = (gp - 2 * g0 + gm) / (2 * d * d);
  }
}

std::array<double, 3> SeedCoefficients::at(double k) const noexcept {
  const double x = std::clamp(std::log1p(std::max(k, 0.0) / kK0) / std::log1p(kMax_ / kK0), 0.0, 1.0) * (nK_ - 1);
  const int i = std::clamp(static_cast<int>(x), 0, nK_ - 2);
  const double t = x - i;
  std::array<double, 3> c{};
  for (std::size_t q = 0; q < 3; ++q)
    c[q] = (1 - t) * c_[static_cast<std::size_t>(3 * i) + q] + t * c_[static_cast<std::size_t>(3 * (i + 1)) + q];
  return c;
}

// ---------------------------------------------------------------------------------------------
GreatCircleMoments::GreatCircleMoments(const Profile& profile, double stepDeg) {
  step_ = radians(stepDeg);
  nPhi_ = static_cast<int>(std::lround(kTwoPi / step_)) + 1;
  step_ = kTwoPi / (nPhi_ - 1);
  symmetric_ = std::holds_alternative<SpotProfile>(profile.model());

  auto fillRow = [&](double* row, auto&& circlePoint) {
    double n0 = 0.0, n1 = 0.0, n2 = 0.0;
    for (int j = 0; j < nPhi_; ++j) {
      const double phi = -kPi + j * step_;
      if (j > 0) {
        gaussCell(phi - step_, phi, [&](double x, double w) {
          const double v = profile.intensity(circlePoint(x)) * w;
          n0 += v;
          n1 += v * x;
          n2 += v * x * x;
        });
      }
      row[3 * j] = n0;
      row[3 * j + 1] = n1;
      row[3 * j + 2] = n2;
    }
  };
  const std::size_t rowSize = static_cast<std::size_t>(nPhi_) * 3;

  if (symmetric_) {
    // Axially symmetric I(ψ): along any great circle, I depends only on the arc φ from the
    // circle's point closest to the axis and on that closest angle δ (cos ψ = cos δ cos φ).
    nA_ = static_cast<int>(std::lround(kHalfPi / step_)) + 1;
    nB_ = 1;
    data_.resize(static_cast<std::size_t>(nA_) * rowSize);
    for (int i = 0; i < nA_; ++i) {
      const double delta = std::min(kHalfPi, i * step_);
      const double cd = std::cos(delta), sd = std::sin(delta);
      // A circle at angular distance δ from +x: points (cosδ cosφ, sinφ, sinδ cosφ).
      fillRow(data_.data() + static_cast<std::size_t>(i) * rowSize,
              [&](double phi) { return Vec3(cd * std::cos(phi), std::sin(phi), sd * std::cos(phi)); });
    }
  } else {
    // Plane normals m on the upper hemisphere, lat-long (ϑ from +z, ϕ about z); circle basis
    // e1 = (−sin ϕ, cos ϕ, 0), e2 = m × e1.
    nA_ = static_cast<int>(std::lround(kHalfPi / step_)) + 1;
    nB_ = static_cast<int>(std::lround(kTwoPi / step_));
    const double dA = kHalfPi / (nA_ - 1), dB = kTwoPi / nB_;
    data_.resize(static_cast<std::size_t>(nA_) * static_cast<std::size_t>(nB_) * rowSize);
    for (int i = 0; i < nA_; ++i) {
      for (int j = 0; j < nB_; ++j) {
        const double th = i * dA, ph = j * dB;
        const Vec3 m(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
        const Vec3 e1(-std::sin(ph), std::cos(ph), 0.0);
        const Vec3 e2 = glm::cross(m, e1);
        fillRow(data_.data() + (static_cast<std::size_t>(i) * static_cast<std::size_t>(nB_) + static_cast<std::size_t>(j)) * rowSize,
                [&](double phi) { return std::cos(phi) * e1 + std::sin(phi) * e2; });
      }
    }
  }
}

std::array<double, 3> GreatCircleMoments::rowMomentsInside(const double* row, double a, double b,
                                                           double beta) const noexcept {
  auto cumAt = [&](double phi, double out[3]) {
    const double x = std::clamp((phi + kPi) / step_, 0.0, static_cast<double>(nPhi_ - 1));
    const int j = std::min(static_cast<int>(x), nPhi_ - 2);
    const double t = x - j;
    for (int q = 0; q < 3; ++q) out[q] = (1 - t) * row[3 * j + q] + t * row[3 * (j + 1) + q];
  };
  double na[3], nb[3];
  cumAt(a, na);
  cumAt(b, nb);
  const double d0 = nb[0] - na[0], d1 = nb[1] - na[1], d2 = nb[2] - na[2];
  return {d0, d1 - beta * d0, d2 - 2 * beta * d1 + beta * beta * d0};
}

std::array<double, 3> GreatCircleMoments::rowMoments(const double* row, double a, double b,
                                                     double beta) const noexcept {
  // Bring a into [−π, π), shifting β with it; the interval is at most π long, so it leaves
  // [−π, π] at most once, at +π.
  const double shift = kTwoPi * std::floor((a + kPi) / kTwoPi);
  a -= shift;
  b -= shift;
  beta -= shift;
  if (b <= kPi) return rowMomentsInside(row, a, b, beta);
  auto m1 = rowMomentsInside(row, a, kPi, beta);
  auto m2 = rowMomentsInside(row, -kPi, b - kTwoPi, beta - kTwoPi);
  return {m1[0] + m2[0], m1[1] + m2[1], m1[2] + m2[2]};
}

std::array<double, 3> GreatCircleMoments::moments(const Vec3& n, const Vec3& t, double theta0,
                                                  double thetaD) const noexcept {
  const std::size_t rowSize = static_cast<std::size_t>(nPhi_) * 3;
  if (symmetric_) {
    // w(θ)·x = R cos(θ − c): the closest approach is at θ = c, at angle δ = acos R.
    const double r = std::min(1.0, std::hypot(n.x, t.x));
    const double c = std::atan2(t.x, n.x);
    const double x = std::acos(r) / step_;
    const int i = std::clamp(static_cast<int>(x), 0, nA_ - 2);
    const double w = std::clamp(x - i, 0.0, 1.0);
    // φ = θ − c, so θ^q = (φ − β)^q with β = −c.
    const auto m0 = rowMoments(data_.data() + static_cast<std::size_t>(i) * rowSize, theta0 - c, thetaD - c, -c);
    const auto m1 = rowMoments(data_.data() + static_cast<std::size_t>(i + 1) * rowSize, theta0 - c, thetaD - c, -c);
    return {(1 - w) * m0[0] + w * m1[0], (1 - w) * m0[1] + w * m1[1], (1 - w) * m0[2] + w * m1[2]};
  }
  Vec3 m = glm::cross(n, t);
  double sgn = 1.0;
  if (m.z < 0.0) {
    m = -m;
    sgn = -1.0;
  }
  const double dA = kHalfPi / (nA_ - 1), dB = kTwoPi / nB_;
  const double x = std::acos(std::clamp(m.z, -1.0, 1.0)) / dA;
  double ph = std::atan2(m.y, m.x);
  if (ph < 0) ph += kTwoPi;
  const double y = ph / dB;
  const int i = std::clamp(static_cast<int>(x), 0, nA_ - 2);
  const int j = static_cast<int>(y) % nB_;
  const double wx = std::clamp(x - i, 0.0, 1.0), wy = std::clamp(y - std::floor(y), 0.0, 1.0);
  std::array<double, 3> out{0, 0, 0};
  for (int di = 0; di < 2; ++di) {
    for (int dj = 0; dj < 2; ++dj) {
      const int ii = i + di, jj = (j + dj) % nB_;
      const double wgt = (di ? wx : 1 - wx) * (dj ? wy : 1 - wy);
      if (wgt == 0.0) continue;
      // Each corner has its own circle basis: place the ray's circle on it through n's
      // position β_c on that circle (this keeps the pole, where the bases turn, consistent).
      const double cph = jj * dB;
      const Vec3 mc(std::sin(ii * dA) * std::cos(cph), std::sin(ii * dA) * std::sin(cph), std::cos(ii * dA));
      const Vec3 e1(-std::sin(cph), std::cos(cph), 0.0);
      const Vec3 e2 = glm::cross(mc, e1);
      const double beta = std::atan2(glm::dot(n, e2), glm::dot(n, e1));
      // w(θ) ≈ c(β + sgn θ) ⇒ θ = sgn (φ − β); dθ has the sign of sgn, which the sorted limits absorb.
      const double pa = beta + sgn * theta0, pb = beta + sgn * thetaD;
      const auto mm = rowMoments(data_.data() + (static_cast<std::size_t>(ii) * static_cast<std::size_t>(nB_) + static_cast<std::size_t>(jj)) * rowSize,
                                 std::min(pa, pb), std::max(pa, pb), beta);
      out[0] += wgt * mm[0];
      out[1] += wgt * sgn * mm[1];
      out[2] += wgt * mm[2];
    }
  }
  return out;
}

}  // namespace fogbeam::detail
