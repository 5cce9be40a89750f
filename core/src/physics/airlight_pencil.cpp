// fogbeam — the accurate method over the pencil of planes through the eye and the lamp
// (airlight_pencil.hpp).
#include <fogbeam/physics/airlight_pencil.hpp>

#include "airlight_kernel.hpp"
#include "airlight_tables.hpp"
#include "profile_simd.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <thread>

namespace fogbeam {

namespace {
// A ray's basis coefficients live on its stack (evaluateCumulative).
constexpr int kMaxFunctions = 128;
constexpr double kHalfPi = 0.5 * kPi;
constexpr double kTwoPi = 2.0 * kPi;
// As in airlight.cpp: beyond this optical eye–lamp distance the airlight underflows.
constexpr double kMaxOpticalDistance = 700.0;
}  // namespace

Status PencilAirlight::validate(const PencilOptions& options) {
  if (!(options.spokes >= 8) || !(options.piece_deg > 0.0 && options.piece_deg <= 45.0) ||
      !(options.merge_tolerance >= 0.0 && options.merge_tolerance < 1.0) ||
      !(options.spoke_tolerance >= 0.0 && options.spoke_tolerance < 1.0))
    return Error{"pencil airlight: need spokes >= 8, 0 < piece_deg <= 45, 0 <= merge_tolerance < 1 and "
                 "0 <= spoke_tolerance < 1"};
  return Ok{};
}

Result<PencilAirlight> PencilAirlight::build(const AirlightEvaluator& lamp, const Vec3& eye,
                                             const PencilOptions& options) {
  if (lamp.method() != AirlightMethod::Accurate)
    return Error{"pencil airlight: the lamp's evaluator must use the accurate method"};
  if (Status v = validate(options); !v) return v.error();
  PencilAirlight p;
  p.lamp_ = &lamp;
  p.options_ = options;
  p.spokeCount_ = options.spokes;
  p.pieces_.resize(static_cast<std::size_t>(p.spokeCount_));
  p.spokeBound_.assign(static_cast<std::size_t>(p.spokeCount_), 0.0);
  if (options.kernel_expansion && detail::psiBasis().functions() <= kMaxFunctions) {
    p.projections_.resize(static_cast<std::size_t>(p.spokeCount_));
    p.pieceAtKnot_.resize(static_cast<std::size_t>(p.spokeCount_));
    p.kernel_ = detail::kernelTableFor(lamp.medium().phase);
  }
  p.state_ = std::make_unique<std::atomic<int>[]>(static_cast<std::size_t>(p.spokeCount_));
  const double eighth = 0.125 * radians(options.piece_deg);
  for (int k = 0; k * eighth <= kPi + 1e-9; ++k) {
    p.gridCos_.push_back(std::cos(k * eighth));
    p.gridSin_.push_back(std::sin(k * eighth));
  }
  p.reset(eye);
  return p;
}

void PencilAirlight::reset(const Vec3& eye) {
  eye_ = eye;
  const Vec3 d = lamp_->lamp().position_m - eye;
  distance_ = glm::length(d);
  negligible_ = lamp_->medium().extinction_per_m * distance_ > kMaxOpticalDistance;
  // The spokes' frame is fixed to the lamp: the axis towards it and two normals chosen in the
  // lamp's own coordinates, so that a lamp that keeps its pose relative to the eye (a vehicle's
  // own lamp, the vehicle moving) has the same spokes, whatever the vehicle's heading.
  bool sameSpokes = false;
  if (distance_ > 0.0) {
    e0_ = d / distance_;
    const Mat3& worldFromLamp = lamp_->lamp().worldFromLamp;
    const Vec3 e0L = lamp_->lampFromWorld_ * e0_;
    const Vec3 a = std::abs(e0L.x) < 0.6 ? Vec3(1, 0, 0) : (std::abs(e0L.y) < 0.6 ? Vec3(0, 1, 0) : Vec3(0, 0, 1));
    const Vec3 e1L = glm::normalize(glm::cross(e0L, a));
    e1_ = worldFromLamp * e1L;
    e2_ = worldFromLamp * glm::cross(e0L, e1L);
    // Spokes depend on the profile and on this axis in the lamp's frame alone (not on the
    // distance or the fog: those enter per ray). Within 1e-9 (rounding of poses recomputed
    // from world coordinates every frame) the sampled ones are kept.
    constexpr double kSameAxis = 1e-9;
    sameSpokes = spokesValid_ && std::abs(e0L.x - spokeAxis_.x) <= kSameAxis &&
                 std::abs(e0L.y - spokeAxis_.y) <= kSameAxis && std::abs(e0L.z - spokeAxis_.z) <= kSameAxis;
    if (!sameSpokes) spokeAxis_ = e0L;
    spokesValid_ = true;
  } else {
    spokesValid_ = false;
  }
  if (!sameSpokes)
    for (int s = 0; s < spokeCount_; ++s) state_[static_cast<std::size_t>(s)].store(0, std::memory_order_relaxed);
  leafW_.assign(static_cast<std::size_t>(spokeCount_), 0);
  leafA_.resize(static_cast<std::size_t>(spokeCount_));
  tau_ = lamp_->medium().extinction_per_m * distance_;
  expNegTau_ = std::exp(-tau_);
  tauPosition_ = kernel_ ? kernel_->tauPosition(tau_) : 0.0;
  sliceRows_.clear();
  sliceCuts_.clear();
  if (kernel_ && tau_ <= detail::KernelTable::kTauMax) kernel_->sliceAt(tauPosition_, sliceRows_, sliceCuts_);
  // The adaptive plan's test rays (middleDiffers): the expansion's coefficients at angles γ
  // from the lamp's direction of 0.25° to 128° (doubling), this τ, up to each one's cut.
  testRows_.clear();
  testCut_.clear();
  if (kernel_ && tau_ <= detail::KernelTable::kTauMax) {
    const int nf = detail::psiBasis().functions();
    for (double deg = 0.25; deg <= 128.0; deg *= 2.0) {
      const detail::KernelTable::Lookup lk = kernel_->lookupAt(radians(deg), tauPosition_);
      const int cut = std::min(nf, lk.cut + 3);
      for (int r = 0; r < nf; ++r) testRows_.push_back(r < cut ? lk.coefficient(r) : 0.0f);
      testCut_.push_back(cut);
    }
  }
}

int PencilAirlight::coarseStep() const noexcept {
  if (!kernel_ || !(options_.spoke_tolerance > 0.0)) return 1;
  int step = 32;
  while (step > 1 && spokeCount_ % step != 0) step /= 2;
  return step;
}

bool PencilAirlight::middleDiffers(int a, int w) const {
  if (!kernel_ || w < 2 || testRows_.empty()) return true;
  const auto at = [&](int s) -> const std::vector<float>& {
    return projections_[static_cast<std::size_t>(((s % spokeCount_) + spokeCount_) % spokeCount_)];
  };
  const std::vector<float>& pa = at(a);
  const std::vector<float>& pm = at(a + w / 2);
  const std::vector<float>& pb = at(a + w);
  const int nf = detail::psiBasis().functions();
  // What a ray of the middle spoke would read from the blend of the ends instead of its own
  // spoke, for sky rays at the test angles γ and for rays ending at every knot (the partial
  // sums of the expansion, eq. 3 less its scale): within spoke_tolerance of its own value, or of
  // 1 % of the largest of these values. Two passes (the largest first) rather than a buffer of
  // the partial sums: this runs on every thread of the pool each frame, and a per-thread buffer
  // would grow on whichever thread first met the largest pencil, an allocation in a steady frame.
  const auto row = [&](std::size_t t) { return testRows_.data() + t * static_cast<std::size_t>(nf); };
  double peak = 0.0;
  for (std::size_t t = 0; t < testCut_.size(); ++t) {
    const float* u = row(t);
    double sm = 0.0;
    for (int r = 0; r < testCut_[t]; ++r) {
      const auto k = static_cast<std::size_t>(r);
      sm += static_cast<double>(u[k]) * static_cast<double>(pm[k]);
      peak = std::max(peak, std::abs(sm));
    }
  }
  const double floor = 0.01 * peak;
  for (std::size_t t = 0; t < testCut_.size(); ++t) {
    const float* u = row(t);
    double sm = 0.0, sd = 0.0;
    for (int r = 0; r < testCut_[t]; ++r) {
      const auto k = static_cast<std::size_t>(r);
      sm += static_cast<double>(u[k]) * static_cast<double>(pm[k]);
      sd += static_cast<double>(u[k]) * (static_cast<double>(pm[k]) - 0.5 * (static_cast<double>(pa[k]) + static_cast<double>(pb[k])));
      if (std::abs(sd) > options_.spoke_tolerance * std::max(std::abs(sm), floor)) return true;
    }
  }
  return false;
}

void PencilAirlight::setLeaf(int a, int w) {
  for (int k = a; k < a + w; ++k) {
    const auto i = static_cast<std::size_t>(((k % spokeCount_) + spokeCount_) % spokeCount_);
    leafA_[i] = a;
    leafW_[i] = w;
  }
}

PencilAirlight::SpokePair PencilAirlight::spokesOf(const Vec3& direction) const noexcept {
  if (negligible_ || !(distance_ > 1e-6)) return {};  // nothing to integrate, or per ray (eye at the lamp)
  return spokesAt(azimuthOf(direction - glm::dot(direction, e0_) * e0_));
}

double PencilAirlight::azimuthOf(const Vec3& perp) const noexcept {
  return fastAtan2(glm::dot(perp, e2_), glm::dot(perp, e1_));  // 0 on the axis itself: any spoke
}

PencilAirlight::SpokePair PencilAirlight::spokesAt(double phi) const noexcept {
  // φ ∈ [−π, π] (atan2), so u ∈ [0, spokeCount_]: wrapping is a comparison, not a division.
  const double u = (phi + kPi) * (spokeCount_ / kTwoPi);
  const double fl = std::floor(u);
  const auto wrap = [n = spokeCount_](int s) { return s >= n ? s - n : (s < 0 ? s + n : s); };
  SpokePair sp;
  sp.s0 = wrap(static_cast<int>(fl));
  const auto k = static_cast<std::size_t>(sp.s0);
  if (leafW_[k] > 0) {  // a planned leaf: blend its two ends
    const int a = leafA_[k], w = leafW_[k];
    sp.t = std::clamp((static_cast<double>(sp.s0) + (u - fl) - a) / w, 0.0, 1.0);
    sp.s0 = wrap(a);
    sp.s1 = wrap(a + w);
    return sp;
  }
  sp.s1 = wrap(sp.s0 + 1);
  sp.t = std::clamp(u - fl, 0.0, 1.0);
  return sp;
}

bool PencilAirlight::ensureSpoke(int s) const {
  std::atomic<int>& st = state_[static_cast<std::size_t>(s)];
  if (st.load(std::memory_order_acquire) == 2) return false;
  int expected = 0;
  if (st.compare_exchange_strong(expected, 1, std::memory_order_acq_rel)) {
    sampleSpoke(s);
    st.store(2, std::memory_order_release);
    return true;
  }
  // Another thread samples it: a spoke takes ~10–30 µs.
  while (st.load(std::memory_order_acquire) != 2) std::this_thread::yield();
  return false;
}

void PencilAirlight::sampleSpoke(int s) const {
  std::vector<Piece>& out = pieces_[static_cast<std::size_t>(s)];
  const AirlightEvaluator& ev = *lamp_;
  const Profile& profile = *ev.lamp().profile;
  const double phi = kTwoPi * s / spokeCount_ - kPi;
  // The spoke's plane in the lamp frame: ψ = 0 points from the lamp to the eye, ψ grows
  // towards the side the spoke's rays leave on (azimuth φ), ψ = π points away from the eye.
  const Vec3 u = ev.lampFromWorld_ * (-e0_);
  const Vec3 v = ev.lampFromWorld_ * (std::cos(phi) * e1_ + std::sin(phi) * e2_);
  const double invEighth = 8.0 / radians(options_.piece_deg);
  auto intensity = [&](double psi) {
    const double g = psi * invEighth, k = std::round(g);
    if (std::abs(g - k) < 1e-9 && k >= 0.0 && k < static_cast<double>(gridCos_.size())) {
      const std::size_t i = static_cast<std::size_t>(k);
      return profile.intensity(gridCos_[i] * u + gridSin_[i] * v);
    }
    return profile.intensity(std::cos(psi) * u + std::sin(psi) * v);
  };

  // Breakpoints as in the accurate method: the profile's kinks (spot rings, feature lines of
  // tabulated data) and, for tabulated data, the edge of the support cone outside which I = 0.
  // Per thread, kept from spoke to spoke: a low-beam spoke has ~60 breakpoints, and a fresh
  // vector cost ~10 allocations a spoke, ~20 000 a traffic frame (sampleSpoke runs only for
  // spokes not sampled before, so steady frames do not reach it).
  thread_local std::vector<double> bp;
  bp.assign({0.0, kPi});
  const bool tabulated = std::holds_alternative<TabulatedProfile>(profile.model());
  if (tabulated) {
    const double sup = profile.supportHalfAngle();
    if (sup < kPi) {
      const double x = u.x, y = v.x, r = std::hypot(x, y), cs = std::cos(sup);
      if (r > 1e-15 && std::abs(cs) <= r) {
        const double centre = std::atan2(y, x), half = std::acos(cs / r);
        for (double base : {centre - half, centre + half})
          for (int kk = -1; kk <= 1; ++kk) {
            const double th = base + kk * kTwoPi;
            if (th > 0.0 && th < kPi) bp.push_back(th);
          }
      }
    }
  }
  profile.appendFeatureKinks(u, v, 0.0, kPi, bp);
  std::sort(bp.begin(), bp.end());

  const double cosSupport = std::cos(profile.supportHalfAngle());
  const double maxWidth = radians(options_.piece_deg);
  out.clear();
  auto emit = [&](double pa, double pb, double iA, double iM, double iB) {
    const double hw = 0.5 * (pb - pa);
    Piece pc{pa, pb, 0.5 * (pa + pb), iM, 0.0, 0.0};
    if (hw > 1e-12) {
      pc.c1 = (iB - iA) / (2 * hw);
      pc.c2 = (iA - 2 * iM + iB) / (2 * hw * hw);
    }
    out.push_back(pc);
  };
  // Pass 1: the live intervals between breakpoints, cut into cells of a coarse grid aligned at
  // 0 (kCoarse × piece_deg, shared by every spoke), with I at every cut; their largest value
  // sets the spoke's tolerance. Ends just inside the interval: at a kink I is continuous for
  // spot edges, tabulated data may drop to 0 at the edge of its range (as in the accurate
  // method).
  constexpr int kCoarse = 8;
  const double coarse = kCoarse * maxWidth;
  struct Cell {
    double c, a, b;   // the grid cell [c, c + coarse] and the interval [a, b] it lies in
    double iLo, iHi;  // I at max(a, c) and at min(b, c + coarse)
  };
  thread_local std::vector<Cell> cells;
  cells.clear();
  double peak = 0.0;
  // Tabulated data: which intervals are live does not depend on I (the support cone), so every
  // sample of this pass is known before it runs: the ends of the live intervals and the coarse
  // cuts inside them, in the order the pass reads them. They are taken in one batch
  // (Profile::intensitiesOnCircle: the trigonometry a SIMD vector at a time), as are pass 2's
  // middles of the pieces of cells cut by breakpoints; most of a spoke's samples are one or the
  // other (measured on the traffic bench: ~119 samples at ~59 breakpoints per low-beam spoke).
  thread_local std::vector<double> batchPsi, batchValue;
  thread_local std::vector<char> liveFlags;  // per breakpoint interval (tabulated data)
  std::size_t nextValue = 0;
  if (tabulated) {
    // Live: the interval's middle inside the support cone (its lamp-axis component, SIMD).
    batchPsi.resize(bp.size());
    batchValue.resize(bp.size());
    for (std::size_t i = 1; i < bp.size(); ++i) batchPsi[i] = 0.5 * (bp[i - 1] + bp[i]);
    if (bp.size() > 1) detail::circleComponent(u.x, v.x, batchPsi.data() + 1, bp.size() - 1, batchValue.data() + 1);
    liveFlags.assign(bp.size(), 0);
    for (std::size_t i = 1; i < bp.size(); ++i) liveFlags[i] = batchValue[i] >= cosSupport ? 1 : 0;
    batchPsi.clear();
    double end = -1.0;
    for (std::size_t i = 1; i < bp.size(); ++i) {
      const double a = bp[i - 1], b = bp[i];
      if (b - a < 1e-13 || !liveFlags[i]) continue;
      if (a != end) batchPsi.push_back(a + 1e-12 * (b - a));
      batchPsi.push_back(b - 1e-12 * (b - a));
      end = b;
      for (double c = std::floor(a / coarse + 1e-12) * coarse; c < b - 1e-13; c += coarse) {
        const double hi = std::min(b, c + coarse);
        if (hi - std::max(a, c) < 1e-13) continue;
        if (hi < b) batchPsi.push_back(hi);
      }
    }
    batchValue.resize(batchPsi.size());
    profile.intensitiesOnCircle(u, v, batchPsi.data(), batchPsi.size(), batchValue.data());
  }
  // Pass 1's samples, in the order above for tabulated data.
  auto pass1 = [&](double psi) { return tabulated ? batchValue[nextValue++] : intensity(psi); };
  // I is continuous across a feature kink or a spot ring (a kink, not a step): the next live
  // interval starts with the value this one ended with. Not across the support cone's edge,
  // where tabulated data may drop to 0, but beyond that edge nothing is live.
  double lastEnd = -1.0, lastValue = 0.0;
  for (std::size_t i = 1; i < bp.size(); ++i) {
    const double a = bp[i - 1], b = bp[i];
    if (b - a < 1e-13) continue;
    const double mid = 0.5 * (a + b);
    const bool live = tabulated ? liveFlags[i] != 0 : intensity(mid) > 0.0;
    if (!live) continue;
    const double ia = a == lastEnd ? lastValue : pass1(a + 1e-12 * (b - a));
    const double ib = pass1(b - 1e-12 * (b - a));
    lastEnd = b;
    lastValue = ib;
    peak = std::max({peak, std::abs(ia), std::abs(ib)});
    if (!tabulated && ia == ib && ia == intensity(mid)) {  // spot: constant between its rings
      emit(a, b, ia, ia, ib);
      continue;
    }
    double iPrev = ia;
    for (double c = std::floor(a / coarse + 1e-12) * coarse; c < b - 1e-13; c += coarse) {
      const double hi = std::min(b, c + coarse);
      if (hi - std::max(a, c) < 1e-13) continue;
      const double iHi = hi >= b ? ib : pass1(hi);
      peak = std::max(peak, std::abs(iHi));
      cells.push_back(Cell{c, a, b, iPrev, iHi});
      iPrev = iHi;
    }
  }
  // Pass 2: each cell top-down on its dyadic grid. A whole cell wider than piece_deg stays one
  // quadratic when that quadratic (through its ends and middle) predicts I at its quarter
  // points within merge_tolerance × the spoke's peak, else its halves are refined in turn
  // (their middles are those quarter points); cells cut by a breakpoint split down to
  // piece_deg. Where I is smooth a cell costs 4 samples instead of 2 per piece_deg (a profile
  // look-up each: two arctangents, two bucket searches; the cut cells' middles batched, below).
  const double tol = options_.merge_tolerance > 0.0 ? options_.merge_tolerance * peak : -1.0;
  // Pieces whose middle sample is deferred to one batch after the pass (tabulated data): the
  // piece's index in `out`, its ends' values.
  struct Deferred {
    std::size_t piece;
    double iA, iB;
  };
  thread_local std::vector<Deferred> deferred;
  deferred.clear();
  batchPsi.clear();
  auto refine = [&](auto& self, double c, double w, double a, double b, double iLo, double iHi, double knownMid) -> void {
    const double lo = std::max(a, c), hi = std::min(b, c + w);
    if (hi - lo < 1e-13) return;
    const double m = c + 0.5 * w;
    if (w <= maxWidth * (1.0 + 1e-9)) {
      const double pm = 0.5 * (lo + hi);
      if (lo == c && hi == c + w && !std::isnan(knownMid)) {
        emit(lo, hi, iLo, knownMid, iHi);
      } else if (tabulated) {
        deferred.push_back({out.size(), iLo, iHi});
        batchPsi.push_back(pm);
        emit(lo, hi, iLo, 0.0, iHi);  // i0 and c2 set after the batch
      } else {
        emit(lo, hi, iLo, intensity(pm), iHi);
      }
      return;
    }
    if (lo == c && hi == c + w) {
      const double im = std::isnan(knownMid) ? intensity(m) : knownMid;
      const double q1 = intensity(c + 0.25 * w), q3 = intensity(c + 0.75 * w);
      const double p1 = (3.0 * iLo + 6.0 * im - iHi) / 8.0, p3 = (-iLo + 6.0 * im + 3.0 * iHi) / 8.0;
      if (std::abs(p1 - q1) <= tol && std::abs(p3 - q3) <= tol) {
        emit(lo, hi, iLo, im, iHi);
        return;
      }
      self(self, c, 0.5 * w, a, b, iLo, im, q1);
      self(self, m, 0.5 * w, a, b, im, iHi, q3);
      return;
    }
    const double nan = std::numeric_limits<double>::quiet_NaN();
    if (m <= lo) {
      self(self, m, 0.5 * w, a, b, iLo, iHi, nan);
    } else if (m >= hi) {
      self(self, c, 0.5 * w, a, b, iLo, iHi, nan);
    } else {
      const double im = intensity(m);
      self(self, c, 0.5 * w, a, b, iLo, im, nan);
      self(self, m, 0.5 * w, a, b, im, iHi, nan);
    }
  };
  for (const Cell& cell : cells)
    refine(refine, cell.c, coarse, cell.a, cell.b, cell.iLo, cell.iHi, std::numeric_limits<double>::quiet_NaN());
  if (!deferred.empty()) {
    batchValue.resize(batchPsi.size());
    profile.intensitiesOnCircle(u, v, batchPsi.data(), batchPsi.size(), batchValue.data());
    for (std::size_t k = 0; k < deferred.size(); ++k) {
      Piece& pc = out[deferred[k].piece];
      const double iM = batchValue[k], hw = 0.5 * (pc.b - pc.a);
      pc.i0 = iM;  // as emit()
      if (hw > 1e-12) pc.c2 = (deferred[k].iA - 2 * iM + deferred[k].iB) / (2 * hw * hw);
    }
  }
  // Spot intervals where I is constant were emitted in pass 1, before the cells: order by ψ.
  std::sort(out.begin(), out.end(), [](const Piece& x, const Piece& y) { return x.a < y.a; });
  mergeSmoothPieces(out);
  double bound = 0.0;
  for (const Piece& pc : out) {
    const double hw = std::max(pc.m - pc.a, pc.b - pc.m);
    bound = std::max(bound, std::abs(pc.i0) + hw * (std::abs(pc.c1) + hw * std::abs(pc.c2)));
  }
  spokeBound_[static_cast<std::size_t>(s)] = bound;
  if (kernel_) projectSpoke(s);
}

namespace {
const double kGL3x[3] = {-0.7745966692414834, 0.0, 0.7745966692414834};
const double kGL3w[3] = {0.5555555555555556, 0.8888888888888888, 0.5555555555555556};
}  // namespace

void PencilAirlight::projectSpoke(int s) const {
  // ∫ β_r I_s over each knot interval (3-point Gauss–Legendre on each piece's share of it:
  // exact, the product being a quintic), then summed per function and per knot.
  const detail::PsiBasis& basis = detail::psiBasis();
  const int m = basis.intervals(), nf = basis.functions();
  const std::vector<Piece>& pcs = pieces_[static_cast<std::size_t>(s)];
  thread_local std::vector<double> per;  // per[j · 4 + i] = ∫_{t_j}^{t_{j+1}} β_{j+i} I_s
  per.assign(static_cast<std::size_t>(m) * 4, 0.0);
  std::vector<std::uint32_t>& atKnot = pieceAtKnot_[static_cast<std::size_t>(s)];
  atKnot.resize(static_cast<std::size_t>(m) + 1);
  std::size_t first = 0;
  for (int j = 0; j < m; ++j) {
    const double a = basis.knot(j), b = basis.knot(j + 1);
    while (first < pcs.size() && pcs[first].b <= a) ++first;
    atKnot[static_cast<std::size_t>(j)] = static_cast<std::uint32_t>(first);
    // The four sums in locals: accumulated through `per` (doubles, as the pieces' fields) the
    // compiler reloaded the piece after every store.
    double acc[4] = {0.0, 0.0, 0.0, 0.0};
    for (std::size_t q = first; q < pcs.size() && pcs[q].a < b; ++q) {
      const Piece pc = pcs[q];
      const double sa = std::max(a, pc.a), sb = std::min(b, pc.b);
      if (!(sb > sa)) continue;
      const double half = 0.5 * (sb - sa), mid = sa + half;
      for (int g = 0; g < 3; ++g) {
        const double x = mid + half * kGL3x[g], u = x - pc.m;
        const double wi = half * kGL3w[g] * (pc.i0 + u * (pc.c1 + u * pc.c2));
        double bv[4];
        basis.eval(j, x, bv);
        for (int i = 0; i < 4; ++i) acc[i] += wi * bv[i];
      }
    }
    for (int i = 0; i < 4; ++i) per[static_cast<std::size_t>(j) * 4 + static_cast<std::size_t>(i)] = acc[i];
  }
  while (first < pcs.size() && pcs[first].b <= basis.knot(m)) ++first;
  atKnot[static_cast<std::size_t>(m)] = static_cast<std::uint32_t>(first);
  std::vector<float>& out = projections_[static_cast<std::size_t>(s)];
  out.assign(static_cast<std::size_t>(nf) + 3 * static_cast<std::size_t>(m + 1), 0.0f);
  for (int r = 0; r < nf; ++r) {
    double sum = 0.0;
    for (int j = std::max(0, r - 3); j <= std::min(m - 1, r); ++j) sum += per[static_cast<std::size_t>(j) * 4 + static_cast<std::size_t>(r - j)];
    out[static_cast<std::size_t>(r)] = static_cast<float>(sum);
  }
  for (int j = 0; j <= m; ++j)
    for (int i = 0; i < 3; ++i) {
      const int r = j + i;
      double sum = 0.0;
      for (int jj = std::max(0, r - 3); jj < j; ++jj) sum += per[static_cast<std::size_t>(jj) * 4 + static_cast<std::size_t>(r - jj)];
      out[static_cast<std::size_t>(nf) + 3 * static_cast<std::size_t>(j) + static_cast<std::size_t>(i)] = static_cast<float>(sum);
    }
}

double PencilAirlight::expansionIntegral(const SpokePair& sp, const float* u, double xEnd,
                                         ExpansionSums& whole) const noexcept {
  const detail::PsiBasis& basis = detail::psiBasis();
  const int nf = basis.functions();
  const float w0 = static_cast<float>(1.0 - sp.t), w1 = static_cast<float>(sp.t);
  const float* p0 = projections_[static_cast<std::size_t>(sp.s0)].data();
  const float* p1 = projections_[static_cast<std::size_t>(sp.s1)].data();
  const int j0 = basis.interval(xEnd);
  const double t0 = basis.knot(j0);
  // Functions that end before t_j0 whole, the three that straddle t_j0 up to it, then the four
  // that live on [t_j0, t_j0+1) from t_j0 to xEnd; both spokes in one pass, blended.
  // Eight float partial sums, function r in lane r mod 8 (the compiler keeps them in one vector
  // register): ~60 terms. `whole` carries them from the last (nearer) end of the same ray, so a
  // ray's ends in ascending order add each function once (a view table's 48 distances).
  // The lanes in a local array: through `whole.acc` (a float* as u, p0, p1) the compiler could
  // not rule out aliasing and added them one float at a time (~a fifth of the function).
  float acc[8];
  std::copy(whole.acc, whole.acc + 8, acc);
  int r = whole.next;
  for (; r < j0 && r % 8 != 0; ++r) acc[r % 8] += u[r] * (w0 * p0[r] + w1 * p1[r]);
  for (; r + 8 <= j0; r += 8)
    for (int l = 0; l < 8; ++l) acc[l] += u[r + l] * (w0 * p0[r + l] + w1 * p1[r + l]);
  for (; r < j0; ++r) acc[r % 8] += u[r] * (w0 * p0[r] + w1 * p1[r]);
  std::copy(acc, acc + 8, whole.acc);
  whole.next = r;
  double sum = 0.0;
  for (int l = 0; l < 8; ++l) sum += static_cast<double>(acc[l]);
  const float* left0 = p0 + nf + 3 * j0;
  const float* left1 = p1 + nf + 3 * j0;
  for (int i = 0; i < 3; ++i) sum += static_cast<double>(u[j0 + i]) * static_cast<double>(w0 * left0[i] + w1 * left1[i]);
  if (xEnd > t0) {
    // The four functions weighted by u are one cubic on the interval: 3-point Gauss on each
    // piece's share of [t_j0, xEnd] is exact (a quintic).
    double gc[4];
    basis.combine(j0, u + j0, gc);
    for (const auto& [s, w] : {std::pair{sp.s0, 1.0 - sp.t}, std::pair{sp.s1, sp.t}}) {
      if (w == 0.0) continue;
      const std::vector<Piece>& pcs = pieces_[static_cast<std::size_t>(s)];
      // The first piece ending after t_j0 (pieceAtKnot_: the binary search it replaces was a
      // tenth of this function, mostly cache misses on the pieces it probed).
      auto it = pcs.begin() + pieceAtKnot_[static_cast<std::size_t>(s)][static_cast<std::size_t>(j0)];
      for (; it != pcs.end() && it->a < xEnd; ++it) {
        const double sa = std::max(t0, it->a), sb = std::min(xEnd, it->b);
        if (!(sb > sa)) continue;
        const double half = 0.5 * (sb - sa), mid = sa + half;
        for (int g = 0; g < 3; ++g) {
          const double x = mid + half * kGL3x[g], d = x - it->m, sl = basis.local(j0, x);
          const double gx = gc[0] + sl * (gc[1] + sl * (gc[2] + sl * gc[3]));
          sum += w * half * kGL3w[g] * (it->i0 + d * (it->c1 + d * it->c2)) * gx;
        }
      }
    }
  }
  return sum;
}

void PencilAirlight::mergeSmoothPieces(std::vector<Piece>& pieces) const {
  // Where I is smooth, two neighbouring grid pieces are as well described by one quadratic
  // through their outer ends and their common end: merge them when that quadratic predicts
  // both pieces' middle samples within `merge_tolerance` × the spoke's peak, and only within
  // cells of a doubling grid (2w, 4w, … aligned at 0), so that neighbouring spokes merge alike
  // and a ray's blend of two spokes still finds their cuts mostly shared. Fewer pieces, fewer
  // G look-ups per ray: they are what a ray costs.
  if (options_.merge_tolerance <= 0.0 || pieces.size() < 2) return;
  double peak = 0.0;
  for (const Piece& p : pieces) peak = std::max(peak, std::abs(p.i0));
  const double tol = options_.merge_tolerance * peak;
  const double w = radians(options_.piece_deg);
  auto at = [](const Piece& p, double x) {
    const double u = x - p.m;
    return p.i0 + u * (p.c1 + u * p.c2);
  };
  // In place: the pieces written (`kept`) never pass the one read (i), and a spoke's vector
  // keeps its memory from frame to frame (a second vector swapped in cost an allocation a spoke).
  for (double cell = 2.0 * w; cell <= kPi + 1e-9; cell *= 2.0) {
    std::size_t kept = 0;
    bool any = false;
    for (std::size_t i = 0; i < pieces.size(); ++i) {
      if (i + 1 < pieces.size()) {
        const Piece p = pieces[i];
        const Piece q = pieces[i + 1];
        // Same doubling cell, contiguous, both of the cell's halves.
        const double c0 = std::floor(p.a / cell + 1e-9) * cell;
        const bool aligned = std::abs(p.a - c0) < 1e-9 && std::abs(q.b - (c0 + cell)) < 1e-9 &&
                             std::abs(p.b - q.a) < 1e-12;
        if (aligned) {
          const double ia = at(p, p.a), im = at(p, p.b), ib = at(q, q.b);
          const double hw = 0.5 * (q.b - p.a), mid = p.b;
          Piece r{p.a, q.b, mid, im, (ib - ia) / (2 * hw), (ia - 2 * im + ib) / (2 * hw * hw)};
          if (std::abs(at(r, p.m) - p.i0) <= tol && std::abs(at(r, q.m) - q.i0) <= tol) {
            pieces[kept++] = r;
            ++i;
            any = true;
            continue;
          }
        }
      }
      pieces[kept++] = pieces[i];
    }
    pieces.resize(kept);
    if (!any) break;
  }
}

void PencilAirlight::evaluateCumulative(const Vec3& direction, const double* distances, std::size_t n,
                                        double* out) const {
  integrateCumulative(direction, distances, n, out);
  for (std::size_t m = 0; m < n; ++m) out[m] = std::max(out[m], 0.0);
}

void PencilAirlight::integrateCumulative(const Vec3& direction, const double* distances, std::size_t n,
                                         double* out) const {
  std::fill(out, out + n, 0.0);
  if (negligible_) return;
  const AirlightEvaluator& ev = *lamp_;
  const double c = glm::dot(direction, e0_);               // cos α
  const Vec3 perp = direction - c * e0_;
  const double sa = glm::length(perp);                     // sin α
  const double alpha = fastAtan2(sa, c);
  const SpokePair sp = distance_ > 1e-6 ? spokesAt(azimuthOf(perp)) : SpokePair{};
  const double kt = ev.medium().extinction_per_m;
  const double h = distance_ * sa, p = distance_ * c;      // eq. (3): lamp–ray distance, foot
  const detail::GMomentTable& g = *ev.tables_->g;
  if (sp.s0 < 0 || !(h > 1e-9) || kt * h > g.kMax() || alpha > kPi - detail::kAwayConeRad) {
    // Per ray: the eye at the lamp, a ray through the lamp, beyond the G table, or looking
    // (nearly) straight away from the lamp (detail::kAwayConeRad).
    ev.evaluateCumulative(Ray{eye_, direction, 0.0}, distances, n, out);
    return;
  }
  const double psiFoot = kHalfPi - alpha;   // ψ of the foot of the perpendicular: θ = ψ − ψF
  const double psiEnd = kPi - alpha;        // ψ at infinity along the ray
  // ψ of each distance (θ = atan((d − p)/h), eq. 3), ascending; one per call in the image path,
  // more (on the heap beyond 64) from tests.
  constexpr std::size_t kStack = 64;
  double psiStack[kStack];
  std::vector<double> heap;
  double* psi = psiStack;
  if (n > kStack) {
    heap.resize(n);
    psi = heap.data();
  }
  for (std::size_t m = 0; m < n; ++m)
    psi[m] = distances[m] > 0.0 ? (std::isinf(distances[m]) ? kHalfPi : fastAtan2(distances[m] - p, h)) + psiFoot : -1.0;
  // The two spokes either side of the ray's azimuth, blended linearly.
  ensureSpoke(sp.s0);
  ensureSpoke(sp.s1);
  const double tau = kt * distance_;
  if (kernel_ && tau <= detail::KernelTable::kTauMax) {
    // The expansion up to its cut, then G-moment product integration from there to each end.
    const detail::PsiBasis& basis = detail::psiBasis();
    const int nf = basis.functions();
    float u[kMaxFunctions];
    int cut = 0, needed = 0;
    if (tau == tau_ && !sliceCuts_.empty()) {
      // The pencil's own τ (every ray of a frame): two rows of its slice of the table.
      int ig = 0;
      double fu = 0.0;
      kernel_->gammaPosition(alpha, ig, fu);
      const auto row = static_cast<std::size_t>(ig) * static_cast<std::size_t>(nf);
      cut = std::min(sliceCuts_[static_cast<std::size_t>(ig)], sliceCuts_[static_cast<std::size_t>(ig) + 1]);
      needed = std::min(nf, basis.interval(std::min(basis.knot(cut), psiEnd)) + 4);
      const float* a = sliceRows_.data() + row;
      const float* b = a + nf;
      const auto wb = static_cast<float>(fu), wa = 1.0f - wb;
      for (int r = 0; r < needed; ++r) u[r] = wa * a[r] + wb * b[r];
    } else {
      // The fog changed since reset() (AirlightEvaluator::setMedium without a reset).
      const detail::KernelTable::Lookup lk = kernel_->lookupAt(alpha, kernel_->tauPosition(tau));
      cut = lk.cut;
      needed = std::min(nf, basis.interval(std::min(basis.knot(cut), psiEnd)) + 4);
      for (int r = 0; r < needed; ++r) u[r] = lk.coefficient(r);
    }
    for (int r = needed; r < std::min(nf, kMaxFunctions); ++r) u[r] = 0.0f;
    const double cutPsi = basis.knot(cut);
    const double scaleFit = ev.medium().albedo * kt / h * (tau == tau_ ? expNegTau_ : std::exp(-tau));
    std::size_t firstTail = n;
    ExpansionSums whole;  // the ends ascend: each function's whole integral added once
    for (std::size_t m = 0; m < n; ++m) {
      if (!(distances[m] > 0.0)) {
        out[m] = 0.0;
        continue;
      }
      const double xEnd = std::min(psi[m], cutPsi);
      out[m] = scaleFit * expansionIntegral(sp, u, xEnd, whole);
      if (psi[m] > cutPsi && firstTail == n) firstTail = m;
    }
    // The tail holds the light scattered beyond the cut, attenuated at least by M's exponent
    // there: past e^{−30} it cannot show (M's e^{−τ} is already out of the scale).
    // tan(χ/2) = sin χ / (1 + cos χ), χ = ψc + α, from the knot's cos and sin: no trigonometry.
    const double sinChi = basis.knotSin(cut) * c + basis.knotCos(cut) * sa;
    const double cosChi = basis.knotCos(cut) * c - basis.knotSin(cut) * sa;
    const double excess = 1.0 + cosChi > 1e-12 ? tau * (c + sa * sinChi / (1.0 + cosChi) - 1.0) : 1e300;
    bool tailCounts = excess < 30.0;
    if (tailCounts && firstTail < n) {
      // Every distance from firstTail on has the same expansion part (it ends at the cut), and
      // the tail beyond it holds at most e^{−excess} · max p(χ ≥ χc) · max |I| · (π − α − ψc)
      // (M's exponent grows along the tail): where that is below kTailShare of the expansion
      // part, the tail's product integration (G-moment look-ups, ~a third of a traffic ray)
      // cannot change the ray beyond that fraction and is skipped. Rays far from a lamp's image
      // end in back-scattering, where the phase function is small.
      constexpr double kTailShare = 1e-5;
      const double chiC = fastAtan2(sinChi, cosChi);
      double iMax = 0.0;  // |I| over the tail, both spokes (bounds of their pieces there)
      for (const int sk : {sp.s0, sp.s1}) {
        const std::vector<Piece>& pcs = pieces_[static_cast<std::size_t>(sk)];
        auto it = pcs.begin() + pieceAtKnot_[static_cast<std::size_t>(sk)][static_cast<std::size_t>(cut)];
        for (; it != pcs.end() && it->a < psiEnd; ++it) {
          const double hw = std::max(it->m - it->a, it->b - it->m);
          iMax = std::max(iMax, std::abs(it->i0) + hw * (std::abs(it->c1) + hw * std::abs(it->c2)));
        }
      }
      const double bound = std::exp(-excess) * kernel_->phaseBoundBeyond(chiC) * iMax * (psiEnd - cutPsi);
      if (bound * scaleFit <= kTailShare * std::abs(out[firstTail])) tailCounts = false;
    }
    if (!tailCounts) firstTail = n;
    if (firstTail < n) {
      double tail[kStack];
      std::vector<double> tailHeap;
      double* tl = tail;
      if (n - firstTail > kStack) {
        tailHeap.resize(n - firstTail);
        tl = tailHeap.data();
      }
      const detail::GMomentTable::KWeights kw = g.kWeights(kt * h);
      integrate(sp.s0, sp.s1, sp.t, psiFoot, psiEnd, &kw, psi + firstTail, n - firstTail, tl, cutPsi);
      const double scale = ev.medium().albedo * kt / h * std::exp(-kt * p);
      for (std::size_t m = firstTail; m < n; ++m) out[m] += scale * tl[m - firstTail];
    }
    return;
  }
  const detail::GMomentTable::KWeights kw = g.kWeights(kt * h);
  integrate(sp.s0, sp.s1, sp.t, psiFoot, psiEnd, &kw, psi, n, out);
  const double scale = ev.medium().albedo * kt / h * std::exp(-kt * p);
  for (std::size_t m = 0; m < n; ++m) out[m] = distances[m] > 0.0 ? scale * out[m] : 0.0;
}

double PencilAirlight::evaluate(const Vec3& direction, double distance_m) const {
  double out = 0.0;
  evaluateCumulative(direction, &distance_m, 1, &out);
  return out;
}

void PencilAirlight::integrate(int s0, int s1, double t, double psiFoot, double psiEnd, const void* kWeights,
                               const double* psi, std::size_t n, double* out, double psiStart) const {
  // ∫ G(k, θ) I(ψ) dθ from the eye (ψ = 0) to each ψ[m], I = (1 − t) I_s0 + t I_s1 with I_s
  // each spoke's quadratic pieces, and G through the exact cumulative moments T_q (product
  // integration, as the accurate method). The walk cuts at both spokes' breakpoints; on each
  // cut the blend is one quadratic, so there is one T lookup per cut. out[m] = 0 where
  // ψ[m] < 0 (distance ≤ 0).
  const detail::GMomentTable& g = *lamp_->tables_->g;
  const auto& kw = *static_cast<const detail::GMomentTable::KWeights*>(kWeights);
  const std::vector<Piece>& p0 = pieces_[static_cast<std::size_t>(s0)];
  const std::vector<Piece>& p1 = pieces_[static_cast<std::size_t>(s1)];
  std::size_t next = 0;
  for (; next < n && psi[next] < psiStart; ++next) out[next] = 0.0;
  // The piece of one spoke at ψ = x: its index (or none) and where that state ends.
  struct Cursor {
    const std::vector<Piece>* pieces;
    std::size_t i = 0;
    const Piece* at(double x, double& until) {
      while (i < pieces->size() && (*pieces)[i].b <= x) ++i;
      if (i == pieces->size()) {
        until = kPi;
        return nullptr;
      }
      const Piece& pc = (*pieces)[i];
      if (pc.a <= x) {
        until = pc.b;
        return &pc;
      }
      until = pc.a;  // a gap where I = 0
      return nullptr;
    }
  };
  Cursor c0{&p0}, c1{&p1};
  double sum = 0.0, x = psiStart;
  bool haveT = false;
  std::array<double, 3> tx{};
  auto value = [](double i0, double k1, double k2, double thetaC, const std::array<double, 3>& ta,
                  const std::array<double, 3>& tb) {
    // ∫ G (i0 + k1 u + k2 u²) dθ, u = θ − θc, from the cumulative moments at both ends.
    const double d0 = tb[0] - ta[0], d1 = tb[1] - ta[1], d2 = tb[2] - ta[2];
    const double m1 = d1 - thetaC * d0, m2 = d2 - 2 * thetaC * d1 + thetaC * thetaC * d0;
    return i0 * d0 + k1 * m1 + k2 * m2;
  };
  while (x < psiEnd && next < n) {
    double b0 = 0.0, b1 = 0.0;
    const Piece* q0 = c0.at(x, b0);
    const Piece* q1 = c1.at(x, b1);
    const double b = std::min({b0, b1, psiEnd});
    if (!(b > x)) break;
    if (!q0 && !q1) {
      // Both dark: distances in here keep the sum.
      for (; next < n && psi[next] < b; ++next) out[next] = sum;
      x = b;
      haveT = false;
      continue;
    }
    // The blend as one quadratic about the cut's centre m: a piece's (i0, c1, c2) about its own
    // centre pm re-expands with δ = m − pm as (i0 + c1 δ + c2 δ², c1 + 2 c2 δ, c2).
    const double m = 0.5 * (x + b);
    double i0 = 0.0, k1 = 0.0, k2 = 0.0;
    for (const auto& [q, w] : {std::pair{q0, 1.0 - t}, std::pair{q1, t}}) {
      if (!q || w == 0.0) continue;
      const double dl = m - q->m;
      i0 += w * (q->i0 + dl * (q->c1 + dl * q->c2));
      k1 += w * (q->c1 + 2 * q->c2 * dl);
      k2 += w * q->c2;
    }
    if (!haveT) tx = g.cumulative(kw, x - psiFoot);
    const double thetaC = m - psiFoot;
    for (; next < n && psi[next] < b; ++next)
      out[next] = sum + value(i0, k1, k2, thetaC, tx, g.cumulative(kw, psi[next] - psiFoot));
    const std::array<double, 3> tb = g.cumulative(kw, b - psiFoot);
    sum += value(i0, k1, k2, thetaC, tx, tb);
    tx = tb;
    haveT = true;
    x = b;
  }
  for (; next < n; ++next) out[next] = sum;
}

}  // namespace fogbeam
