#version 450 core
// fogbeam — airlight_accurate.frag: the accurate airlight method per pixel on the GPU (issue 7,
// "GPU airlight path"; docs/airlight.md, "GPU path"). A full-screen pass after the surface draws:
// it reads the surface pass's distance attachment directly, so the airlight needs no round trip
// through the CPU. The CPU twin is AirlightEvaluator (core/src/physics/airlight.cpp, method
// Accurate); the G moments are the same table (AirlightOptions), uploaded in float.
//
// Per pixel and lamp (Lecocq et al. 2001, eq. 3; notation of docs/physics.md):
//   L = Ω K_t e^{−K_t p} / h · ∫_{θ0}^{θd} G(k, θ) I(w(θ)) dθ,   k = K_t h,
//   w(θ) = cos θ · n + sin θ · ω,  θ0 = atan(−p/h),  θd = atan((d − p)/h) (π/2 for the sky).
// Product integration, as the CPU: G is integrated exactly through the cumulative moments
// T_q(k, θ) = ∫_{−π/2}^{θ} θ'^q G dθ' (cubic Hermite in θ, Catmull-Rom in k: GMomentTable);
// I is sampled as quadratics on pieces:
//   isotropic: no piece, I₀ (T_0(θd) − T_0(θ0));
//   spot: cut at the inner and outer cone crossings (closed form), a constant core, uPieces/8
//         quadratic pieces across the ring, nothing outside;
//   measured (tabulated): cut to the profile's support cone, uPieces equal pieces (the CPU also
//         cuts at the profile's feature lines, e.g. a low beam's cut-off; here the pieces are
//         finer instead).
// Within 1° of straight away from the lamp (θ0 > π/2 − 1°, detail::kAwayConeRad) the moments
// lose their precision; there the integral is taken directly in t = k tan(π/4 + θ/2), where
// G = e^{−t} p is smooth (32 Gauss–Legendre points). Lamps beyond 60 optical lengths from the eye
// are left out (their airlight is below e^{−60} I; e^{K_t |p|} must stay finite in float).
// Output: location 0: airlight, rgb [cd/m²]. Units: metres, radians, cd.
#include "common_photometry.glsl"

layout(binding = 1) uniform sampler2D uDistance;  // R32F: true distance along the ray [m], +inf for sky
// The table in double precision as two float textures, value = hi + lo: a ray that ends on a
// near surface spans a short θ range, and T_q(θd) − T_q(θ0) (and the moments about a piece's
// centre) is then a small difference of O(1) values, which float (6e-8) cannot resolve.
layout(binding = 2) uniform sampler2D uGMoments;    // RGBA32F, width nθ, height nK: T_0, T_1, T_2, G (hi)
layout(binding = 4) uniform sampler2D uGMomentsLo;  // the same, value − hi (lo)
layout(binding = 3) uniform sampler2D uGTheta;      // RG32F, width nθ, height 1: the θ nodes [rad], hi and lo
uniform int uGThetaN;
uniform int uGKN;
uniform float uGK0;       // k scale of the row coordinate
uniform float uGLogSpan;  // log1p(kMax / k0)
uniform float uGKMax;
uniform float uAlbedo;    // Ω
uniform int uPhaseKind;   // 0 isotropic, 1 Henyey–Greenstein, 2 fog-mie (HG + Draine blend)
uniform vec4 uPhase;      // HG: x = g; fog-mie: x = g_HG, y = g_D, z = α, w = blend weight
uniform int uPieces;      // quadratic pieces per ray, measured profiles
uniform mat3 uWorldFromCamera;  // columns: camera +x (view axis), +y (left), +z (up)
uniform vec3 uFocalPrincipal;   // (f, cx, H − cy) [px], principal point in window coordinates

layout(location = 0) out vec4 outAirlight;

// ---- phase functions (medium.cpp), normalised to 1 over the sphere ----
float hg(float g, float mu) { return (1.0 - g * g) / (4.0 * PI * pow(1.0 + g * g - 2.0 * g * mu, 1.5)); }
float phaseOf(float mu) {
  if (uPhaseKind == 1) return hg(uPhase.x, mu);
  if (uPhaseKind == 2) {
    float gD = uPhase.y, a = uPhase.z;
    float draine = hg(gD, mu) * (1.0 + a * mu * mu) / (1.0 + a * (1.0 + 2.0 * gD * gD) / 3.0);
    return (1.0 - uPhase.w) * hg(uPhase.x, mu) + uPhase.w * draine;
  }
  return 1.0 / (4.0 * PI);
}

// ---- the G-moment table (GMomentTable::kWeights, ::cumulative) ----
struct KWeights {
  ivec4 row;
  vec4 w;
};
KWeights kWeights(float k) {
  float u = log(1.0 + max(k, 0.0) / uGK0) / uGLogSpan * float(uGKN - 1);
  int i = clamp(int(u), 0, uGKN - 2);
  float t = clamp(u - float(i), 0.0, 1.0);
  float t2 = t * t, t3 = t2 * t;
  KWeights kw;
  kw.w = vec4(0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t),
              0.5 * (t3 - t2));
  kw.row = clamp(ivec4(i - 1, i, i + 1, i + 2), 0, uGKN - 1);
  return kw;
}

double thetaNode(int j) {
  vec2 t = texelFetch(uGTheta, ivec2(j, 0), 0).rg;
  return double(t.r) + double(t.g);
}
dvec4 gCell(int j, int row) {
  return dvec4(texelFetch(uGMoments, ivec2(j, row), 0)) + dvec4(texelFetch(uGMomentsLo, ivec2(j, row), 0));
}

// T_0, T_1, T_2 at θ (double: see uGMoments).
dvec3 cumulative(KWeights kw, double theta) {
  theta = clamp(theta, double(-HALF_PI), double(HALF_PI));
  float x = clamp(1.0 - 2.0 * (float(theta) + HALF_PI) / PI, -1.0, 1.0);
  int j = clamp(int(acos(x) / PI * float(uGThetaN - 1)), 0, uGThetaN - 2);
  double a = thetaNode(j), b = thetaNode(j + 1);
  // The node's cell from acos in float can be off by one near the ends: step to the right one.
  if (theta < a && j > 0) {
    --j;
    b = a;
    a = thetaNode(j);
  } else if (theta > b && j < uGThetaN - 2) {
    ++j;
    a = b;
    b = thetaNode(j + 1);
  }
  double dt = b - a;
  double s = dt > 0.0 ? clamp((theta - a) / dt, 0.0, 1.0) : 0.0;
  double s2 = s * s, s3 = s2 * s;
  double h00 = 2.0 * s3 - 3.0 * s2 + 1.0, h10 = (s3 - 2.0 * s2 + s) * dt, h01 = -2.0 * s3 + 3.0 * s2,
         h11 = (s3 - s2) * dt;
  dvec3 sum = dvec3(0.0);
  for (int r = 0; r < 4; ++r) {
    dvec4 c0 = gCell(j, kw.row[r]), c1 = gCell(j + 1, kw.row[r]);
    dvec3 da = c0.w * dvec3(1.0, a, a * a), db = c1.w * dvec3(1.0, b, b * b);  // dT_q/dθ = θ^q G
    sum += double(kw.w[r]) * (h00 * c0.xyz + h10 * da + h01 * c1.xyz + h11 * db);
  }
  return sum;
}

// ---- the integral along one ray ----
// The ray's great circle on the lamp's direction sphere: w(θ) = cos θ n + sin θ ω (world).
vec3 dirAt(vec3 n, vec3 om, float theta) { return cos(theta) * n + sin(theta) * om; }

// ∫ G Î over [a, b] in `pieces` quadratic pieces; the piece ends and moments in double, the
// intensities in float. Î goes through I at the piece's centre and at ±2/3 of its half-width
// (the CPU samples the ends): a breakpoint computed in float can be 1e-7 rad off, and a sample
// on the wrong side of a spot's hard edge would tilt the whole piece.
double piecewise(LampGpu L, KWeights kw, vec3 n, vec3 om, double a, double b, int pieces) {
  if (!(b > a)) return 0.0;
  double width = (b - a) / double(pieces), hw = 0.5 * width, off = hw * (2.0 / 3.0);
  dvec3 tPrev = cumulative(kw, a);
  double sum = 0.0;
  for (int s = 0; s < pieces; ++s) {
    double pb = (s + 1 == pieces) ? b : a + double(s + 1) * width;
    double pm = pb - hw;
    dvec3 tNext = cumulative(kw, pb);
    double i0 = lampIntensity(L, dirAt(n, om, float(pm - off)));
    double im = lampIntensity(L, dirAt(n, om, float(pm)));
    double i2 = lampIntensity(L, dirAt(n, om, float(pm + off)));
    dvec3 d = tNext - tPrev;
    double m0 = d.x, m1 = d.y - pm * d.x, m2 = d.z - 2.0 * pm * d.y + pm * pm * d.x;
    double c1 = (i2 - i0) / (2.0 * off), c2 = (i0 - 2.0 * im + i2) / (2.0 * off * off);
    sum += im * m0 + c1 * m1 + c2 * m2;
    tPrev = tNext;
  }
  return sum;
}

// Where the ray's great circle crosses the cone w·x = cos ψ about the lamp axis x (lamp frame):
// w·x = R cos(θ − φ), R = |(n·x, ω·x)|. Appends the crossings inside (a, b) to bp.
void coneCrossings(float nx, float ox, float cosPsi, float a, float b, inout float bp[8], inout int count) {
  float R = length(vec2(nx, ox));
  if (R <= 1e-7 || abs(cosPsi) > R) return;
  float phi = atan(ox, nx), halfAngle = acos(clamp(cosPsi / R, -1.0, 1.0));
  for (int sgn = -1; sgn <= 1; sgn += 2)
    for (int wrap = -1; wrap <= 1; ++wrap) {
      float th = phi + float(sgn) * halfAngle + float(wrap) * TWO_PI;
      if (th > a && th < b && count < 8) bp[count++] = th;
    }
}

// The integral of the direct form in t = k tan(π/4 + θ/2) (θ = π/2 − 2 atan(k/t),
// dθ = 2k/(k² + t²) dt, G = e^{−t} p(−sin θ)): 32 Gauss–Legendre points on [t(θ0), t(θd)]
// (the exponential has fallen below e^{−40} beyond t(θ0) + 40).
const float GL16_X[8] = float[8](0.0950125098, 0.2816035508, 0.4580167777, 0.6178762444, 0.7554044084, 0.8656312024,
                                 0.9445750231, 0.9894009350);
const float GL16_W[8] = float[8](0.1894506105, 0.1826034150, 0.1691565194, 0.1495959888, 0.1246289713, 0.0951585117,
                                 0.0622535239, 0.0271524594);
float directAway(LampGpu L, float k, vec3 n, vec3 om, float th0, float thD) {
  float t0 = k * tan(0.25 * PI + 0.5 * th0);
  float t1 = thD >= HALF_PI ? t0 + 40.0 : min(k * tan(0.25 * PI + 0.5 * thD), t0 + 40.0);
  if (!(t1 > t0)) return 0.0;
  float sum = 0.0;
  for (int panel = 0; panel < 2; ++panel) {
    float lo = mix(t0, t1, 0.5 * float(panel)), hi = mix(t0, t1, 0.5 * float(panel + 1));
    float c = 0.5 * (lo + hi), r = 0.5 * (hi - lo);
    for (int i = 0; i < 16; ++i) {
      float x = i < 8 ? -GL16_X[7 - i] : GL16_X[i - 8];
      float wgt = i < 8 ? GL16_W[7 - i] : GL16_W[i - 8];
      float t = c + r * x;
      float s = k * k + t * t;
      float theta = HALF_PI - 2.0 * atan(k, t);
      sum += r * wgt * exp(-t) * phaseOf((k * k - t * t) / s) * lampIntensity(L, dirAt(n, om, theta)) * 2.0 * k / s;
    }
  }
  return sum;
}

void main() {
  ivec2 px = ivec2(gl_FragCoord.xy);
  float d = texelFetch(uDistance, px, 0).r;
  vec3 acc = vec3(0.0);
  if (d > 0.0) {
    vec3 local = vec3(uFocalPrincipal.x, uFocalPrincipal.y - gl_FragCoord.x, gl_FragCoord.y - uFocalPrincipal.z);
    vec3 om = normalize(uWorldFromCamera * local);  // ray direction (world)
    for (int l = 0; l < uLampCount; ++l) {
      LampGpu L = lamps[l];
      vec3 S = L.position.xyz;  // lamp − eye
      if (uExtinction * length(S) > 60.0) continue;
      float p = dot(S, om);
      // h from the cross product (|S|² − p² cancels in float for rays that graze the lamp).
      float h = max(length(cross(S, om)), 1e-6);
      vec3 foot = p * om - S;
      float fl = length(foot);
      vec3 n = fl > 1e-9 ? foot / fl : normalize(cross(om, abs(om.z) < 0.9 ? vec3(0.0, 0.0, 1.0) : vec3(1.0, 0.0, 0.0)));
      float k = uExtinction * h;
      float th0 = atan(-p, h);
      float thD = isinf(d) ? HALF_PI : atan(d - p, h);
      if (!(thD > th0) || k > uGKMax) continue;
      double integral = 0.0;
      if (th0 > HALF_PI - 0.0175) {
        integral = directAway(L, k, n, om, th0, thD);
      } else if (L.kind.x == KIND_ISOTROPIC) {
        KWeights kw = kWeights(k);
        integral = double(L.params.x) * (cumulative(kw, double(thD)).x - cumulative(kw, double(th0)).x);
      } else {
        KWeights kw = kWeights(k);
        // Directions along the circle in the lamp frame: w·x = cos θ (n·x) + sin θ (ω·x).
        float nx = dot(L.axisX.xyz, n), ox = dot(L.axisX.xyz, om);
        float bp[8];
        int count = 0;
        bp[count++] = th0;
        if (L.kind.x == KIND_SPOT) {
          coneCrossings(nx, ox, cos(L.params.y), th0, thD, bp, count);
          coneCrossings(nx, ox, cos(L.params.z), th0, thD, bp, count);
        } else if (L.params.w < PI) {
          coneCrossings(nx, ox, cos(L.params.w), th0, thD, bp, count);
        }
        if (count < 8) bp[count++] = thD;
        // Sort the few breakpoints (insertion). Written without a short-circuit `j > 0 &&
        // bp[j − 1] > bp[j]` loop condition and swaps: Mesa 22's llvmpipe compiled that form
        // into duplicated entries (seen on this shader: a spot's inner-cone crossings vanished).
        for (int i = 1; i < count; ++i) {
          float v = bp[i];
          int j = i;
          for (; j > 0; --j) {
            if (bp[j - 1] <= v) break;
            bp[j] = bp[j - 1];
          }
          bp[j] = v;
        }
        float cosLimit = L.kind.x == KIND_SPOT ? cos(L.params.z) : cos(L.params.w);
        for (int i = 1; i < count; ++i) {
          float a = bp[i - 1], b = bp[i];
          if (!(b > a)) continue;
          float mid = 0.5 * (a + b);
          if (cos(mid) * nx + sin(mid) * ox < cosLimit) continue;  // outside the cone: I = 0
          int pieces = uPieces;
          if (L.kind.x == KIND_SPOT) {
            float psi = acos(clamp(cos(mid) * nx + sin(mid) * ox, -1.0, 1.0));
            pieces = psi <= L.params.y ? 1 : max(2, uPieces / 8);  // core: constant
          }
          integral += piecewise(L, kw, n, om, double(a), double(b), pieces);
        }
      }
      acc += L.color.rgb * (uAlbedo * uExtinction / h * exp(-uExtinction * p) * float(integral));
    }
  }
  outAirlight = vec4(acc, 1.0);
}
