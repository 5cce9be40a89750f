// fogbeam — the per-frame step that `fogbeam serve` and `fogbeam replay` share: one state
// snapshot → every channel rendered (ChannelRenderer, frame_renderer.hpp) → each frame handed,
// with the frame loop's bookkeeping, to a sink. The service's sink maps frames to the wire and
// publishes them in shared memory (Service, service.hpp); replay's writes image files and CSV
// rows (plugin/cli/cmd_replay.cpp). Neither renders any other way, so a replay shows what a cab
// is shown for the same states, byte for byte.
//
// A pipeline owns a copy of the service configuration (its renderers point into it), the GL
// surface pass when there is one, one ChannelRenderer per [[channel]] and one reused frame.
//
// Overlapped frames ([render] overlap_frames; docs/service.md, "Overlapped frames"): submit()
// runs the surface pass of the state it is given (ChannelRenderer::begin, on the calling thread,
// which owns the GL context) while the previous state's airlight, glow, glare, composite and
// packing (ChannelRenderer::finish) run on the pipeline's worker thread; then it starts this
// one's rest on the worker and hands the previous frame to the sink meanwhile (two sets of
// frame buffers per channel). A frame therefore reaches the sink one submit() (or flush())
// later than in sequence. The renderers make the same calls
// in the same order on the same data either way, so the frames are byte for byte those of
// step(). Without overlap, submit() is step().
//
// Errors: a call stops at the first error in frame order (a renderer's, the sink's) and says
// which channel; frames before it have been handed to the sink, none after. The pipeline is then
// stopped: nothing runs on its worker, and every later call returns that error again (a renderer
// that failed is not trusted with another frame; serve and replay stop).
//
// Thread-safety: one thread drives a FramePipeline; the sink is called on that thread. The
// worker thread (overlap only) touches the renderers' finish() side and the frames it fills,
// never the sink or GL.
#pragma once

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/render/fog_light.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <array>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

namespace fogbeam::plugin {

/// What the frame loop adds to a rendered frame: which frame it is and how fresh its input was.
struct FrameBookkeeping {
  /// The frame's number: in lock-step the requested one, free-running a count from 1; replay's
  /// frame index k.
  std::uint64_t frame = 0;
  std::uint64_t frame_request = 0;  ///< the frame request it answers (lock-step); 0 otherwise
  /// Input to frame, ms: from the receive time of the newest ego, lamp, environment or
  /// frame-request message of the state to the moment the channel's frame is handed to the sink
  /// (in sequence: the end of its render). Empty when the state holds none of them. Measured by
  /// FramePipeline, per channel.
  std::optional<double> latency_ms;
};

/// Where a pipeline's frames go.
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  /// One channel's frame, `channel` indexing ServiceConfig::channels, called by
  /// FramePipeline::step / submit / flush in channel order on the pipeline's thread. `frame` is valid during the call only
  /// (the pipeline reuses its buffers). An error ends the step with it.
  [[nodiscard]] virtual Status consume(std::size_t channel, const RenderedFrame& frame,
                                       const FrameBookkeeping& book) = 0;
};

/// The surface pass a configuration asks for ([render] surface): "cpu" none; "gl" a GL pass or
/// an error; "auto" a GL pass, or none with the reason in `fallback` (the caller says so in its
/// own words) — except with [render] airlight = "gpu", which needs the pass (an error).
struct SurfacePass {
  std::unique_ptr<GlSurfacePass> gl;  ///< null: CPU planes
  std::string fallback;               ///< "auto" without GL: why (empty otherwise)
};
[[nodiscard]] Result<SurfacePass> openSurfacePass(const ServiceConfig& config);

/// "auto" overlaps frames from this many hardware threads on (measured on 2: no gain).
inline constexpr unsigned kOverlapMinCores = 4;

/// Whether `config` overlaps frames: [render] overlap_frames "on"; "auto" where cores allow
/// (std::thread::hardware_concurrency() ≥ kOverlapMinCores and [render] threads ≠ 1); never
/// with a depth_from channel (a host's depth frame is its request, and its buffers are the
/// host's: no next state to begin early).
[[nodiscard]] bool overlapsFrames(const ServiceConfig& config);

class FramePipeline {
 public:
  /// A renderer for every channel of `config` over `world` (its world lamps, planes, glTF),
  /// with `gl` (from openSurfacePass; may be null). `awaitTables`: a frame waits for fog and
  /// bending table builds (lock-step, replay: deterministic frames) instead of going on with
  /// the previous tables while a build runs in the background (free-running). Frames overlap
  /// when overlapsFrames(config) (a worker thread is started).
  [[nodiscard]] static Result<std::unique_ptr<FramePipeline>> create(ServiceConfig config, const Scene& world,
                                                                     std::unique_ptr<GlSurfacePass> gl,
                                                                     bool awaitTables);
  /// Waits for the frame in flight on the worker (if any; it is not handed to a sink) and joins
  /// the worker; the renderers then wait for their table builds.
  ~FramePipeline();
  FramePipeline(const FramePipeline&) = delete;
  FramePipeline& operator=(const FramePipeline&) = delete;

  /// The step, in sequence: hands the frame in flight to `sink` first (flush()), then renders
  /// every channel of `state` as of `now` (traffic liveness) and hands each frame to `sink` with
  /// `book` (frame number and request as given; latency_ms measured here). Stops at the first
  /// error, of a renderer or of the sink; `failedChannel` (may be null) then receives its
  /// channel. `hosts` (empty, or one per channel): the host view of each channel with
  /// depth_from (ChannelRenderer::render); a channel with depth_from whose entry is null (no
  /// host frame yet) is skipped: no frame, the sink is not called for it.
  [[nodiscard]] Status step(const ipc::SimSnapshot& state, ipc::Clock::time_point now, FrameBookkeeping book,
                            FrameSink& sink, std::size_t* failedChannel = nullptr,
                            std::span<const HostFrame* const> hosts = {});

  /// Overlapped (overlapping()): the surface pass of every channel of `state` on this thread
  /// while the frame in flight finishes on the worker; then this one's rest started on the
  /// worker, and meanwhile the previous submit's frame to `sink` with its own `book`. This one
  /// reaches the sink at the next submit() or flush(). `state` is read during the call only. Errors as
  /// step()'s, in frame order (the previous frame's before this one's). Otherwise step().
  [[nodiscard]] Status submit(const ipc::SimSnapshot& state, ipc::Clock::time_point now, FrameBookkeeping book,
                              FrameSink& sink, std::size_t* failedChannel = nullptr,
                              std::span<const HostFrame* const> hosts = {});
  /// Waits for the frame in flight (submit()) and hands it to `sink`; Ok at once when there is
  /// none. Call it when no next state is coming soon: lock-step without a new request, a
  /// free-running loop ahead of its rate, the end of a replay or a run.
  [[nodiscard]] Status flush(FrameSink& sink, std::size_t* failedChannel = nullptr);

  /// A submitted frame not yet handed to a sink.
  [[nodiscard]] bool inFlight() const noexcept { return inFlight_; }
  /// Frames overlap (overlapsFrames of the configuration).
  [[nodiscard]] bool overlapping() const noexcept { return overlap_; }
  /// Frames handed to sinks, every channel of each consumed without error, since create().
  [[nodiscard]] std::uint64_t handed() const noexcept { return handed_; }

  /// The fog light's maps made ahead ([glow] surfaces on): started by create() for the ego's,
  /// the world's and every traffic class's lamps (FogLightPrewarm); null when the fog light is
  /// off or every channel takes the host's depth. Tests wait on it; frames never do, except for
  /// a map they need that it is building.
  [[nodiscard]] const FogLightPrewarm* fogLightPrewarm() const noexcept { return fogPrewarm_.get(); }

  [[nodiscard]] const ServiceConfig& config() const noexcept { return config_; }
  [[nodiscard]] std::size_t channelCount() const noexcept { return renderers_.size(); }
  /// Channel `c`'s renderer (its FOGBEAM_FORMAT_* for the shared-memory segment: shmFormat()).
  [[nodiscard]] const ChannelRenderer& renderer(std::size_t c) const { return *renderers_.at(c); }

 private:
  FramePipeline() = default;
  /// The error that stopped the pipeline, with its channel; the error itself. Waits for the
  /// worker first, so that nothing runs after it.
  Status stopWith(Error e, std::size_t channel, std::size_t* failedChannel);
  void workerLoop();
  void waitForWorker();
  /// Frame buffers `buffer` (a finished frame) to the sink with `book`.
  Status handOver(std::size_t buffer, FrameBookkeeping book, ipc::Clock::time_point newest, FrameSink& sink,
                  std::size_t* failedChannel);

  ServiceConfig config_;
  std::unique_ptr<FogLightPrewarm> fogPrewarm_;  ///< before gl_ and the renderers: destroyed after them
  std::unique_ptr<GlSurfacePass> gl_;
  std::vector<std::unique_ptr<ChannelRenderer>> renderers_;
  bool awaitTables_ = false;
  bool overlap_ = false;
  RenderedFrame frame_;  ///< one frame's buffers, reused by every channel and step
  std::uint64_t handed_ = 0;
  std::optional<Error> stopped_;  ///< the first error; the pipeline runs nothing after it
  std::size_t stoppedChannel_ = 0;

  // Overlap: the frame in flight and the worker that finishes it. Two sets of buffers: the
  // worker finishes one frame into one while the sink reads the previous from the other.
  std::array<std::vector<RenderedFrame>, 2> frames_;  ///< [set][channel]
  std::size_t flightBuffer_ = 0;  ///< the set the frame in flight is finished into
  bool inFlight_ = false;
  FrameBookkeeping flightBook_;
  ipc::Clock::time_point flightNewest_{};  ///< its state's newest input (latency_ms)
  std::thread worker_;
  std::mutex mutex_;  ///< guards the four below
  std::condition_variable wake_;
  bool jobQueued_ = false;  ///< the frame in flight's finish() is to run or running
  bool quit_ = false;
  /// The worker's result for the frame in flight: the first error and its channel.
  std::optional<Error> jobError_;
  std::size_t jobChannel_ = 0;
};

}  // namespace fogbeam::plugin
