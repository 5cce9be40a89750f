// fogbeam — lamps and tabulated profiles for the GL shaders (lamp_upload.hpp).
#include "lamp_upload.hpp"

#include <algorithm>
#include <string>
#include <tuple>
#include <type_traits>
#include <utility>
#include <variant>

namespace fogbeam::gl {

namespace {

// std430 mirror of LampGpu in common_photometry.glsl.
struct LampGpu {
  float position[4];
  float axisX[4];
  float axisY[4];
  float axisZ[4];
  float color[4];
  float params[4];
  std::int32_t kind[4];
  std::int32_t table[4];
};
static_assert(sizeof(LampGpu) == 128);


void setVec(float (&dst)[4], const Vec3& v, double w = 0.0) {
  dst[0] = static_cast<float>(v.x);
  dst[1] = static_cast<float>(v.y);
  dst[2] = static_cast<float>(v.z);
  dst[3] = static_cast<float>(w);
}

}  // namespace

LampUpload::LampUpload()
    : lampSsbo_(genBuffer()), profileBuffer_(genBuffer()), profileTex_(genTexture()), fogBuffer_(genBuffer()),
      fogTex_(genTexture()) {
  // One texel to start with: a buffer texture over an empty buffer is not valid everywhere.
  // The fog light's buffer is read four floats a texel (RGBA32F): its every record (a table row's
  // 8 coefficients per bin, a sum row, an annulus map's 4 values per bin) is a multiple of 4 floats
  // long, and one vec4 fetch instead of four scalar ones took the fog light's share of the GPU
  // draw on an NVIDIA H100 at 1280×720 from 16.5 to 6.9 ms (docs/surface_pass.md, "Shading in GL").
  const float zeros[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  for (auto [buffer, texture, format] : {std::tuple{profileBuffer_.get(), profileTex_.get(), GLenum{GL_R32F}},
                                         std::tuple{fogBuffer_.get(), fogTex_.get(), GLenum{GL_RGBA32F}}}) {
    glBindBuffer(GL_TEXTURE_BUFFER, buffer);
    glBufferData(GL_TEXTURE_BUFFER, sizeof zeros, zeros, GL_DYNAMIC_DRAW);
    glBindTexture(GL_TEXTURE_BUFFER, texture);
    glTexBuffer(GL_TEXTURE_BUFFER, format, buffer);
  }
  glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &maxTextureBufferSize_);
}

Status LampUpload::ensureFogLight(const FogLightFrame& fog) {
  lampMaps_.assign(fog.lamps.size(), -1);
  if (fog.table == nullptr) {
    fogTable_.reset();
    return Ok{};
  }
  std::vector<std::shared_ptr<const AnnulusMeanMap>>& wanted = fogWanted_;  // kept: a steady frame allocates nothing
  wanted.clear();
  for (const FogLightFrame::Lamp& l : fog.lamps)
    if (l.map_owner && std::find(wanted.begin(), wanted.end(), l.map_owner) == wanted.end()) wanted.push_back(l.map_owner);
  if (fog.table_owner.get() != fogTable_.get() || wanted != fogMaps_) {
    const FogLightTable& t = *fog.table_owner;
    // Offsets in texels of 4 floats (RGBA32F; every part is a multiple of 4 floats long).
    std::vector<float> data(t.dense());
    fogSums_ = static_cast<int>(data.size() / 4);
    data.insert(data.end(), t.denseSums().begin(), t.denseSums().end());
    std::vector<std::int32_t> offsets;
    for (const auto& m : wanted) {
      offsets.push_back(static_cast<std::int32_t>(data.size() / 4));
      data.insert(data.end(), m->values().begin(), m->values().end());
      fogMapRows_ = m->rows();
      fogMapColumns_ = m->columns();
    }
    if (data.size() % 4 != 0) return Error{"the fog light's data are not whole texels of 4 floats"};
    if (data.size() / 4 > static_cast<std::size_t>(maxTextureBufferSize_))
      return Error{"the fog light needs " + std::to_string(data.size() / 4) +
                   " texels, more than GL_MAX_TEXTURE_BUFFER_SIZE " + std::to_string(maxTextureBufferSize_)};
    glBindBuffer(GL_TEXTURE_BUFFER, fogBuffer_.get());
    glBufferData(GL_TEXTURE_BUFFER, static_cast<GLsizeiptr>(data.size() * sizeof(float)), data.data(), GL_STATIC_DRAW);
    fogTable_ = fog.table_owner;
    fogMaps_ = wanted;
    fogMapOffsets_ = std::move(offsets);
  }
  for (std::size_t i = 0; i < fog.lamps.size(); ++i) {
    const auto it = std::find(fogMaps_.begin(), fogMaps_.end(), fog.lamps[i].map_owner);
    if (fog.lamps[i].map_owner && it != fogMaps_.end())
      lampMaps_[i] = fogMapOffsets_[static_cast<std::size_t>(it - fogMaps_.begin())];
  }
  return Ok{};
}

Status LampUpload::ensureProfiles(const Scene& scene) {
  std::vector<std::shared_ptr<const Profile>> wanted;
  for (const SceneLamp& sl : scene.lamps) {
    if (!sl.lamp.profile) return Error{"lamp '" + sl.name + "' has no profile"};
    if (std::holds_alternative<TabulatedProfile>(sl.lamp.profile->model()) &&
        std::find(wanted.begin(), wanted.end(), sl.lamp.profile) == wanted.end())
      wanted.push_back(sl.lamp.profile);
  }
  if (wanted == uploaded_) return Ok{};
  std::vector<float> data;
  std::vector<std::int32_t> offsets;
  for (const auto& p : wanted) {
    const auto& t = std::get<TabulatedProfile>(p->model());
    offsets.push_back(static_cast<std::int32_t>(data.size()));
    for (double h : t.horizontal) data.push_back(static_cast<float>(h));
    for (double v : t.vertical) data.push_back(static_cast<float>(v));
    for (double c : t.candela) data.push_back(static_cast<float>(c));
  }
  if (data.empty()) data.push_back(0.0f);
  if (data.size() > static_cast<std::size_t>(maxTextureBufferSize_))
    return Error{"lamp profiles need " + std::to_string(data.size()) + " texels, more than GL_MAX_TEXTURE_BUFFER_SIZE " +
                 std::to_string(maxTextureBufferSize_)};
  glBindBuffer(GL_TEXTURE_BUFFER, profileBuffer_.get());
  glBufferData(GL_TEXTURE_BUFFER, static_cast<GLsizeiptr>(data.size() * sizeof(float)), data.data(), GL_STATIC_DRAW);
  uploaded_ = std::move(wanted);
  offsets_ = std::move(offsets);
  return Ok{};
}

void LampUpload::uploadLamps(const Scene& scene) {
  std::vector<LampGpu> lamps(std::max<std::size_t>(1, scene.lamps.size()), LampGpu{});
  const Vec3& eye = scene.camera.position_m;
  for (std::size_t i = 0; i < scene.lamps.size(); ++i) {
    const Lamp& l = scene.lamps[i].lamp;
    LampGpu& g = lamps[i];
    setVec(g.position, l.position_m - eye);
    setVec(g.axisX, l.worldFromLamp[0]);
    setVec(g.axisY, l.worldFromLamp[1]);
    setVec(g.axisZ, l.worldFromLamp[2]);
    setVec(g.color, l.color);
    g.table[3] = i < lampMaps_.size() ? lampMaps_[i] : -1;  // the fog light's annulus map (ensureFogLight)
    std::visit(
        [&](const auto& m) {
          using M = std::decay_t<decltype(m)>;
          if constexpr (std::is_same_v<M, IsotropicProfile>) {
            g.kind[0] = 0;
            g.params[0] = static_cast<float>(m.intensity_cd);
          } else if constexpr (std::is_same_v<M, SpotProfile>) {
            g.kind[0] = 1;
            g.params[0] = static_cast<float>(m.peak_cd);
            g.params[1] = static_cast<float>(m.inner);
            g.params[2] = static_cast<float>(m.outer);
          } else {
            g.kind[0] = 2;
            g.kind[1] = static_cast<int>(m.type);
            g.kind[2] = static_cast<int>(m.symmetry);
            g.params[0] = 1.0f;
            // Outside this cone about the axis I = 0 (the GPU airlight cuts rays to it).
            g.params[3] = static_cast<float>(l.profile->supportHalfAngle());
            const auto it = std::find(uploaded_.begin(), uploaded_.end(), l.profile);
            g.table[0] = offsets_[static_cast<std::size_t>(it - uploaded_.begin())];
            g.table[1] = static_cast<std::int32_t>(m.horizontal.size());
            g.table[2] = static_cast<std::int32_t>(m.vertical.size());
          }
        },
        l.profile->model());
  }
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, lampSsbo_.get());
  glBufferData(GL_SHADER_STORAGE_BUFFER, static_cast<GLsizeiptr>(lamps.size() * sizeof(LampGpu)), lamps.data(),
               GL_DYNAMIC_DRAW);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, lampSsbo_.get());
}

}  // namespace fogbeam::gl
