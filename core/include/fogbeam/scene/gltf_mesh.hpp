// fogbeam — glTF 2.0 geometry for the surface pass, flattened to world-space triangles.
//
// Frame mapping: glTF is y-up, its assets face +z and its +x is to their left (right-handed).
// fogbeam is x forward, y left, z up. A glTF point (x, y, z) becomes the fogbeam point
//     (x_f, y_f, z_f) = (z, x, y)
// i.e. glTF +Z (forward) → fogbeam +x, glTF +X (left) → +y, glTF +Y (up) → +z (a rotation,
// determinant +1; normals map the same way). Scene nodes' matrices or TRS are applied first.
// Material: the Lambertian reflectance of a primitive is its PBR baseColorFactor.rgb (default 1);
// textures, metallic/roughness and vertex colours are ignored. Primitives without normals get
// flat (per-triangle) normals. Only TRIANGLES (mode 4) are drawn; POINTS/LINES are skipped,
// strips and fans are converted. No GL here: plain data, testable anywhere; it is its own library
// (fogbeam_gltf, no GL or EGL; it sits with the scene because a scene names its glTF), so that the fuzz target `gltf` can run it without a GL context.
#pragma once

#include <fogbeam/physics/math.hpp>
#include <fogbeam/util/result.hpp>

#include <span>
#include <string>
#include <vector>

namespace fogbeam {

struct MeshVertex {
  float position[3];     ///< m, fogbeam world frame, relative to MeshData::anchor_m
  float normal[3];       ///< unit, fogbeam world frame
  float reflectance[3];  ///< Lambertian ρ per channel
};

struct MeshData {
  Vec3 anchor_m{0.0};               ///< centre of the bounding box (world, double)
  std::vector<MeshVertex> vertices; ///< three per triangle (non-indexed)
  std::size_t skippedPrimitives = 0;  ///< points/lines primitives, not drawn
};

/// glTF (x, y, z) → fogbeam (z, x, y).
[[nodiscard]] inline Vec3 fogbeamFromGltf(const Vec3& g) { return {g.z, g.x, g.y}; }

/// Loads a .gltf (JSON, external or data-URI buffers) or .glb file. Errors name the file and
/// what is wrong ("road.gltf: mesh 2 primitive 0: POSITION accessor is not VEC3 float").
[[nodiscard]] Result<MeshData> loadGltfMesh(const std::string& path);

/// The same from bytes in memory: GLB when they start with "glTF", JSON otherwise; `what` names
/// them in errors. Reads no file: buffers must be data: URIs or the GLB's own chunk.
[[nodiscard]] Result<MeshData> loadGltfMeshFromMemory(std::span<const unsigned char> bytes, const std::string& what);

}  // namespace fogbeam
