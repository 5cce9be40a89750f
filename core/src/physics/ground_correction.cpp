// The ground's factor on the multiple-scattering tables (ground_correction.hpp).
#include <fogbeam/physics/ground_correction.hpp>

#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/physics/path_tracer.hpp>
#include <fogbeam/physics/profile.hpp>

#include "table_text.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <mutex>
#include <sstream>

namespace fogbeam {

GroundCorrectionOptions GroundCorrectionOptions::defaults() {
  GroundCorrectionOptions o;
  // From 0.5: below it factor() is 1 (kFadeFrom).
  for (int i = -1; i <= 4; ++i) o.optical_distances.push_back(std::ldexp(1.0, i));  // 0.5 … 16
  o.ring_edges_deg = {0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 180.0};
  // Wet and dry asphalt (0.05–0.15), concrete, snow.
  o.reflectances = {0.0, 0.1, 0.3, 0.8};
  // A car's eye (1.2 m) and lamps (0.65 m) in fog of K_t 0.03–0.1 /m: 0.02–0.12; a street
  // lamp's head and the eye: 0.14–0.5.
  o.heights_optical = {0.03, 0.09, 0.27};
  return o;
}

namespace {

constexpr double kDeg = kPi / 180.0;

Status checkAscending(const std::vector<double>& v, const char* what, double lo, double hi, bool loOpen) {
  if (v.empty()) return Error{std::string("ground correction: no ") + what + " nodes"};
  for (std::size_t k = 0; k < v.size(); ++k) {
    const bool inLo = loOpen ? v[k] > lo : v[k] >= lo;
    if (!std::isfinite(v[k]) || !inLo || v[k] > hi || (k > 0 && !(v[k] > v[k - 1])))
      return Error{std::string("ground correction: ") + what + " nodes must ascend within " + (loOpen ? "(" : "[") +
                   std::to_string(lo) + ", " + std::to_string(hi) + "]"};
  }
  return Ok{};
}

/// Position of x among ascending nodes: (i, w) with x ≈ (1 − w) v[i] + w v[i + 1], clamped.
std::pair<std::size_t, double> locate(const std::vector<double>& v, double x) {
  if (v.size() < 2 || !(x > v.front())) return {0, 0.0};
  if (x >= v.back()) return {v.size() - 2, 1.0};
  std::size_t i = static_cast<std::size_t>(std::upper_bound(v.begin(), v.end(), x) - v.begin()) - 1;
  return {i, (x - v[i]) / (v[i + 1] - v[i])};
}

/// Weighted least squares of a polynomial of degree ≤ 3 through (x_j, y_j) with weights w_j;
/// returns its values at the x_j. Normal equations (4 × 4 at most, Gaussian elimination with
/// partial pivoting): a handful of rings, nothing a library would add to.
std::vector<double> weightedCubic(const std::vector<double>& x, const std::vector<double>& y, const std::vector<double>& w) {
  const std::size_t n = x.size(), m = std::min<std::size_t>(4, n);
  if (m == 0) return y;
  const double x0 = 0.5 * (x.front() + x.back()), sx = std::max(1e-12, 0.5 * (x.back() - x.front()));
  double a[4][5] = {};
  for (std::size_t j = 0; j < n; ++j) {
    double p[4];
    const double u = (x[j] - x0) / sx;
    p[0] = 1.0;
    for (std::size_t k = 1; k < m; ++k) p[k] = p[k - 1] * u;
    for (std::size_t r = 0; r < m; ++r) {
      for (std::size_t c = 0; c < m; ++c) a[r][c] += w[j] * p[r] * p[c];
      a[r][m] += w[j] * p[r] * y[j];
    }
  }
  for (std::size_t c = 0; c < m; ++c) {
    std::size_t piv = c;
    for (std::size_t r = c + 1; r < m; ++r)
      if (std::abs(a[r][c]) > std::abs(a[piv][c])) piv = r;
    if (!(std::abs(a[piv][c]) > 1e-300)) return y;  // degenerate: keep the nodes
    for (std::size_t k = 0; k <= m; ++k) std::swap(a[c][k], a[piv][k]);
    for (std::size_t r = 0; r < m; ++r) {
      if (r == c) continue;
      const double f = a[r][c] / a[c][c];
      for (std::size_t k = c; k <= m; ++k) a[r][k] -= f * a[c][k];
    }
  }
  std::vector<double> out(n);
  for (std::size_t j = 0; j < n; ++j) {
    const double u = (x[j] - x0) / sx;
    double v = 0.0, p = 1.0;
    for (std::size_t k = 0; k < m; ++k, p *= u) v += a[k][m] / a[k][k] * p;
    out[j] = std::max(0.0, v);
  }
  return out;
}

}  // namespace

void GroundCorrectionTable::smooth() {
  // The path tracer's nodes are noisy (5–15 % at 30 000 paths) and heavy-tailed: a path whose
  // vertex falls next to the lamp, or a ground vertex under it, can carry most of a node's sum
  // (its standard error then says so: one node of the HG 0.85 table reads 1046 ± 1045). What the
  // glow reads is, per (ρ, T), a cubic in log θ fitted over the rings' centres by weighted least
  // squares, weights 1/σ², σ the node's standard error floored at 2 % of it plus 0.005 (so that
  // a lucky node with a small σ does not pin the curve).
  const std::size_t nT = t_.size(), nR = edges_.size() - 1, nHR = h_.size() * rho_.size();
  logH_.clear();
  for (double x : h_) logH_.push_back(std::log(x));
  centresLog_.clear();
  for (std::size_t j = 0; j < nR; ++j) centresLog_.push_back(0.5 * (std::log(edges_[j]) + std::log(edges_[j + 1])));
  fit_.assign(c_.size(), 1.0);
  std::vector<double> y(nR), w(nR);
  for (std::size_t r = 0; r < nHR; ++r)
    for (std::size_t i = 0; i < nT; ++i) {
      for (std::size_t j = 0; j < nR; ++j) {
        y[j] = c_[index(r, i, j)];
        const double sigma = std::max(se_[index(r, i, j)], 0.02 * y[j] + 0.005);
        w[j] = 1.0 / (sigma * sigma);
      }
      const std::vector<double> f = weightedCubic(centresLog_, y, w);
      for (std::size_t j = 0; j < nR; ++j) fit_[index(r, i, j)] = f[j];
    }
}

Result<GroundCorrectionTable> GroundCorrectionTable::build(const Phase& phase, const MultipleScatteringTable& ms,
                                                           const GroundCorrectionOptions& o, ThreadPool* pool,
                                                           const std::function<void(const std::string&)>& progress) {
  if (Status s = checkAscending(o.optical_distances, "optical distance", 0.0, 1e3, true); !s) return s.error();
  if (Status s = checkAscending(o.ring_edges_deg, "ring edge", 0.0, 180.0, true); !s) return s.error();
  if (o.ring_edges_deg.size() < 2) return Error{"ground correction: at least two ring edges (one ring)"};
  if (Status s = checkAscending(o.reflectances, "reflectance", 0.0, 0.999, false); !s) return s.error();
  if (Status s = checkAscending(o.heights_optical, "height", 0.0, 10.0, true); !s) return s.error();
  if (o.paths < 2) return Error{"ground correction: at least 2 paths per ring (the standard error needs two)"};
  if (o.quadrature < 4) return Error{"ground correction: quadrature must be at least 4"};
  if (phaseIdentity(ms.phase()) != phaseIdentity(phase))
    return Error{"ground correction: the multiple-scattering table is for " + describe(ms.phase()) + ", not " +
                 describe(phase)};

  GroundCorrectionTable t;
  t.phase_ = phase;
  t.t_ = o.optical_distances;
  for (double e : o.ring_edges_deg) t.edges_.push_back(e * kDeg);
  t.rho_ = o.reflectances;
  t.h_ = o.heights_optical;
  t.paths_ = o.paths;
  t.seed_ = o.seed;
  const std::size_t nT = t.t_.size(), nR = t.edges_.size() - 1, nRho = t.rho_.size(), nH = t.h_.size();
  t.c_.assign(nH * nRho * nT * nR, 1.0);
  t.se_.assign(t.c_.size(), 0.0);

  // K_t = 1 /m: lengths are optical depths, the tables' radiance K_t² f(T, θ) is f. The eye at the
  // origin, the lamp (1 cd, isotropic) at (T, 0, 0), the ground at z = −H.
  const Medium medium{1.0, 1.0, phase, 0.0};
  auto iso = makeProfile(IsotropicProfile{1.0});
  if (!iso) return iso.error();
  double H = 0.0;  // the eye's and the lamp's height over the ground (the loop's)
  auto rayIn = [&](std::size_t ring, double u1, double u2) {
    const double c0 = std::cos(t.edges_[ring]), c1 = std::cos(t.edges_[ring + 1]);
    const double ct = c0 - u1 * (c0 - c1), st = std::sqrt(std::max(0.0, 1.0 - ct * ct)), phi = 2.0 * kPi * u2;
    const Vec3 w(ct, st * std::cos(phi), st * std::sin(phi));
    const double end = w.z < 0.0 ? H / -w.z : std::numeric_limits<double>::infinity();
    return Ray{Vec3(0.0), w, end};
  };
  for (std::size_t h = 0; h < nH; ++h)
  for (std::size_t i = 0; i < nT; ++i) {
    H = t.h_[h];
    const double T = t.t_[i];
    // The denominator: the glow layer's value over each ring (tables × occlusion weight),
    // stratified in cos θ and azimuth; the same for every ρ.
    std::vector<double> den(nR, 0.0);
    const int q = o.quadrature;
    for (std::size_t j = 0; j < nR; ++j) {
      double sum = 0.0;
      for (int a = 0; a < q; ++a)
        for (int b = 0; b < q; ++b) {
          const Ray r = rayIn(j, (a + 0.5) / q, (b + 0.5) / q);
          const double theta = std::acos(std::clamp(r.direction.x, -1.0, 1.0));
          sum += ms.value(T, theta, 1.0) * glowOcclusionWeight(r.distance_m, T);
        }
      den[j] = sum / (static_cast<double>(q) * q);
    }
    for (std::size_t r = 0; r < nRho; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      Lamp lamp;
      lamp.position_m = Vec3(T, 0.0, 0.0);
      lamp.profile = *iso;
      auto pt = PathTracer::build({lamp}, medium, GroundPlane{-H, t.rho_[r]});
      if (!pt) return pt.error();
      const std::size_t hr = h * nRho + r;
      const std::uint64_t seed = o.seed * 1000003ULL + hr * 1009ULL + i;
      const auto est = pt->estimate(nR, o.paths, seed, pool, [&](std::uint64_t ring, std::uint64_t, PathRng& rng) {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        return pt->trace(rayIn(static_cast<std::size_t>(ring), u1, u2), rng);
      });
      std::string line;
      char buf[96];
      std::snprintf(buf, sizeof buf, "  H %.3f  rho %.2f  K_t R %6.3f:", H, t.rho_[r], T);
      line = buf;
      for (std::size_t j = 0; j < nR; ++j) {
        const double d = den[j];
        const std::size_t k = t.index(hr, i, j);
        t.c_[k] = d > 0.0 ? std::max(0.0, est[j].multiple.mean) / d : 1.0;
        t.se_[k] = d > 0.0 ? est[j].multiple.std_error / d : 0.0;
        std::snprintf(buf, sizeof buf, " %.3f", t.c_[k]);
        line += buf;
      }
      std::snprintf(buf, sizeof buf, "  (%.1f s)",
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      line += buf;
      if (progress) progress(line);
    }
  }
  t.smooth();
  return t;
}

double GroundCorrectionTable::atRho(std::size_t r, double logT, double logTheta) const noexcept {
  // Linear in log T between T nodes and in log θ between the rings' centres, held beyond.
  const std::size_t nT = t_.size(), nR = edges_.size() - 1;
  std::size_t i = 0;
  double wi = 0.0;
  if (nT > 1) {
    const double lt0 = std::log(t_.front()), ltN = std::log(t_.back());
    if (logT >= ltN) {
      i = nT - 2;
      wi = 1.0;
    } else if (logT > lt0) {
      while (i + 2 < nT && logT > std::log(t_[i + 1])) ++i;
      wi = (logT - std::log(t_[i])) / (std::log(t_[i + 1]) - std::log(t_[i]));
    }
  }
  std::size_t j = 0;
  double wj = 0.0;
  if (nR > 1) {
    if (logTheta >= centresLog_.back()) {
      j = nR - 2;
      wj = 1.0;
    } else if (logTheta > centresLog_.front()) {
      while (j + 2 < nR && logTheta > centresLog_[j + 1]) ++j;
      wj = (logTheta - centresLog_[j]) / (centresLog_[j + 1] - centresLog_[j]);
    }
  }
  auto at = [&](std::size_t ii, std::size_t jj) { return fit_[index(r, std::min(ii, nT - 1), std::min(jj, nR - 1))]; };
  const double a = (1.0 - wj) * at(i, j) + wj * at(i, j + 1);
  const double b = (1.0 - wj) * at(i + 1, j) + wj * at(i + 1, j + 1);
  return nT > 1 ? (1.0 - wi) * a + wi * b : a;
}

double GroundCorrectionTable::factor(double opticalDistance, double theta, double reflectance,
                                     double heightOptical) const noexcept {
  if (fit_.empty() || !(opticalDistance > kFadeFrom)) return 1.0;
  const double logT = std::log(opticalDistance), logTheta = std::log(std::max(theta, 1e-6));
  // Linear in ρ and in log H between nodes, held beyond.
  // (Plain variables, not structured bindings: the lambda below captures them, which clang 14
  // refuses for bindings.)
  const std::pair<std::size_t, double> rw = locate(rho_, std::clamp(reflectance, 0.0, 1.0));
  const std::pair<std::size_t, double> hw = locate(logH_, std::log(std::max(heightOptical, 1e-9)));
  const std::size_t r = rw.first, h = hw.first;
  const double w = rw.second, wh = hw.second;
  auto atH = [&](std::size_t hh) {
    const std::size_t base = std::min(hh, h_.size() - 1) * rho_.size();
    double v = atRho(base + r, logT, logTheta);
    if (rho_.size() >= 2 && w > 0.0) v = (1.0 - w) * v + w * atRho(base + r + 1, logT, logTheta);
    return v;
  };
  double v = atH(h);
  if (h_.size() >= 2 && wh > 0.0) v = (1.0 - wh) * v + wh * atH(h + 1);
  v = std::max(0.0, v);
  if (opticalDistance >= kFullFrom) return v;
  const double f = std::log(opticalDistance / kFadeFrom) / std::log(kFullFrom / kFadeFrom);
  return 1.0 + f * (v - 1.0);
}

void GroundCorrectionTable::factors(double opticalDistance, double reflectance, double heightOptical, const double* theta,
                                    std::size_t n, double* out) const noexcept {
  // The rings' centre values once for this (T, ρ, H) (factor() at each centre), then linear in
  // log θ between them for every angle: the same interpolation as factor(), without its per-call
  // node searches (a glow curve has 512 angles).
  const std::size_t nR = edges_.size() - 1;
  double at[64];
  if (fit_.empty() || nR > 64) {
    for (std::size_t k = 0; k < n; ++k) out[k] = factor(opticalDistance, theta[k], reflectance, heightOptical);
    return;
  }
  for (std::size_t j = 0; j < nR; ++j)
    at[j] = factor(opticalDistance, std::exp(centresLog_[j]), reflectance, heightOptical);
  std::size_t j = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const double lt = std::log(std::max(theta[k], 1e-6));
    if (nR < 2 || lt <= centresLog_.front()) {
      out[k] = at[0];
      continue;
    }
    if (lt >= centresLog_.back()) {
      out[k] = at[nR - 1];
      continue;
    }
    if (j + 1 < nR && lt < centresLog_[j]) j = 0;  // angles not ascending: search again
    while (j + 2 < nR && lt > centresLog_[j + 1]) ++j;
    const double w = (lt - centresLog_[j]) / (centresLog_[j + 1] - centresLog_[j]);
    out[k] = (1.0 - w) * at[j] + w * at[j + 1];
  }
}

Result<GroundCorrectionTable> GroundCorrectionTable::blend(const GroundCorrectionTable& a, const GroundCorrectionTable& b,
                                                           double w, const Phase& phase) {
  if (a.t_ != b.t_ || a.edges_ != b.edges_ || a.rho_ != b.rho_ || a.h_ != b.h_)
    return Error{"ground correction: cannot blend tables with different nodes"};
  GroundCorrectionTable t = a;
  t.phase_ = phase;
  for (std::size_t k = 0; k < t.c_.size(); ++k) {
    t.c_[k] = (1.0 - w) * a.c_[k] + w * b.c_[k];
    t.se_[k] = (1.0 - w) * a.se_[k] + w * b.se_[k];
  }
  t.paths_ = std::min(a.paths_, b.paths_);
  t.smooth();
  return t;
}

// ---- text form ----------------------------------------------------------------------------
// fogbeam-ground-correction 1
// phase <describe(phase)>            (informational; the identity below is what parse checks)
// phase_identity <kind> <a> <b> <c>
// paths <N> seed <S>
// heights_optical <n> v…
// optical_distances <n> v…
// ring_edges_deg <n> v…
// reflectances <n> v…
// then n_H × n_ρ × n_T lines (H, then ρ, then T order), each n_rings pairs "factor stderr".

Status GroundCorrectionTable::save(const std::filesystem::path& path) const {
  std::ofstream f(path);
  if (!f) return Error{"cannot write " + path.string()};
  f.precision(17);
  f << "fogbeam-ground-correction 1\n";
  detail::writePhase(f, phase_);
  f << "paths " << paths_ << " seed " << seed_ << "\n";
  auto list = [&](const char* name, const std::vector<double>& v, double scale) { detail::writeList(f, name, v, scale); };
  list("optical_distances", t_, 1.0);
  list("ring_edges_deg", edges_, 180.0 / kPi);
  list("reflectances", rho_, 1.0);
  list("heights_optical", h_, 1.0);
  f.precision(6);
  const std::size_t nR = edges_.size() - 1;
  for (std::size_t r = 0; r < h_.size() * rho_.size(); ++r)
    for (std::size_t i = 0; i < t_.size(); ++i) {
      for (std::size_t j = 0; j < nR; ++j) f << (j ? "  " : "") << c_[index(r, i, j)] << ' ' << se_[index(r, i, j)];
      f << "\n";
    }
  if (!f) return Error{"error writing " + path.string()};
  return Ok{};
}

Result<GroundCorrectionTable> GroundCorrectionTable::load(const std::filesystem::path& path) {
  auto text = detail::readTextFile(path, "ground-correction table");
  if (!text) return text.error();
  return parse(*text, path.string());
}

Result<GroundCorrectionTable> GroundCorrectionTable::parse(std::string_view text, const std::string& source) {
  detail::TableText in(text, source);
  auto fail = [&](const std::string& what) { return in.fail(what); };
  auto phase = in.headerAndPhase("fogbeam-ground-correction");
  if (!phase) return phase.error();
  GroundCorrectionTable t;
  t.phase_ = *phase;
  std::string k1;
  if (!in.next("paths") || !(in.words() >> t.paths_ >> k1 >> t.seed_) || k1 != "seed")
    return fail("expected 'paths <N> seed <S>'");
  // Each list as TableText::list reads it, then its nodes ascending within their range.
  auto list = [&](const char* key, std::vector<double>& v, double scale, double lo, double hi, bool loOpen) -> Status {
    if (Status s = in.list(key, v, scale); !s) return s;
    if (Status s = checkAscending(v, key, lo, hi, loOpen); !s) return fail(s.error().message);
    return Ok{};
  };
  if (Status s = list("optical_distances", t.t_, 1.0, 0.0, 1e3, true); !s) return s.error();
  if (Status s = list("ring_edges_deg", t.edges_, kPi / 180.0, 0.0, kPi + 1e-12, true); !s) return s.error();
  if (t.edges_.size() < 2) return fail("ring_edges_deg: at least two edges");
  if (Status s = list("reflectances", t.rho_, 1.0, 0.0, 0.999, false); !s) return s.error();
  if (Status s = list("heights_optical", t.h_, 1.0, 0.0, 10.0, true); !s) return s.error();
  const std::size_t nR = t.edges_.size() - 1;
  t.c_.resize(t.h_.size() * t.rho_.size() * t.t_.size() * nR);
  t.se_.resize(t.c_.size());
  for (std::size_t r = 0; r < t.h_.size() * t.rho_.size(); ++r)
    for (std::size_t i = 0; i < t.t_.size(); ++i) {
      if (!in.nextLine())
        return in.failMissing("expected " + std::to_string(nR) + " pairs 'factor stderr' (the file ends early)");
      std::istringstream& ss = in.words();
      for (std::size_t j = 0; j < nR; ++j) {
        double v = 0, e = 0;
        if (!(ss >> v >> e) || !std::isfinite(v) || !std::isfinite(e) || v < 0.0 || e < 0.0)
          return fail("pair " + std::to_string(j + 1) + ": expected 'factor stderr', both finite and >= 0");
        t.c_[t.index(r, i, j)] = v;
        t.se_[t.index(r, i, j)] = e;
      }
      std::string extra;
      if (ss >> extra) return fail("more than " + std::to_string(nR) + " pairs on the line");
    }
  t.smooth();
  return t;
}

namespace detail {
extern const EmbeddedTable kEmbeddedGroundCorrections[];
extern const std::size_t kEmbeddedGroundCorrectionCount;
}  // namespace detail

std::shared_ptr<const GroundCorrectionTable> shippedGroundCorrection(const Phase& phase) {
  return detail::shippedTable<GroundCorrectionTable>(phase, detail::kEmbeddedGroundCorrections,
                                                     detail::kEmbeddedGroundCorrectionCount, ".gnd",
                                                     multipleScatteringTableName);
}

}  // namespace fogbeam
