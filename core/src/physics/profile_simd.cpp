// fogbeam — Highway SIMD trigonometry of a profile along a great circle of the lamp's direction
// sphere: the file angles of its samples (profile.hpp, Profile::intensitiesOnCircle) and its
// crossings with the profile's feature lines (Profile::appendFeatureKinks).
//
// A moving lamp's spoke (airlight_pencil.cpp) samples the profile ~120 times along one great
// circle, most samples at the circle's crossings with the profile's feature lines, and each
// sample was a libm sincos, two atan2 and a square root before the bilinear look-up: about a
// fifth of a traffic frame's CPU time (perf, `fogbeam bench --only-traffic`). Here the
// trigonometry runs a vector of samples at a time; the look-up itself (two bucket searches and
// a bilinear cell) stays scalar (TabulatedProfile::atAngles). The circle's crossings with the
// up to 64 feature lines of tabulated data (two atan2 each) go the same way, a vector of lines
// at a time.
//
// Compiled once per SIMD target by hwy/foreach_target.h and chosen at run time
// (HWY_DYNAMIC_DISPATCH). The angles are those of anglesFromDirection (profile.cpp) up to the
// last bits: Highway's Sin, Cos and Atan are within 3 ulp of the library's, the scalar path's
// fastAtan2 within 2 (tests/physics/test_profile.cpp compares the intensities).

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "physics/profile_simd.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include "profile_simd.hpp"

#include <cmath>
#include <cstddef>
#include <limits>

HWY_BEFORE_NAMESPACE();
namespace fogbeam::detail::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DD = hn::ScalableTag<double>;
using VD = hn::Vec<DD>;

// atan2(y, x) in [−π, π] from Highway's Atan on [0, 1] (the smaller of |x|, |y| over the
// larger, then the octant); 0 where x = y = 0.
HWY_INLINE VD Atan2(DD d, VD y, VD x) {
  const VD ax = hn::Abs(x), ay = hn::Abs(y);
  const auto swap = hn::Gt(ay, ax);
  const VD num = hn::IfThenElse(swap, ax, ay), den = hn::IfThenElse(swap, ay, ax);
  const auto zero = hn::Eq(den, hn::Zero(d));
  const VD t = hn::Div(num, hn::IfThenElse(zero, hn::Set(d, 1.0), den));
  VD a = hn::CallAtan(d, t);
  a = hn::IfThenElse(swap, hn::Sub(hn::Set(d, 1.5707963267948966), a), a);
  a = hn::IfThenElse(hn::Lt(x, hn::Zero(d)), hn::Sub(hn::Set(d, 3.141592653589793), a), a);
  a = hn::CopySign(a, y);
  return hn::IfThenZeroElse(zero, a);
}

void CircleAngles(int type, const double* u, const double* v, const double* psi, std::size_t n, double* hOut,
                  double* vOut) {
  const DD d;
  const std::size_t N = hn::Lanes(d);
  const VD ux = hn::Set(d, u[0]), uy = hn::Set(d, u[1]), uz = hn::Set(d, u[2]);
  const VD vx = hn::Set(d, v[0]), vy = hn::Set(d, v[1]), vz = hn::Set(d, v[2]);
  auto one = [&](VD p, VD& h, VD& vv) {
    const VD c = hn::CallCos(d, p), s = hn::CallSin(d, p);
    const VD x = hn::MulAdd(c, ux, hn::Mul(s, vx));
    const VD y = hn::MulAdd(c, uy, hn::Mul(s, vy));
    const VD z = hn::MulAdd(c, uz, hn::Mul(s, vz));
    // The conventions of anglesFromDirection (profile.cpp): acos and asin as atan2.
    switch (type) {
      case kTypeC:
        h = Atan2(d, z, y);
        vv = Atan2(d, hn::Sqrt(hn::MulAdd(y, y, hn::Mul(z, z))), x);
        break;
      case kTypeB:
        h = Atan2(d, hn::Neg(y), hn::Sqrt(hn::MulAdd(x, x, hn::Mul(z, z))));
        vv = Atan2(d, z, x);
        break;
      default:  // kTypeA
        h = Atan2(d, hn::Neg(y), x);
        vv = Atan2(d, z, hn::Sqrt(hn::MulAdd(x, x, hn::Mul(y, y))));
        break;
    }
  };
  std::size_t i = 0;
  for (; i + N <= n; i += N) {
    VD h, vv;
    one(hn::LoadU(d, psi + i), h, vv);
    hn::StoreU(h, d, hOut + i);
    hn::StoreU(vv, d, vOut + i);
  }
  if (i < n) {
    const std::size_t rest = n - i;
    HWY_ALIGN double p[hn::MaxLanes(d)] = {};
    HWY_ALIGN double hb[hn::MaxLanes(d)], vb[hn::MaxLanes(d)];
    for (std::size_t k = 0; k < rest; ++k) p[k] = psi[i + k];
    VD h, vv;
    one(hn::Load(d, p), h, vv);
    hn::Store(h, d, hb);
    hn::Store(vv, d, vb);
    for (std::size_t k = 0; k < rest; ++k) {
      hOut[i + k] = hb[k];
      vOut[i + k] = vb[k];
    }
  }
}

// cos ψ_i a + sin ψ_i b for each ψ_i: one component of the circle's direction (the lamp-axis
// component decides whether a sample lies inside a tabulated profile's support cone).
void CircleComponent(double a, double b, const double* psi, std::size_t n, double* out) {
  const DD d;
  const std::size_t N = hn::Lanes(d);
  const VD av = hn::Set(d, a), bv = hn::Set(d, b);
  std::size_t i = 0;
  for (; i + N <= n; i += N) {
    const VD p = hn::LoadU(d, psi + i);
    hn::StoreU(hn::MulAdd(hn::CallCos(d, p), av, hn::Mul(hn::CallSin(d, p), bv)), d, out + i);
  }
  for (; i < n; ++i) out[i] = std::cos(psi[i]) * a + std::sin(psi[i]) * b;
}

// Per line i: the two solutions θ = atan2(y, x) ± acos(c / r) (r = √(x² + y²), x = n·a_i,
// y = t·a_i) of w(θ)·a_i = c_i on the circle w(θ) = cos θ n + sin θ t, NaN where there is none
// (r < 1e-15 or |c| > r), as crossingsDot in profile.cpp.
void LineCrossings(const double* n, const double* t, const double* ax, const double* ay, const double* az,
                   const double* c, std::size_t count, double* thA, double* thB) {
  const DD d;
  const std::size_t N = hn::Lanes(d);
  const VD nx = hn::Set(d, n[0]), ny = hn::Set(d, n[1]), nz = hn::Set(d, n[2]);
  const VD tx = hn::Set(d, t[0]), ty = hn::Set(d, t[1]), tz = hn::Set(d, t[2]);
  const VD nan = hn::Set(d, std::numeric_limits<double>::quiet_NaN());
  auto one = [&](VD axv, VD ayv, VD azv, VD cv, VD& a, VD& b) {
    const VD x = hn::MulAdd(nx, axv, hn::MulAdd(ny, ayv, hn::Mul(nz, azv)));
    const VD y = hn::MulAdd(tx, axv, hn::MulAdd(ty, ayv, hn::Mul(tz, azv)));
    const VD r = hn::Sqrt(hn::MulAdd(x, x, hn::Mul(y, y)));
    const auto none = hn::Or(hn::Lt(r, hn::Set(d, 1e-15)), hn::Gt(hn::Abs(cv), r));
    const VD centre = Atan2(d, y, x);
    const VD half = Atan2(d, hn::Sqrt(hn::ZeroIfNegative(hn::Mul(hn::Sub(r, cv), hn::Add(r, cv)))), cv);
    a = hn::IfThenElse(none, nan, hn::Sub(centre, half));
    b = hn::IfThenElse(none, nan, hn::Add(centre, half));
  };
  std::size_t i = 0;
  for (; i + N <= count; i += N) {
    VD a, b;
    one(hn::LoadU(d, ax + i), hn::LoadU(d, ay + i), hn::LoadU(d, az + i), hn::LoadU(d, c + i), a, b);
    hn::StoreU(a, d, thA + i);
    hn::StoreU(b, d, thB + i);
  }
  if (i < count) {
    const std::size_t rest = count - i;
    HWY_ALIGN double bx[hn::MaxLanes(d)] = {}, by[hn::MaxLanes(d)] = {}, bz[hn::MaxLanes(d)] = {};
    HWY_ALIGN double bc[hn::MaxLanes(d)] = {}, oa[hn::MaxLanes(d)], ob[hn::MaxLanes(d)];
    for (std::size_t k = 0; k < rest; ++k) {
      bx[k] = ax[i + k];
      by[k] = ay[i + k];
      bz[k] = az[i + k];
      bc[k] = c[i + k];
    }
    VD a, b;
    one(hn::Load(d, bx), hn::Load(d, by), hn::Load(d, bz), hn::Load(d, bc), a, b);
    hn::Store(a, d, oa);
    hn::Store(b, d, ob);
    for (std::size_t k = 0; k < rest; ++k) {
      thA[i + k] = oa[k];
      thB[i + k] = ob[k];
    }
  }
}

}  // namespace fogbeam::detail::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam::detail {
HWY_EXPORT(CircleAngles);
HWY_EXPORT(LineCrossings);
HWY_EXPORT(CircleComponent);

void circleAngles(int type, const double* u, const double* v, const double* psi, std::size_t n, double* h,
                  double* vOut) {
  HWY_DYNAMIC_DISPATCH(CircleAngles)(type, u, v, psi, n, h, vOut);
}

void lineCrossings(const double* n, const double* t, const double* ax, const double* ay, const double* az,
                   const double* c, std::size_t count, double* thA, double* thB) {
  HWY_DYNAMIC_DISPATCH(LineCrossings)(n, t, ax, ay, az, c, count, thA, thB);
}

void circleComponent(double a, double b, const double* psi, std::size_t n, double* out) {
  HWY_DYNAMIC_DISPATCH(CircleComponent)(a, b, psi, n, out);
}
}  // namespace fogbeam::detail
#endif  // HWY_ONCE
