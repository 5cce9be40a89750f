#version 450 core
// fogbeam — surface_mesh.frag: glTF surfaces into the geometry buffer. Units: metres.
//   d = |p| (p: camera-relative surface point, interpolated perspective-correctly at the pixel
//   centre, so it lies on the pixel's ray), n = the shading normal turned to face the eye.
// Outputs: location 0 (n, ρ red), location 1 d [m], location 2 (ρ green, blue); depth 1/(1 + d)
// (GL_GREATER). surface_deferred.frag (GPU shading) or SurfaceShader (CPU shading) lights them.
#include "common_photometry.glsl"

in vec3 vPosition;
in vec3 vNormal;
in vec3 vReflectance;

layout(location = 0) out vec4 outNormalRho;  // (n, ρ red)
layout(location = 1) out float outDistance;
layout(location = 2) out vec2 outRhoGB;       // ρ green, blue

void main() {
  float d = length(vPosition);
  vec3 n = normalize(vNormal);
  if (dot(n, vPosition) > 0.0) n = -n;  // two-sided: the side facing the eye
  outNormalRho = vec4(n, vReflectance.r);
  outRhoGB = vReflectance.gb;
  outDistance = d;
  gl_FragDepth = depthFromDistance(d);
}
