// fogbeam — near-field lamps (aperture.hpp): quadrature rules over a lamp's emitting face and the
// point lamps that stand for it.
#include <fogbeam/physics/aperture.hpp>

#include <boost/math/special_functions/legendre.hpp>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <string>
#include <utility>

namespace fogbeam {

namespace {

struct GaussNode {
  double x;  ///< node on [−1, 1]
  double w;  ///< weight; the n weights sum to 2
};

/// The n-point Gauss–Legendre rule on [−1, 1], ascending: nodes are the zeros of P_n (Boost.Math
/// gives the non-negative ones), weights w = 2 / ((1 − x²) P_n'(x)²) (Abramowitz & Stegun 25.4.29).
/// The same construction as boost::math::quadrature::gauss<double, N>, for an n known at run time.
std::vector<GaussNode> gaussLegendre(int n) {
  std::vector<GaussNode> nodes;
  nodes.reserve(static_cast<std::size_t>(n));
  for (double x : boost::math::legendre_p_zeros<double>(n)) {
    const double dp = boost::math::legendre_p_prime(n, x);
    const double w = 2.0 / ((1.0 - x * x) * dp * dp);
    nodes.push_back({x, w});
    if (x != 0.0) nodes.push_back({-x, w});
  }
  std::sort(nodes.begin(), nodes.end(), [](const GaussNode& a, const GaussNode& b) { return a.x < b.x; });
  return nodes;
}

int discRings(int n) { return (n + 1) / 2; }  // ⌈n/2⌉: the m = 0 part has degree ≤ n − 1 in s
int discAngles(int n) { return 2 * n; }       // exact for Fourier modes |m| ≤ 2n − 1

}  // namespace

std::string_view toString(ApertureShape s) {
  switch (s) {
    case ApertureShape::Point: return "point";
    case ApertureShape::Rectangle: return "rectangle";
    case ApertureShape::Disc: return "disc";
  }
  return "?";
}

Status Aperture::validate() const {
  auto positive = [](double x) { return std::isfinite(x) && x > 0.0; };
  if (shape == ApertureShape::Point) return Ok{};
  if (samples < 1 || samples > kMaxApertureSamples)
    return Error{"aperture: samples per axis must be in [1, " + std::to_string(kMaxApertureSamples) + "], found " +
                 std::to_string(samples)};
  if (!positive(width_m)) return Error{"aperture: width must be finite and > 0 m, found " + std::to_string(width_m)};
  if (shape == ApertureShape::Rectangle && !positive(height_m))
    return Error{"aperture: height must be finite and > 0 m, found " + std::to_string(height_m)};
  return Ok{};
}

std::size_t apertureSampleCount(const Aperture& a) noexcept {
  const auto n = static_cast<std::size_t>(std::max(a.samples, 1));
  switch (a.shape) {
    case ApertureShape::Point: return 1;
    case ApertureShape::Rectangle: return n * n;
    case ApertureShape::Disc:
      return n == 1 ? 1 : static_cast<std::size_t>(discRings(a.samples)) * static_cast<std::size_t>(discAngles(a.samples));
  }
  return 1;
}

std::vector<ApertureSample> apertureSamples(const Aperture& a) {
  assert(a.validate().has_value());
  std::vector<ApertureSample> out;
  out.reserve(apertureSampleCount(a));
  const int n = a.samples;
  if (a.shape == ApertureShape::Point || n == 1) {
    out.push_back({0.0, 0.0, 1.0});  // the 1-point rule of either shape: the centre
    return out;
  }
  if (a.shape == ApertureShape::Rectangle) {
    // ∫∫ f dA / A over [−W/2, W/2] × [−H/2, H/2]: nodes x·W/2, weights w/2 per axis.
    const std::vector<GaussNode> g = gaussLegendre(n);
    for (const GaussNode& gz : g)
      for (const GaussNode& gy : g) out.push_back({0.5 * a.width_m * gy.x, 0.5 * a.height_m * gz.x, 0.25 * gy.w * gz.w});
    return out;
  }
  // Disc: s = r²/R² ∈ [0, 1] (uniform density in s, module comment), nodes s = (1 + x)/2 with
  // weights w/2; angles equally spaced with weight 1/n_φ.
  const double radius = 0.5 * a.width_m;
  const std::vector<GaussNode> g = gaussLegendre(discRings(n));
  const int nPhi = discAngles(n);
  for (const GaussNode& gs : g) {
    const double r = radius * std::sqrt(0.5 * (1.0 + gs.x));
    for (int j = 0; j < nPhi; ++j) {
      const double phi = 2.0 * kPi * (j + 0.5) / nPhi;
      out.push_back({r * std::cos(phi), r * std::sin(phi), 0.5 * gs.w / nPhi});
    }
  }
  return out;
}

std::vector<Lamp> expandAperture(const Lamp& lamp, const Aperture& a) {
  if (a.shape == ApertureShape::Point) return {lamp};
  std::vector<Lamp> out;
  const std::vector<ApertureSample> samples = apertureSamples(a);
  out.reserve(samples.size());
  for (const ApertureSample& s : samples) {
    Lamp l = lamp;  // the profile's shared_ptr is copied: one profile, one set of tables
    // The face lies in the lamp's y–z plane: columns 1 and 2 of worldFromLamp are its +y, +z.
    l.position_m = lamp.position_m + s.y_m * lamp.worldFromLamp[1] + s.z_m * lamp.worldFromLamp[2];
    l.color = lamp.color * s.weight;
    out.push_back(std::move(l));
  }
  return out;
}

Result<ApertureAirlight> ApertureAirlight::build(const Lamp& lamp, const Aperture& a, const Medium& medium,
                                                 AirlightMethod method, const AirlightOptions& options) {
  if (Status s = a.validate(); !s) return s.error();
  ApertureAirlight out;
  const std::vector<ApertureSample> samples = apertureSamples(a);
  const std::vector<Lamp> lamps = expandAperture(lamp, a);
  out.lamps_.reserve(lamps.size());
  for (std::size_t i = 0; i < lamps.size(); ++i) {
    auto ev = AirlightEvaluator::build(lamps[i], medium, method, options);
    if (!ev) return ev.error();
    out.lamps_.push_back(std::move(ev).value());
    out.weights_.push_back(samples[i].weight);
  }
  return out;
}

Result<ApertureAirlight> ApertureAirlight::reference(const Lamp& lamp, const Aperture& a, const Medium& medium,
                                                     int samplesPerAxis, const AirlightOptions& options) {
  Aperture fine = a;
  fine.samples = samplesPerAxis;
  return build(lamp, fine, medium, AirlightMethod::Reference, options);
}

double ApertureAirlight::evaluate(const Ray& ray) const noexcept {
  // Weights are applied here rather than through Lamp::color: evaluate() reports white light.
  double sum = 0.0;
  for (std::size_t i = 0; i < lamps_.size(); ++i) sum += weights_[i] * lamps_[i].evaluate(ray);
  return sum;
}

}  // namespace fogbeam
