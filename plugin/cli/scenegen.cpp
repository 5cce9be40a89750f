// fogbeam_scenegen — writes the default road scene (config/scenes/road.glb, glTF 2.0 binary)
// from the parametric model in road_model.hpp, or checks that the shipped file still matches.
//
//   fogbeam_scenegen --out-dir config/scenes     regenerate road.glb
//   fogbeam_scenegen --check config/scenes       exit 1 if road.glb differs from the output
//
// The output is deterministic: no time stamps, positions rounded to 0.1 mm and normals to
// 1e-6 before they become floats (so the last bit of libm's sin/cos cannot change a byte),
// and tinygltf's JSON writer orders keys.
#include "road_model.hpp"

#include <fogbeam/util/tiny_gltf.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace {

constexpr const char* kFileName = "road.glb";

double roundTo(double v, double quantum) { return std::round(v / quantum) * quantum; }

// fogbeam (x forward, y left, z up) → glTF (x, y, z) = fogbeam (y, z, x): the inverse of the
// loader's glTF (x, y, z) → fogbeam (z, x, y) (docs/surface_pass.md). A rotation, so
// windings and normals carry over.
std::array<float, 3> gltfFromFogbeam(const glm::dvec3& v, double quantum) {
  return {static_cast<float>(roundTo(v.y, quantum)), static_cast<float>(roundTo(v.z, quantum)),
          static_cast<float>(roundTo(v.x, quantum))};
}

void appendBytes(std::vector<unsigned char>& buf, const void* data, std::size_t size) {
  const auto* p = static_cast<const unsigned char*>(data);
  buf.insert(buf.end(), p, p + size);
  while (buf.size() % 4 != 0) buf.push_back(0);  // keep every view 4-byte aligned
}

// Adds a buffer view + accessor for tightly packed data; returns the accessor index.
int addAccessor(tinygltf::Model& model, std::vector<unsigned char>& buf, const void* data, std::size_t bytes,
                int target, int componentType, int type, std::size_t count) {
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buf.size();
  view.byteLength = bytes;
  view.target = target;
  appendBytes(buf, data, bytes);
  model.bufferViews.push_back(view);
  tinygltf::Accessor acc;
  acc.bufferView = static_cast<int>(model.bufferViews.size() - 1);
  acc.componentType = componentType;
  acc.type = type;
  acc.count = count;
  model.accessors.push_back(acc);
  return static_cast<int>(model.accessors.size() - 1);
}

tinygltf::Model toGltf(const fogbeam::road::RoadScene& scene) {
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "fogbeam_scenegen (plugin/cli/road_model.hpp); synthetic, no third-party assets";
  std::vector<unsigned char> bin;

  for (const auto& m : scene.materials) {
    tinygltf::Material mat;
    mat.name = m.name;
    mat.pbrMetallicRoughness.baseColorFactor = {m.reflectance[0], m.reflectance[1], m.reflectance[2], 1.0};
    mat.pbrMetallicRoughness.metallicFactor = 0.0;   // Lambertian stand-ins: no metal,
    mat.pbrMetallicRoughness.roughnessFactor = 1.0;  // fully rough
    mat.doubleSided = true;  // the surface pass shades both sides; ribbons have one
    model.materials.push_back(mat);
  }

  tinygltf::Scene gscene;
  gscene.name = "road";
  for (const auto& group : scene.groups) {
    tinygltf::Mesh mesh;
    mesh.name = group.name;
    for (const auto& prim : group.primitives) {
      if (prim.indices.empty()) continue;
      std::vector<float> pos, nrm;
      pos.reserve(prim.positions.size() * 3);
      nrm.reserve(prim.normals.size() * 3);
      std::vector<double> lo(3, std::numeric_limits<double>::infinity());
      std::vector<double> hi(3, -std::numeric_limits<double>::infinity());
      for (std::size_t i = 0; i < prim.positions.size(); ++i) {
        const auto p = gltfFromFogbeam(prim.positions[i], 1e-4);
        const auto n = gltfFromFogbeam(prim.normals[i], 1e-6);
        for (std::size_t k = 0; k < 3; ++k) {
          lo[k] = std::min(lo[k], static_cast<double>(p[k]));
          hi[k] = std::max(hi[k], static_cast<double>(p[k]));
        }
        pos.insert(pos.end(), p.begin(), p.end());
        nrm.insert(nrm.end(), n.begin(), n.end());
      }
      const std::size_t vertexCount = prim.positions.size();
      tinygltf::Primitive gp;
      gp.mode = TINYGLTF_MODE_TRIANGLES;
      gp.material = static_cast<int>(prim.material);
      gp.attributes["POSITION"] = addAccessor(model, bin, pos.data(), pos.size() * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER,
                                              TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertexCount);
      model.accessors.back().minValues = lo;  // required for POSITION
      model.accessors.back().maxValues = hi;
      gp.attributes["NORMAL"] = addAccessor(model, bin, nrm.data(), nrm.size() * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER,
                                            TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, vertexCount);
      if (vertexCount <= 65536) {  // 16-bit indices halve the index data of every primitive here
        std::vector<std::uint16_t> idx(prim.indices.size());
        std::transform(prim.indices.begin(), prim.indices.end(), idx.begin(),
                       [](std::uint32_t i) { return static_cast<std::uint16_t>(i); });
        gp.indices = addAccessor(model, bin, idx.data(), idx.size() * sizeof(std::uint16_t), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER,
                                 TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_SCALAR, idx.size());
      } else {
        gp.indices = addAccessor(model, bin, prim.indices.data(), prim.indices.size() * sizeof(std::uint32_t),
                                 TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                                 TINYGLTF_TYPE_SCALAR, prim.indices.size());
      }
      mesh.primitives.push_back(gp);
    }
    if (mesh.primitives.empty()) continue;
    model.meshes.push_back(mesh);
    tinygltf::Node node;
    node.name = group.name;
    node.mesh = static_cast<int>(model.meshes.size() - 1);
    model.nodes.push_back(node);
    gscene.nodes.push_back(static_cast<int>(model.nodes.size() - 1));
  }
  model.scenes.push_back(gscene);
  model.defaultScene = 0;

  tinygltf::Buffer buffer;
  buffer.data = std::move(bin);
  model.buffers.push_back(std::move(buffer));
  return model;
}

std::string glbBytes(const fogbeam::road::RoadScene& scene) {
  const tinygltf::Model model = toGltf(scene);
  tinygltf::TinyGLTF writer;
  std::ostringstream out(std::ios::binary);
  if (!writer.WriteGltfSceneToStream(&model, out, /*prettyPrint=*/false, /*writeBinary=*/true)) return {};
  return out.str();
}

void printSummary(const fogbeam::road::RoadParams& p, const fogbeam::road::RoadScene& scene, std::size_t bytes) {
  std::printf("  %zu triangles, %zu bytes; groups:", scene.triangleCount(), bytes);
  for (const auto& g : scene.groups) {
    std::size_t n = 0;
    for (const auto& pr : g.primitives) n += pr.indices.size() / 3;
    std::printf(" %s %zu,", g.name.c_str(), n);
  }
  std::printf("\n  street-lamp light points (fogbeam frame, m):");
  for (const auto& lamp : p.street_lamps) {
    const auto q = fogbeam::road::lampPosition(p, lamp);
    std::printf(" (%.2f, %.2f, %.2f)", q.x, q.y, q.z);
  }
  std::printf("\n  lane centres (x, y) and heading by station, for placing vehicles:");
  for (double s = 0.0; s <= 100.0; s += 20.0) {
    const auto c = fogbeam::road::centreLine(p, s);
    const auto ego = fogbeam::road::roadPoint(p, s, -0.5 * p.lane_width_m);
    const auto other = fogbeam::road::roadPoint(p, s, 0.5 * p.lane_width_m);
    std::printf("\n    s %5.1f: ego (%.2f, %.2f), oncoming (%.2f, %.2f), heading %.2f deg", s, ego.x, ego.y, other.x,
                other.y, c.heading * 180.0 / 3.14159265358979323846);
  }
  const auto end = fogbeam::road::centreLine(p, p.end_s_m);
  std::printf("\n  road end: centre line at (%.1f, %.1f), heading %.1f deg\n", end.x, end.y,
              end.heading * 180.0 / 3.14159265358979323846);
}

int writeScene(const std::string& dir) {
  const fogbeam::road::RoadParams params;
  const auto scene = fogbeam::road::buildRoadScene(params);
  const std::string bytes = glbBytes(scene);
  if (bytes.empty()) {
    std::fprintf(stderr, "fogbeam_scenegen: tinygltf could not serialise the scene\n");
    return 1;
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    std::fprintf(stderr, "fogbeam_scenegen: cannot create %s (%s)\n", dir.c_str(), ec.message().c_str());
    return 1;
  }
  const std::string path = (std::filesystem::path(dir) / kFileName).string();
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) {
    std::fprintf(stderr, "fogbeam_scenegen: cannot write %s\n", path.c_str());
    return 1;
  }
  std::printf("wrote %s\n", path.c_str());
  printSummary(params, scene, bytes.size());
  return 0;
}

int checkScene(const std::string& dir) {
  const std::string expected = glbBytes(fogbeam::road::buildRoadScene());
  const std::string path = (std::filesystem::path(dir) / kFileName).string();
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "fogbeam_scenegen: cannot read %s\n", path.c_str());
    return 1;
  }
  const std::string actual((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (actual != expected) {
    const auto mism = std::mismatch(actual.begin(), actual.end(), expected.begin(), expected.end());
    std::fprintf(stderr,
                 "fogbeam_scenegen: %s differs from the generator output (%zu bytes vs %zu, first difference at byte "
                 "%td); regenerate with: fogbeam_scenegen --out-dir %s\n",
                 path.c_str(), actual.size(), expected.size(), mism.first - actual.begin(), dir.c_str());
    return 1;
  }
  std::printf("%s matches the generator\n", path.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "fogbeam_scenegen: writes the default road scene road.glb (glTF 2.0 binary: a two-lane road with a "
      "left bend, markings, shoulders, reflector posts, trees, a sign, a guard rail, street-lamp poles) from "
      "the parametric model in plugin/cli/road_model.hpp, or checks a shipped file against it."};
  std::string outDir;
  std::string checkDir;
  auto* outOpt = app.add_option("--out-dir", outDir, "Directory to write road.glb into (created if missing)");
  auto* checkOpt = app.add_option("--check", checkDir,
                                  "Directory whose road.glb must equal the generator output byte for byte; "
                                  "exit status 1 says where it differs");
  outOpt->excludes(checkOpt);
  app.require_option(1);
  CLI11_PARSE(app, argc, argv);
  return outDir.empty() ? checkScene(checkDir) : writeScene(outDir);
}
