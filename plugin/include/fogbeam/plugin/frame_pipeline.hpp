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
// Thread-safety: one thread drives a FramePipeline; the sink is called on that thread.
#pragma once

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace fogbeam::plugin {

/// What the frame loop adds to a rendered frame: which frame it is and how fresh its input was.
struct FrameBookkeeping {
  /// The frame's number: in lock-step the requested one, free-running a count from 1; replay's
  /// frame index k.
  std::uint64_t frame = 0;
  std::uint64_t frame_request = 0;  ///< the frame request it answers (lock-step); 0 otherwise
  /// Input to frame, ms: from the receive time of the newest ego, lamp, environment or
  /// frame-request message of the state to the end of the channel's render. Empty when the
  /// state holds none of them. Measured by FramePipeline::step, per channel.
  std::optional<double> latency_ms;
};

/// Where a pipeline's frames go.
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  /// One channel's frame, `channel` indexing ServiceConfig::channels, called by
  /// FramePipeline::step in channel order on its thread. `frame` is valid during the call only
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

class FramePipeline {
 public:
  /// A renderer for every channel of `config` over `world` (its world lamps, planes, glTF),
  /// with `gl` (from openSurfacePass; may be null). `awaitTables`: a frame waits for fog and
  /// bending table builds (lock-step, replay: deterministic frames) instead of going on with
  /// the previous tables while a build runs in the background (free-running).
  [[nodiscard]] static Result<std::unique_ptr<FramePipeline>> create(ServiceConfig config, const Scene& world,
                                                                     std::unique_ptr<GlSurfacePass> gl,
                                                                     bool awaitTables);
  ~FramePipeline();
  FramePipeline(const FramePipeline&) = delete;
  FramePipeline& operator=(const FramePipeline&) = delete;

  /// The step: renders every channel of `state` as of `now` (traffic liveness) and hands each
  /// frame to `sink` with `book` (frame number and request as given; latency_ms measured here).
  /// Stops at the first error, of a renderer or of the sink; `failedChannel` (may be null)
  /// then receives its channel. `hosts` (empty, or one per channel): the host view of each
  /// channel with depth_from (ChannelRenderer::render); a channel with depth_from whose entry is
  /// null (no host frame yet) is skipped: no frame, the sink is not called for it.
  [[nodiscard]] Status step(const ipc::SimSnapshot& state, ipc::Clock::time_point now, FrameBookkeeping book,
                            FrameSink& sink, std::size_t* failedChannel = nullptr,
                            std::span<const HostFrame* const> hosts = {});

  [[nodiscard]] const ServiceConfig& config() const noexcept { return config_; }
  [[nodiscard]] std::size_t channelCount() const noexcept { return renderers_.size(); }
  /// Channel `c`'s renderer (its FOGBEAM_FORMAT_* for the shared-memory segment: shmFormat()).
  [[nodiscard]] const ChannelRenderer& renderer(std::size_t c) const { return *renderers_.at(c); }

 private:
  FramePipeline() = default;
  ServiceConfig config_;
  std::unique_ptr<GlSurfacePass> gl_;
  std::vector<std::unique_ptr<ChannelRenderer>> renderers_;
  bool awaitTables_ = false;
  RenderedFrame frame_;  ///< one frame's buffers, reused by every channel and step
};

}  // namespace fogbeam::plugin
