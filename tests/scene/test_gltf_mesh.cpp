// glTF import without GL (fogbeam_gltf): the memory loader used by the fuzz target `gltf` gives
// what the file loader gives, reads no external file, and bounds shared-node instancing.
#include <fogbeam/scene/gltf_mesh.hpp>

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

namespace {

std::vector<unsigned char> readAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

std::span<const unsigned char> bytesOf(const std::string& s) {
  return {reinterpret_cast<const unsigned char*>(s.data()), s.size()};
}

}  // namespace

TEST(GltfMesh, MemoryLoaderMatchesFileLoaderForJsonAndGlb) {
  const std::string json = FOGBEAM_TEST_DATA_DIR "/gltf/wall_quad.gltf";
  auto fromFile = fogbeam::loadGltfMesh(json);
  ASSERT_TRUE(fromFile) << fromFile.error().message;
  ASSERT_EQ(fromFile->vertices.size(), 6u);  // one quad, two triangles
  // The same quad as JSON from memory and as GLB (tests/fuzz/corpus/gltf/wall_quad.glb).
  for (const std::string& path : {json, std::string(FOGBEAM_FUZZ_CORPUS_DIR "/gltf/wall_quad.glb")}) {
    const auto bytes = readAll(path);
    auto m = fogbeam::loadGltfMeshFromMemory(bytes, path);
    ASSERT_TRUE(m) << m.error().message;
    ASSERT_EQ(m->vertices.size(), fromFile->vertices.size()) << path;
    for (std::size_t i = 0; i < m->vertices.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(m->vertices[i].position[k], fromFile->vertices[i].position[k]) << path;
        EXPECT_EQ(m->vertices[i].normal[k], fromFile->vertices[i].normal[k]) << path;
      }
    EXPECT_EQ(m->anchor_m, fromFile->anchor_m) << path;
  }
}

TEST(GltfMesh, MemoryLoaderReadsNoExternalFile) {
  const std::string g = R"({"asset":{"version":"2.0"},"buffers":[{"uri":"/etc/passwd","byteLength":4}]})";
  auto m = fogbeam::loadGltfMeshFromMemory(bytesOf(g), "external.gltf");
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("external.gltf: cannot load glTF"), std::string::npos) << m.error().message;
}

TEST(GltfMesh, SharedChildrenAreBounded) {
  // 40 levels of a node listing its child twice: 2^40 instances from 41 nodes.
  std::string nodes;
  for (int i = 0; i < 40; ++i) nodes += "{\"children\":[" + std::to_string(i + 1) + "," + std::to_string(i + 1) + "]},";
  nodes += "{}";
  const std::string g = R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[)" + nodes + "]}";
  auto m = fogbeam::loadGltfMeshFromMemory(bytesOf(g), "shared.gltf");
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("more than 100000 node instances"), std::string::npos) << m.error().message;
}

TEST(GltfMesh, AccessorPastItsBufferViewIsRefused) {
  // A VEC3 float accessor of 2 elements (24 bytes) in a buffer view of 12 bytes.
  const std::string g = R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
    "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
    "accessors":[{"bufferView":0,"componentType":5126,"count":2,"type":"VEC3"}],
    "bufferViews":[{"buffer":0,"byteLength":12}],
    "buffers":[{"byteLength":24,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA"}]})";
  auto m = fogbeam::loadGltfMeshFromMemory(bytesOf(g), "short.gltf");
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("runs past the end of its buffer view"), std::string::npos) << m.error().message;
}
