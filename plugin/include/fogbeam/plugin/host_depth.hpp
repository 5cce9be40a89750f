// fogbeam — host depth input: the image generator publishes its own distance buffer and camera
// through a shared-memory channel (format FOGBEAM_FORMAT_DISTANCE_F32, written with the C SDK's
// fogbeam_depth_* functions); fogbeam renders the airlight for exactly that view instead of
// running its surface pass, and the host composites the overlay (host·T + A) on its own image.
// In the service library, not ipc/: it turns ipc's shm reader into the renderer's Camera and
// SurfaceBuffers, and ipc/ knows nothing of the renderer.
//
// Thread-safety: one thread per HostDepthInput.
#pragma once

#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam::plugin {

struct HostView {
  Camera camera;             ///< position, orientation, fov, size from the host
  std::uint64_t frame = 0;   ///< the host's frame number
  double sim_time_s = 0.0;
};

class HostDepthInput {
 public:
  /// Attaches to the host's channel; fails when it does not exist or is not a distance channel.
  [[nodiscard]] static Result<std::unique_ptr<HostDepthInput>> attach(const std::string& channel);

  /// Reads the newest view into `view` and `surface` (distance filled, rgb zero: the host has
  /// the surfaces). ipc::ReadStatus as ipc::ShmReader. Errors (as WriterGone plus a message in
  /// lastError()): a field of view outside (0°, 180°) or non-square pixels (fov_y given and
  /// not matching the aspect ratio within 0.1 %), which fogbeam's pinhole camera cannot take.
  ipc::ReadStatus latest(HostView& view, SurfaceBuffers& surface);
  [[nodiscard]] const std::string& lastError() const noexcept { return lastError_; }

 private:
  HostDepthInput() = default;
  std::unique_ptr<ipc::ShmReader> reader_;
  std::vector<std::byte> bytes_;
  std::string lastError_;
};

}  // namespace fogbeam::plugin
