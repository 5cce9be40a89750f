#version 450 core
// fogbeam — surface_fullscreen.vert: one triangle that covers the viewport (no attributes).
// The fragment shader (surface_plane.frag) builds each pixel's ray itself; nothing here has units.
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));  // (0,0) (2,0) (0,2)
  gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
