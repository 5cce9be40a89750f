// fogbeam — the scene's lamps as the GL shaders read them (common_photometry.glsl): one LampGpu
// record per lamp in a shader storage buffer (binding 0), and the tabulated profiles, unresampled
// (h angles, v angles, candela grid), in one R32F buffer texture (`uProfileData`, texture unit 0).
// Used by the surface draws and the GPU airlight stage alike (docs/surface_pass.md, "Lamp
// profiles").
// Private to fogbeam_gl. Thread-safety: that of the owning GL context (one thread at a time).
#pragma once

#include "gl_object.hpp"

#include <fogbeam/physics/profile.hpp>
#include <fogbeam/render/fog_light.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <memory>
#include <vector>

namespace fogbeam::gl {

class LampUpload {
 public:
  /// Creates the buffers (a GL context must be current; they belong to it).
  LampUpload();

  /// Uploads every tabulated profile used by the scene, once: the buffer texture is kept while
  /// the set of profiles (by identity) stays the same. Errors: a lamp without a profile, more
  /// texels than GL_MAX_TEXTURE_BUFFER_SIZE.
  [[nodiscard]] Status ensureProfiles(const Scene& scene);
  /// Writes this frame's lamp records (positions relative to the eye, metres; axes; colour;
  /// profile parameters and table offsets) and binds them to storage-buffer binding 0.
  /// Needs ensureProfiles() for the same scene first.
  void uploadLamps(const Scene& scene);
  /// The profile buffer texture, for GL_TEXTURE_BUFFER on the shaders' unit 0.
  [[nodiscard]] GLuint profileTexture() const noexcept { return profileTex_.get(); }

  /// The fog light's data for the shaders (`uFogData`, unit 5: the dense table, its sums over the
  /// bins, then each annulus map the frame's lamps read), uploaded when the table or the set of
  /// maps changes; `fog.table` null: off. Lamp i of the next uploadLamps() reads the map of
  /// fog.lamps[i] (its offset in LampGpu.table.w; −1: isotropic, none). Errors: more texels than
  /// GL_MAX_TEXTURE_BUFFER_SIZE.
  [[nodiscard]] Status ensureFogLight(const FogLightFrame& fog);
  [[nodiscard]] GLuint fogTexture() const noexcept { return fogTex_.get(); }
  /// The shaders' uniforms: bins (0: off), the sums' offset, the maps' rows and columns.
  [[nodiscard]] int fogBins() const noexcept { return fogTable_ ? static_cast<int>(fogTable_->bins()) : 0; }
  [[nodiscard]] int fogSums() const noexcept { return fogSums_; }
  [[nodiscard]] int fogMapRows() const noexcept { return fogMapRows_; }
  [[nodiscard]] int fogMapColumns() const noexcept { return fogMapColumns_; }

 private:
  Buffer lampSsbo_, profileBuffer_;
  Texture profileTex_;
  GLint maxTextureBufferSize_ = 0;
  std::vector<std::shared_ptr<const Profile>> uploaded_;  // tabulated profiles in profileBuffer_, in order
  std::vector<std::int32_t> offsets_;                      // each one's first texel
  Buffer fogBuffer_;
  Texture fogTex_;
  std::shared_ptr<const FogLightTable> fogTable_;            // in fogBuffer_ (null: off)
  std::vector<std::shared_ptr<const AnnulusMeanMap>> fogMaps_;  // in fogBuffer_, in order
  std::vector<std::int32_t> fogMapOffsets_;                   // each one's first texel
  std::vector<std::int32_t> lampMaps_;                        // per lamp of the last ensureFogLight: its map's offset
  std::vector<std::shared_ptr<const AnnulusMeanMap>> fogWanted_;  // ensureFogLight's scratch
  int fogSums_ = 0, fogMapRows_ = 0, fogMapColumns_ = 0;
};

}  // namespace fogbeam::gl
