// libFuzzer target (issue 6): glTF 2.0 import, JSON or GLB (fogbeam/scene/gltf_mesh.hpp), from
// memory: tinygltf's parser, then fogbeam's accessor, index and node-graph checks. No GL context:
// the import is its own library (fogbeam_gltf). External files are not read from memory (only
// data: URIs and the GLB buffer), so the fuzzer cannot make it open paths.
// Built by the fuzz preset (clang, -fsanitize=fuzzer,address,undefined); run by scripts/fuzz.sh.
#include <fogbeam/scene/gltf_mesh.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto r = fogbeam::loadGltfMeshFromMemory(std::span<const unsigned char>(data, size), "fuzz input");
  if (!r) return 0;
  // Property: the surface pass draws non-indexed triangles, three vertices each.
  if (r->vertices.size() % 3 != 0) std::abort();
  return 0;
}
