// fogbeam — the CPU planes renderer (fogbeam/render/surface.hpp).
//
// Rows go to the pool; each row's pixels that hit a plane are gathered into batches of
// kBatch (structure of arrays), and each lamp is applied to a whole batch: the geometry of
// lambertianLuminance (r² = |X − S|², r = √r², w = (X − S)/r, cos(incidence) = −w·n, the lamp-
// frame direction Mᵀw) and the attenuation e^{−K_t r} are a Highway kernel in double (compiled
// per SIMD target by hwy/foreach_target.h, chosen at run time); the profile I(Mᵀw) of
// non-isotropic lamps stays Profile::intensity, per pixel. The result is bit-identical to the
// scalar definition (renderSurfacesCpu before 2026-11-26: one pixel at a time through
// lambertianLuminance; tests/render/test_surface_cpu.cpp keeps it and compares):
//
//  * every operation but the exp is the scalar one, in the same order (glm's dot is
//    (x + y) + z, its mat3 · vec3 the same per row), and no fused multiply-add: GCC contracts
//    a·b + c into an FMA on targets that have one unless told not to, hence -ffp-contract=off for this file (core/CMakeLists.txt: GCC and clang alike);
//  * e^{−K_t r}: Highway's Exp (≤ 1 ulp, its documentation) and std::exp (< 1 ulp, glibc) may
//    differ in the last bit of the double (measured: 1 value in 10, never more than 1 ulp). All
//    terms of L_s are ≥ 0 (intensities, colours, reflectances, T), so L_s in double is then
//    within a few ulp of the scalar one, and both round to the same float unless it lies within
//    kMidpointMarginUlp ulp of a midpoint between two floats, or below the normal floats; such
//    pixels (~1e-5 of them) are shaded again by the scalar definition (shadePixelScalar).

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/surface.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include <fogbeam/render/surface.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <thread>
#include <variant>

#ifndef FOGBEAM_SURFACE_DETAIL_ONCE
#define FOGBEAM_SURFACE_DETAIL_ONCE
namespace fogbeam::surface_detail {
/// Pixels per batch: a multiple of every target's double lanes (8 on AVX-512).
constexpr std::size_t kBatch = 64;

/// One lamp as the kernel needs it: position S [m], M = worldFromLamp (column-major, glm's
/// m[c][r] at 3c + r), and −K_t [1/m].
struct LampGeometry {
  double sx, sy, sz;
  double m[9];
  double negKt;
  double isoIntensity;  // I [cd] of an isotropic lamp (then Mᵀw is not needed), NaN otherwise
  double colour[3];
};

/// Per batch pixel: the point X and the normal facing the eye (inputs); cos(incidence) (0
/// where r² ≤ 0, as lambertianLuminance returns 0 there), e^{−K_t r}, r², Mᵀw (outputs).
struct BatchArrays {
  alignas(64) double px[kBatch], py[kBatch], pz[kBatch];
  alignas(64) double nx[kBatch], ny[kBatch], nz[kBatch];
  alignas(64) double cosInc[kBatch], att[kBatch], r2[kBatch];
  alignas(64) double wx[kBatch], wy[kBatch], wz[kBatch];
  alignas(64) double rhoPi[kBatch];     // ρ/π of the pixel's plane (input)
  alignas(64) double intensity[kBatch];  // I(Mᵀw) [cd] of a non-isotropic lamp (input of Accumulate)
  alignas(64) double acc[3][kBatch];     // Σ_lamps colour · L(S) so far, per channel
};
}  // namespace fogbeam::surface_detail
#endif

HWY_BEFORE_NAMESPACE();
namespace fogbeam::surface_detail::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// The geometry of lambertianLuminance for pixels [0, n) of the batch, n a multiple of the lanes.
void LampBatch(const LampGeometry& L, BatchArrays& b, std::size_t n) {
  const hn::ScalableTag<double> d;
  const std::size_t N = hn::Lanes(d);
  const auto sx = hn::Set(d, L.sx), sy = hn::Set(d, L.sy), sz = hn::Set(d, L.sz);
  const auto negKt = hn::Set(d, L.negKt);
  const auto zero = hn::Zero(d);
  for (std::size_t i = 0; i < n; i += N) {
    const auto tx = hn::Sub(hn::Load(d, b.px + i), sx);
    const auto ty = hn::Sub(hn::Load(d, b.py + i), sy);
    const auto tz = hn::Sub(hn::Load(d, b.pz + i), sz);
    const auto r2 = hn::Add(hn::Add(hn::Mul(tx, tx), hn::Mul(ty, ty)), hn::Mul(tz, tz));
    const auto r = hn::Sqrt(r2);
    const auto wx = hn::Div(tx, r), wy = hn::Div(ty, r), wz = hn::Div(tz, r);
    const auto dn = hn::Add(hn::Add(hn::Mul(wx, hn::Load(d, b.nx + i)), hn::Mul(wy, hn::Load(d, b.ny + i))),
                            hn::Mul(wz, hn::Load(d, b.nz + i)));
    const auto cosInc = hn::IfThenElseZero(hn::Gt(r2, zero), hn::Neg(dn));
    hn::Store(cosInc, d, b.cosInc + i);
    hn::Store(hn::CallExp(d, hn::Mul(negKt, r)), d, b.att + i);
    hn::Store(r2, d, b.r2 + i);
    if (std::isnan(L.isoIntensity)) {
      const double* m = L.m;
      auto row = [&](int k) {  // (Mᵀw)_k = (M[k][0] w.x + M[k][1] w.y) + M[k][2] w.z
        return hn::Add(hn::Add(hn::Mul(hn::Set(d, m[3 * k]), wx), hn::Mul(hn::Set(d, m[3 * k + 1]), wy)),
                       hn::Mul(hn::Set(d, m[3 * k + 2]), wz));
      };
      hn::Store(row(0), d, b.wx + i);
      hn::Store(row(1), d, b.wy + i);
      hn::Store(row(2), d, b.wz + i);
    }
  }
}

// acc += colour · ρ/π ((I cos) e^{−K_t r}) / r², 0 unless cos > 0 (lambertianLuminance's order
// of operations), with I the isotropic lamp's or b.intensity.
void Accumulate(const LampGeometry& L, BatchArrays& b, std::size_t n) {
  const hn::ScalableTag<double> d;
  const std::size_t N = hn::Lanes(d);
  const bool iso = !std::isnan(L.isoIntensity);
  const auto isoI = hn::Set(d, iso ? L.isoIntensity : 0.0);
  const auto zero = hn::Zero(d);
  const auto c0 = hn::Set(d, L.colour[0]), c1 = hn::Set(d, L.colour[1]), c2 = hn::Set(d, L.colour[2]);
  for (std::size_t i = 0; i < n; i += N) {
    const auto cosInc = hn::Load(d, b.cosInc + i);
    const auto intensity = iso ? isoI : hn::Load(d, b.intensity + i);
    const auto e = hn::Div(hn::Mul(hn::Mul(intensity, cosInc), hn::Load(d, b.att + i)), hn::Load(d, b.r2 + i));
    const auto l = hn::IfThenElseZero(hn::Gt(cosInc, zero), hn::Mul(hn::Load(d, b.rhoPi + i), e));
    hn::Store(hn::Add(hn::Load(d, b.acc[0] + i), hn::Mul(l, c0)), d, b.acc[0] + i);
    hn::Store(hn::Add(hn::Load(d, b.acc[1] + i), hn::Mul(l, c1)), d, b.acc[1] + i);
    hn::Store(hn::Add(hn::Load(d, b.acc[2] + i), hn::Mul(l, c2)), d, b.acc[2] + i);
  }
}

}  // namespace fogbeam::surface_detail::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace fogbeam {

void SurfaceBuffers::resize(int w, int h) {
  width = w;
  height = h;
  const auto n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  rgb.assign(3 * n, 0.0f);
  distance.assign(n, std::numeric_limits<float>::infinity());
}

double lambertianLuminance(const Lamp& lamp, const Medium& fog, const Vec3& point, const Vec3& normal,
                           double reflectance) noexcept {
  const Vec3 toPoint = point - lamp.position_m;
  const double r2 = glm::dot(toPoint, toPoint);
  if (r2 <= 0.0) return 0.0;
  const double r = std::sqrt(r2);
  const Vec3 w = toPoint / r;
  const double cosInc = -glm::dot(w, normal);  // light arrives against the normal
  if (cosInc <= 0.0) return 0.0;
  const Vec3 wLamp = glm::transpose(lamp.worldFromLamp) * w;
  const double e = lamp.profile->intensity(wLamp) * cosInc * std::exp(-fog.extinction_per_m * r) / r2;  // lux
  return reflectance / kPi * e;
}

namespace surface_detail {
HWY_EXPORT(LampBatch);
HWY_EXPORT(Accumulate);

// A double y rounds to float ambiguously when it is within this many double ulp of a float
// midpoint (bits 0–28 of its mantissa near 2^28): far above the few ulp by which the SIMD and
// scalar L_s can differ, and still only 2^13 / 2^29 ≈ 1.5e-5 of the values.
constexpr std::uint64_t kMidpointMarginUlp = 4096;

bool floatRoundingAmbiguous(double y) noexcept {
  if (y == 0.0) return false;  // every term 0 (a term the scalar exp keeps is < 1e-300: float 0 too)
  if (!(y >= 0x1p-126 && y <= 0x1p127)) return true;  // subnormal floats, overflow, NaN, negative
  const std::uint64_t low = std::bit_cast<std::uint64_t>(y) & ((std::uint64_t{1} << 29) - 1);
  const std::uint64_t mid = std::uint64_t{1} << 28;
  return (low > mid ? low - mid : mid - low) < kMidpointMarginUlp;
}

// The nearest surface along the unit ray d from the eye: the planes (`num[k]` = (P_k − O)·n_k),
// then the body quads (Scene::body, the bonnet: the plane through the quad, kept where the hit's
// coordinates on its edges lie in [0, 1]). Its distance, its normal (as stored: the caller turns
// it to face the eye) and its reflectance; false for the sky.
bool nearestSurface(const Scene& scene, const double* num, const Vec3& d, double& best, Vec3& normal,
                    double& reflectance) {
  best = std::numeric_limits<double>::infinity();
  int hit = -1;
  for (std::size_t k = 0; k < scene.planes.size(); ++k) {
    const double denom = glm::dot(d, scene.planes[k].normal);
    if (std::abs(denom) < 1e-12) continue;
    const double t = num[k] / denom;
    if (t > 0.0 && t < best) {
      best = t;
      hit = static_cast<int>(k);
    }
  }
  if (hit >= 0) {
    normal = scene.planes[static_cast<std::size_t>(hit)].normal;
    reflectance = scene.planes[static_cast<std::size_t>(hit)].reflectance;
  }
  for (const Quad& q : scene.body) {
    const Vec3 n = glm::normalize(glm::cross(q.edge_u_m, q.edge_v_m));
    const Vec3 corner = q.corner_m - scene.camera.position_m;
    const double denom = glm::dot(d, n);
    if (std::abs(denom) < 1e-12) continue;
    const double t = glm::dot(corner, n) / denom;
    if (!(t > 0.0 && t < best)) continue;
    const Vec3 r = t * d - corner;
    const double uu = glm::dot(q.edge_u_m, q.edge_u_m), uv = glm::dot(q.edge_u_m, q.edge_v_m),
                 vv = glm::dot(q.edge_v_m, q.edge_v_m), det = uu * vv - uv * uv;
    const double ru = glm::dot(r, q.edge_u_m), rv = glm::dot(r, q.edge_v_m);
    const double su = (vv * ru - uv * rv) / det, sv = (uu * rv - uv * ru) / det;
    if (su < 0.0 || su > 1.0 || sv < 0.0 || sv > 1.0) continue;
    best = t;
    hit = 1;
    normal = n;
    reflectance = q.reflectance;
  }
  return hit >= 0;
}

// The scalar definition of one pixel (what renderSurfacesCpu computed before the batches):
// the reference the batch path falls back to. `num[p]` = (P_p − O)·n_p, as it computed per
// pixel.
void shadePixelScalar(const Scene& scene, const Vec3& d, const double* num, float* rgbOut, float* distOut) {
  const Camera& cam = scene.camera;
  double best = 0.0, rho = 0.0;
  Vec3 normal(0.0);
  const bool hit = nearestSurface(scene, num, d, best, normal, rho);
  double rgb[3] = {0.0, 0.0, 0.0};
  if (hit) {
    const Vec3 x = cam.position_m + best * d;
    const Vec3 n = glm::dot(normal, d) < 0.0 ? normal : -normal;  // faces the eye
    for (const SceneLamp& sl : scene.lamps) {
      const double l = lambertianLuminance(sl.lamp, scene.fog, x, n, rho);
      for (int c = 0; c < 3; ++c) rgb[c] += l * sl.lamp.color[c];
    }
  }
  const double kt = scene.fog.extinction_per_m, ia = scene.fog.ambient_cd_m2;
  const double t = hit ? std::exp(-kt * best) : 0.0;
  for (int c = 0; c < 3; ++c) rgbOut[c] = static_cast<float>(rgb[c] * t + ia * (1.0 - t));
  *distOut = hit ? static_cast<float>(best) : std::numeric_limits<float>::infinity();
}

// Planes and lamps whose per-frame constants live on the stack (more go to the heap).
constexpr std::size_t kMaxInlinePlanes = 64;

struct Context {
  const Scene* scene;
  SurfaceBuffers* out;
  const LampGeometry* lamps;
  const double* num;           // per plane: (P − O)·n
  double f;
  Vec2 c;
};

// Applies every lamp to the batch's first m pixels and writes them (pixel index in `pix`,
// distance in `tHit`, ray in `dir` for the fallback).
void flushBatch(const Context& ctx, BatchArrays& b, std::size_t m, const std::uint32_t* pix, const double* tHit,
                const Vec3* dir) {
  const Scene& scene = *ctx.scene;
  // Pad the tail with the last pixel (finite values; the results are not used).
  for (std::size_t k = m; k < kBatch; ++k) {
    b.px[k] = b.px[m - 1];
    b.py[k] = b.py[m - 1];
    b.pz[k] = b.pz[m - 1];
    b.nx[k] = b.nx[m - 1];
    b.ny[k] = b.ny[m - 1];
    b.nz[k] = b.nz[m - 1];
  }
  const std::size_t padded = (m + 7) / 8 * 8;  // 8 doubles: a multiple of every target's lanes
  for (std::size_t k = m; k < padded; ++k) b.rhoPi[k] = 0.0;
  for (auto& a : b.acc) std::fill(a, a + padded, 0.0);
  for (std::size_t li = 0; li < scene.lamps.size(); ++li) {
    const LampGeometry& g = ctx.lamps[li];
    HWY_DYNAMIC_DISPATCH(LampBatch)(g, b, padded);
    if (std::isnan(g.isoIntensity)) {
      // The profile per pixel (tabulated: file angles and a bilinear cell; spot: the cone),
      // only where the surface faces the lamp, as lambertianLuminance.
      const Profile& prof = *scene.lamps[li].lamp.profile;
      for (std::size_t k = 0; k < padded; ++k)
        b.intensity[k] = k < m && b.cosInc[k] > 0.0 ? prof.intensity(Vec3(b.wx[k], b.wy[k], b.wz[k])) : 0.0;
    }
    HWY_DYNAMIC_DISPATCH(Accumulate)(g, b, padded);
  }
  const auto& acc = b.acc;
  const double kt = scene.fog.extinction_per_m, ia = scene.fog.ambient_cd_m2;
  SurfaceBuffers& out = *ctx.out;
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t px = pix[k];
    const double t = std::exp(-kt * tHit[k]);
    double v[3];
    bool ambiguous = false;
    for (int ch = 0; ch < 3; ++ch) {
      v[ch] = acc[ch][k] * t + ia * (1.0 - t);
      ambiguous = ambiguous || floatRoundingAmbiguous(v[ch]);
    }
    if (ambiguous) {
      shadePixelScalar(scene, dir[k], ctx.num, &out.rgb[3 * px], &out.distance[px]);
      continue;
    }
    for (int ch = 0; ch < 3; ++ch) out.rgb[3 * px + static_cast<std::size_t>(ch)] = static_cast<float>(v[ch]);
    out.distance[px] = static_cast<float>(tHit[k]);
  }
}

void renderRow(const Context& ctx, int j) {
  const Scene& scene = *ctx.scene;
  const Camera& cam = scene.camera;
  SurfaceBuffers& out = *ctx.out;
  const double ia = scene.fog.ambient_cd_m2;
  BatchArrays b;
  std::uint32_t pix[kBatch];
  double tHit[kBatch];
  Vec3 dir[kBatch];
  std::size_t m = 0;
  for (int i = 0; i < cam.width; ++i) {
    // Camera::rayDirection(i + 0.5, j + 0.5) with f and the principal point hoisted.
    const Vec3 local(ctx.f, ctx.c.x - (i + 0.5), ctx.c.y - (j + 0.5));
    const Vec3 d = glm::normalize(cam.worldFromCamera * local);
    double best = 0.0, rho = 0.0;
    Vec3 normal(0.0);
    const bool hit = nearestSurface(scene, ctx.num, d, best, normal, rho);
    const auto px = static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
    if (!hit) {  // sky: L_s = I_a, d = +inf
      const auto sky = static_cast<float>(ia);
      out.rgb[3 * px] = out.rgb[3 * px + 1] = out.rgb[3 * px + 2] = sky;
      out.distance[px] = std::numeric_limits<float>::infinity();
      continue;
    }
    const Vec3 x = cam.position_m + best * d;
    const Vec3 n = glm::dot(normal, d) < 0.0 ? normal : -normal;  // faces the eye
    b.px[m] = x.x;
    b.py[m] = x.y;
    b.pz[m] = x.z;
    b.nx[m] = n.x;
    b.ny[m] = n.y;
    b.nz[m] = n.z;
    b.rhoPi[m] = rho / kPi;
    pix[m] = static_cast<std::uint32_t>(px);
    tHit[m] = best;
    dir[m] = d;
    if (++m == kBatch) {
      flushBatch(ctx, b, m, pix, tHit, dir);
      m = 0;
    }
  }
  if (m > 0) flushBatch(ctx, b, m, pix, tHit, dir);
}

void renderAll(const Scene& scene, SurfaceBuffers& out, ThreadPool* pool, const double* num, const LampGeometry* lamps) {
  const Camera& cam = scene.camera;
  const Context ctx{&scene, &out, lamps, num, cam.focalLengthPixels(), cam.principalPoint()};
  const auto rows = static_cast<std::size_t>(cam.height);
  if (pool) {
    // One pointer captured: std::function keeps it without allocating.
    const Context* c = &ctx;
    pool->parallelFor(rows, [c](std::size_t j) { renderRow(*c, static_cast<int>(j)); });
    return;
  }
  // No pool: threads for this call, as many as cores (the behaviour before pools were passed).
  const int nThreads = std::max(1, std::min(static_cast<int>(std::thread::hardware_concurrency()), cam.height));
  auto band = [&](int j0, int j1) {
    for (int j = j0; j < j1; ++j) renderRow(ctx, j);
  };
  std::vector<std::thread> threads;
  for (int k = 1; k < nThreads; ++k) threads.emplace_back(band, cam.height * k / nThreads, cam.height * (k + 1) / nThreads);
  band(0, cam.height / nThreads);
  for (auto& th : threads) th.join();
}

}  // namespace surface_detail

void renderSurfacesCpu(const Scene& scene, SurfaceBuffers& out, ThreadPool* pool) {
  using namespace surface_detail;
  const Camera& cam = scene.camera;
  // Every pixel is written below, so buffers of the right size are kept as they are.
  const auto n = static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height);
  if (out.width != cam.width || out.height != cam.height || out.rgb.size() != 3 * n || out.distance.size() != n)
    out.resize(cam.width, cam.height);
  // Per plane (P − O)·n and per lamp its kernel form: on the stack up to a few dozen of each
  // (the frame loop does not allocate), on the heap beyond.
  constexpr std::size_t kInline = kMaxInlinePlanes;
  double numInline[kInline];
  LampGeometry lampsInline[kInline];
  std::vector<double> numHeap;
  std::vector<LampGeometry> lampsHeap;
  double* num = numInline;
  LampGeometry* lamps = lampsInline;
  if (scene.planes.size() > kInline) {
    numHeap.resize(scene.planes.size());
    num = numHeap.data();
  }
  if (scene.lamps.size() > kInline) {
    lampsHeap.resize(scene.lamps.size());
    lamps = lampsHeap.data();
  }
  for (std::size_t k = 0; k < scene.planes.size(); ++k)
    num[k] = glm::dot(scene.planes[k].point_m - cam.position_m, scene.planes[k].normal);
  for (std::size_t k = 0; k < scene.lamps.size(); ++k) {
    const Lamp& l = scene.lamps[k].lamp;
    const auto* isoModel = std::get_if<IsotropicProfile>(&l.profile->model());
    LampGeometry& g = lamps[k];
    g.sx = l.position_m.x;
    g.sy = l.position_m.y;
    g.sz = l.position_m.z;
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) g.m[3 * c + r] = l.worldFromLamp[c][r];
    g.negKt = -scene.fog.extinction_per_m;
    g.isoIntensity = isoModel ? isoModel->intensity_cd : std::numeric_limits<double>::quiet_NaN();
    for (int c = 0; c < 3; ++c) g.colour[c] = l.color[c];
  }
  renderAll(scene, out, pool, num, lamps);
}

}  // namespace fogbeam
#endif
