#version 450 core
// fogbeam — surface_deferred.frag: lights the geometry buffer once per pixel (GPU shading).
// The planes and glTF triangles write, per pixel, only what lighting needs (their FOGBEAM_GBUFFER
// variant: the normal facing the eye and ρ red in uGNormalRho, ρ green and blue in uGRhoGB, the
// true distance d in uGDistance, +inf for the sky); this full-screen pass then evaluates
//   L_s = L(S) e^{−K_t d} + I_a (1 − e^{−K_t d}),  L(S) = ρ/π Σ colour · (I(w) cos(inc) e^{−K_t r}/r² + E_fog)
// at the point p = d · ray(pixel) (camera-relative, metres). Why not in the geometry shaders:
// they write gl_FragDepth (the depth is 1/(1 + d), not the rasteriser's), which turns off early
// depth testing, so every fragment of every overlapping triangle was lit, the hidden ones too;
// here each visible pixel is lit exactly once (docs/surface_pass.md, "Shading in GL").
// Outputs: location 0 L_s [cd/m², rgb; a = 1 on surfaces, 0 on the sky].
#include "common_photometry.glsl"

layout(binding = 1) uniform sampler2D uGNormalRho;  // RGBA32F: n (world, facing the eye), ρ red
layout(binding = 2) uniform sampler2D uGDistance;   // R32F: d [m], +inf for the sky
layout(binding = 3) uniform sampler2D uGRhoGB;      // RG32F: ρ green, blue

uniform mat3 uWorldFromCamera;  // columns: camera +x (view axis), +y (left), +z (up)
uniform vec3 uFocalPrincipal;   // (f, cx, H − cy) [px]: principal point in window coordinates (y up)

layout(location = 0) out vec4 outLuminance;

void main() {
  ivec2 px = ivec2(gl_FragCoord.xy);
  float d = texelFetch(uGDistance, px, 0).r;
  if (isinf(d)) {  // the sky: no surface, ambient in-scatter only
    outLuminance = vec4(vec3(uAmbient), 0.0);
    return;
  }
  vec4 nr = texelFetch(uGNormalRho, px, 0);
  vec2 gb = texelFetch(uGRhoGB, px, 0).rg;
  // The pixel centre's ray, as surface_plane.frag builds it (lit in single precision).
  vec3 local = vec3(pixelRayLocal(dvec3(uFocalPrincipal), dvec2(gl_FragCoord.xy)));
  vec3 p = d * normalize(uWorldFromCamera * local);
  vec3 ls = surfaceLuminance(p, nr.xyz, vec3(nr.w, gb));
  outLuminance = vec4(viewedThroughFog(ls, d), 1.0);
}
