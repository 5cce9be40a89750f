#include <fogbeam/scene/gltf_mesh.hpp>

#include <fogbeam/util/tiny_gltf.hpp>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <cstring>
#include <limits>

namespace fogbeam {

namespace {

using DMat4 = glm::dmat4;

/// Node instances (a node counted once per path from a root) in one file; far above any road
/// scene (road.glb has 3), low enough that a hostile file cannot loop for hours.
constexpr std::size_t kMaxNodeInstances = 100'000;

DMat4 nodeMatrix(const tinygltf::Node& node) {
  if (node.matrix.size() == 16) return glm::make_mat4(node.matrix.data());  // column-major, as glTF
  DMat4 m(1.0);
  if (node.translation.size() == 3) m = glm::translate(m, glm::dvec3(node.translation[0], node.translation[1], node.translation[2]));
  if (node.rotation.size() == 4) {
    const glm::dquat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);  // glTF: x, y, z, w
    m = m * glm::mat4_cast(q);
  }
  if (node.scale.size() == 3) m = glm::scale(m, glm::dvec3(node.scale[0], node.scale[1], node.scale[2]));
  return m;
}

struct Loader {
  const tinygltf::Model& model;
  std::string file;
  std::vector<Vec3> positions, normals, reflectances;  // world (fogbeam), per triangle corner
  std::size_t skipped = 0;
  std::size_t nodeVisits = 0;

  /// The first element of an accessor and its stride (bytes), after checking that every element
  /// of `elementSize` bytes lies inside its buffer view and buffer. The sums are done so that they
  /// cannot overflow, whatever the file's offsets and counts.
  Result<std::pair<const unsigned char*, std::size_t>> accessorBytes(const tinygltf::Accessor& acc, std::size_t elementSize,
                                                                     const std::string& what) const {
    if (acc.bufferView < 0 || static_cast<std::size_t>(acc.bufferView) >= model.bufferViews.size())
      return Error{file + ": " + what + ": accessor has no buffer view"};
    const auto& view = model.bufferViews[static_cast<std::size_t>(acc.bufferView)];
    if (view.buffer < 0 || static_cast<std::size_t>(view.buffer) >= model.buffers.size())
      return Error{file + ": " + what + ": buffer view names no buffer"};
    const auto& buf = model.buffers[static_cast<std::size_t>(view.buffer)];
    const std::size_t size = buf.data.size();
    const std::size_t stride = view.byteStride ? view.byteStride : elementSize;
    if (stride < elementSize) return Error{file + ": " + what + ": byte stride smaller than an element"};
    if (view.byteOffset > size || view.byteLength > size - view.byteOffset)
      return Error{file + ": " + what + ": buffer view runs past the end of its buffer"};
    if (acc.count == 0) return std::pair{buf.data.data(), stride};
    // The last element ends at byteOffset + stride·(count−1) + elementSize inside the view.
    const std::size_t room = view.byteLength;
    if (acc.byteOffset > room || elementSize > room - acc.byteOffset ||
        (acc.count - 1) > (room - acc.byteOffset - elementSize) / stride)
      return Error{file + ": " + what + ": accessor runs past the end of its buffer view"};
    return std::pair{buf.data.data() + view.byteOffset + acc.byteOffset, stride};
  }

  Result<std::vector<glm::dvec3>> readVec3(int accessorIndex, const std::string& what) const {
    if (accessorIndex < 0 || static_cast<std::size_t>(accessorIndex) >= model.accessors.size())
      return Error{file + ": " + what + ": accessor index out of range"};
    const auto& acc = model.accessors[static_cast<std::size_t>(accessorIndex)];
    if (acc.type != TINYGLTF_TYPE_VEC3 || acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT)
      return Error{file + ": " + what + " accessor is not VEC3 float"};
    if (acc.sparse.isSparse) return Error{file + ": " + what + ": sparse accessors are not supported"};
    if (acc.bufferView < 0 || static_cast<std::size_t>(acc.bufferView) >= model.bufferViews.size())
      return Error{file + ": " + what + ": accessor has no buffer view"};
    auto bytes = accessorBytes(acc, 12, what);
    if (!bytes) return bytes.error();
    const auto [data, stride] = *bytes;
    std::vector<glm::dvec3> out(acc.count);
    for (std::size_t i = 0; i < acc.count; ++i) {
      float v[3];
      std::memcpy(v, data + i * stride, sizeof v);
      out[i] = {v[0], v[1], v[2]};
    }
    return out;
  }

  Result<std::vector<std::uint32_t>> readIndices(int accessorIndex, std::size_t vertexCount, const std::string& what) const {
    std::vector<std::uint32_t> out;
    if (accessorIndex < 0) {
      out.resize(vertexCount);
      for (std::size_t i = 0; i < vertexCount; ++i) out[i] = static_cast<std::uint32_t>(i);
      return out;
    }
    if (static_cast<std::size_t>(accessorIndex) >= model.accessors.size()) return Error{file + ": " + what + ": index accessor out of range"};
    const auto& acc = model.accessors[static_cast<std::size_t>(accessorIndex)];
    if (acc.type != TINYGLTF_TYPE_SCALAR || acc.bufferView < 0) return Error{file + ": " + what + ": indices must be a SCALAR accessor with a buffer view"};
    std::size_t size = 0;
    switch (acc.componentType) {
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: size = 1; break;
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: size = 2; break;
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: size = 4; break;
      default: return Error{file + ": " + what + ": indices must be unsigned byte, short or int"};
    }
    auto bytes = accessorBytes(acc, size, what + ": index");
    if (!bytes) return bytes.error();
    const auto [data, stride] = *bytes;
    out.resize(acc.count);
    for (std::size_t i = 0; i < acc.count; ++i) {
      const unsigned char* p = data + i * stride;
      std::uint32_t v = 0;
      if (size == 1) v = p[0];
      else if (size == 2) { std::uint16_t s; std::memcpy(&s, p, 2); v = s; }
      else std::memcpy(&v, p, 4);
      if (v >= vertexCount) return Error{file + ": " + what + ": index " + std::to_string(v) + " out of range"};
      out[i] = v;
    }
    return out;
  }

  Status addPrimitive(const tinygltf::Primitive& prim, const DMat4& worldFromNode, const std::string& what) {
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    if (mode == TINYGLTF_MODE_POINTS || mode == TINYGLTF_MODE_LINE || mode == TINYGLTF_MODE_LINE_LOOP || mode == TINYGLTF_MODE_LINE_STRIP) {
      ++skipped;
      return Ok{};
    }
    const auto pit = prim.attributes.find("POSITION");
    if (pit == prim.attributes.end()) return Error{file + ": " + what + ": no POSITION attribute"};
    auto pos = readVec3(pit->second, what + ": POSITION");
    if (!pos) return pos.error();
    std::vector<glm::dvec3> nrm;
    if (const auto nit = prim.attributes.find("NORMAL"); nit != prim.attributes.end()) {
      auto n = readVec3(nit->second, what + ": NORMAL");
      if (!n) return n.error();
      if (n->size() != pos->size()) return Error{file + ": " + what + ": NORMAL and POSITION counts differ"};
      nrm = std::move(*n);
    }
    auto idx = readIndices(prim.indices, pos->size(), what);
    if (!idx) return idx.error();
    std::vector<std::uint32_t> tri;  // triangle list
    const auto& ix = *idx;
    if (mode == TINYGLTF_MODE_TRIANGLES) {
      tri = ix;
      tri.resize(tri.size() / 3 * 3);
    } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      for (std::size_t i = 2; i < ix.size(); ++i) {
        if (i % 2 == 0) tri.insert(tri.end(), {ix[i - 2], ix[i - 1], ix[i]});
        else tri.insert(tri.end(), {ix[i - 1], ix[i - 2], ix[i]});
      }
    } else if (mode == TINYGLTF_MODE_TRIANGLE_FAN) {
      for (std::size_t i = 2; i < ix.size(); ++i) tri.insert(tri.end(), {ix[0], ix[i - 1], ix[i]});
    } else {
      return Error{file + ": " + what + ": unknown primitive mode " + std::to_string(mode)};
    }

    Vec3 rho(1.0);
    if (prim.material >= 0 && static_cast<std::size_t>(prim.material) < model.materials.size()) {
      const auto& f = model.materials[static_cast<std::size_t>(prim.material)].pbrMetallicRoughness.baseColorFactor;
      if (f.size() >= 3) rho = Vec3(f[0], f[1], f[2]);
    }
    const glm::dmat3 linear(worldFromNode);
    const glm::dmat3 normalFromNode = glm::transpose(glm::inverse(linear));
    for (std::size_t t = 0; t + 2 < tri.size(); t += 3) {
      Vec3 p[3];
      for (int k = 0; k < 3; ++k)
        p[k] = fogbeamFromGltf(glm::dvec3(worldFromNode * glm::dvec4((*pos)[tri[t + static_cast<std::size_t>(k)]], 1.0)));
      const Vec3 face = glm::cross(p[1] - p[0], p[2] - p[0]);
      const double faceLen = glm::length(face);
      if (!(faceLen > 0.0)) continue;  // degenerate
      for (int k = 0; k < 3; ++k) {
        Vec3 n = face / faceLen;
        if (!nrm.empty()) {
          const Vec3 nk = fogbeamFromGltf(normalFromNode * nrm[tri[t + static_cast<std::size_t>(k)]]);
          if (glm::length(nk) > 0.0) n = glm::normalize(nk);
        }
        positions.push_back(p[k]);
        normals.push_back(n);
        reflectances.push_back(rho);
      }
    }
    return Ok{};
  }

  Status addNode(int nodeIndex, const DMat4& parent, int depth) {
    if (nodeIndex < 0 || static_cast<std::size_t>(nodeIndex) >= model.nodes.size()) return Error{file + ": node index out of range"};
    if (depth > 64) return Error{file + ": node hierarchy deeper than 64 (a cycle?)"};
    // A node may be the child of several: a small file can name 2^64 instances. Bounded.
    if (++nodeVisits > kMaxNodeInstances)
      return Error{file + ": more than " + std::to_string(kMaxNodeInstances) + " node instances (shared children)"};
    const auto& node = model.nodes[static_cast<std::size_t>(nodeIndex)];
    const DMat4 m = parent * nodeMatrix(node);
    if (node.mesh >= 0) {
      if (static_cast<std::size_t>(node.mesh) >= model.meshes.size()) return Error{file + ": node " + std::to_string(nodeIndex) + ": mesh index out of range"};
      const auto& mesh = model.meshes[static_cast<std::size_t>(node.mesh)];
      for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
        const std::string what = "mesh " + std::to_string(node.mesh) + " primitive " + std::to_string(p);
        if (Status s = addPrimitive(mesh.primitives[p], m, what); !s) return s;
      }
    }
    for (int child : node.children)
      if (Status s = addNode(child, m, depth + 1); !s) return s;
    return Ok{};
  }
};

Result<MeshData> meshFromModel(const tinygltf::Model& model, const std::string& path);

// Loading from memory reads no other file: a buffer or image URI that is not a data: URI fails.
bool noFileExists(const std::string&, void*) { return false; }
std::string noExpand(const std::string& p, void*) { return p; }
bool noRead(std::vector<unsigned char>*, std::string* err, const std::string& p, void*) {
  if (err) *err += "external file '" + p + "' not read (glTF from memory: data: URIs and GLB buffers only)\n";
  return false;
}
bool noWrite(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err += "no writing\n";
  return false;
}

}  // namespace

Result<MeshData> loadGltfMesh(const std::string& path) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  const bool binary = path.size() >= 4 && path.compare(path.size() - 4, 4, ".glb") == 0;
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path) : loader.LoadASCIIFromFile(&model, &err, &warn, path);
  if (!ok) return Error{path + ": cannot load glTF: " + (err.empty() ? std::string("unknown error") : err)};
  return meshFromModel(model, path);
}

Result<MeshData> loadGltfMeshFromMemory(std::span<const unsigned char> bytes, const std::string& what) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks(tinygltf::FsCallbacks{&noFileExists, &noExpand, &noRead, &noWrite, nullptr});
  std::string err, warn;
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  const auto size = static_cast<unsigned int>(std::min<std::size_t>(bytes.size(), std::numeric_limits<unsigned int>::max()));
  const bool ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(), size, "")
                         : loader.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(bytes.data()), size, "");
  if (!ok) return Error{what + ": cannot load glTF: " + (err.empty() ? std::string("unknown error") : err)};
  return meshFromModel(model, what);
}

namespace {

Result<MeshData> meshFromModel(const tinygltf::Model& model, const std::string& path) {
  Loader l{model, path, {}, {}, {}, 0, 0};
  std::vector<int> roots;
  if (!model.scenes.empty()) {
    const std::size_t s = model.defaultScene >= 0 ? static_cast<std::size_t>(model.defaultScene) : 0;
    if (s >= model.scenes.size()) return Error{path + ": default scene index out of range"};
    roots = model.scenes[s].nodes;
  } else {
    // No scene (allowed, rare): every node that is no other node's child.
    std::vector<bool> isChild(model.nodes.size(), false);
    for (const auto& n : model.nodes)
      for (int c : n.children)
        if (c >= 0 && static_cast<std::size_t>(c) < isChild.size()) isChild[static_cast<std::size_t>(c)] = true;
    for (std::size_t i = 0; i < model.nodes.size(); ++i)
      if (!isChild[i]) roots.push_back(static_cast<int>(i));
  }
  for (int r : roots)
    if (Status s = l.addNode(r, DMat4(1.0), 0); !s) return s.error();

  MeshData out;
  out.skippedPrimitives = l.skipped;
  if (!l.positions.empty()) {
    Vec3 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
    for (const Vec3& p : l.positions) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
    out.anchor_m = 0.5 * (lo + hi);
  }
  out.vertices.resize(l.positions.size());
  for (std::size_t i = 0; i < l.positions.size(); ++i) {
    const Vec3 p = l.positions[i] - out.anchor_m;
    MeshVertex& v = out.vertices[i];
    for (int k = 0; k < 3; ++k) {
      v.position[k] = static_cast<float>(p[k]);
      v.normal[k] = static_cast<float>(l.normals[i][k]);
      v.reflectance[k] = static_cast<float>(l.reflectances[i][k]);
    }
  }
  return out;
}

}  // namespace

}  // namespace fogbeam
