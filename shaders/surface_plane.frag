#version 450 core
// fogbeam — surface_plane.frag: infinite planes by ray–plane intersection per pixel, into the
// geometry buffer. Units: metres. The ray of pixel (i, j) goes through its centre, as Camera::rayDirection:
//   ω = normalize(worldFromCamera · pixelRayLocal(...))   (common_photometry.glsl)
// with (cx, cy) the principal point in image pixels (x right, y down; (W/2, H/2) when centred).
// Plane n·(X − P₀) = 0 with c = n·(P₀ − O) (camera-relative): t = c / (n·ω), the nearest t > 0 wins.
// The ray and t are computed in double precision so that the distance stays within ~1e-7
// relative even at grazing incidence near the horizon. Outputs (nothing is lit here:
// surface_deferred.frag or the CPU's SurfaceShader lights them, docs/surface_pass.md):
//   location 0: the normal facing the eye, ρ red;  location 2: ρ green, blue
//   location 1: t, the true distance along the ray [m]
// Pixels where no plane is hit are discarded (they keep the sky clear values: +inf).
#include "common_photometry.glsl"

struct PlaneGpu {
  dvec4 normalOffset;  // xyz: unit normal n (world), w: c = n·(P₀ − O) [m]
  dvec4 reflectance;   // x: ρ
};
layout(std430, binding = 1) readonly buffer Planes { PlaneGpu planes[]; };
uniform int uPlaneCount;

uniform dmat3 uWorldFromCamera;  // columns: camera +x (view axis), +y (left), +z (up)
uniform dvec3 uFocalPrincipal;   // (f, cx, H − cy) [px]: principal point in window coordinates (y up)

layout(location = 0) out vec4 outNormalRho;  // (n, ρ red)
layout(location = 1) out float outDistance;
layout(location = 2) out vec2 outRhoGB;       // ρ green, blue

void main() {
  dvec3 d = normalize(uWorldFromCamera * pixelRayLocal(uFocalPrincipal, dvec2(gl_FragCoord.xy)));
  double best = 1.0e300LF;
  int hit = -1;
  for (int k = 0; k < uPlaneCount; ++k) {
    double denom = dot(d, planes[k].normalOffset.xyz);
    if (abs(denom) < 1e-12) continue;
    double t = planes[k].normalOffset.w / denom;
    if (t > 0.0 && t < best) {
      best = t;
      hit = k;
    }
  }
  if (hit < 0) discard;
  vec3 n = vec3(planes[hit].normalOffset.xyz);
  vec3 dir = vec3(d);
  if (dot(n, dir) > 0.0) n = -n;  // the side facing the eye
  float t = float(best);
  float rho = float(planes[hit].reflectance.x);
  outNormalRho = vec4(n, rho);
  outRhoGB = vec2(rho, rho);
  outDistance = t;
  gl_FragDepth = depthFromDistance(t);
}
