#include <fogbeam/util/overloaded.hpp>
#include <fogbeam/physics/profile.hpp>

#include "profile_simd.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace fogbeam {

namespace {


constexpr double kTwoPi = 2.0 * kPi;
constexpr double kHalfPi = 0.5 * kPi;

double clampUnit(double x) { return std::clamp(x, -1.0, 1.0); }

// Linear interpolation position of x in an ascending grid: index i and weight t with
// x = (1 − t) g[i] + t g[i+1]. Returns false outside [g.front(), g.back()].
bool locate(const std::vector<double>& g, const TabulatedProfile::AxisIndex& index, double x, std::size_t& i,
            double& t) {
  if (g.size() == 1) {
    i = 0;
    t = 0.0;
    return std::abs(x - g[0]) < 1e-12;
  }
  constexpr double eps = 1e-12;  // accept values on the end points despite rounding
  if (x < g.front() - eps || x > g.back() + eps) return false;
  const std::size_t last = g.size() - 2;  // the cell index runs over [0, n − 2]
  if (!index.first.empty()) {
    // Bucket start, then a few steps forward: the buckets are narrower than any cell.
    const double b = std::clamp((x - index.lo) * index.scale, 0.0, static_cast<double>(index.first.size() - 1));
    i = index.first[static_cast<std::size_t>(b)];
    while (i < last && g[i + 1] <= x) ++i;
  } else {
    auto it = std::upper_bound(g.begin(), g.end(), x);
    const auto hi = static_cast<std::size_t>(it - g.begin());
    i = hi == 0 ? 0 : std::min(hi - 1, last);
  }
  const double span = g[i + 1] - g[i];
  t = span > 0.0 ? std::clamp((x - g[i]) / span, 0.0, 1.0) : 0.0;
  return true;
}

TabulatedProfile::AxisIndex makeAxisIndex(const std::vector<double>& g) {
  TabulatedProfile::AxisIndex index;
  if (g.size() < 3) return index;  // binary search is as fast
  double finest = g.back() - g.front();
  for (std::size_t k = 1; k < g.size(); ++k) finest = std::min(finest, g[k] - g[k - 1]);
  const double range = g.back() - g.front();
  const auto buckets = static_cast<std::size_t>(std::min(65536.0, std::ceil(2.0 * range / finest) + 1.0));
  index.lo = g.front();
  index.scale = static_cast<double>(buckets - 1) / range;
  index.first.resize(buckets);
  std::size_t i = 0;
  for (std::size_t b = 0; b < buckets; ++b) {
    const double start = g.front() + static_cast<double>(b) / index.scale;
    while (i + 1 < g.size() - 1 && g[i + 1] <= start) ++i;
    index.first[b] = static_cast<std::uint32_t>(i);
  }
  return index;
}

// Folds a type C plane angle C (radians, any value) into the range the data cover.
double foldTypeC(double c, PlaneSymmetry sym) {
  c = std::fmod(c, kTwoPi);
  if (c < 0.0) c += kTwoPi;
  switch (sym) {
    case PlaneSymmetry::Quadrant:
      if (c > kPi) c = kTwoPi - c;
      if (c > kHalfPi) c = kPi - c;
      return c;
    case PlaneSymmetry::Half0To180:
      return c > kPi ? kTwoPi - c : c;
    case PlaneSymmetry::Half90To270:
      if (c < kHalfPi) return kPi - c;            // mirror about the 90–270 plane
      if (c > 1.5 * kPi) return 3.0 * kPi - c;
      return c;
    default:
      return c;
  }
}

// The angles base + 2πk (|k| ≤ 2) within (lo, hi): one crossing of a great circle, every turn.
void appendTurns(double base, double lo, double hi, std::vector<double>& out) {
  for (int k = -2; k <= 2; ++k) {
    const double th = base + k * kTwoPi;
    if (th > lo && th < hi) out.push_back(th);
  }
}

// Great-circle crossings: w(θ) = cos θ n + sin θ t. Solutions of w·a = c (|a| = 1).
void crossingsDot(const Vec3& n, const Vec3& t, const Vec3& a, double c, double lo, double hi,
                  std::vector<double>& out) {
  const double x = glm::dot(n, a), y = glm::dot(t, a);
  const double r = std::sqrt(x * x + y * y);  // |n|, |t|, |a| = 1: no overflow for hypot to guard
  if (r < 1e-15 || std::abs(c) > r) return;
  // acos(c / r) as atan2(√(r² − c²), c), both through the inlined fastAtan2: a moving lamp's
  // spoke crosses ~60 feature lines of a measured low beam (profile.hpp, appendFeatureKinks).
  const double centre = fastAtan2(y, x);
  const double half = fastAtan2(std::sqrt(std::max(0.0, (r - c) * (r + c))), c);
  appendTurns(centre - half, lo, hi, out);
  appendTurns(centre + half, lo, hi, out);
}

double sphereFlux(const Profile& p) {
  // Midpoint rule in (ψ, φ) about +x; 0.05° rings resolve spot edges and tabulated grids
  // of 0.1° and coarser to < 1e-5 relative.
  constexpr int nPsi = 3600, nPhi = 720;
  const double dPsi = kPi / nPsi, dPhi = kTwoPi / nPhi;
  double sum = 0.0;
  for (int i = 0; i < nPsi; ++i) {
    const double psi = (i + 0.5) * dPsi;
    const double s = std::sin(psi), c = std::cos(psi);
    double ring = 0.0;
    for (int j = 0; j < nPhi; ++j) {
      const double phi = (j + 0.5) * dPhi;
      ring += p.intensity(Vec3(c, s * std::cos(phi), s * std::sin(phi)));
    }
    sum += ring * s;
  }
  return sum * dPsi * dPhi;
}

double computeSupport(const Profile& p) {
  return std::visit(
      Overloaded{
          [](const IsotropicProfile& m) { return m.intensity_cd > 0.0 ? kPi : 0.0; },
          [](const SpotProfile& m) { return m.outer; },
          [&](const TabulatedProfile&) {
            // Sampled on 0.25° rings; one ring of margin covers features between samples
            // (a grid finer than 0.25° is not expected in lamp data).
            constexpr int nPsi = 720, nPhi = 1440;
            int last = -1;
            for (int i = 0; i < nPsi; ++i) {
              const double psi = (i + 0.5) * kPi / nPsi;
              const double s = std::sin(psi), c = std::cos(psi);
              for (int j = 0; j < nPhi; ++j) {
                const double phi = (j + 0.5) * kTwoPi / nPhi;
                if (p.intensity(Vec3(c, s * std::cos(phi), s * std::sin(phi))) > 0.0) {
                  last = i;
                  break;
                }
              }
            }
            if (last < 0) return 0.0;
            return std::min(kPi, (last + 2) * kPi / nPsi);
          },
      },
      p.model());
}

// Grid lines of a tabulated profile: families of cones (w·a = c) or planes through an axis
// (w·q = 0), as in appendKinks. Returns the line for the i-th horizontal or vertical angle.
using GridLine = Profile::Line;
GridLine horizontalLine(PhotometricType type, double h) {
  switch (type) {
    case PhotometricType::C: return {Vec3(0, std::sin(h), -std::cos(h)), 0.0};
    case PhotometricType::B: return {Vec3(0, -1, 0), std::sin(h)};
    case PhotometricType::A: return {Vec3(-std::sin(h), -std::cos(h), 0), 0.0};
  }
  return {Vec3(1, 0, 0), 1.0};
}
GridLine verticalLine(PhotometricType type, double v) {
  switch (type) {
    case PhotometricType::C: return {Vec3(1, 0, 0), std::cos(v)};
    case PhotometricType::B: return {Vec3(-std::sin(v), 0, std::cos(v)), 0.0};
    case PhotometricType::A: return {Vec3(0, 0, 1), std::sin(v)};
  }
  return {Vec3(1, 0, 0), 1.0};
}

// The grid lines of horizontal angle h as seen on the whole sphere: the line itself and, where
// symmetry folds the data, its mirror image (type C planes are mirrored about C = 0 for
// every folded layout; the extra line is harmless for full data).
void appendHorizontalLines(const TabulatedProfile& t, double h, std::vector<GridLine>& out) {
  out.push_back(horizontalLine(t.type, h));
  if (t.symmetry == PlaneSymmetry::MirrorH || t.type == PhotometricType::C) out.push_back(horizontalLine(t.type, -h));
}

// Every kink of the bilinear interpolant: all grid lines, their mirror images and, for folded
// type C data, the fold planes C = 0 and C = 90°.
std::vector<GridLine> allGridLines(const TabulatedProfile& t) {
  std::vector<GridLine> lines;
  const bool rotational = t.symmetry == PlaneSymmetry::Rotational || t.horizontal.size() == 1;
  if (!rotational) {
    for (double h : t.horizontal) appendHorizontalLines(t, h, lines);
    if (t.type == PhotometricType::C) {
      lines.push_back(horizontalLine(t.type, 0.0));
      lines.push_back(horizontalLine(t.type, kHalfPi));
    }
  }
  for (double v : t.vertical) lines.push_back(verticalLine(t.type, v));
  return lines;
}

}  // namespace

// Every angle as an atan2 (acos x = atan2(√(y² + z²), x), asin z = atan2(z, √(x² + y²)) for a
// unit w), through the inlined fastAtan2 (within ~2 ulp of libm's): this runs once per profile
// look-up, and libm's atan2 and asin were 10 % and 6 % of the CPU time of `fogbeam bench
// --only-traffic` in perf (spokes, view tables, per-ray checks). The atan2 forms also keep full
// precision near the poles, where acos and asin lose half the digits, and do not need |w| = 1
// exactly.
FileAngles anglesFromDirection(PhotometricType type, const Vec3& w) noexcept {
  switch (type) {
    case PhotometricType::C:
      return {fastAtan2(w.z, w.y), fastAtan2(std::sqrt(w.y * w.y + w.z * w.z), w.x)};
    case PhotometricType::B:
      return {fastAtan2(-w.y, std::sqrt(w.x * w.x + w.z * w.z)), fastAtan2(w.z, w.x)};
    case PhotometricType::A:
      return {fastAtan2(-w.y, w.x), fastAtan2(w.z, std::sqrt(w.x * w.x + w.y * w.y))};
  }
  return {0.0, 0.0};
}

Vec3 directionFromAngles(PhotometricType type, double h, double v) noexcept {
  switch (type) {
    case PhotometricType::C:
      return {std::cos(v), std::sin(v) * std::cos(h), std::sin(v) * std::sin(h)};
    case PhotometricType::B:
      return {std::cos(h) * std::cos(v), -std::sin(h), std::cos(h) * std::sin(v)};
    case PhotometricType::A:
      return {std::cos(v) * std::cos(h), -std::cos(v) * std::sin(h), std::sin(v)};
  }
  return {1.0, 0.0, 0.0};
}

Status TabulatedProfile::validate() const {
  const std::string where = source.empty() ? std::string("profile") : source;
  if (horizontal.empty()) return Error{where + ": no horizontal angles"};
  if (vertical.size() < 2) return Error{where + ": need at least 2 vertical angles"};
  if (candela.size() != horizontal.size() * vertical.size()) {
    return Error{where + ": expected " + std::to_string(horizontal.size() * vertical.size()) +
                 " candela values, found " + std::to_string(candela.size())};
  }
  auto ascending = [](const std::vector<double>& g) {
    for (std::size_t i = 1; i < g.size(); ++i)
      if (!(g[i] > g[i - 1])) return false;
    return true;
  };
  if (!ascending(horizontal)) return Error{where + ": horizontal angles must be strictly ascending"};
  if (!ascending(vertical)) return Error{where + ": vertical angles must be strictly ascending"};
  for (double a : horizontal)
    if (!std::isfinite(a)) return Error{where + ": horizontal angle is not a finite number"};
  for (double a : vertical)
    if (!std::isfinite(a)) return Error{where + ": vertical angle is not a finite number"};
  for (double c : candela)
    if (!std::isfinite(c) || c < 0.0) return Error{where + ": candela values must be finite and >= 0"};
  const double eps = 1e-9;
  if (type == PhotometricType::C) {
    if (vertical.front() < -eps || vertical.back() > kPi + eps)
      return Error{where + ": type C vertical angles must lie in [0, 180] degrees"};
    if (horizontal.front() < -eps || horizontal.back() > kTwoPi + eps)
      return Error{where + ": type C horizontal angles must lie in [0, 360] degrees"};
  } else {
    if (vertical.front() < -kHalfPi - eps || vertical.back() > kHalfPi + eps)
      return Error{where + ": type A/B vertical angles must lie in [-90, 90] degrees"};
    const double hmax = type == PhotometricType::B ? kHalfPi : kPi;
    if (horizontal.front() < -hmax - eps || horizontal.back() > hmax + eps)
      return Error{where + ": type A/B horizontal angles out of range"};
    if (symmetry == PlaneSymmetry::MirrorH && horizontal.front() < -eps)
      return Error{where + ": mirrored type A/B data must start at H = 0"};
  }
  return Ok{};
}

void TabulatedProfile::buildIndex() {
  horizontalIndex = makeAxisIndex(horizontal);
  verticalIndex = makeAxisIndex(vertical);
}

double TabulatedProfile::atAngles(double h, double v) const noexcept {
  std::size_t iv = 0;
  double tv = 0.0;
  if (!locate(vertical, verticalIndex, v, iv, tv)) return 0.0;
  const std::size_t nv = vertical.size();
  const std::size_t iv1 = std::min(iv + 1, nv - 1);
  auto row = [&](std::size_t ih) {
    const double* r = candela.data() + ih * nv;
    return (1.0 - tv) * r[iv] + tv * r[iv1];
  };
  if (horizontal.size() == 1 || symmetry == PlaneSymmetry::Rotational) return row(0);

  if (type == PhotometricType::C) {
    h = foldTypeC(h, symmetry);
    if (symmetry == PlaneSymmetry::None && h > horizontal.back()) {
      // Wrap between the last plane and the first one + 360°.
      const double span = horizontal.front() + kTwoPi - horizontal.back();
      if (span <= 0.0) return row(0);
      const double t = (h - horizontal.back()) / span;
      return (1.0 - t) * row(horizontal.size() - 1) + t * row(0);
    }
    if (symmetry == PlaneSymmetry::None && h < horizontal.front()) {
      const double span = horizontal.front() + kTwoPi - horizontal.back();
      if (span <= 0.0) return row(0);
      const double t = (h + kTwoPi - horizontal.back()) / span;
      return (1.0 - t) * row(horizontal.size() - 1) + t * row(0);
    }
  } else if (symmetry == PlaneSymmetry::MirrorH) {
    h = std::abs(h);
  }
  std::size_t ih = 0;
  double th = 0.0;
  if (!locate(horizontal, horizontalIndex, h, ih, th)) return 0.0;
  const std::size_t ih1 = std::min(ih + 1, horizontal.size() - 1);
  return (1.0 - th) * row(ih) + th * row(ih1);
}

double Profile::intensity(const Vec3& w) const noexcept {
  return std::visit(
      Overloaded{
          [](const IsotropicProfile& m) { return m.intensity_cd; },
          [&](const SpotProfile& m) {
            const double psi = std::acos(clampUnit(w.x));
            if (psi <= m.inner) return m.peak_cd;
            if (psi >= m.outer) return 0.0;
            return m.peak_cd * (m.outer - psi) / (m.outer - m.inner);
          },
          [&](const TabulatedProfile& m) {
            const FileAngles a = anglesFromDirection(m.type, w);
            return m.atAngles(a.h, a.v);
          },
      },
      model_);
}

void Profile::intensitiesOnCircle(const Vec3& u, const Vec3& v, const double* psi, std::size_t n, double* out) const {
  const auto* tab = std::get_if<TabulatedProfile>(&model_);
  if (tab == nullptr) {
    for (std::size_t i = 0; i < n; ++i) out[i] = intensity(std::cos(psi[i]) * u + std::sin(psi[i]) * v);
    return;
  }
  // The file angles of every sample first (SIMD: profile_simd.cpp), then the look-ups.
  thread_local std::vector<double> h, vv;
  if (h.size() < n) {
    h.resize(n);
    vv.resize(n);
  }
  const int type = tab->type == PhotometricType::A ? detail::kTypeA
                   : tab->type == PhotometricType::B ? detail::kTypeB
                                                     : detail::kTypeC;
  const double ua[3] = {u.x, u.y, u.z}, va[3] = {v.x, v.y, v.z};
  detail::circleAngles(type, ua, va, psi, n, h.data(), vv.data());
  for (std::size_t i = 0; i < n; ++i) out[i] = tab->atAngles(h[i], vv[i]);
}

double Profile::totalFlux() const { return sphereFlux(*this); }

Profile::Peak Profile::peak() const {
  return std::visit(
      Overloaded{
          [](const IsotropicProfile& m) { return Peak{m.intensity_cd, Vec3(1, 0, 0)}; },
          [](const SpotProfile& m) { return Peak{m.peak_cd, Vec3(1, 0, 0)}; },
          [](const TabulatedProfile& m) {
            Peak best{0.0, Vec3(1, 0, 0)};
            const std::size_t nv = m.vertical.size();
            for (std::size_t ih = 0; ih < m.horizontal.size(); ++ih)
              for (std::size_t iv = 0; iv < nv; ++iv)
                if (m.candela[ih * nv + iv] > best.intensity_cd)
                  best = {m.candela[ih * nv + iv], directionFromAngles(m.type, m.horizontal[ih], m.vertical[iv])};
            return best;
          },
      },
      model_);
}

void Profile::appendKinks(const Vec3& n, const Vec3& t, double lo, double hi, std::vector<double>& out) const {
  const Vec3 ex(1, 0, 0);
  std::visit(
      Overloaded{
          [](const IsotropicProfile&) {},
          [&](const SpotProfile& m) {
            crossingsDot(n, t, ex, std::cos(m.inner), lo, hi, out);
            crossingsDot(n, t, ex, std::cos(m.outer), lo, hi, out);
          },
          [&](const TabulatedProfile&) {
            for (const Line& l : gridLines_) crossingsDot(n, t, l.axis, l.c, lo, hi, out);
          },
      },
      model_);
}

void Profile::appendFeatureKinks(const Vec3& n, const Vec3& t, double lo, double hi, std::vector<double>& out) const {
  if (!std::holds_alternative<TabulatedProfile>(model_)) {
    appendKinks(n, t, lo, hi, out);
    return;
  }
  // The crossings of every feature line at once (SIMD: profile_simd.cpp; crossingsDot's
  // arithmetic), then each solution's turns within (lo, hi) (appendTurns).
  const std::size_t count = featureC_.size();
  thread_local std::vector<double> thA, thB;
  if (thA.size() < count) {
    thA.resize(count);
    thB.resize(count);
  }
  const double na[3] = {n.x, n.y, n.z}, ta[3] = {t.x, t.y, t.z};
  detail::lineCrossings(na, ta, featureAx_.data(), featureAy_.data(), featureAz_.data(), featureC_.data(), count,
                        thA.data(), thB.data());
  for (std::size_t i = 0; i < count; ++i) {
    if (std::isnan(thA[i])) continue;
    appendTurns(thA[i], lo, hi, out);
    appendTurns(thB[i], lo, hi, out);
  }
}

Result<std::shared_ptr<const Profile>> makeProfile(Profile::Model model) {
  if (const auto* iso = std::get_if<IsotropicProfile>(&model)) {
    if (!std::isfinite(iso->intensity_cd) || iso->intensity_cd < 0.0)
      return Error{"isotropic profile: intensity_cd must be finite and >= 0"};
  } else if (const auto* spot = std::get_if<SpotProfile>(&model)) {
    if (!std::isfinite(spot->peak_cd) || spot->peak_cd < 0.0)
      return Error{"spot profile: intensity_cd must be finite and >= 0"};
    if (!(spot->inner >= 0.0 && spot->inner < spot->outer && spot->outer <= kPi))
      return Error{"spot profile: need 0 <= inner_deg < outer_deg <= 180"};
  } else if (auto* tab = std::get_if<TabulatedProfile>(&model)) {
    if (Status s = tab->validate(); !s) return s.error();
    tab->buildIndex();
  }
  auto p = std::make_shared<Profile>(std::move(model));
  p->support_ = computeSupport(*p);
  if (const auto* t = std::get_if<TabulatedProfile>(&p->model_)) {
    p->gridLines_ = allGridLines(*t);
    // Feature lines: where the slope of I across a grid line changes by more than 1 % of the
    // peak per grid step (largest second difference over the other angle). Mirrored copies
    // are added for symmetric data.
    const std::size_t nh = t->horizontal.size(), nv = t->vertical.size();
    double peakCd = 0.0;
    for (double c : t->candela) peakCd = std::max(peakCd, c);
    const double threshold = 0.01 * peakCd;
    auto at = [&](std::size_t ih, std::size_t iv) { return t->candela[ih * nv + iv]; };
    std::vector<std::pair<double, GridLine>> cand;
    for (std::size_t iv = 1; iv + 1 < nv; ++iv) {
      double s2 = 0.0;
      for (std::size_t ih = 0; ih < nh; ++ih)
        s2 = std::max(s2, std::abs(at(ih, iv + 1) - 2 * at(ih, iv) + at(ih, iv - 1)));
      if (s2 > threshold) cand.emplace_back(s2, verticalLine(t->type, t->vertical[iv]));
    }
    std::vector<std::pair<double, GridLine>> candH;
    for (std::size_t ih = 1; ih + 1 < nh; ++ih) {
      double s2 = 0.0;
      for (std::size_t iv = 0; iv < nv; ++iv)
        s2 = std::max(s2, std::abs(at(ih + 1, iv) - 2 * at(ih, iv) + at(ih - 1, iv)));
      if (s2 > threshold) {
        std::vector<GridLine> lines;
        appendHorizontalLines(*t, t->horizontal[ih], lines);
        for (const GridLine& l : lines) candH.emplace_back(s2, l);
      }
    }
    auto keepLargest = [&](std::vector<std::pair<double, GridLine>>& v) {
      std::sort(v.begin(), v.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
      if (v.size() > static_cast<std::size_t>(Profile::kMaxFeatureLines)) v.resize(static_cast<std::size_t>(Profile::kMaxFeatureLines));
      for (const auto& [s2, line] : v) {
        p->featureAx_.push_back(line.axis.x);
        p->featureAy_.push_back(line.axis.y);
        p->featureAz_.push_back(line.axis.z);
        p->featureC_.push_back(line.c);
      }
    };
    keepLargest(cand);
    keepLargest(candH);
  }
  return std::shared_ptr<const Profile>(std::move(p));
}

}  // namespace fogbeam
