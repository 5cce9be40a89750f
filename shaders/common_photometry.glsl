// fogbeam — common_photometry.glsl: lamp intensity I(w) and Lambertian surface luminance.
// Included by surface_*.frag (after their #version line). Units: metres, radians, candela,
// lux, cd/m². Positions are relative to the camera (world axes: x forward, y left, z up), so
// that single precision keeps millimetres at kilometres from the world origin.
//
//   E = I(w) · cos(incidence) · e^{−K_t r} / r²            [lux]   per lamp, w = (X − S)/r
//   L(S) = ρ/π · Σ_lamps colour · E                         [cd/m²] Lambertian
//   L_s = L(S) · e^{−K_t d} + I_a · (1 − e^{−K_t d})         [cd/m²] seen through fog at distance d
//
// I(w) is evaluated in the lamp frame (+x photometric axis, +y left, +z up):
//   isotropic: I₀;  spot: I₀ for ψ ≤ inner, I₀ (outer − ψ)/(outer − inner) to 0 at outer
//   (ψ = angle from +x);  tabulated: the file's (h, v) angles of w for type A/B/C, symmetry
//   folding, then bilinear interpolation on the file's own grid — the same as
//   TabulatedProfile::atAngles (core/src/physics/profile.cpp), so cut-offs are exactly where the
//   file puts them. The grid is uploaded unresampled in a buffer texture (R32F):
//   [h angles (nh)] [v angles (nv)] [candela (nh × nv), candela[ih·nv + iv]].

const float PI = 3.14159265358979;
const float TWO_PI = 6.28318530717959;
const float HALF_PI = 1.57079632679490;

const int KIND_ISOTROPIC = 0;
const int KIND_SPOT = 1;
const int KIND_TABULATED = 2;
const int TYPE_A = 0;
const int TYPE_B = 1;
const int TYPE_C = 2;
const int SYM_NONE = 0;
const int SYM_ROTATIONAL = 1;
const int SYM_QUADRANT = 2;
const int SYM_HALF_0_180 = 3;
const int SYM_HALF_90_270 = 4;
const int SYM_MIRROR_H = 5;

struct LampGpu {
  vec4 position;  // xyz: lamp position relative to the camera [m]
  vec4 axisX;     // xyz: lamp +x (photometric axis) in world
  vec4 axisY;     // xyz: lamp +y in world
  vec4 axisZ;     // xyz: lamp +z in world
  vec4 color;     // rgb: linear colour weights
  vec4 params;    // x: I₀ [cd] (isotropic, spot peak) or scale (tabulated); y: inner, z: outer [rad];
                  // w: tabulated: half-angle of the cone about the axis outside which I = 0 [rad]
  ivec4 kind;     // x: KIND_*, y: TYPE_*, z: SYM_*
  ivec4 table;    // x: offset of the h angles in uProfileData, y: nh, z: nv
};

layout(std430, binding = 0) readonly buffer Lamps { LampGpu lamps[]; };
uniform int uLampCount;      // lamps used (the buffer holds at least one entry)
layout(binding = 0) uniform samplerBuffer uProfileData;  // R32F: angles [rad], candela [cd]
uniform float uExtinction;  // K_t [1/m]
uniform float uAmbient;     // I_a [cd/m²]

float profileValue(int i) { return texelFetch(uProfileData, i).r; }

// Position of x in the ascending grid g[off .. off+n): the largest i ≤ n − 2 with g[i] ≤ x and
// the weight t of g[i+1]. False outside [g₀, g_{n−1}] (1e-6 rad of slack for rounding).
bool locateGrid(int off, int n, float x, out int i, out float t) {
  i = 0;
  t = 0.0;
  if (n == 1) return abs(x - profileValue(off)) < 1e-6;
  if (x < profileValue(off) - 1e-6 || x > profileValue(off + n - 1) + 1e-6) return false;
  int lo = 0, hi = n - 1;
  while (hi - lo > 1) {
    int mid = (lo + hi) / 2;
    if (profileValue(off + mid) <= x) lo = mid; else hi = mid;
  }
  i = lo;
  float a = profileValue(off + lo), b = profileValue(off + lo + 1);
  t = b > a ? clamp((x - a) / (b - a), 0.0, 1.0) : 0.0;
  return true;
}

// Folds a type C plane angle into the range the data cover (see foldTypeC in profile.cpp).
float foldTypeC(float c, int sym) {
  c = mod(c, TWO_PI);
  if (sym == SYM_QUADRANT) {
    if (c > PI) c = TWO_PI - c;
    if (c > HALF_PI) c = PI - c;
  } else if (sym == SYM_HALF_0_180) {
    if (c > PI) c = TWO_PI - c;
  } else if (sym == SYM_HALF_90_270) {
    if (c < HALF_PI) c = PI - c;
    else if (c > 1.5 * PI) c = 3.0 * PI - c;
  }
  return c;
}

// atan(y, x) that is 0 where GLSL leaves it undefined (x = y = 0).
float atan2Safe(float y, float x) { return (x == 0.0 && y == 0.0) ? 0.0 : atan(y, x); }

float tabulatedIntensity(LampGpu L, vec3 w) {
  int type = L.kind.y, sym = L.kind.z;
  int offH = L.table.x, nh = L.table.y, nv = L.table.z;
  int offV = offH + nh, offC = offV + nv;
  float h, v;
  if (type == TYPE_C) {         // C about +x from +y towards +z; γ from +x
    h = atan2Safe(w.z, w.y);
    v = atan(length(w.yz), w.x);
  } else if (type == TYPE_B) {  // H positive to the right (−y); V about y, positive up
    h = atan(-w.y, length(w.xz));
    v = atan2Safe(w.z, w.x);
  } else {                      // type A: H about z, positive right; V elevation
    h = atan2Safe(-w.y, w.x);
    v = atan(w.z, length(w.xy));
  }
  int iv;
  float tv;
  if (!locateGrid(offV, nv, v, iv, tv)) return 0.0;
  int iv1 = min(iv + 1, nv - 1);
  int ih0 = 0, ih1 = 0;
  float th = 0.0;
  if (!(nh == 1 || sym == SYM_ROTATIONAL)) {
    float hFirst = profileValue(offH), hLast = profileValue(offH + nh - 1);
    bool located = false;
    if (type == TYPE_C) {
      h = foldTypeC(h, sym);
      if (sym == SYM_NONE && (h > hLast || h < hFirst)) {  // between the last plane and the first + 360°
        float span = hFirst + TWO_PI - hLast;
        ih0 = nh - 1;
        ih1 = 0;
        th = span > 0.0 ? ((h > hLast ? h : h + TWO_PI) - hLast) / span : 0.0;
        located = true;
      }
    } else if (sym == SYM_MIRROR_H) {
      h = abs(h);
    }
    if (!located) {
      if (!locateGrid(offH, nh, h, ih0, th)) return 0.0;
      ih1 = min(ih0 + 1, nh - 1);
    }
  }
  float r0 = mix(profileValue(offC + ih0 * nv + iv), profileValue(offC + ih0 * nv + iv1), tv);
  float r1 = mix(profileValue(offC + ih1 * nv + iv), profileValue(offC + ih1 * nv + iv1), tv);
  return mix(r0, r1, th);
}

// I(w) [cd] of lamp L towards the unit world direction wWorld.
float lampIntensity(LampGpu L, vec3 wWorld) {
  vec3 w = vec3(dot(L.axisX.xyz, wWorld), dot(L.axisY.xyz, wWorld), dot(L.axisZ.xyz, wWorld));
  if (L.kind.x == KIND_ISOTROPIC) return L.params.x;
  if (L.kind.x == KIND_SPOT) {
    float psi = atan(length(w.yz), w.x);  // accurate near the axis, unlike acos(w.x)
    if (psi <= L.params.y) return L.params.x;
    if (psi >= L.params.z) return 0.0;
    return L.params.x * (L.params.z - psi) / (L.params.z - L.params.y);
  }
  return L.params.x * tabulatedIntensity(L, w);
}

// The fog's scattered light on a surface element (render/fog_light.hpp; the CPU's
// FogLightTable::weighted and AnnulusMeanMap::lookup, per pixel here where the CPU blends them
// over an adaptive grid): E_fog = Σ_q b_q(μ) s_q + d_q(μ) D_q · n lux, b = (1, μ, two smoothed
// ramps), d = (1, three smoothed steps) (fogLightBasis), μ = cos(incidence), s the lamp's
// coefficients at optical distance T = K_t r: K_t² Σ_k Ī_k c_kq(T), and D_q = K_t² Σ_k Ī₁_k g_kq(T)
// its dipoles (Ī_k, Ī₁_k the lamp's annulus means and first harmonics about its direction to the
// point). uFogData (RGBA32F, a texel = 4 floats): the dense table [row][bin][2 texels] (c0 … c3,
// g0 … g3) from texel 0 (rows at T = 2^(−7 + i/16) up to 1, then every 1/16 to 32), its sums of
// the c over the bins [row][1 texel] from texel uFogSums, then the lamps' annulus maps
// (LampGpu.table.w, in texels; −1: an isotropic lamp, I₀ = params.x): rows of the angle from the
// lamp's axis every 0.5° to 24°, then every 3°; uFogMapColumns azimuths every 3°; uFogBins texels
// each (the mean, the harmonic in the lamp frame). uFogBins = 0: off. Whole texels: one fetch
// where scalar R32F texels took four (the fog light's shading time, docs/surface_pass.md).
layout(binding = 5) uniform samplerBuffer uFogData;
uniform int uFogBins;
uniform int uFogSums;
uniform int uFogMapRows;
uniform int uFogMapColumns;
const int FOG_DENSE_LOG = 112;
const int FOG_DENSE_NODES = 609;
const float FOG_T_FIRST = 0.0078125;
const float FOG_T_LAST = 32.0;
const float FOG_DEG = 0.0174532925199433;
// AnnulusMeanMap::kFineDeg, kFineRows: rows every 0.5° up to 24°.
const float FOG_FINE = 0.5 * FOG_DEG;
const float FOG_FINE_ROWS = 48.0;
const float FOG_FINE_END = FOG_FINE_ROWS * FOG_FINE;
// fogLightBasis's widths: kFogRampWidth, kFogStepWidth.
const vec2 FOG_RAMP = vec2(0.01, 0.1);
const vec3 FOG_STEP = vec3(0.3, 0.005, 0.04);

vec4 fogTexel(int i) { return texelFetch(uFogData, i); }

// E_fog [lux] of lamp L at distance r [m] from the point, wWorld the unit direction from the lamp
// to the point, mu the cosine of the incidence (any sign: the fog lights both sides), n the
// element's unit normal (world).
float fogLight(LampGpu L, vec3 wWorld, float r, float mu, vec3 n) {
  float T = uExtinction * r;
  if (uFogBins == 0 || !(T > 0.0) || T > FOG_T_LAST) return 0.0;
  float x = T < 1.0 ? max(0.0, (log2(T) + 7.0) * 16.0) : float(FOG_DENSE_LOG) + (T - 1.0) * 16.0;
  int i0 = min(int(x), FOG_DENSE_NODES - 2);
  float t = min(x - float(i0), 1.0);
  vec4 s = vec4(0.0);
  vec4 dn = vec4(0.0);  // D_q · n, q = 0 … 3 (lamp frame, before the K_t² scale)
  int map = L.table.w;
  if (map < 0) {
    s = L.params.x * mix(fogTexel(uFogSums + i0), fogTexel(uFogSums + i0 + 1), t);
  } else {
    vec3 w = vec3(dot(L.axisX.xyz, wWorld), dot(L.axisY.xyz, wWorld), dot(L.axisZ.xyz, wWorld));
    vec3 nl = vec3(dot(L.axisX.xyz, n), dot(L.axisY.xyz, n), dot(L.axisZ.xyz, n));
    float alpha = atan(length(w.yz), w.x);
    float beta = atan2Safe(w.z, w.y);
    if (beta < 0.0) beta += TWO_PI;
    float row = alpha < FOG_FINE_END ? alpha / FOG_FINE : FOG_FINE_ROWS + (alpha - FOG_FINE_END) / (3.0 * FOG_DEG);
    float col = beta / (3.0 * FOG_DEG);
    row = clamp(row, 0.0, float(uFogMapRows - 1));
    col = clamp(col, 0.0, float(uFogMapColumns - 1));
    int ia = min(int(row), uFogMapRows - 2), ib = min(int(col), uFogMapColumns - 2);
    float u = row - float(ia), v = col - float(ib);
    int node = uFogBins;  // texels per map node
    int p00 = map + (ia * uFogMapColumns + ib) * node;
    int p10 = p00 + uFogMapColumns * node;
    int ra = i0 * uFogBins * 2, rb = ra + uFogBins * 2;
    for (int k = 0; k < uFogBins; ++k) {
      vec4 m = (1.0 - u) * ((1.0 - v) * fogTexel(p00 + k) + v * fogTexel(p00 + node + k)) +
               u * ((1.0 - v) * fogTexel(p10 + k) + v * fogTexel(p10 + node + k));
      vec3 h = m.yzw - dot(m.yzw, w) * w;  // perpendicular to w, as AnnulusMeanMap::lookup
      s += m.x * mix(fogTexel(ra + 2 * k), fogTexel(rb + 2 * k), t);
      dn += dot(h, nl) * mix(fogTexel(ra + 2 * k + 1), fogTexel(rb + 2 * k + 1), t);
    }
  }
  float scale = uExtinction * uExtinction * (T < FOG_T_FIRST ? FOG_T_FIRST / T : 1.0);
  float mu2 = mu * mu;
  vec4 b = vec4(1.0, mu, 0.5 * (mu + sqrt(mu2 + FOG_RAMP.x * FOG_RAMP.x)), 0.5 * (mu + sqrt(mu2 + FOG_RAMP.y * FOG_RAMP.y)));
  vec4 d = vec4(1.0, mu / sqrt(mu2 + FOG_STEP.x * FOG_STEP.x), mu / sqrt(mu2 + FOG_STEP.y * FOG_STEP.y),
                mu / sqrt(mu2 + FOG_STEP.z * FOG_STEP.z));
  return max(scale * (dot(b, s) + dot(d, dn)), 0.0);
}

// L(S) [cd/m², rgb] of a Lambertian point p (camera-relative, m) with unit normal n facing the
// viewer and reflectance rho, lit by every lamp through fog (no shadows), and by the fog's
// scattered light where uFogBins > 0.
vec3 surfaceLuminance(vec3 p, vec3 n, vec3 rho) {
  vec3 sum = vec3(0.0);
  for (int k = 0; k < uLampCount; ++k) {
    vec3 toPoint = p - lamps[k].position.xyz;
    float r2 = dot(toPoint, toPoint);
    if (r2 <= 0.0) continue;
    float r = sqrt(r2);
    vec3 w = toPoint / r;
    float cosInc = -dot(w, n);  // light arrives against the normal
    float e = fogLight(lamps[k], w, r, cosInc, n);  // lux
    if (cosInc > 0.0) e += lampIntensity(lamps[k], w) * cosInc * exp(-uExtinction * r) / r2;
    sum += lamps[k].color.rgb * e;
  }
  return rho / PI * sum;
}

// L_s [cd/m²]: surface luminance seen through fog at distance d plus ambient in-scatter.
vec3 viewedThroughFog(vec3 surface, float d) {
  float T = exp(-uExtinction * d);
  return surface * T + vec3(uAmbient * (1.0 - T));
}

// Depth-buffer value for the true distance d [m]: 1/(1 + d), compared with GL_GREATER on a
// 32-bit float depth buffer (relative precision ≈ 1e-7 at every distance; 0 = sky).
float depthFromDistance(float d) { return 1.0 / (1.0 + d); }

// The ray through the centre of the pixel at window coordinates `frag` (gl_FragCoord.xy, y up),
// in the camera frame and not normalised, as Camera::rayDirection builds it:
//   local = (f, cx − x, cy − y_down) = (f, cx − frag.x, frag.y − (H − cy)),
// with focalPrincipal = (f, cx, H − cy) [px]. In double: surface_plane.frag intersects planes
// with it in double precision (distances within ~1e-7 relative near the horizon).
dvec3 pixelRayLocal(dvec3 focalPrincipal, dvec2 frag) {
  return dvec3(focalPrincipal.x, focalPrincipal.y - frag.x, frag.y - focalPrincipal.z);
}
