// fogbeam — host depth input: the image generator publishes its own distance buffer and camera
// through a shared-memory channel (format FOGBEAM_FORMAT_DISTANCE_F32, written with the C SDK's
// fogbeam_depth_* functions); fogbeam renders the airlight for exactly that view instead of
// running its surface pass, and the host composites the overlay (host·T + A) on its own image
// (docs/service.md, "Host depth"). In the service library, not ipc/: it turns ipc's shm reader
// into the renderer's Camera and SurfaceBuffers, and ipc/ knows nothing of the renderer.
//
// Thread-safety: one thread per HostDepthInput.
#pragma once

#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam::plugin {

/// One host view: where the host's camera is, what it covers, which of its frames it is.
struct HostView {
  /// Position, orientation, size and field of view (centred) or principal point (off-axis
  /// frustum) from the host, in fogbeam's axes (docs/physics.md).
  Camera camera;
  std::uint64_t frame = 0;   ///< the host's frame number (from 1)
  double sim_time_s = 0.0;   ///< the host's simulation time of this view, s
  std::uint64_t publish_ns = 0;  ///< when the host published it (CLOCK_MONOTONIC, ns)
  float yaw_deg = 0.0f, pitch_deg = 0.0f, roll_deg = 0.0f;  ///< as published (echoed in the overlay)
  float fov_x_deg = 0.0f, fov_y_deg = 0.0f;                 ///< whole extent, deg
  std::array<float, 4> frustum_deg{0.0f, 0.0f, 0.0f, 0.0f};  ///< as published (all 0: centred)
  /// The host published its colour too (fogbeam_depth_create_colour): SurfaceBuffers::rgb holds
  /// it as linear luminance, cd/m²; else rgb is zero.
  bool colour = false;
};

enum class HostDepthStatus {
  Ok,          ///< a whole frame was read into the view and distances
  NoFrame,     ///< the host has published nothing yet
  Busy,        ///< every attempt overlapped a write; the previous frame stands
  WriterGone,  ///< the host closed the channel, died or was replaced: attach again
  Refused,     ///< the frame's camera or distances cannot be used (lastError() says why)
};

class HostDepthInput {
 public:
  /// Attaches to the host's channel; fails when it is not there or is neither a distance channel
  /// (format 4) nor a colour channel (RGBA16F linear or RGBA8 sRGB) with a distance plane.
  /// `exposureEv`: an RGBA8 sRGB host colour is decoded through the inverse of fogbeam's own
  /// tone curve at this exposure (packRgba8Srgb: y = x/(1 + x) of x = L·2^EV, sRGB-encoded), so
  /// that a host image passed through a fog-free frame comes back as it was (up to 8-bit steps;
  /// code 255 reads as y = 0.999).
  [[nodiscard]] static Result<std::unique_ptr<HostDepthInput>> attach(const std::string& channel,
                                                                      double exposureEv = 0.0);
  /// The host publishes its colour with its distances.
  [[nodiscard]] bool hasColour() const noexcept { return reader_->format() != FOGBEAM_FORMAT_DISTANCE_F32; }

  /// Reads the newest view into `view` and `surface` (distance filled, rgb zero: the host has
  /// the surfaces). Refused (message in lastError(), `view` and `surface` untouched): a field
  /// of view outside (0°, 180°); a centred view whose fov_y_deg does not give square pixels
  /// (within 0.1 %); an off-axis frustum that Camera::fromFrustum refuses for the channel's
  /// size; a distance that is NaN or negative (+inf is sky; the first bad pixel is named).
  HostDepthStatus latest(HostView& view, SurfaceBuffers& surface);
  [[nodiscard]] const std::string& lastError() const noexcept { return lastError_; }
  /// The channel's `latest` word (ShmReader::latestTag): changes with every host publish.
  [[nodiscard]] std::uint64_t latestTag() const noexcept { return reader_->latestTag(); }
  [[nodiscard]] std::uint32_t width() const noexcept { return reader_->width(); }
  [[nodiscard]] std::uint32_t height() const noexcept { return reader_->height(); }
  [[nodiscard]] std::uint64_t generation() const noexcept { return reader_->generation(); }

 private:
  HostDepthInput() = default;
  std::unique_ptr<ipc::ShmReader> reader_;
  std::vector<std::byte> bytes_;
  std::vector<float> distance_;
  std::array<float, 256> srgbToLinear_{};  ///< RGBA8 host colour: code → cd/m² (attach())
  std::string lastError_;
};

/// What a HostDepthLink has seen since it was made.
struct HostDepthCounts {
  std::uint64_t frames = 0;    ///< distinct host frames read
  std::uint64_t repeated = 0;  ///< steps rendered on a host frame already rendered (a slow or stopped host)
  std::uint64_t refused = 0;   ///< host frames refused (HostDepthInput::latest) or channels of the wrong size
  std::uint64_t lost = 0;      ///< times the host went away (closed, died, replaced)
  std::uint64_t attached = 0;  ///< attaches (the first and every re-attach)
  std::uint64_t last_frame = 0;  ///< the host frame number last read (0 = none)
  bool connected = false;      ///< attached now
  bool stale = false;          ///< no new host frame for more than HostDepthLink::kStaleS
};

/// One output channel's link to its host depth channel (docs/service.md, "Host depth"), for the
/// service's frame loop. It attaches when the host's channel appears (tried at most every
/// 250 ms), keeps the newest valid view, and goes on with it when the host stops publishing or
/// goes away; a host that comes back (a new writer generation) is attached again. Every change
/// is logged once per transition, refused frames at most once per second; nothing the host
/// publishes stops the service.
///
/// Thread-safety: one thread (the frame loop) per link; counts() from the same thread.
class HostDepthLink {
 public:
  /// Seconds without a new host frame before the link reports the host stale (logged once).
  static constexpr double kStaleS = 1.0;
  using Clock = std::chrono::steady_clock;

  /// `channel`: the host's depth channel; `width` × `height`: the output channel's size, which
  /// the host's must equal; `output`: the output channel's name (for the log). `needsColour`:
  /// the output channel composites (host·T + A), so a depth-only host channel is refused;
  /// `exposureEv`: its exposure (HostDepthInput::attach).
  HostDepthLink(std::string channel, int width, int height, std::string output, bool needsColour = false,
                double exposureEv = 0.0);

  /// Once per frame: attaches if needed, reads the newest host view into view() and
  /// surface(). False while no host view has been read yet (nothing to render).
  bool poll(Clock::time_point now);
  /// Lock-step: whether the host has published since the frame last read (one atomic load when
  /// attached; attaches when it is not, at most every 250 ms).
  [[nodiscard]] bool newFrameReady(Clock::time_point now);
  [[nodiscard]] const HostDepthCounts& counts() const noexcept { return counts_; }
  [[nodiscard]] const std::string& channel() const noexcept { return channel_; }
  [[nodiscard]] const HostView& view() const noexcept { return view_; }
  [[nodiscard]] const SurfaceBuffers& surface() const noexcept { return surface_; }
  [[nodiscard]] bool hasView() const noexcept { return counts_.last_frame != 0; }

 private:
  void tryAttach(Clock::time_point now);
  void drop(const char* why);
  std::string channel_, output_;
  int width_, height_;
  bool needsColour_;
  double exposureEv_;
  std::unique_ptr<HostDepthInput> in_;
  HostView view_, scratchView_;
  SurfaceBuffers surface_, scratch_;
  HostDepthCounts counts_;
  std::uint64_t renderedTag_ = 0;  ///< latestTag() of the frame last read
  std::uint64_t sizeRefusedGeneration_ = 0;  ///< a wrong-size host generation, refused once
  Clock::time_point nextAttach_{}, lastNew_{}, lastRefusedLog_{}, nextLiveCheck_{};
  bool waitingLogged_ = false;
};

}  // namespace fogbeam::plugin
