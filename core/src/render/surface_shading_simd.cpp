// fogbeam — the SIMD kernel of the CPU surface shading (fogbeam/render/surface_shading.hpp):
// one image row of a geometry buffer, a vector of pixels at a time, every lamp of the frame.
//
// Compiled once per SIMD target by hwy/foreach_target.h and chosen at run time
// (HWY_DYNAMIC_DISPATCH). Per pixel and lamp it is the surface pass's shader
// (shaders/common_photometry.glsl: surfaceLuminance, lampIntensity) in float: the profile's
// file angles from the lamp-frame direction, the cell of each angle from a bucket index (one
// gather, then a step either way for rounding: the same cell as the binary search of
// TabulatedProfile::atAngles), bilinear interpolation of four gathered intensities.
// tests/gl/test_surface_pass.cpp checks it against the CPU planes renderer (double) and the
// GL shaders.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/surface_shading_simd.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include <fogbeam/render/surface_shading.hpp>

#include <utility>

#include <limits>

HWY_BEFORE_NAMESPACE();
namespace fogbeam::kernels::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
using VI = hn::Vec<DI>;
using MF = hn::Mask<DF>;

constexpr float kPiF = 3.14159265358979f;
constexpr float kHalfPiF = 1.57079632679490f;
constexpr float kTwoPiF = 6.28318530717959f;

// atan2(y, x) in (−π, π], 0 at x = y = 0 (as the shaders' atan2Safe): Highway's atan of the
// ratio of the smaller to the larger magnitude, then the octant.
HWY_INLINE VF Atan2(DF d, VF y, VF x) {
  const VF ax = hn::Abs(x), ay = hn::Abs(y);
  const VF mx = hn::Max(ax, ay), mn = hn::Min(ax, ay);
  const MF nonzero = hn::Gt(mx, hn::Zero(d));
  const VF ratio = hn::IfThenElseZero(nonzero, hn::Div(mn, hn::IfThenElse(nonzero, mx, hn::Set(d, 1.0f))));
  VF a = hn::Atan(d, ratio);
  a = hn::IfThenElse(hn::Gt(ay, ax), hn::Sub(hn::Set(d, kHalfPiF), a), a);
  a = hn::IfThenElse(hn::Lt(x, hn::Zero(d)), hn::Sub(hn::Set(d, kPiF), a), a);
  return hn::CopySign(a, y);
}

HWY_INLINE VF ClampUnit(DF d, VF x) { return hn::Min(hn::Max(x, hn::Set(d, -1.0f)), hn::Set(d, 1.0f)); }

// The cell of x on an axis: index i ∈ [0, n − 2] with angle[i] ≤ x < angle[i + 1] (the last
// cell takes the end point) and the weight t of angle[i + 1]; `inside` is false beyond the
// axis's ends (1e-6 rad of slack for float rounding, as the shaders). Four gathers: the bucket's
// cell and grid line, the cell's start and inverse width. Where x lies within rounding of a
// grid line the bucket may name the neighbouring cell: t is clamped, and bilinear interpolation
// is continuous across the line, so the value is the same to that rounding. x must be finite.
HWY_INLINE void Locate(DF d, DI di, const ShadeAxis& a, VF x, VI& i, VF& t, MF& inside) {
  inside = hn::And(hn::Ge(x, hn::Set(d, a.first - 1e-6f)), hn::Le(x, hn::Set(d, a.last + 1e-6f)));
  if (a.n == 1) {
    i = hn::Zero(di);
    t = hn::Zero(d);
    inside = hn::And(inside, hn::Lt(hn::Abs(hn::Sub(x, hn::Set(d, a.first))), hn::Set(d, 1e-6f)));
    return;
  }
  const VF b = hn::Min(hn::Max(hn::Mul(hn::Sub(x, hn::Set(d, a.lo)), hn::Set(d, a.scale)), hn::Zero(d)),
                       hn::Set(d, static_cast<float>(a.buckets - 1)));
  const VI bi = hn::ConvertTo(di, b);
  const VI cell = hn::GatherIndex(di, a.bucket_cell, bi);
  const VF split = hn::GatherIndex(d, a.bucket_split, bi);
  i = hn::IfThenElse(hn::RebindMask(di, hn::Ge(x, split)), hn::Add(cell, hn::Set(di, 1)), cell);
  const VF lo = hn::GatherIndex(d, a.cell_lo, i), inv = hn::GatherIndex(d, a.cell_inv, i);
  t = hn::Min(hn::Max(hn::Mul(hn::Sub(x, lo), inv), hn::Zero(d)), hn::Set(d, 1.0f));
}

// I(w) of a tabulated profile for lamp-frame unit directions (wx, wy, wz), as
// TabulatedProfile::atAngles after anglesFromDirection.
HWY_INLINE VF Tabulated(DF d, DI di, const ShadeTable& tb, VF wx, VF wy, VF wz) {
  VF h, v;
  if (tb.type == 2) {  // C: plane angle about +x from +y towards +z; γ from +x
    h = Atan2(d, wz, wy);
    v = hn::Acos(d, ClampUnit(d, wx));
  } else if (tb.type == 1) {  // B: H positive to the right (−y), V about y, positive up
    h = hn::Asin(d, ClampUnit(d, hn::Neg(wy)));
    v = Atan2(d, wz, wx);
  } else {  // A: H about z, positive to the right; V elevation
    h = Atan2(d, hn::Neg(wy), wx);
    v = hn::Asin(d, ClampUnit(d, wz));
  }
  VI iv;
  VF tv;
  MF inside;
  Locate(d, di, tb.v, v, iv, tv, inside);
  const int nv = tb.v.n;
  const VI iv1 = hn::Min(hn::Add(iv, hn::Set(di, 1)), hn::Set(di, nv - 1));
  auto row = [&](VI ih) {
    const VI base = hn::Mul(ih, hn::Set(di, nv));
    const VF c0 = hn::GatherIndex(d, tb.candela, hn::Add(base, iv));
    const VF c1 = hn::GatherIndex(d, tb.candela, hn::Add(base, iv1));
    return hn::MulAdd(tv, hn::Sub(c1, c0), c0);
  };
  if (tb.single_plane) return hn::IfThenElseZero(inside, row(hn::Zero(di)));
  if (tb.type == 2) {
    h = hn::IfThenElse(hn::Lt(h, hn::Zero(d)), hn::Add(h, hn::Set(d, kTwoPiF)), h);  // [0, 2π)
    const VF pi = hn::Set(d, kPiF), twoPi = hn::Set(d, kTwoPiF);
    switch (tb.symmetry) {
      case 2:  // quadrant: mirrored about the 0–180° and 90–270° planes
        h = hn::IfThenElse(hn::Gt(h, pi), hn::Sub(twoPi, h), h);
        h = hn::IfThenElse(hn::Gt(h, hn::Set(d, kHalfPiF)), hn::Sub(pi, h), h);
        break;
      case 3:  // 0–180°
        h = hn::IfThenElse(hn::Gt(h, pi), hn::Sub(twoPi, h), h);
        break;
      case 4:  // 90–270°
        h = hn::IfThenElse(hn::Lt(h, hn::Set(d, kHalfPiF)), hn::Sub(pi, h),
                           hn::IfThenElse(hn::Gt(h, hn::Set(d, 1.5f * kPiF)), hn::Sub(hn::Set(d, 3.0f * kPiF), h), h));
        break;
      case 0:  // the whole circle: below the first plane is beyond the last (the table's extra plane)
        h = hn::IfThenElse(hn::Lt(h, hn::Set(d, tb.h.first)), hn::Add(h, twoPi), h);
        h = hn::Min(h, hn::Set(d, tb.h.last));
        break;
      default:
        break;
    }
  } else if (tb.symmetry == 5) {  // mirrored H
    h = hn::Abs(h);
  }
  VI ih;
  VF th;
  MF insideH;
  Locate(d, di, tb.h, h, ih, th, insideH);
  const VI ih1 = hn::Min(hn::Add(ih, hn::Set(di, 1)), hn::Set(di, tb.h.n - 1));
  const VF r0 = row(ih), r1 = row(ih1);
  return hn::IfThenElseZero(hn::And(inside, insideH), hn::MulAdd(th, hn::Sub(r1, r0), r0));
}

// The scene's planes along one row's rays, in double (the GL plane shader's arithmetic):
// nearest t > 0 and its plane, or +inf and −1.
void CastPlanesRowImpl(const ShadeFrame& fr, int j, int x0, int count, float* HWY_RESTRICT tOut,
                       std::int32_t* HWY_RESTRICT planeOut) {
  if (fr.planes.empty()) {
    for (int i = 0; i < count; ++i) {
      tOut[i] = std::numeric_limits<float>::infinity();
      planeOut[i] = -1;
    }
    return;
  }
  const hn::ScalableTag<double> dd;
  const int N = static_cast<int>(hn::Lanes(dd));
  const double* R = fr.world_from_camera;
  const double ly = fr.cy - (static_cast<double>(j) + 0.5);
  const auto f = hn::Set(dd, fr.focal), lyv = hn::Set(dd, ly);
  HWY_ALIGN double t[hn::MaxLanes(dd)];
  HWY_ALIGN double idx[hn::MaxLanes(dd)];
  for (int i = 0; i < count; i += N) {
    const auto lx = hn::Sub(hn::Set(dd, fr.cx), hn::Iota(dd, static_cast<double>(x0 + i) + 0.5));
    auto ox = hn::MulAdd(hn::Set(dd, R[0]), f, hn::MulAdd(hn::Set(dd, R[3]), lx, hn::Mul(hn::Set(dd, R[6]), lyv)));
    auto oy = hn::MulAdd(hn::Set(dd, R[1]), f, hn::MulAdd(hn::Set(dd, R[4]), lx, hn::Mul(hn::Set(dd, R[7]), lyv)));
    auto oz = hn::MulAdd(hn::Set(dd, R[2]), f, hn::MulAdd(hn::Set(dd, R[5]), lx, hn::Mul(hn::Set(dd, R[8]), lyv)));
    const auto inv = hn::Div(hn::Set(dd, 1.0), hn::Sqrt(hn::MulAdd(ox, ox, hn::MulAdd(oy, oy, hn::Mul(oz, oz)))));
    ox = hn::Mul(ox, inv);
    oy = hn::Mul(oy, inv);
    oz = hn::Mul(oz, inv);
    auto best = hn::Set(dd, std::numeric_limits<double>::infinity());
    auto which = hn::Set(dd, -1.0);
    for (std::size_t k = 0; k < fr.planes.size(); ++k) {
      const ShadePlane& p = fr.planes[k];
      const auto denom = hn::MulAdd(ox, hn::Set(dd, p.n[0]), hn::MulAdd(oy, hn::Set(dd, p.n[1]), hn::Mul(oz, hn::Set(dd, p.n[2]))));
      const auto ok = hn::Ge(hn::Abs(denom), hn::Set(dd, 1e-12));
      const auto tk = hn::Div(hn::Set(dd, p.c), hn::IfThenElse(ok, denom, hn::Set(dd, 1.0)));
      auto nearer = hn::And(ok, hn::And(hn::Gt(tk, hn::Zero(dd)), hn::Lt(tk, best)));
      if (p.bounded) {  // a body quad: the hit's coordinates on its edges within [0, 1]
        const auto qx = hn::Sub(hn::Mul(tk, ox), hn::Set(dd, p.corner[0]));
        const auto qy = hn::Sub(hn::Mul(tk, oy), hn::Set(dd, p.corner[1]));
        const auto qz = hn::Sub(hn::Mul(tk, oz), hn::Set(dd, p.corner[2]));
        const auto su = hn::MulAdd(qx, hn::Set(dd, p.u_dual[0]), hn::MulAdd(qy, hn::Set(dd, p.u_dual[1]), hn::Mul(qz, hn::Set(dd, p.u_dual[2]))));
        const auto sv = hn::MulAdd(qx, hn::Set(dd, p.v_dual[0]), hn::MulAdd(qy, hn::Set(dd, p.v_dual[1]), hn::Mul(qz, hn::Set(dd, p.v_dual[2]))));
        const auto zero = hn::Zero(dd), one = hn::Set(dd, 1.0);
        nearer = hn::And(nearer, hn::And(hn::And(hn::Ge(su, zero), hn::Le(su, one)), hn::And(hn::Ge(sv, zero), hn::Le(sv, one))));
      }
      best = hn::IfThenElse(nearer, tk, best);
      which = hn::IfThenElse(nearer, hn::Set(dd, static_cast<double>(k)), which);
    }
    hn::Store(best, dd, t);
    hn::Store(which, dd, idx);
    for (int k = 0; k < N && i + k < count; ++k) {
      tOut[i + k] = static_cast<float>(t[k]);
      planeOut[i + k] = static_cast<std::int32_t>(idx[k]);
    }
  }
}

// One vector of pixels starting at image column i of row j: the geometry buffer's interleaved
// inputs (normal and ρ red, 4 floats a pixel; ρ green and blue, 2; distance, 1; null: no mesh)
// and the planes' t and index; interleaved output (3 floats) and the distance. `fog` (null: none):
// the fog light's blocks, lamp after lamp, one row (of `stride` floats) per float: s0 … s3, and
// for a measured lamp D0 … D3 (fogLightFloats; shadeRow).
HWY_INLINE void ShadeVector(const ShadeFrame& fr, int j, int i, const float* HWY_RESTRICT nrho,
                            const float* HWY_RESTRICT rgb2, const float* HWY_RESTRICT dp,
                            const float* HWY_RESTRICT planeT, const std::int32_t* HWY_RESTRICT planeIndex,
                            float* HWY_RESTRICT out, float* HWY_RESTRICT outDistance, const float* HWY_RESTRICT fog,
                            std::size_t stride) {
  const DF d;
  const DI di;
  const VF kt = hn::Set(d, fr.extinction), ia = hn::Set(d, fr.ambient);
  const VF inf = hn::Set(d, std::numeric_limits<float>::infinity());
  const VF invPi = hn::Set(d, 1.0f / kPiF), zero = hn::Zero(d), one = hn::Set(d, 1.0f);
  // The pixel ray as Camera::rayDirection: local = (f, cx − x, cy − y), world = R · local.
  VF R[9];
  for (int k = 0; k < 9; ++k) R[k] = hn::Set(d, static_cast<float>(fr.world_from_camera[k]));
  const VF lx = hn::Sub(hn::Set(d, static_cast<float>(fr.cx)), hn::Iota(d, static_cast<float>(i) + 0.5f));
  const VF f = hn::Set(d, static_cast<float>(fr.focal));
  const VF ly = hn::Set(d, static_cast<float>(fr.cy - (static_cast<double>(j) + 0.5)));
  const VF ox = hn::MulAdd(R[0], f, hn::MulAdd(R[3], lx, hn::Mul(R[6], ly)));
  const VF oy = hn::MulAdd(R[1], f, hn::MulAdd(R[4], lx, hn::Mul(R[7], ly)));
  const VF oz = hn::MulAdd(R[2], f, hn::MulAdd(R[5], lx, hn::Mul(R[8], ly)));
  const VF inv = hn::Div(one, hn::Sqrt(hn::MulAdd(ox, ox, hn::MulAdd(oy, oy, hn::Mul(oz, oz)))));
  VF nx = zero, ny = zero, nz = zero, rhoR = zero, rhoG = zero, rhoB = zero, dist = inf;
  if (nrho != nullptr) {
    hn::LoadInterleaved4(d, nrho, nx, ny, nz, rhoR);
    hn::LoadInterleaved2(d, rgb2, rhoG, rhoB);
    dist = hn::LoadU(d, dp);
  }
  // The nearer of the mesh and the planes: a plane's normal turned to face the eye.
  const VF tp = hn::LoadU(d, planeT);
  const MF plane = hn::Lt(tp, dist);
  if (!hn::AllFalse(d, plane)) {
    const VI k = hn::Max(hn::LoadU(di, planeIndex), hn::Zero(di));
    for (std::size_t q = 0; q < fr.planes.size(); ++q) {
      const MF m = hn::And(plane, hn::RebindMask(d, hn::Eq(k, hn::Set(di, static_cast<std::int32_t>(q)))));
      if (hn::AllFalse(d, m)) continue;
      const ShadePlane& p = fr.planes[q];
      VF px = hn::Set(d, static_cast<float>(p.n[0])), py = hn::Set(d, static_cast<float>(p.n[1])),
         pz = hn::Set(d, static_cast<float>(p.n[2]));
      const MF flip = hn::Gt(hn::MulAdd(px, ox, hn::MulAdd(py, oy, hn::Mul(pz, oz))), zero);
      px = hn::IfThenElse(flip, hn::Neg(px), px);
      py = hn::IfThenElse(flip, hn::Neg(py), py);
      pz = hn::IfThenElse(flip, hn::Neg(pz), pz);
      nx = hn::IfThenElse(m, px, nx);
      ny = hn::IfThenElse(m, py, ny);
      nz = hn::IfThenElse(m, pz, nz);
      const VF r = hn::Set(d, p.rho);
      rhoR = hn::IfThenElse(m, r, rhoR);
      rhoG = hn::IfThenElse(m, r, rhoG);
      rhoB = hn::IfThenElse(m, r, rhoB);
    }
    dist = hn::IfThenElse(plane, tp, dist);
  }
  hn::StoreU(dist, d, outDistance);
  const MF hit = hn::Lt(dist, inf);
  const VF ds = hn::IfThenElse(hit, dist, one);  // sky lanes: any finite point, masked below
  const VF px = hn::Mul(hn::Mul(ox, inv), ds), py = hn::Mul(hn::Mul(oy, inv), ds), pz = hn::Mul(hn::Mul(oz, inv), ds);
  VF sr = zero, sg = zero, sb = zero;
  std::size_t fogRow = 0;  // the first row of lamp l's block
  if (!hn::AllFalse(d, hit)) {
    for (std::size_t l = 0; l < fr.lamps.size(); ++l) {
      const ShadeLamp& L = fr.lamps[l];
      const VF tx = hn::Sub(px, hn::Set(d, L.pos[0])), ty = hn::Sub(py, hn::Set(d, L.pos[1])),
               tz = hn::Sub(pz, hn::Set(d, L.pos[2]));
      const VF r2 = hn::MulAdd(tx, tx, hn::MulAdd(ty, ty, hn::Mul(tz, tz)));
      const MF away = hn::Gt(r2, zero);
      const VF r = hn::Sqrt(hn::IfThenElse(away, r2, one));
      const VF ir = hn::Div(one, r);
      const VF wx = hn::Mul(tx, ir), wy = hn::Mul(ty, ir), wz = hn::Mul(tz, ir);
      const VF cosInc = hn::Neg(hn::MulAdd(wx, nx, hn::MulAdd(wy, ny, hn::Mul(wz, nz))));  // light against the normal
      const MF lit = hn::And(hn::And(hit, away), hn::Gt(cosInc, zero));
      VF e = zero;
      if (fog != nullptr) {
        // The fog's scattered light (render/fog_light.hpp): Σ_q b_q(μ) s_q + d_q(μ) D_q · n, b and
        // d fogLightBasis's (1, μ, two smoothed ramps; 1, three smoothed steps), μ = cos i, on
        // every surface pixel whatever side it faces.
        const float* fl = fog + fogRow * stride;
        const bool dipole = fr.fog_light.lamps[l].map != nullptr;
        fogRow += fogLightFloats(fr.fog_light.lamps[l]);
        const VF mu = cosInc, mu2 = hn::Mul(cosInc, cosInc), half = hn::Set(d, 0.5f), threeHalves = hn::Set(d, 1.5f);
        // 1/√(μ² + w²): the reciprocal square-root estimate and one Newton step (~2e-7 relative),
        // cheaper than a square root and a division (five of them per measured lamp and pixel).
        auto rsqrt = [&](double w) {
          const VF v = hn::Add(mu2, hn::Set(d, static_cast<float>(w * w)));
          const VF y = hn::ApproximateReciprocalSqrt(v);
          return std::pair{v, hn::Mul(y, hn::NegMulAdd(hn::Mul(half, v), hn::Mul(y, y), threeHalves))};
        };
        auto ramp = [&](double w) {
          const auto [v, y] = rsqrt(w);
          return hn::Mul(half, hn::MulAdd(v, y, mu));
        };
        VF ef = hn::MulAdd(hn::LoadU(d, fl + stride), mu, hn::LoadU(d, fl));
        ef = hn::MulAdd(hn::LoadU(d, fl + 2 * stride), ramp(kFogRampWidth[0]), ef);
        ef = hn::MulAdd(hn::LoadU(d, fl + 3 * stride), ramp(kFogRampWidth[1]), ef);
        if (dipole) {
          for (std::size_t q = 0; q < 4; ++q) {
            const float* dq = fl + (4 + 3 * q) * stride;
            const VF dn = hn::MulAdd(hn::LoadU(d, dq), nx,
                                     hn::MulAdd(hn::LoadU(d, dq + stride), ny, hn::Mul(hn::LoadU(d, dq + 2 * stride), nz)));
            const VF dq_mu = q == 0 ? one : hn::Mul(mu, rsqrt(kFogStepWidth[q - 1]).second);
            ef = hn::MulAdd(dn, dq_mu, ef);
          }
        }
        e = hn::IfThenElseZero(hit, hn::Max(ef, zero));
      }
      if (hn::AllFalse(d, lit)) {
        if (fog != nullptr) {
          sr = hn::MulAdd(hn::Set(d, L.color[0]), e, sr);
          sg = hn::MulAdd(hn::Set(d, L.color[1]), e, sg);
          sb = hn::MulAdd(hn::Set(d, L.color[2]), e, sb);
        }
        continue;
      }
      VF intensity;
      if (L.kind == 0) {
        intensity = hn::Set(d, L.i0);
      } else {
        // The direction in the lamp frame: its components along the lamp's axes.
        const VF ux = hn::MulAdd(hn::Set(d, L.ax[0]), wx, hn::MulAdd(hn::Set(d, L.ax[1]), wy, hn::Mul(hn::Set(d, L.ax[2]), wz)));
        const VF uy = hn::MulAdd(hn::Set(d, L.ay[0]), wx, hn::MulAdd(hn::Set(d, L.ay[1]), wy, hn::Mul(hn::Set(d, L.ay[2]), wz)));
        const VF uz = hn::MulAdd(hn::Set(d, L.az[0]), wx, hn::MulAdd(hn::Set(d, L.az[1]), wy, hn::Mul(hn::Set(d, L.az[2]), wz)));
        if (L.kind == 1) {  // spot: ψ from the axis (atan of |yz|/x: accurate near the axis)
          const VF psi = Atan2(d, hn::Sqrt(hn::MulAdd(uy, uy, hn::Mul(uz, uz))), ux);
          const VF ramp = hn::Mul(hn::Set(d, L.i0 / (L.outer - L.inner)), hn::Sub(hn::Set(d, L.outer), psi));
          intensity = hn::IfThenElse(hn::Le(psi, hn::Set(d, L.inner)), hn::Set(d, L.i0),
                                     hn::IfThenElseZero(hn::Lt(psi, hn::Set(d, L.outer)), ramp));
        } else {
          intensity = Tabulated(d, di, *L.table, ux, uy, uz);
        }
      }
      // E = I cos(incidence) e^{−K_t r} / r² [lux]
      e = hn::Add(e, hn::IfThenElseZero(lit, hn::Mul(hn::Mul(hn::Mul(intensity, cosInc), hn::Exp(d, hn::Neg(hn::Mul(kt, r)))),
                                                     hn::Mul(ir, ir))));
      sr = hn::MulAdd(hn::Set(d, L.color[0]), e, sr);
      sg = hn::MulAdd(hn::Set(d, L.color[1]), e, sg);
      sb = hn::MulAdd(hn::Set(d, L.color[2]), e, sb);
    }
  }
  // L_s = ρ/π · Σ · T + I_a (1 − T), T = e^{−K_t d}; the sky is I_a.
  const VF T = hn::IfThenElseZero(hit, hn::Exp(d, hn::Neg(hn::Mul(kt, ds))));
  const VF amb = hn::Mul(ia, hn::Sub(one, T));
  const VF w = hn::Mul(invPi, T);
  hn::StoreInterleaved3(hn::MulAdd(hn::Mul(rhoR, sr), w, amb), hn::MulAdd(hn::Mul(rhoG, sg), w, amb),
                        hn::MulAdd(hn::Mul(rhoB, sb), w, amb), d, out);
}

void ShadeRowImpl(const ShadeFrame& fr, int j, int x0, int count, const float* HWY_RESTRICT nrho, const float* HWY_RESTRICT rgb2,
                  const float* HWY_RESTRICT dist, const float* HWY_RESTRICT planeT,
                  const std::int32_t* HWY_RESTRICT planeIndex, float* HWY_RESTRICT outRgb, float* HWY_RESTRICT outDist,
                  const float* HWY_RESTRICT fog, std::size_t fogStride) {
  const DF d;
  const int N = static_cast<int>(hn::Lanes(d));
  const bool mesh = nrho != nullptr;
  int i = 0;
  for (; i + N <= count; i += N)
    ShadeVector(fr, j, x0 + i, mesh ? nrho + 4 * i : nullptr, mesh ? rgb2 + 2 * i : nullptr, mesh ? dist + i : nullptr,
                planeT + i, planeIndex + i, outRgb + 3 * i, outDist + i, fog != nullptr ? fog + i : nullptr, fogStride);
  if (i == count) return;
  // The row's last pixels, through a vector padded with sky: interleaved loads past the row's
  // end would read past the buffer on the last row.
  constexpr std::size_t M = hn::MaxLanes(d);
  HWY_ALIGN float n4[4 * M] = {}, g2[2 * M] = {}, dd[M], tp[M], o3[3 * M], od[M];
  HWY_ALIGN std::int32_t ip[M];
  const int rest = count - i;  // 1 … N − 1
  for (int k = 0; k < N; ++k) {
    const bool in = k < rest;
    dd[k] = in && mesh ? dist[i + k] : std::numeric_limits<float>::infinity();
    tp[k] = in ? planeT[i + k] : std::numeric_limits<float>::infinity();
    ip[k] = in ? planeIndex[i + k] : -1;
    for (int c = 0; c < 4; ++c) n4[4 * k + c] = in && mesh ? nrho[4 * (i + k) + c] : 0.0f;
    for (int c = 0; c < 2; ++c) g2[2 * k + c] = in && mesh ? rgb2[2 * (i + k) + c] : 0.0f;
  }
  // The fog light's rows are padded (shadeRow: fogStride ≥ count + the widest vector): read as is.
  ShadeVector(fr, j, x0 + i, n4, g2, dd, tp, ip, o3, od, fog != nullptr ? fog + i : nullptr, fogStride);
  for (int k = 0; k < 3 * rest; ++k) outRgb[3 * i + k] = o3[k];
  for (int k = 0; k < rest; ++k) outDist[i + k] = od[k];
}

}  // namespace fogbeam::kernels::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam::kernels {

HWY_EXPORT(ShadeRowImpl);
HWY_EXPORT(CastPlanesRowImpl);

void castPlanesRow(const ShadeFrame& frame, int j, int count, float* t, std::int32_t* plane, int x0) {
  HWY_DYNAMIC_DISPATCH(CastPlanesRowImpl)(frame, j, x0, count, t, plane);
}

void shadeRow(const ShadeFrame& frame, int j, int count, const float* normalRhoR, const float* rhoGB,
              const float* distance, const float* planeT, const std::int32_t* planeIndex, float* outRgb,
              float* outDistance, const float* fogLight, std::size_t fogStride, int x0) {
  HWY_DYNAMIC_DISPATCH(ShadeRowImpl)(frame, j, x0, count, normalRhoR, rhoGB, distance, planeT, planeIndex, outRgb,
                                     outDistance, fogLight, fogStride);
}

}  // namespace fogbeam::kernels
#endif
