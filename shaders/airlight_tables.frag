#version 450 core
// fogbeam — airlight_tables.frag: the accurate method's per-pixel table formula as a full-screen
// fragment shader (GlAirlightPass; the CPU twin is core/src/render/airlight_kernels*.cpp).
//
// Per pixel (image x right, y down; camera frame x forward, y left, z up):
//   isotropic lamps   L = w · e^{−K_t p}/h · [F(k, ζ(q_d)) − F(k, ζ(q_0))]   (Lecocq et al. 2001,
//                     eq. 3, with the Sun et al. 2005 F table; k = K_t h, q = tan θ; the row of k
//                     on the table's pseudo-log axis read off the float's bits); against the sky
//                     L = w · S(x) / sin γ from the lamp's sky table (x the half-chord to the
//                     lamp's direction or its opposite: airlight_kernels.hpp, IsoSky)
//   vehicle lamps     L = bilinear over view directions × cubic Hermite over x = d/(d + D)
// Output: RGB airlight in cd/m² (linear), A unused. Distances in metres, +inf for the sky.
// Pixels inside a vehicle lamp's last guard disc (about 2 px at 1080p) are evaluated per ray
// on the CPU; here they read the finest inset table (the host knows which pixels those are).

layout(location = 0) out vec4 fragColor;

uniform vec2 uPrincipal;       // principal point (image centre unless off-axis), pixels, x right, y down
uniform float uInvF;        // 1 / focal length, 1/pixels
uniform int uHeight;        // image height, pixels
layout(binding = 0) uniform sampler2D uDistance;  // R32F, row 0 = image row 0

// F table: nK rows × nZ columns, R32F.
layout(binding = 1) uniform sampler2D uIso;
uniform int uIsoNK;
uniform int uIsoNZ;
uniform float uIsoK0;
uniform float uIsoUScale;
const int kMaxIso = 32;
uniform int uIsoCount;
uniform vec4 uIsoPos[kMaxIso];     // xyz: lamp − eye (camera frame, m); w: K_t (1/m)
uniform vec3 uIsoWeight[kMaxIso];  // Ω K_t I × colour
uniform vec3 uIsoDir[kMaxIso];     // unit vector eye → lamp
// Sky tables: one row of 2 · uIsoSkyNodes values per lamp (R32F; NaN: the lamp has none).
layout(binding = 8) uniform sampler2D uIsoSky;
uniform int uIsoSkyNodes;

// View tables: RG32F 3D textures, x = distance node, y = a node, z = b node.
const int kMaxView = 6;
uniform int uViewCount;
layout(binding = 2) uniform sampler3D uView[kMaxView];
uniform vec4 uViewGrid[kMaxView];   // a0, b0, 1/step, D
uniform ivec3 uViewSize[kMaxView];  // nA, nB, nX
uniform vec4 uViewGuard[kMaxView];  // guard a, guard b, inner r², outer r²
uniform vec3 uViewWeight[kMaxView];

// Node coordinate g → (index, fraction) clamped to [0, n − 2] × [0, 1].
void cell(float g, int n, out int i, out float t) {
  float gc = clamp(g, 0.0, float(n - 1));
  float fl = min(floor(gc), float(n - 2));
  i = int(fl);
  t = gc - fl;
}

float zetaNode(float q) {
  float z = isinf(q) ? 1.0 : 1.0 - 1.0 / sqrt(1.0 + abs(q));
  return (sign(q) * z + 1.0) * 0.5 * float(uIsoNZ - 1);
}

float isoF(int iu, float tu, float gz) {
  int iz;
  float tz;
  cell(gz, uIsoNZ, iz, tz);
  float a0 = texelFetch(uIso, ivec2(iz, iu), 0).r, a1 = texelFetch(uIso, ivec2(iz + 1, iu), 0).r;
  float b0 = texelFetch(uIso, ivec2(iz, iu + 1), 0).r, b1 = texelFetch(uIso, ivec2(iz + 1, iu + 1), 0).r;
  float a = mix(a0, a1, tz), b = mix(b0, b1, tz);
  return mix(a, b, tu);
}

// L / w of a sky ray (unit direction wv) from lamp l's sky table; -1 when it has none.
float isoSky(int l, vec3 wv) {
  vec3 e = uIsoDir[l];
  bool behind = dot(wv, e) < 0.0;
  vec3 v = wv - (behind ? -e : e);
  float x = 0.5 * length(v);
  int i;
  float t;
  cell(x * (float(uIsoSkyNodes - 1) / 0.70710678118654752440), uIsoSkyNodes, i, t);
  if (behind) i += uIsoSkyNodes;
  float s0 = texelFetch(uIsoSky, ivec2(i, l), 0).r;
  if (isnan(s0)) return -1.0;
  float s1 = texelFetch(uIsoSky, ivec2(i + 1, l), 0).r;
  float sinG = max(2.0 * x * sqrt(max(1.0 - x * x, 0.0)), 1e-7);
  return mix(s0, s1, t) / sinG;
}

float hermite(float t, vec2 n0, vec2 n1) {  // n = (value, slope · cell)
  float t2 = t * t, t3 = t2 * t;
  float h01 = 3.0 * t2 - 2.0 * t3;
  return (1.0 - h01) * n0.x + (t3 - 2.0 * t2 + t) * n0.y + h01 * n1.x + (t3 - t2) * n1.y;
}

void main() {
  float x = gl_FragCoord.x;
  float y = float(uHeight) - gl_FragCoord.y;  // image y (down), pixel centre at j + 0.5
  int j = int(y);
  float dist = texelFetch(uDistance, ivec2(int(x), j), 0).r;
  vec3 acc = vec3(0.0);
  if (dist > 0.0) {
    float a = (uPrincipal.x - x) * uInvF, b = (uPrincipal.y - y) * uInvF;
    float invLen = inversesqrt(1.0 + a * a + b * b);
    for (int l = 0; l < uIsoCount; ++l) {
      if (isinf(dist)) {
        float ls = isoSky(l, vec3(1.0, a, b) * invLen);
        if (ls >= 0.0) {
          acc += ls * uIsoWeight[l];
          continue;
        }
      }
      vec3 L = uIsoPos[l].xyz;
      float kt = uIsoPos[l].w;
      float p = (L.x + a * L.y + b * L.z) * invLen;
      vec3 c = vec3(L.y * b - L.z * a, L.z - L.x * b, L.x * a - L.y);
      float h = max(length(c) * invLen, 1e-6);
      int iu;
      float tu;
      cell(float(floatBitsToInt(1.0 + kt * h / uIsoK0) - 0x3F800000) * (uIsoUScale / 8388608.0), uIsoNK, iu, tu);
      float f0 = isoF(iu, tu, zetaNode(-p / h));
      float fd = isoF(iu, tu, isinf(dist) ? float(uIsoNZ - 1) : zetaNode((dist - p) / h));
      float lm = max(exp(-kt * p) / h * (fd - f0), 0.0);
      acc += lm * uIsoWeight[l];
    }
    for (int v = 0; v < uViewCount; ++v) {
      vec2 g = vec2(a, b) - uViewGuard[v].xy;
      float r2 = dot(g, g);
      if (r2 <= uViewGuard[v].z || r2 > uViewGuard[v].w) continue;
      int ia, ib, ix;
      float ta, tb, tx;
      cell((a - uViewGrid[v].x) * uViewGrid[v].z, uViewSize[v].x, ia, ta);
      cell((b - uViewGrid[v].y) * uViewGrid[v].z, uViewSize[v].y, ib, tb);
      float xs = isinf(dist) ? 1.0 : dist / (dist + uViewGrid[v].w);
      cell(xs * float(uViewSize[v].z - 1), uViewSize[v].z, ix, tx);
      float l00 = hermite(tx, texelFetch(uView[v], ivec3(ix, ia, ib), 0).rg, texelFetch(uView[v], ivec3(ix + 1, ia, ib), 0).rg);
      float l10 = hermite(tx, texelFetch(uView[v], ivec3(ix, ia + 1, ib), 0).rg, texelFetch(uView[v], ivec3(ix + 1, ia + 1, ib), 0).rg);
      float l01 = hermite(tx, texelFetch(uView[v], ivec3(ix, ia, ib + 1), 0).rg, texelFetch(uView[v], ivec3(ix + 1, ia, ib + 1), 0).rg);
      float l11 = hermite(tx, texelFetch(uView[v], ivec3(ix, ia + 1, ib + 1), 0).rg,
                          texelFetch(uView[v], ivec3(ix + 1, ia + 1, ib + 1), 0).rg);
      float lm = max(mix(mix(l00, l10, ta), mix(l01, l11, ta), tb), 0.0);
      acc += lm * uViewWeight[v];
    }
  }
  fragColor = vec4(acc, 1.0);
}
