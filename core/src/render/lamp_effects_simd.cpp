// fogbeam — Highway SIMD kernels of the glow and glare layers (lamp_effects.hpp, namespace
// lamp_fx): the lamps' radial tables at a row of points (or at any points), and one pixel row of
// a layer from the coarse grid, with the tiles flagged half-cell taken bilinearly from their
// 3 × 3 nodes and those flagged exact per pixel.
//
// Compiled once per SIMD target by hwy/foreach_target.h and chosen at run time
// (HWY_DYNAMIC_DISPATCH), as airlight_kernels_simd.cpp. The per-pixel arithmetic is the exact
// path's (LampEffectsPath::Exact, lamp_effects.cpp) in float: the half-chord s = |ω − e|/2, the
// table coordinate √s (n − 1) and linear interpolation between its nodes;
// tests/render/test_lamp_effects.cpp compares the layers against the exact path.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/lamp_effects_simd.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/highway.h>

#include <fogbeam/render/lamp_effects.hpp>

#include <algorithm>
#include <cstring>

HWY_BEFORE_NAMESPACE();
namespace fogbeam::lamp_fx::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// At most one cell (kCell = 16 pixels) per vector: a cell's lanes share their grid corners.
using DF = hn::CappedTag<float, kCell>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;

// The unit ray ω of the pixel-centre coordinates (x, y) (pixels, x right, y down; the pixel
// (i, j) has its centre at i + ½, j + ½), b = (c_y − y)/f and b2 = 1 + b² (rounded as the
// scalar float expression): shared by every lamp at the point.
struct Ray {
  VF x, y, z;
};
HWY_INLINE Ray RayAt(DF d, VF x, VF b, VF b2, float f, float cx) {
  const VF a = hn::Div(hn::Sub(hn::Set(d, cx), x), hn::Set(d, f));
  const VF inv = hn::Div(hn::Set(d, 1.0f), hn::Sqrt(hn::MulAdd(a, a, b2)));
  return {inv, hn::Mul(a, inv), hn::Mul(b, inv)};
}
HWY_INLINE Ray RayAtRow(DF d, VF x, float b, float f, float cx) {
  return RayAt(d, x, hn::Set(d, b), hn::Set(d, 1.0f + b * b), f, cx);
}

// The lamp's radial table along ω: s = |ω − e|/2 = sin(θ/2), table coordinate
// g = √min(s, 1) · (n − 1), linear between nodes (exact path, lamp_effects.cpp).
HWY_INLINE VF RadialAt(DF d, const KernelLamp& L, const Ray& w) {
  const DI di;
  const VF one = hn::Set(d, 1.0f);
  const VF vx = hn::Sub(w.x, hn::Set(d, L.e[0]));
  const VF vy = hn::Sub(w.y, hn::Set(d, L.e[1]));
  const VF vz = hn::Sub(w.z, hn::Set(d, L.e[2]));
  const VF s = hn::Mul(hn::Set(d, 0.5f), hn::Sqrt(hn::MulAdd(vx, vx, hn::MulAdd(vy, vy, hn::Mul(vz, vz)))));
  const VF g = hn::Mul(hn::Sqrt(hn::Min(s, one)), hn::Set(d, static_cast<float>(kNodes - 1)));
  const auto k0 = hn::Min(hn::ConvertTo(di, g), hn::Set(di, kNodes - 2));  // g ≥ 0: truncation = floor
  const VF t = hn::Sub(g, hn::ConvertTo(d, k0));
  const VF t0 = hn::GatherIndex(d, L.table, k0);
  const VF t1 = hn::GatherIndex(d, L.table + 1, k0);
  return hn::MulAdd(t, hn::Sub(t1, t0), t0);
}

void RadialRow(const KernelLamp* lamps, int nLamps, std::size_t stride, float f, float cx, float cy, float x0,
               float dx, float y, int count, float* out) {
  const DF d;
  const int N = static_cast<int>(hn::Lanes(d));
  const float b = (cy - y) / f;
  const VF step = hn::Mul(hn::Iota(d, 0.0f), hn::Set(d, dx));
  HWY_ALIGN float tmp[kCell];
  for (int k = 0; k < count; k += N) {
    const Ray w = RayAtRow(d, hn::Add(hn::Set(d, x0 + dx * static_cast<float>(k)), step), b, f, cx);
    for (int l = 0; l < nLamps; ++l) {
      const VF v = RadialAt(d, lamps[l], w);
      float* o = out + static_cast<std::size_t>(l) * stride;
      if (k + N <= count) {
        hn::StoreU(v, d, o + k);
      } else {  // the tail: never past `count` (the next grid row may belong to another thread)
        hn::Store(v, d, tmp);
        std::memcpy(o + k, tmp, sizeof(float) * static_cast<std::size_t>(count - k));
      }
    }
  }
}

void RadialPoints(const KernelLamp& L, float f, float cx, float cy, const float* px, const float* py, int count,
                  float* out) {
  const DF d;
  const int N = static_cast<int>(hn::Lanes(d));
  HWY_ALIGN float xs[kCell], ys[kCell], tmp[kCell];
  for (int k = 0; k < count; k += N) {
    const int m = std::min(N, count - k);
    for (int i = 0; i < N; ++i) {  // lanes past `count` repeat the last point
      xs[i] = px[k + std::min(i, m - 1)];
      ys[i] = py[k + std::min(i, m - 1)];
    }
    const VF b = hn::Div(hn::Sub(hn::Set(d, cy), hn::Load(d, ys)), hn::Set(d, f));
    const VF b2 = hn::Add(hn::Mul(b, b), hn::Set(d, 1.0f));
    hn::Store(RadialAt(d, L, RayAt(d, hn::Load(d, xs), b, b2, f, cx)), d, tmp);
    std::memcpy(out + k, tmp, sizeof(float) * static_cast<std::size_t>(m));
  }
}

void FillRow(const LayerRow& R) {
  const DF d;
  const DI di;
  const int N = static_cast<int>(hn::Lanes(d));
  const int r = R.j / kCell;
  const int jj = R.j - r * kCell;                       // the row inside its cell
  const float v = static_cast<float>(jj) / kCell;       // row weight inside the cell
  const bool lowerHalf = 2 * jj >= kCell;               // which half-cell row (kTileHalf)
  const float vh = static_cast<float>(2 * jj - (lowerHalf ? kCell : 0)) / kCell;  // row weight inside it
  const float y = static_cast<float>(R.j) + 0.5f;
  const float b = (R.cy - y) / R.f;
  const std::size_t gw = static_cast<std::size_t>(R.gw), plane = gw * static_cast<std::size_t>(R.gh);
  const int tilesW = R.gw - 1;
  const VF one = hn::Set(d, 1.0f), zero = hn::Zero(d);
  const VF lane = hn::Iota(d, 0.0f);
  HWY_ALIGN float dtmp[kCell];
  HWY_ALIGN float otmp[3 * kCell];
  const int cells = (R.width + kCell - 1) / kCell;
  for (int c = 0; c < cells; ++c) {
    const int i0 = c * kCell;
    const int m = std::min(kCell, R.width - i0);
    const std::uint8_t* flags = R.exact + (static_cast<std::size_t>(r) * static_cast<std::size_t>(tilesW) +
                                           static_cast<std::size_t>(c)) * static_cast<std::size_t>(R.nLamps);
    const int fineFirst = R.fine_first[static_cast<std::size_t>(r) * static_cast<std::size_t>(tilesW) +
                                       static_cast<std::size_t>(c)];
    const std::size_t n00 = static_cast<std::size_t>(r) * gw + static_cast<std::size_t>(c);
    const std::size_t n10 = n00 + 1, n01 = n00 + gw, n11 = n01 + 1;
    // The glow's weight per lamp is clamp((d − from) × scale, 0, 1): 1 where d ≥ to, 0 where
    // d ≤ from (d = +inf: 1). With the lamps sorted by `to`, the m1 lamps whose `to` is at most
    // the segment's nearest surface weigh 1 at every pixel of it and come from their partial
    // sum, one grid; of the others, those whose `from` is at least its farthest surface weigh 0
    // and are skipped, the rest are weighted pixel by pixel. Glare: weights 1, m1 = every lamp.
    int m1 = R.nLamps, m2 = R.nLamps;
    float dmaxSeg = 0.0f;
    const float* dist = nullptr;
    if (R.distance != nullptr) {
      float dmin, dmax;
      if (m == kCell) {
        dist = R.distance + i0;
        VF lo = hn::LoadU(d, dist), hi = lo;
        for (int k = N; k < kCell; k += N) {
          const VF dv = hn::LoadU(d, dist + k);
          lo = hn::Min(lo, dv);
          hi = hn::Max(hi, dv);
        }
        dmin = hn::GetLane(hn::MinOfLanes(d, lo));
        dmax = hn::GetLane(hn::MaxOfLanes(d, hi));
      } else {
        dmin = dmax = R.distance[i0];
        for (int k = 1; k < m; ++k) {
          dmin = std::min(dmin, R.distance[i0 + k]);
          dmax = std::max(dmax, R.distance[i0 + k]);
        }
        for (int k = 0; k < kCell; ++k) dtmp[k] = k < m ? R.distance[i0 + k] : 1e30f;
        dist = dtmp;
      }
      // The lamps are sorted by weight_to: m1 is how many have weight_to ≤ dmin (a count of
      // lanes, vector by vector), and with weight_from sorted too the lamps from m2 on have
      // weight_from ≥ dmax (weight 0 at every pixel of the segment).
      m1 = 0;
      const VF dminV = hn::Set(d, dmin), dmaxV = hn::Set(d, dmax);
      for (int l = 0; l < R.nLamps; l += N) {
        const int cnt = std::min(N, R.nLamps - l);
        const auto valid = hn::FirstN(d, static_cast<std::size_t>(cnt));
        const std::size_t below = hn::CountTrue(d, hn::And(valid, hn::Le(hn::LoadU(d, R.weight_to + l), dminV)));
        m1 += static_cast<int>(below);
        if (static_cast<int>(below) < cnt) break;
      }
      if (R.from_sorted) {
        m2 = m1;
        for (int l = m1; l < R.nLamps; l += N) {
          const int cnt = std::min(N, R.nLamps - l);
          const auto valid = hn::FirstN(d, static_cast<std::size_t>(cnt));
          const std::size_t before = hn::CountTrue(d, hn::And(valid, hn::Lt(hn::LoadU(d, R.weight_from + l), dmaxV)));
          m2 += static_cast<int>(before);
          if (static_cast<int>(before) < cnt) break;
        }
      }
      dmaxSeg = dmax;
    }
    const float* sum = m1 == 0 ? nullptr
                               : R.prefix + (R.prefix_all ? static_cast<std::size_t>(m1 - 1) * 3 * plane : 0);
    // Bilinear weights along the row: the row's two grid values a (left), bb (right) at v.
    auto rowLerp = [&](const float* g, float& a, float& bb) {
      a = g[n00] + v * (g[n01] - g[n00]);
      bb = g[n10] + v * (g[n11] - g[n10]);
    };
    // kTileHalf: the row's values at the tile's left edge, middle and right edge (A0, A1, A2),
    // from the half-cells' nodes above and below it; lanes then blend A0–A1 or A1–A2.
    auto halfLerp = [&](const KernelLamp& L, VF u) {
      float top[3], bottom[3];
      if (!lowerHalf) {
        top[0] = L.grid[n00], top[1] = L.hmid[n00], top[2] = L.grid[n10];
        bottom[0] = L.vmid[n00], bottom[1] = L.centre[n00], bottom[2] = L.vmid[n10];
      } else {
        top[0] = L.vmid[n00], top[1] = L.centre[n00], top[2] = L.vmid[n10];
        bottom[0] = L.grid[n01], bottom[1] = L.hmid[n01], bottom[2] = L.grid[n11];
      }
      const float A0 = top[0] + vh * (bottom[0] - top[0]);
      const float A1 = top[1] + vh * (bottom[1] - top[1]);
      const float A2 = top[2] + vh * (bottom[2] - top[2]);
      const VF left = hn::MulAdd(u, hn::Set(d, A1 - A0), hn::Set(d, A0));
      const VF right = hn::MulAdd(hn::Sub(u, one), hn::Set(d, A2 - A1), hn::Set(d, A1));
      return hn::IfThenElse(hn::Lt(u, one), left, right);
    };
    for (int k0 = 0; k0 < m; k0 += N) {
      const VF kk = hn::Add(lane, hn::Set(d, static_cast<float>(k0)));
      const VF t = hn::Mul(kk, hn::Set(d, 1.0f / kCell));
      const VF u = hn::Mul(kk, hn::Set(d, 2.0f / kCell));  // position in half-cells
      const VF x = hn::Add(hn::Add(lane, hn::Set(d, static_cast<float>(i0 + k0))), hn::Set(d, 0.5f));
      // The pixels' rays, made when a lamp first needs its table per pixel (shared by all).
      Ray ray{};
      bool rayMade = false;
      auto exactAt = [&](const KernelLamp& L) {
        if (!rayMade) {
          ray = RayAtRow(d, x, b, R.f, R.cx);
          rayMade = true;
        }
        return RadialAt(d, L, ray);
      };
      VF acc[3] = {zero, zero, zero};
      if (sum != nullptr) {
        for (int ch = 0; ch < 3; ++ch) {
          float a, bb;
          rowLerp(sum + static_cast<std::size_t>(ch) * plane, a, bb);
          acc[ch] = hn::MulAdd(t, hn::Set(d, bb - a), hn::Set(d, a));
        }
        // Lamps evaluated per pixel (or on half-cells) here: that value replaces their
        // interpolated share.
        for (int l = fineFirst; l < m1; ++l) {
          if (flags[l] == kTileBilinear) continue;
          const KernelLamp& L = R.lamps[l];
          float a, bb;
          rowLerp(L.grid, a, bb);
          const VF fine = flags[l] == kTileExact ? exactAt(L) : halfLerp(L, u);
          const VF diff = hn::Sub(fine, hn::MulAdd(t, hn::Set(d, bb - a), hn::Set(d, a)));
          for (int ch = 0; ch < 3; ++ch) acc[ch] = hn::MulAdd(hn::Set(d, L.color[ch]), diff, acc[ch]);
        }
      }
      if (m2 > m1) {
        const VF dv = hn::LoadU(d, dist + k0);
        for (int l = m1; l < m2; ++l) {
          const KernelLamp& L = R.lamps[l];
          if (L.weight_from >= dmaxSeg) continue;
          const VF w = hn::Min(hn::Max(hn::Mul(hn::Sub(dv, hn::Set(d, L.weight_from)), hn::Set(d, L.weight_scale)), zero), one);
          if (hn::AllTrue(d, hn::Eq(w, zero))) continue;
          VF val;
          if (flags[l] == kTileExact) {
            val = exactAt(L);
          } else if (flags[l] == kTileHalf) {
            val = halfLerp(L, u);
          } else {
            float a, bb;
            rowLerp(L.grid, a, bb);
            val = hn::MulAdd(t, hn::Set(d, bb - a), hn::Set(d, a));
          }
          const VF wv = hn::Mul(w, val);
          for (int ch = 0; ch < 3; ++ch) acc[ch] = hn::MulAdd(hn::Set(d, L.color[ch]), wv, acc[ch]);
        }
      }
      if (R.veil_line != nullptr && dist != nullptr) {
        // The road veil (LayerRow): the same float arithmetic as LampEffects' addVeil.
        const VF fx = hn::Mul(x, hn::Set(d, static_cast<float>(R.veil_nx - 1) / static_cast<float>(R.width)));
        const auto ix = hn::Min(hn::ConvertTo(di, fx), hn::Set(di, R.veil_nx - 2));  // fx ≥ 0: truncation = floor
        const VF tx = hn::Sub(fx, hn::ConvertTo(d, ix));
        // Nodes are ~36 px apart at 1280 × 720: most vectors lie between two of them (no gather).
        // ix ascends over the lanes: its first and last, in the lanes' own float arithmetic.
        const float sx = static_cast<float>(R.veil_nx - 1) / static_cast<float>(R.width);
        const int ixLo = std::min(static_cast<int>((static_cast<float>(i0 + k0) + 0.5f) * sx), R.veil_nx - 2);
        const int ixHi =
            std::min(static_cast<int>((static_cast<float>(N - 1) + static_cast<float>(i0 + k0) + 0.5f) * sx), R.veil_nx - 2);
        VF v0, v1;
        if (ixLo == ixHi) {
          v0 = hn::Set(d, R.veil_line[ixLo]);
          v1 = hn::Set(d, R.veil_line[ixLo + 1]);
        } else if (ixHi == ixLo + 1) {  // one node inside the vector: a blend, no gather
          const auto first = hn::RebindMask(d, hn::Eq(ix, hn::Set(di, ixLo)));
          v0 = hn::IfThenElse(first, hn::Set(d, R.veil_line[ixLo]), hn::Set(d, R.veil_line[ixLo + 1]));
          v1 = hn::IfThenElse(first, hn::Set(d, R.veil_line[ixLo + 1]), hn::Set(d, R.veil_line[ixLo + 2]));
        } else {
          v0 = hn::GatherIndex(d, R.veil_line, ix);
          v1 = hn::GatherIndex(d, R.veil_line + 1, ix);
        }
        const VF val = hn::Add(v0, hn::Mul(tx, hn::Sub(v1, v0)));
        const VF rampD = hn::Min(one, hn::Mul(hn::Set(d, R.veil_hk), hn::LoadU(d, dist + k0)));
        VF wv = val;  // surfaces at least 2 / K_t away (and the sky): weight 1, whatever rampU ≤ 1 is
        if (!hn::AllTrue(d, hn::Ge(rampD, one))) {
          const VF a = hn::Sub(hn::Set(d, R.cx), x);
          const float bb = R.cy - y;
          const VF num = hn::Add(hn::Set(d, R.veil_zf + R.veil_zu * bb), hn::Mul(hn::Set(d, R.veil_zl), a));
          const VF len = hn::Sqrt(hn::Add(hn::Set(d, R.f * R.f + bb * bb), hn::Mul(a, a)));
          const VF rampU = hn::Min(one, hn::Div(hn::Mul(hn::Set(d, R.veil_hkh), len),
                                                hn::Max(hn::Neg(num), hn::Set(d, 1e-12f))));
          wv = hn::Mul(hn::Min(one, hn::Div(rampD, hn::Max(rampU, hn::Set(d, 1e-3f)))), val);
        }
        for (int ch = 0; ch < 3; ++ch) acc[ch] = hn::Add(acc[ch], hn::Mul(wv, hn::Set(d, R.veil_color[ch])));
      }
      if (k0 + N <= m) {
        hn::StoreInterleaved3(acc[0], acc[1], acc[2], d, R.out + 3 * (i0 + k0));
      } else {
        hn::StoreInterleaved3(acc[0], acc[1], acc[2], d, otmp);
        std::memcpy(R.out + 3 * (i0 + k0), otmp, sizeof(float) * 3 * static_cast<std::size_t>(m - k0));
      }
    }
  }
}

}  // namespace fogbeam::lamp_fx::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam::lamp_fx {

HWY_EXPORT(RadialRow);
HWY_EXPORT(RadialPoints);
HWY_EXPORT(FillRow);

void radialRow(const KernelLamp* lamps, int nLamps, std::size_t stride, float f, float cx, float cy, float x0,
               float dx, float y, int count, float* out) {
  HWY_DYNAMIC_DISPATCH(RadialRow)(lamps, nLamps, stride, f, cx, cy, x0, dx, y, count, out);
}

void radialPoints(const KernelLamp& lamp, float f, float cx, float cy, const float* x, const float* y, int count,
                  float* out) {
  HWY_DYNAMIC_DISPATCH(RadialPoints)(lamp, f, cx, cy, x, y, count, out);
}

void fillRow(const LayerRow& row) { HWY_DYNAMIC_DISPATCH(FillRow)(row); }

}  // namespace fogbeam::lamp_fx
#endif  // HWY_ONCE
