#version 450 core
// fogbeam — surface_mesh.vert: glTF triangles, already in the fogbeam world frame (x forward,
// y left, z up; glTF (x, y, z) → fogbeam (z, x, y)) and stored relative to an anchor point [m].
// The camera-relative position p = position + (anchor − O) goes to the fragment shader, which
// takes the true distance |p|; clip space uses an infinite-far pinhole projection that puts
// pixel centres exactly on Camera::rayDirection's rays, off-axis cameras included (its
// off-centre terms, core/src/gl/surface_pass.cpp clipFromCameraRel).
layout(location = 0) in vec3 aPosition;     // m, relative to the anchor
layout(location = 1) in vec3 aNormal;       // unit, world
layout(location = 2) in vec3 aReflectance;  // Lambertian ρ per channel (glTF baseColorFactor.rgb)

uniform vec3 uAnchorFromCamera;   // anchor − O [m]
uniform mat4 uClipFromCameraRel;  // projection · view, without the camera translation

out vec3 vPosition;
out vec3 vNormal;
out vec3 vReflectance;

void main() {
  vPosition = aPosition + uAnchorFromCamera;
  vNormal = aNormal;
  vReflectance = aReflectance;
  gl_Position = uClipFromCameraRel * vec4(vPosition, 1.0);
}
