// fogbeam — Highway SIMD kernels for the airlight tables (see airlight_kernels.hpp).
//
// Compiled once per SIMD target by hwy/foreach_target.h and chosen at run time
// (HWY_DYNAMIC_DISPATCH). The arithmetic mirrors the scalar definitions in
// airlight_kernels.cpp step by step, in float; tests/physics/test_airlight_kernels.cpp checks
// every compiled target against them.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/airlight_kernels_simd.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/cache_control.h>
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

// The four floats at base[idx[i]] … base[idx[i] + 3] for every lane i, transposed into
// q0 … q3. A gather fetches one float per lane through microcode: on the Zen 3 machine of the
// benchmark four gathers of 8 lanes take 16–29 ns, eight 128-bit loads and a 4 × 4 transpose per
// half 5–7 ns (docs/airlight.md, "Kernels"). Vectors wider than 128 bits are put together from
// halves; the scalar target reads directly.
#if HWY_TARGET == HWY_SCALAR
template <class D>
HWY_INLINE void LoadQuads(D d, const float* HWY_RESTRICT base, const int32_t* HWY_RESTRICT idx, hn::Vec<D>& q0,
                          hn::Vec<D>& q1, hn::Vec<D>& q2, hn::Vec<D>& q3) {
  const float* p = base + static_cast<std::ptrdiff_t>(idx[0]);
  q0 = hn::Set(d, p[0]);
  q1 = hn::Set(d, p[1]);
  q2 = hn::Set(d, p[2]);
  q3 = hn::Set(d, p[3]);
}
#else
template <class D>
HWY_INLINE void LoadQuads(D d, const float* HWY_RESTRICT base, const int32_t* HWY_RESTRICT idx, hn::Vec<D>& q0,
                          hn::Vec<D>& q1, hn::Vec<D>& q2, hn::Vec<D>& q3) {
  constexpr std::size_t kN = hn::MaxLanes(D());
  if constexpr (kN == 4) {
    const hn::Repartition<uint64_t, D> d64;
    const auto r0 = hn::LoadU(d, base + static_cast<std::ptrdiff_t>(idx[0]));
    const auto r1 = hn::LoadU(d, base + static_cast<std::ptrdiff_t>(idx[1]));
    const auto r2 = hn::LoadU(d, base + static_cast<std::ptrdiff_t>(idx[2]));
    const auto r3 = hn::LoadU(d, base + static_cast<std::ptrdiff_t>(idx[3]));
    const auto t0 = hn::BitCast(d64, hn::InterleaveLower(d, r0, r1));  // r0.0 r1.0 r0.1 r1.1
    const auto t1 = hn::BitCast(d64, hn::InterleaveUpper(d, r0, r1));  // r0.2 r1.2 r0.3 r1.3
    const auto t2 = hn::BitCast(d64, hn::InterleaveLower(d, r2, r3));
    const auto t3 = hn::BitCast(d64, hn::InterleaveUpper(d, r2, r3));
    q0 = hn::BitCast(d, hn::InterleaveLower(d64, t0, t2));
    q1 = hn::BitCast(d, hn::InterleaveUpper(d64, t0, t2));
    q2 = hn::BitCast(d, hn::InterleaveLower(d64, t1, t3));
    q3 = hn::BitCast(d, hn::InterleaveUpper(d64, t1, t3));
  } else {
    static_assert(kN % 8 == 0, "LoadQuads: 1, 4 or a multiple of 8 lanes");
    const hn::Half<D> dh;
    hn::Vec<hn::Half<D>> l0, l1, l2, l3, h0, h1, h2, h3;
    LoadQuads(dh, base, idx, l0, l1, l2, l3);
    LoadQuads(dh, base, idx + kN / 2, h0, h1, h2, h3);
    q0 = hn::Combine(d, h0, l0);
    q1 = hn::Combine(d, h1, l1);
    q2 = hn::Combine(d, h2, l2);
    q3 = hn::Combine(d, h3, l3);
  }
}
#endif

// Lane indices as scalars for LoadQuads (the widest target has 16 float lanes).
struct Lanes {
  alignas(64) int32_t i[16];
};

// F at (row, ζ node) of the iso table: bilinear, from the table's quads.
HWY_INLINE VF IsoF(DF d, DI di, const float* quads, VI row0, VF tu, VF gz, float nZm2) {
  VI iz;
  VF tz;
  Cell(d, di, gz, nZm2, iz, tz);
  Lanes at;
  hn::Store(hn::ShiftLeft<2>(hn::Add(row0, iz)), di, at.i);  // 4 floats per cell
  VF a0, a1, b0, b1;
  LoadQuads(d, quads, at.i, a0, a1, b0, b1);
  const VF a = hn::MulAdd(tz, hn::Sub(a1, a0), a0), b = hn::MulAdd(tz, hn::Sub(b1, b0), b0);
  return hn::MulAdd(tu, hn::Sub(b, a), a);
}

// Row coordinate of k on the table's pseudo-log axis: plog2(1 + k/k0) · uScale, read off the
// float's bits (airlight_kernels.hpp, pseudoLog2): exponent and mantissa as one integer.
HWY_INLINE VF RowNode(DF d, DI di, VF k, float invK0, float uScale) {
  const VF y = hn::MulAdd(k, hn::Set(d, invK0), hn::Set(d, 1.0f));
  const VI bits = hn::Sub(hn::BitCast(di, y), hn::Set(di, 0x3F800000));
  return hn::Mul(hn::ConvertTo(d, bits), hn::Set(d, uScale * (1.0f / 8388608.0f)));  // 2^-23
}

// Sky rays of one isotropic lamp: L_m / (Ω K_t I) from its IsoSky table (airlight_kernels.hpp).
// (wx, wy, wz): the unit ray direction.
HWY_INLINE VF IsoSky(DF d, DI di, const IsoLamp& L, VF wx, VF wy, VF wz) {
  constexpr float kScale = static_cast<float>((kIsoSkyNodes - 1) / 0.70710678118654752440);
  const VF ex = hn::Set(d, L.dir[0]), ey = hn::Set(d, L.dir[1]), ez = hn::Set(d, L.dir[2]);
  const VF dot = hn::MulAdd(wx, ex, hn::MulAdd(wy, ey, hn::Mul(wz, ez)));
  const auto behind = hn::Lt(dot, hn::Zero(d));
  // Half-chord to the lamp's direction (in front) or to its opposite (behind): no cancellation.
  const VF sx = hn::IfThenElse(behind, hn::Neg(ex), ex), sy = hn::IfThenElse(behind, hn::Neg(ey), ey),
           sz = hn::IfThenElse(behind, hn::Neg(ez), ez);
  const VF vx = hn::Sub(wx, sx), vy = hn::Sub(wy, sy), vz = hn::Sub(wz, sz);
  const VF x = hn::Mul(hn::Set(d, 0.5f), hn::Sqrt(hn::MulAdd(vx, vx, hn::MulAdd(vy, vy, hn::Mul(vz, vz)))));
  VI i;
  VF t;
  Cell(d, di, hn::Mul(x, hn::Set(d, kScale)), static_cast<float>(kIsoSkyNodes - 2), i, t);
  i = hn::Add(i, hn::IfThenElseZero(hn::RebindMask(di, behind), hn::Set(di, kIsoSkyNodes)));
  const VF v0 = hn::GatherIndex(d, L.sky, i), v1 = hn::GatherIndex(d, L.sky, hn::Add(i, hn::Set(di, 1)));
  const VF v = hn::MulAdd(t, hn::Sub(v1, v0), v0);
  // sin γ = 2 x √(1 − x²) for x = sin γ/2 or cos γ/2.
  const VF sinG = hn::Max(hn::Mul(hn::Add(x, x), hn::Sqrt(hn::Max(hn::NegMulAdd(x, x, hn::Set(d, 1.0f)), hn::Zero(d)))),
                          hn::Set(d, 1e-7f));
  return hn::Div(v, sinG);
}

void AccumulateIsoLamps(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                        const PixelBatch& px, float* r, float* gr, float* b) {
  const DF d;
  const DI di;
  const std::size_t N = hn::Lanes(d);
  const float nZm2 = static_cast<float>(table.nZ - 2), nKm2 = static_cast<float>(table.nK - 2);
  const float halfNz1 = 0.5f * static_cast<float>(table.nZ - 1);
  const float invK0 = 1.0f / table.k0;
  const VI rowStride = hn::Set(di, table.nZ);
  const float* quads = table.quads.data();
  for (std::size_t i = 0; i < px.n; i += N) {
    const VF x = hn::LoadU(d, px.x + i), y = hn::LoadU(d, px.y + i), dist = hn::LoadU(d, px.d + i);
    const VF a = hn::Mul(hn::Sub(hn::Set(d, g.cx), x), hn::Set(d, g.invF));
    const VF bb = hn::Mul(hn::Sub(hn::Set(d, g.cy), y), hn::Set(d, g.invF));
    const VF one = hn::Set(d, 1.0f);
    const VF invLen = RSqrt(d, hn::MulAdd(a, a, hn::MulAdd(bb, bb, one)));
    const auto sky = hn::Ge(dist, hn::Set(d, 3.0e38f));
    const bool allSky = hn::AllTrue(d, sky), anySky = !hn::AllFalse(d, sky);
    const auto positive = hn::Gt(dist, hn::Zero(d));
    VF accR = hn::LoadU(d, r + i), accG = hn::LoadU(d, gr + i), accB = hn::LoadU(d, b + i);
    for (std::size_t l = 0; l < nLamps; ++l) {
      const IsoLamp& L = lamps[l];
      VF lm;
      if (L.sky && allSky) {
        lm = IsoSky(d, di, L, invLen, hn::Mul(a, invLen), hn::Mul(bb, invLen));
      } else {
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
        VI iu;
        VF tu;
        Cell(d, di, RowNode(d, di, k, invK0, table.uScale), nKm2, iu, tu);
        const VI row0 = hn::Mul(iu, rowStride);
        const VF q0 = hn::Mul(hn::Neg(p), invH);
        const VF qd = hn::Mul(hn::Sub(dist, p), invH);
        const VF f0 = IsoF(d, di, quads, row0, tu, ZetaNode(d, q0, halfNz1), nZm2);
        const VF fd = IsoF(d, di, quads, row0, tu, ZetaNode(d, qd, halfNz1), nZm2);
        // L_m / weight = e^{−K_t p} / h · (F(θd) − F(θ0)).
        lm = hn::Mul(hn::Mul(hn::Exp(d, hn::Mul(hn::Set(d, -L.kt), p)), invH), hn::Sub(fd, f0));
        if (L.sky && anySky) lm = hn::IfThenElse(sky, IsoSky(d, di, L, invLen, hn::Mul(a, invLen), hn::Mul(bb, invLen)), lm);
      }
      lm = hn::IfThenElseZero(positive, hn::Max(lm, hn::Zero(d)));  // zero for d ≤ 0
      accR = hn::MulAdd(lm, hn::Set(d, L.weight[0]), accR);
      accG = hn::MulAdd(lm, hn::Set(d, L.weight[1]), accG);
      accB = hn::MulAdd(lm, hn::Set(d, L.weight[2]), accB);
    }
    hn::StoreU(accR, d, r + i);
    hn::StoreU(accG, d, gr + i);
    hn::StoreU(accB, d, b + i);
  }
}

void AccumulateViewTable(const ViewTable& table, const ViewTableUse& use, const PixelGeometry& g,
                         const PixelBatch& px, float* r, float* gr, float* b) {
  const DF d;
  const DI di;
  const std::size_t N = hn::Lanes(d);
  const float* data = table.data.data();
  const float* sky = table.skyQuads.data();
  const int stride = 2 * table.nX;
  const VI dirStride = hn::Set(di, stride), rowStride = hn::Set(di, stride * table.nA);
  const float nAm2 = static_cast<float>(table.nA - 2), nBm2 = static_cast<float>(table.nB - 2),
              nXm2 = static_cast<float>(table.nX - 2), nXm1 = static_cast<float>(table.nX - 1);
  const int32_t cornerOffset[4] = {0, stride, stride * table.nA, stride * table.nA + stride};
  for (std::size_t i = 0; i < px.n; i += N) {
    const VF x = hn::LoadU(d, px.x + i), y = hn::LoadU(d, px.y + i), dist = hn::LoadU(d, px.d + i);
    const VF a = hn::Mul(hn::Sub(hn::Set(d, g.cx), x), hn::Set(d, g.invF));
    const VF bb = hn::Mul(hn::Sub(hn::Set(d, g.cy), y), hn::Set(d, g.invF));
    const VF ga = hn::Sub(a, hn::Set(d, use.guardA)), gb = hn::Sub(bb, hn::Set(d, use.guardB));
    const VF r2 = hn::MulAdd(ga, ga, hn::Mul(gb, gb));
    auto covered = hn::And(hn::And(hn::Gt(r2, hn::Set(d, use.innerR2)), hn::Le(r2, hn::Set(d, use.outerR2))),
                           hn::Gt(dist, hn::Zero(d)));
    VF la = a, lb = bb;  // where the table is read
    if (use.rotated) {
      auto turn = hn::FirstN(d, N);
      for (int k = 0; k < use.nKeep; ++k) {
        const VF ka = hn::Sub(a, hn::Set(d, use.keepA[k])), kb = hn::Sub(bb, hn::Set(d, use.keepB[k]));
        turn = hn::And(turn, hn::Gt(hn::MulAdd(ka, ka, hn::Mul(kb, kb)), hn::Set(d, use.keepR2[k])));
      }
      const float* m = use.rot;
      const VF xr = hn::MulAdd(hn::Set(d, m[2]), bb, hn::MulAdd(hn::Set(d, m[1]), a, hn::Set(d, m[0])));
      const auto ahead = hn::Gt(xr, hn::Zero(d));
      covered = hn::And(covered, hn::Or(hn::Not(turn), ahead));
      // x' > 0 where turned and covered; elsewhere 1, so that the division stays finite.
      const VF inv = hn::Div(hn::Set(d, 1.0f), hn::IfThenElse(hn::And(turn, ahead), xr, hn::Set(d, 1.0f)));
      const VF ra = hn::Mul(hn::MulAdd(hn::Set(d, m[5]), bb, hn::MulAdd(hn::Set(d, m[4]), a, hn::Set(d, m[3]))), inv);
      const VF rb = hn::Mul(hn::MulAdd(hn::Set(d, m[8]), bb, hn::MulAdd(hn::Set(d, m[7]), a, hn::Set(d, m[6]))), inv);
      la = hn::IfThenElse(turn, ra, a);
      lb = hn::IfThenElse(turn, rb, bb);
    }
    if (hn::AllFalse(d, covered)) continue;
    VI ia, ib;
    VF ta, tb;
    Cell(d, di, hn::Mul(hn::Sub(la, hn::Set(d, table.a0)), hn::Set(d, table.invStep)), nAm2, ia, ta);
    Cell(d, di, hn::Mul(hn::Sub(lb, hn::Set(d, table.b0)), hn::Set(d, table.invStep)), nBm2, ib, tb);
    VF l00, l10, l01, l11;
    Lanes at;
    if (hn::AllTrue(d, hn::Ge(dist, hn::Set(d, 3.0e38f)))) {
      // The sky's x = 1 is the last distance node: its four direction nodes in one quad.
      hn::Store(hn::ShiftLeft<2>(hn::Add(hn::Mul(ib, hn::Set(di, table.nA)), ia)), di, at.i);
      LoadQuads(d, sky, at.i, l00, l10, l01, l11);
    } else {
      // x = d / (d + D): 1 for the sky (+inf / +inf is avoided by the select).
      const VF dPos = hn::Max(dist, hn::Zero(d));
      const VF xs = hn::IfThenElse(hn::Lt(dPos, hn::Set(d, 3.0e38f)),
                                   hn::Div(dPos, hn::Add(dPos, hn::Set(d, table.distanceScale))), hn::Set(d, 1.0f));
      VI ix;
      VF tx;
      Cell(d, di, hn::Mul(xs, hn::Set(d, nXm1)), nXm2, ix, tx);
      // (L, slope) at nodes ix and ix + 1 are four consecutive floats at 2·ix of the direction.
      const VI base = hn::Add(hn::Add(hn::Mul(ib, rowStride), hn::Mul(ia, dirStride)), hn::Add(ix, ix));
      hn::Store(base, di, at.i);
      VF* out[4] = {&l00, &l10, &l01, &l11};
      for (int c = 0; c < 4; ++c) {
        Lanes q;
        for (std::size_t k = 0; k < N; ++k) q.i[k] = at.i[k] + cornerOffset[c];
        VF f0, m0, f1, m1;
        LoadQuads(d, data, q.i, f0, m0, f1, m1);
        *out[c] = Hermite(d, tx, f0, m0, f1, m1);
      }
    }
    const VF l0 = hn::MulAdd(ta, hn::Sub(l10, l00), l00), l1 = hn::MulAdd(ta, hn::Sub(l11, l01), l01);
    VF lm = hn::MulAdd(tb, hn::Sub(l1, l0), l0);
    lm = hn::IfThenElseZero(covered, hn::Max(lm, hn::Zero(d)));
    hn::StoreU(hn::MulAdd(lm, hn::Set(d, use.weight[0]), hn::LoadU(d, r + i)), d, r + i);
    hn::StoreU(hn::MulAdd(lm, hn::Set(d, use.weight[1]), hn::LoadU(d, gr + i)), d, gr + i);
    hn::StoreU(hn::MulAdd(lm, hn::Set(d, use.weight[2]), hn::LoadU(d, b + i)), d, b + i);
  }
}

void DistanceEdgeBits(const float* up, const float* c, const float* dn, std::size_t n, float tol, float floor,
                      std::uint64_t* bits) {
  const DF d;
  const std::size_t N = hn::Lanes(d);
  const VF t = hn::Set(d, tol), two = hn::Set(d, 2.0f), fl = hn::Set(d, floor);
  auto second = [&](VF a, VF b, VF m) {
    // |a + b − 2m| > tol · max(a, b, m) and max(a, b, m) > floor
    const VF top = hn::Max(hn::Max(a, b), m);
    return hn::And(hn::Gt(hn::Abs(hn::NegMulAdd(two, m, hn::Add(a, b))), hn::Mul(t, top)), hn::Gt(top, fl));
  };
  const std::size_t words = (n + 63) / 64 + 1;
  for (std::size_t w = 0; w < words; ++w) bits[w] = 0;
  uint8_t packed[8];
  for (std::size_t i = 0; i < n; i += N) {
    const VF m = hn::LoadU(d, c + i);
    auto e = second(hn::LoadU(d, c + i - 1), hn::LoadU(d, c + i + 1), m);
    if (up && dn) e = hn::Or(e, second(hn::LoadU(d, up + i), hn::LoadU(d, dn + i), m));
    std::uint64_t v = 0;
    const std::size_t bytes = hn::StoreMaskBits(d, e, packed);
    for (std::size_t k = 0; k < bytes; ++k) v |= static_cast<std::uint64_t>(packed[k]) << (8 * k);
    if (N < 8) v &= (std::uint64_t{1} << N) - 1;
    bits[i / 64] |= v << (i % 64);  // N divides 64: a vector never straddles two words
  }
  // Beyond n, and the x test at the two ends: the ends keep the cross-row test only.
  const std::uint64_t keep = n % 64 == 0 ? ~std::uint64_t{0} : (std::uint64_t{1} << (n % 64)) - 1;
  bits[(n - 1) / 64] &= n % 64 == 0 ? ~std::uint64_t{0} : keep;
  for (std::size_t w = (n + 63) / 64; w < words; ++w) bits[w] = 0;
  for (std::size_t i : {std::size_t{0}, n - 1}) {
    const float top = up && dn ? std::max({up[i], dn[i], c[i]}) : 0.0f;
    const bool yEdge = up && dn && std::abs(up[i] + dn[i] - 2.0f * c[i]) > tol * top && top > floor;
    const std::uint64_t bit = std::uint64_t{1} << (i % 64);
    bits[i / 64] = yEdge ? (bits[i / 64] | bit) : (bits[i / 64] & ~bit);
  }
}

void InverseDistances(const float* dist, std::size_t n, float* q) {
  const DF d;
  const std::size_t N = hn::Lanes(d);
  std::size_t i = 0;
  // The hardware estimate (relative error ≤ 1.5 · 2^-12, 0 for +inf): the edge test compares
  // second differences with 2 % of q and the layer test differences with 10 %; a division per
  // pixel would cost more than the rest of the test.
  for (; i + N <= n; i += N) hn::StoreU(hn::ApproximateReciprocal(hn::LoadU(d, dist + i)), d, q + i);
  for (; i < n; ++i) q[i] = 1.0f / dist[i];
}

void FillBlocks(const FillBlock* blocks, std::size_t n, float* r, float* g, float* b, const std::uint8_t* done,
                std::size_t stride) {
  const DF d;
  const hn::Rebind<uint8_t, DF> d8;
  const hn::Rebind<uint32_t, DF> du;
  const std::size_t N = hn::Lanes(d);
  const VF iota = hn::Iota(d, 0.0f);
  float* planes[3] = {r, g, b};
  for (std::size_t k = 0; k < n; ++k) {
    const FillBlock& bl = blocks[k];
    const std::size_t c00 = static_cast<std::size_t>(bl.j0) * stride + static_cast<std::size_t>(bl.i0);
    const std::size_t c10 = c00 + static_cast<std::size_t>(bl.w);
    const std::size_t c01 = c00 + static_cast<std::size_t>(bl.h) * stride;
    const std::size_t c11 = c01 + static_cast<std::size_t>(bl.w);
    const float invW = bl.w > 0 ? 1.0f / static_cast<float>(bl.w) : 0.0f;
    const float invH = bl.h > 0 ? 1.0f / static_cast<float>(bl.h) : 0.0f;
    const std::size_t count = static_cast<std::size_t>(bl.iEnd - bl.i0 + 1);
    // A leaf's evaluated pixels are its corners, its centre (the block test) and, on its first
    // row and column, points its upper and left neighbours added when they split. So the first
    // row and column go through the `done` mask; the rest is written whole, and the corners and
    // centre it covers are put back afterwards (the image's last row and column hold corners).
    const std::size_t cm = c00 + static_cast<std::size_t>(bl.h / 2) * stride + static_cast<std::size_t>(bl.w / 2);
    const std::size_t keep[4] = {c10, c01, c11, cm};
    float saved[4][3];
    for (int q = 0; q < 4; ++q)
      for (int p = 0; p < 3; ++p) saved[q][p] = planes[p][keep[q]];
    float left[3], dl[3], step[3], dstep[3];
    for (int p = 0; p < 3; ++p) {
      const float* pl = planes[p];
      left[p] = pl[c00];
      dl[p] = (pl[c01] - pl[c00]) * invH;
      step[p] = (pl[c10] - pl[c00]) * invW;
      dstep[p] = ((pl[c11] - pl[c10]) - (pl[c01] - pl[c00])) * invW * invH;
    }
    for (int j = bl.j0; j <= bl.jEnd; ++j) {
      // The row's left end and slope along it: bilinear, left = c00 + v (c01 − c00), step likewise.
      const float v = static_cast<float>(j - bl.j0);
      const std::size_t row = static_cast<std::size_t>(j) * stride + static_cast<std::size_t>(bl.i0);
      const bool first = j == bl.j0;
      for (std::size_t i = 0; i < count; i += N) {
        auto open = hn::FirstN(d, count - i);
        if (first || i == 0)
          open = hn::And(open, hn::RebindMask(d, hn::Eq(hn::PromoteTo(du, hn::LoadU(d8, done + row + i)), hn::Zero(du))));
        const VF u = hn::Add(iota, hn::Set(d, static_cast<float>(i)));
        const bool whole = !first && i > 0 && i + N <= count;
        for (int p = 0; p < 3; ++p) {
          const VF value = hn::MulAdd(u, hn::Set(d, step[p] + v * dstep[p]), hn::Set(d, left[p] + v * dl[p]));
          float* at = planes[p] + row + i;
          // Load, blend, store where part of the vector must be kept: a masked store
          // (vmaskmovps) is microcoded and slow on AMD cores, and the rows are padded.
          hn::StoreU(whole ? value : hn::IfThenElse(open, value, hn::LoadU(d, at)), d, at);
        }
      }
    }
    for (int q = 0; q < 4; ++q)
      for (int p = 0; p < 3; ++p) planes[p][keep[q]] = saved[q][p];
  }
}

void InterleaveRgb(const float* r, const float* g, const float* b, std::size_t n, float* out) {
  const DF d;
  const std::size_t N = hn::Lanes(d);
  // Interleave into a staging row in cache, then stream it out: the image (24 MB at 1080p) is
  // written once and read by the next stage, so caching it only costs a read for ownership per
  // line; non-temporal stores wrote 24 MB in 1.3 ms where plain stores took 4.4 ms here.
  constexpr std::size_t kStage = 3 * 256;
  HWY_ALIGN float stage[kStage + 3 * 16];
  std::size_t done = 0;
  while (done < n) {
    const std::size_t m = std::min(n - done, kStage / 3);
    std::size_t i = 0;
    for (; i + N <= m; i += N)
      hn::StoreInterleaved3(hn::LoadU(d, r + done + i), hn::LoadU(d, g + done + i), hn::LoadU(d, b + done + i), d,
                            stage + 3 * i);
    for (; i < m; ++i) {
      stage[3 * i] = r[done + i];
      stage[3 * i + 1] = g[done + i];
      stage[3 * i + 2] = b[done + i];
    }
    float* dst = out + 3 * done;
    const std::size_t total = 3 * m;
    const std::size_t align = N * sizeof(float);
    std::size_t k = 0;
    while (k < total && reinterpret_cast<std::uintptr_t>(dst + k) % align != 0) {
      dst[k] = stage[k];
      ++k;
    }
    for (; k + N <= total; k += N) hn::Stream(hn::LoadU(d, stage + k), d, dst + k);
    for (; k < total; ++k) dst[k] = stage[k];
    done += m;
  }
}

void InterleaveAddRgb(const float* r, const float* g, const float* b, std::size_t n, float* out) {
  const DF d;
  const std::size_t N = hn::Lanes(d);
  std::size_t i = 0;
  for (; i + N <= n; i += N) {
    float* o = out + 3 * i;
    hn::Vec<DF> vr, vg, vb;
    hn::LoadInterleaved3(d, o, vr, vg, vb);
    hn::StoreInterleaved3(hn::Add(vr, hn::LoadU(d, r + i)), hn::Add(vg, hn::LoadU(d, g + i)),
                          hn::Add(vb, hn::LoadU(d, b + i)), d, o);
  }
  for (; i < n; ++i) {
    out[3 * i] += r[i];
    out[3 * i + 1] += g[i];
    out[3 * i + 2] += b[i];
  }
}

const char* TargetNameHere() { return hwy::TargetName(HWY_TARGET); }

}  // namespace fogbeam::kernels::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam::kernels {

HWY_EXPORT(AccumulateIsoLamps);
HWY_EXPORT(AccumulateViewTable);
HWY_EXPORT(TargetNameHere);
HWY_EXPORT(DistanceEdgeBits);
HWY_EXPORT(InverseDistances);
HWY_EXPORT(FillBlocks);
HWY_EXPORT(InterleaveRgb);
HWY_EXPORT(InterleaveAddRgb);

void distanceEdgeBits(const float* up, const float* c, const float* dn, std::size_t n, float tol, float floor,
                      std::uint64_t* bits) {
  HWY_DYNAMIC_DISPATCH(DistanceEdgeBits)(up, c, dn, n, tol, floor, bits);
}

void inverseDistances(const float* d, std::size_t n, float* q) { HWY_DYNAMIC_DISPATCH(InverseDistances)(d, n, q); }


void fillBlocks(const FillBlock* blocks, std::size_t n, float* r, float* g, float* b, const std::uint8_t* done,
                std::size_t stride) {
  HWY_DYNAMIC_DISPATCH(FillBlocks)(blocks, n, r, g, b, done, stride);
}

void interleaveRgb(const float* r, const float* g, const float* b, std::size_t n, float* out) {
  HWY_DYNAMIC_DISPATCH(InterleaveRgb)(r, g, b, n, out);
}

void interleaveAddRgb(const float* r, const float* g, const float* b, std::size_t n, float* out) {
  HWY_DYNAMIC_DISPATCH(InterleaveAddRgb)(r, g, b, n, out);
}

void flushStreams() { hwy::FlushStream(); }


void accumulateIsoLamps(const IsoTable& table, const IsoLamp* lamps, std::size_t nLamps, const PixelGeometry& g,
                        const PixelBatch& px, float* r, float* gr, float* b) {
  HWY_DYNAMIC_DISPATCH(AccumulateIsoLamps)(table, lamps, nLamps, g, px, r, gr, b);
}

void accumulateViewTable(const ViewTable& table, const PixelGeometry& g, const PixelBatch& px, float* r, float* gr,
                         float* b) {
  HWY_DYNAMIC_DISPATCH(AccumulateViewTable)(table, ViewTableUse::of(table), g, px, r, gr, b);
}

void accumulateViewTable(const ViewTable& table, const ViewTableUse& use, const PixelGeometry& g, const PixelBatch& px,
                         float* r, float* gr, float* b) {
  HWY_DYNAMIC_DISPATCH(AccumulateViewTable)(table, use, g, px, r, gr, b);
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
