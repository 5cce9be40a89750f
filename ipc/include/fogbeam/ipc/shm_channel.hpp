// fogbeam — shared-memory frame channels (layout: fogbeam/ipc/shm_layout.h, docs/shm.md).
//
// ShmWriter (the fogbeam service, one per output channel) creates a POSIX shared-memory segment
// "/fogbeam.<channel>" (mode 0600, or 0660 with group access), publishes frames into a ring of
// slots with a seqlock per slot, keeps a heartbeat, and marks the channel closed and unlinks it
// on destruction (unless another writer has replaced it as stale meanwhile: ShmName,
// shm_mapping.hpp). A segment left by a crashed writer (dead pid or heartbeat older than 2 s) is
// replaced; one whose writer is alive is refused with the writer's pid.
//
// ShmReader (image generators, tests, `fogbeam view`; the C SDK in fogbeam_host.h wraps it)
// attaches by channel name, validates the header against the mapping, and copies the newest
// complete frame; it notices a closed, dead or restarted writer (generation change).
//
// Thread-safety: one thread per ShmWriter (heartbeat() from any thread); one thread per ShmReader. Any number of readers in
// any number of processes may read one channel while its writer publishes.
#pragma once

#include <fogbeam/ipc/shm_mapping.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace fogbeam::ipc {

/// Longest channel name (docs/shm.md): "/fogbeam." + 48 characters stays well inside NAME_MAX,
/// and the name fits the header's NUL-terminated char[64].
inline constexpr std::size_t kMaxChannelName = 48;

/// A valid channel name: 1–kMaxChannelName characters from [A-Za-z0-9_.-].
[[nodiscard]] bool validChannelName(const std::string& name) noexcept;

struct ShmChannelOptions {
  std::string channel;        ///< [A-Za-z0-9_.-], 1–48 characters; segment "/fogbeam.<channel>"
  std::uint32_t width = 0, height = 0;
  std::uint32_t format = 1;   ///< FOGBEAM_FORMAT_* (shm_layout.h); DISTANCE_F32 for host depth input
  bool distance = false;      ///< add an f32 distance plane per slot
  std::uint32_t slots = 3;    ///< ≥ 3
  bool group_access = false;  ///< mode 0660 instead of 0600
};

/// Metadata published with every frame (shm_layout.h, FOGBEAM_SLOT_*).
struct FrameMeta {
  std::uint64_t frame = 0;
  double sim_time_s = 0.0;
  std::array<double, 3> position_m{0.0, 0.0, 0.0};
  float yaw_deg = 0.0f, pitch_deg = 0.0f, roll_deg = 0.0f;
  std::uint32_t lights = 0;
  std::uint32_t ego_sequence = 0, lamp_sequence = 0, environment_sequence = 0;
  std::uint32_t traffic_count = 0;
  double surface_ms = 0.0, airlight_ms = 0.0, composite_ms = 0.0, total_ms = 0.0;
  double latency_ms = 0.0;      ///< input receive → publish
  std::uint64_t frame_request = 0;
  std::uint64_t publish_ns = 0; ///< CLOCK_MONOTONIC, set by publish()
  float fov_x_deg = 0.0f;       ///< camera field of view (host depth input; 0 elsewhere)
  float fov_y_deg = 0.0f;       ///< 0 = from the aspect ratio
  /// Off-axis view: left, right, up, down half-angles from the view axis, deg (positive
  /// outwards); all 0 = a centred pinhole given by fov_x_deg (and fov_y_deg).
  std::array<float, 4> frustum_deg{0.0f, 0.0f, 0.0f, 0.0f};
  /// On fogbeam's frames: the host depth frame (its `frame`) the frame was rendered on; 0 = a
  /// view of fogbeam's own (docs/service.md, depth_from).
  std::uint64_t host_frame = 0;
};

/// Bytes per pixel of a FOGBEAM_FORMAT_* value (0 for an unknown one).
[[nodiscard]] std::uint32_t bytesPerPixel(std::uint32_t format) noexcept;
/// CLOCK_MONOTONIC in nanoseconds (the clock of heartbeats and publish times).
[[nodiscard]] std::uint64_t monotonicNs() noexcept;

class ShmWriter {
 public:
  [[nodiscard]] static Result<std::unique_ptr<ShmWriter>> create(const ShmChannelOptions& options);
  ~ShmWriter();  ///< marks the channel closed, unmaps, closes and unlinks (once; only its own segment)
  ShmWriter(const ShmWriter&) = delete;
  ShmWriter& operator=(const ShmWriter&) = delete;

  /// Publishes one frame. `pixels` must hold width·height·bytesPerPixel bytes, `distance`
  /// width·height floats when the channel has a distance plane (else it is ignored). Never
  /// waits for readers. Returns the slot used.
  std::uint32_t publish(FrameMeta meta, std::span<const std::byte> pixels, std::span<const float> distance = {});
  /// Refreshes the heartbeat without a frame (a paused or slow service stays "alive"). May be
  /// called from another thread than publish() (one atomic store).
  void heartbeat() noexcept;

  [[nodiscard]] const std::string& segmentName() const noexcept { return name_; }
  [[nodiscard]] std::uint64_t generation() const noexcept { return generation_; }
  [[nodiscard]] bool replacedStale() const noexcept { return replacedStale_; }

 private:
  ShmWriter() = default;
  std::string name_;
  // Destroyed in reverse order: unmap, close, then unlink the name (once: ShmName).
  ShmName segment_;
  UniqueFd fd_;
  ShmMapping mapping_;
  std::uint32_t slots_ = 0, next_ = 0;
  std::uint64_t generation_ = 0;
  bool replacedStale_ = false;
};

enum class ReadStatus {
  Ok,          ///< a whole frame was copied
  NoFrame,     ///< nothing published yet
  Busy,        ///< every attempt overlapped a write (the reader is too slow); try again
  WriterGone,  ///< the writer closed the channel, died (pid gone or no heartbeat) or was replaced: re-attach
};

class ShmReader {
 public:
  /// Maps "/fogbeam.<channel>" read-only and checks the header (magic, version, sizes).
  [[nodiscard]] static Result<std::unique_ptr<ShmReader>> attach(const std::string& channel);
  ~ShmReader();
  ShmReader(const ShmReader&) = delete;
  ShmReader& operator=(const ShmReader&) = delete;

  /// Copies the newest complete frame (pixels resized to fit; distance only when non-null and
  /// the channel has the plane). `heartbeat_timeout_s`: a writer silent for longer is gone.
  ReadStatus latest(FrameMeta& meta, std::vector<std::byte>& pixels, std::vector<float>* distance = nullptr,
                    double heartbeat_timeout_s = 2.0);

  [[nodiscard]] std::uint32_t width() const noexcept { return width_; }
  [[nodiscard]] std::uint32_t height() const noexcept { return height_; }
  [[nodiscard]] std::uint32_t format() const noexcept { return format_; }
  [[nodiscard]] bool hasDistance() const noexcept { return distanceOffset_ != 0; }
  [[nodiscard]] std::uint64_t generation() const noexcept { return generation_; }
  /// The header's `latest` word, (frame number << 8) | slot, 0 before the first frame: it changes
  /// with every publish, so a poller (`fogbeam view`) calls latest() only when it did. One atomic
  /// load; says nothing about the writer's liveness (latest() checks that).
  [[nodiscard]] std::uint64_t latestTag() const noexcept;
  /// Attempts that overlapped a write and were retried, since attach.
  [[nodiscard]] std::uint64_t retries() const noexcept { return retries_; }

 private:
  ShmReader() = default;
  std::string name_;
  ShmMapping mapping_;  ///< read-only
  std::uint32_t width_ = 0, height_ = 0, format_ = 0, slots_ = 0;
  std::uint64_t firstSlot_ = 0, stride_ = 0, pixelsOffset_ = 0, pixelsBytes_ = 0, distanceOffset_ = 0;
  std::uint64_t generation_ = 0;
  std::uint64_t retries_ = 0;
};

}  // namespace fogbeam::ipc
