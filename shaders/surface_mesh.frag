#version 450 core
// fogbeam — surface_mesh.frag: Lambertian glTF surfaces. Units: metres, cd/m².
//   d = |p| (p: camera-relative surface point, interpolated perspective-correctly at the pixel
//   centre, so it lies on the pixel's ray), n = the shading normal turned to face the eye,
//   L_s = L(S) e^{−K_t d} + I_a (1 − e^{−K_t d}) with L(S) = ρ/π Σ colour · I(w) cos(inc) e^{−K_t r}/r².
// Outputs: location 0 L_s [cd/m², rgb; a = 1], location 1 d [m]; depth 1/(1 + d) (GL_GREATER).
// With FOGBEAM_GBUFFER (shading on the CPU): location 0 (n, ρ red), location 2 (ρ green, blue).
#include "common_photometry.glsl"

in vec3 vPosition;
in vec3 vNormal;
in vec3 vReflectance;

layout(location = 0) out vec4 outLuminance;  // FOGBEAM_GBUFFER: (n, ρ red)
layout(location = 1) out float outDistance;
#ifdef FOGBEAM_GBUFFER
layout(location = 2) out vec2 outRhoGB;       // ρ green, blue
#endif

void main() {
  float d = length(vPosition);
  vec3 n = normalize(vNormal);
  if (dot(n, vPosition) > 0.0) n = -n;  // two-sided: the side facing the eye
#ifdef FOGBEAM_GBUFFER
  // Deferred: the CPU lights the pixel (render/surface_shading.hpp) from its normal, ρ and d.
  outLuminance = vec4(n, vReflectance.r);
  outRhoGB = vReflectance.gb;
#else
  vec3 ls = surfaceLuminance(vPosition, n, vReflectance);
  outLuminance = vec4(viewedThroughFog(ls, d), 1.0);
#endif
  outDistance = d;
  gl_FragDepth = depthFromDistance(d);
}
