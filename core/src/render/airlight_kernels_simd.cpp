// fogbeam — Highway SIMD kernels for the airlight tables (see airlight_kernels.hpp).
//
// Compiled once per SIMD target by hwy/foreach_target.h and chosen at run time
// (HWY_DYNAMIC_DISPATCH). The arithmetic mirrors the scalar definitions in
// airlight_kernels.cpp step by step, in float; tests/physics/test_airlight_kernels.cpp checks
// every compiled target against them.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/airlight_kernels_simd.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include <fogbeam/render/airlight_kernels.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>

HWY_BEFORE_NAMESPACE();
namespace fogbeam::kernels::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
using VI = hn::Vec<DI>;

// Cubic Hermite on a node pair: (f0, m0, f1, m1) with slopes already scaled to the cell.
HWY_INLINE VF Hermite(DF d, VF t, VF f0, VF m0, VF f1, VF m1) {
  const VF t2 = hn::Mul(t, t), t3 = hn::Mul(t2, t);
  const VF h01 = hn::Sub(hn::Mul(hn::Set(d, 3.0f), t2), hn::Mul(hn::Set(d, 2.0f), t3));  // 3t² − 2t³
  const VF h00 = hn::Sub(hn::Set(d, 1.0f), h01);
  const VF h10 = hn::Add(hn::Sub(t3, hn::Mul(hn::Set(d, 2.0f), t2)), t);  // t³ − 2t² + t
  const VF h11 = hn::Sub(t3, t2);
  return hn::MulAdd(h00, f0, hn::MulAdd(h10, m0, hn::MulAdd(h01, f1, hn::Mul(h11, m1))));
}

// Splits a node coordinate into (index, fraction), clamped to [0, n − 2] × [0, 1].
HWY_INLINE void Cell(DF d, DI di, VF g, float nMinus2, VI& i, VF& t) {
  const VF gc = hn::Min(hn::Max(g, hn::Zero(d)), hn::Set(d, nMinus2 + 1.0f));
  const VF fl = hn::Min(hn::Floor(gc), hn::Set(d, nMinus2));
  i = hn::ConvertTo(di, fl);
  t = hn::Sub(gc, fl);
}

// 1/√x for finite x > 0: the hardware estimate (12–14 bits) and one Newton step (≈ 23 bits),
// a fraction of the cost of a square root and a division.
HWY_INLINE VF RSqrt(DF d, VF x) {
  const VF y = hn::ApproximateReciprocalSqrt(x);
  return hn::Mul(y, hn::NegMulAdd(hn::Mul(hn::Set(d, 0.5f), x), hn::Mul(y, y), hn::Set(d, 1.5f)));
}

// ζ(q) = sgn q (1 − (1 + |q|)^{−1/2}) mapped to node units (ζ + 1)/2 · (nZ − 1). |q| is
// clamped to 1e30 (ζ = 1 − 1e-15, i.e. 1 in float) so that the sky's q = ∞ stays finite.
HWY_INLINE VF ZetaNode(DF d, VF q, float halfNz1) {
  const VF one = hn::Set(d, 1.0f);
  const VF z = hn::Sub(one, RSqrt(d, hn::Add(one, hn::Min(hn::Abs(q), hn::Set(d, 1e30f)))));
  return hn::Mul(hn::Add(hn::CopySign(z, q), one), hn::Set(d, halfNz1));
}

// F at (row pair, ζ node) of the iso table: bilinear.
HWY_INLINE VF IsoF(DF d, DI di, const float* data, VI row0, VI rowStride, VF tu, VF gz, float nZm2) {
  VI iz;
  VF tz;
  Cell(d, di, gz, nZm2, iz, tz);
  const VI i0 = hn::Add(row0, iz);
  const VI i1 = hn::Add(i0, rowStride);
  const VI one = hn::Set(di, 1);
  const VF a0 = hn::GatherIndex(d, data, i0), a1 = hn::GatherIndex(d, data, hn::Add(i0, one));
  const VF b0 = hn::GatherIndex(d, data, i1), b1 = hn::GatherIndex(d, data, hn::Add(i1, one));
  const VF a = hn::MulAdd(tz, hn::Sub(a1, a0), a0), b = hn::MulAdd(tz, hn::Sub(b1, b0), b0);
  return hn::MulAdd(tu, hn::Sub(b, a), a);
}

void AccumulateIsoLamps(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                        const PixelBatch& px, float* r, float* gr, float* b) {
  const DF d;
  const DI di;
  const std::size_t N = hn::Lanes(d);
  const float nZm2 = static_cast<float>(table.nZ - 2), nKm2 = static_cast<float>(table.nK - 2);
  const float halfNz1 = 0.5f * static_cast<float>(table.nZ - 1);
  const VI rowStride = hn::Set(di, table.nZ);
  const float* data = table.data.data();
  for (std::size_t i = 0; i < px.n; i += N) {
    const VF x = hn::LoadU(d, px.x + i), y = hn::LoadU(d, px.y + i), dist = hn::LoadU(d, px.d + i);
    const VF a = hn::Mul(hn::Sub(hn::Set(d, g.cx), x), hn::Set(d, g.invF));
    const VF bb = hn::Mul(hn::Sub(hn::Set(d, g.cy), y), hn::Set(d, g.invF));
    const VF one = hn::Set(d, 1.0f);
    const VF invLen = RSqrt(d, hn::MulAdd(a, a, hn::MulAdd(bb, bb, one)));
    VF accR = hn::LoadU(d, r + i), accG = hn::LoadU(d, gr + i), accB = hn::LoadU(d, b + i);
    for (std::size_t l = 0; l < nLamps; ++l) {
      const IsoLamp& L = lamps[l];
      // p = (S − O)·ω and h = |(S − O) × ω| (eq. 3 geometry). h from the cross product: the
      // form √(|S − O|² − p²) cancels catastrophically in float for rays grazing a lamp.
      const VF lx = hn::Set(d, L.pos[0]), ly = hn::Set(d, L.pos[1]), lz = hn::Set(d, L.pos[2]);
      const VF p = hn::Mul(invLen, hn::MulAdd(a, ly, hn::MulAdd(bb, lz, lx)));
      const VF cx = hn::NegMulAdd(lz, a, hn::Mul(ly, bb));  // ly·b − lz·a
      const VF cy = hn::NegMulAdd(lx, bb, lz);              // lz − lx·b
      const VF cz = hn::MulAdd(lx, a, hn::Neg(ly));          // lx·a − ly
      const VF h = hn::Max(hn::Mul(invLen, hn::Sqrt(hn::MulAdd(cx, cx, hn::MulAdd(cy, cy, hn::Mul(cz, cz))))),
                           hn::Set(d, 1e-6f));
      const VF invH = hn::Div(one, h);
      const VF k = hn::Mul(hn::Set(d, L.kt), h);
      const VF gu = hn::Mul(hn::Log1p(d, hn::Mul(k, hn::Set(d, 1.0f / table.k0))), hn::Set(d, table.uScale));
      VI iu;
      VF tu;
      Cell(d, di, gu, nKm2, iu, tu);
      const VI row0 = hn::Mul(iu, rowStride);
      const VF q0 = hn::Mul(hn::Neg(p), invH);
      const VF qd = hn::Mul(hn::Sub(dist, p), invH);
      const VF f0 = IsoF(d, di, data, row0, rowStride, tu, ZetaNode(d, q0, halfNz1), nZm2);
      const VF fd = IsoF(d, di, data, row0, rowStride, tu, ZetaNode(d, qd, halfNz1), nZm2);
      // L_m / weight = e^{−K_t p} / h · (F(θd) − F(θ0)); zero for d ≤ 0.
      VF lm = hn::Mul(hn::Mul(hn::Exp(d, hn::Mul(hn::Set(d, -L.kt), p)), invH), hn::Sub(fd, f0));
      lm = hn::IfThenElseZero(hn::Gt(dist, hn::Zero(d)), hn::Max(lm, hn::Zero(d)));
      accR = hn::MulAdd(lm, hn::Set(d, L.weight[0]), accR);
      accG = hn::MulAdd(lm, hn::Set(d, L.weight[1]), accG);
      accB = hn::MulAdd(lm, hn::Set(d, L.weight[2]), accB);
    }
    hn::StoreU(accR, d, r + i);
    hn::StoreU(accG, d, gr + i);
    hn::StoreU(accB, d, b + i);
  }
}

void AccumulateViewTable(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r, float* gr,
                         float* b) {
  const DF d;
  const DI di;
  const std::size_t N = hn::Lanes(d);
  const float* data = table.data.data();
  const int stride = 2 * table.nX;
  const VI dirStride = hn::Set(di, stride), rowStride = hn::Set(di, stride * table.nA);
  const VI one = hn::Set(di, 1), two = hn::Set(di, 2), three = hn::Set(di, 3);
  const float nAm2 = static_cast<float>(table.nA - 2), nBm2 = static_cast<float>(table.nB - 2),
              nXm2 = static_cast<float>(table.nX - 2), nXm1 = static_cast<float>(table.nX - 1);
  for (std::size_t i = 0; i < px.n; i += N) {
    const VF x = hn::LoadU(d, px.x + i), y = hn::LoadU(d, px.y + i), dist = hn::LoadU(d, px.d + i);
    const VF a = hn::Mul(hn::Sub(hn::Set(d, g.cx), x), hn::Set(d, g.invF));
    const VF bb = hn::Mul(hn::Sub(hn::Set(d, g.cy), y), hn::Set(d, g.invF));
    VI ia, ib, ix;
    VF ta, tb, tx;
    Cell(d, di, hn::Mul(hn::Sub(a, hn::Set(d, table.a0)), hn::Set(d, table.invStep)), nAm2, ia, ta);
    Cell(d, di, hn::Mul(hn::Sub(bb, hn::Set(d, table.b0)), hn::Set(d, table.invStep)), nBm2, ib, tb);
    // x = d / (d + D): 1 for the sky (+inf / +inf is avoided by the select).
    const VF dPos = hn::Max(dist, hn::Zero(d));
    const VF xs = hn::IfThenElse(hn::Lt(dPos, hn::Set(d, 3.0e38f)),
                                 hn::Div(dPos, hn::Add(dPos, hn::Set(d, table.distanceScale))), hn::Set(d, 1.0f));
    Cell(d, di, hn::Mul(xs, hn::Set(d, nXm1)), nXm2, ix, tx);
    const VI base = hn::Add(hn::Add(hn::Mul(ib, rowStride), hn::Mul(ia, dirStride)), hn::Add(ix, ix));
    auto corner = [&](VI idx) {
      return Hermite(d, tx, hn::GatherIndex(d, data, idx), hn::GatherIndex(d, data, hn::Add(idx, one)),
                     hn::GatherIndex(d, data, hn::Add(idx, two)), hn::GatherIndex(d, data, hn::Add(idx, three)));
    };
    const VF l00 = corner(base), l10 = corner(hn::Add(base, dirStride));
    const VF l01 = corner(hn::Add(base, rowStride)), l11 = corner(hn::Add(hn::Add(base, rowStride), dirStride));
    const VF l0 = hn::MulAdd(ta, hn::Sub(l10, l00), l00), l1 = hn::MulAdd(ta, hn::Sub(l11, l01), l01);
    VF lm = hn::MulAdd(tb, hn::Sub(l1, l0), l0);
    const VF ga = hn::Sub(a, hn::Set(d, table.guardA)), gb = hn::Sub(bb, hn::Set(d, table.guardB));
    const VF r2 = hn::MulAdd(ga, ga, hn::Mul(gb, gb));
    const auto covered = hn::And(hn::Gt(r2, hn::Set(d, table.innerR2)), hn::Le(r2, hn::Set(d, table.outerR2)));
    lm = hn::IfThenElseZero(hn::And(covered, hn::Gt(dist, hn::Zero(d))), hn::Max(lm, hn::Zero(d)));
    hn::StoreU(hn::MulAdd(lm, hn::Set(d, table.weight[0]), hn::LoadU(d, r + i)), d, r + i);
    hn::StoreU(hn::MulAdd(lm, hn::Set(d, table.weight[1]), hn::LoadU(d, gr + i)), d, gr + i);
    hn::StoreU(hn::MulAdd(lm, hn::Set(d, table.weight[2]), hn::LoadU(d, b + i)), d, b + i);
  }
}

void MarkDistanceEdges(const float* up, const float* c, const float* dn, std::size_t n, float tol,
                       std::uint32_t* out) {
  const DF d;
  const hn::RebindToUnsigned<DF> du;
  const std::size_t N = hn::Lanes(d);
  const VF t = hn::Set(d, tol), two = hn::Set(d, 2.0f);
  auto second = [&](VF a, VF b, VF m) {
    // |a + b − 2m| > tol · max(a, b, m)
    return hn::Gt(hn::Abs(hn::NegMulAdd(two, m, hn::Add(a, b))), hn::Mul(t, hn::Max(hn::Max(a, b), m)));
  };
  auto scalarAt = [&](std::size_t i) {
    auto edge = [&](float a, float b, float m) { return std::abs(a + b - 2.0f * m) > tol * std::max(std::max(a, b), m); };
    bool e = i > 0 && i + 1 < n && edge(c[i - 1], c[i + 1], c[i]);
    if (up && dn) e = e || edge(up[i], dn[i], c[i]);
    out[i] = e ? 1u : 0u;
  };
  std::size_t i = 0;
  scalarAt(0);
  i = 1;
  for (; i + N + 1 <= n; i += N) {
    const VF m = hn::LoadU(d, c + i);
    auto e = second(hn::LoadU(d, c + i - 1), hn::LoadU(d, c + i + 1), m);
    if (up && dn) e = hn::Or(e, second(hn::LoadU(d, up + i), hn::LoadU(d, dn + i), m));
    hn::StoreU(hn::IfThenElseZero(hn::RebindMask(du, e), hn::Set(du, 1u)), du, out + i);
  }
  for (; i < n; ++i) scalarAt(i);
}

const char* TargetNameHere() { return hwy::TargetName(HWY_TARGET); }

}  // namespace fogbeam::kernels::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam::kernels {

HWY_EXPORT(AccumulateIsoLamps);
HWY_EXPORT(AccumulateViewTable);
HWY_EXPORT(TargetNameHere);
HWY_EXPORT(MarkDistanceEdges);

void markDistanceEdges(const float* up, const float* c, const float* dn, std::size_t n, float tol, std::uint32_t* out) {
  HWY_DYNAMIC_DISPATCH(MarkDistanceEdges)(up, c, dn, n, tol, out);
}

void accumulateIsoLamps(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                        const PixelBatch& px, float* r, float* gr, float* b) {
  HWY_DYNAMIC_DISPATCH(AccumulateIsoLamps)(table, lamps, nLamps, g, px, r, gr, b);
}

void accumulateViewTable(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r, float* gr,
                         float* b) {
  HWY_DYNAMIC_DISPATCH(AccumulateViewTable)(table, g, px, r, gr, b);
}

std::string activeTarget() { return HWY_DYNAMIC_DISPATCH(TargetNameHere)(); }

namespace {
// The targets as found before any forceTarget() narrowed them (lowest bit first, i.e. the
// best target first on x86).
const std::vector<int64_t>& allTargets() {
  static const std::vector<int64_t> all = hwy::SupportedAndGeneratedTargets();
  return all;
}
}  // namespace

std::vector<std::string> availableTargets() {
  std::vector<std::string> names;
  for (int64_t t : allTargets()) names.emplace_back(hwy::TargetName(t));
  return names;
}

bool forceTarget(const std::string& name) {
  if (name.empty()) {
    hwy::SetSupportedTargetsForTest(0);
    return true;
  }
  for (int64_t t : allTargets())
    if (name == hwy::TargetName(t)) {
      hwy::SetSupportedTargetsForTest(t);
      return true;
    }
  return false;
}

}  // namespace fogbeam::kernels
#endif
