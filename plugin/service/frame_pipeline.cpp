// fogbeam — the per-frame step shared by serve and replay (frame_pipeline.hpp).
#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/plugin/frame_pipeline.hpp>

#include <algorithm>
#include <chrono>
#include <utility>

namespace fogbeam::plugin {

Result<SurfacePass> openSurfacePass(const ServiceConfig& config) {
  SurfacePass pass;
  if (config.surface == "cpu") return pass;
  auto g = GlSurfacePass::create();
  if (g) {
    pass.gl = std::move(g).value();
    return pass;
  }
  if (config.surface == "gl") return g.error();
  if (config.effects.render.airlight == AirlightDevice::Gpu)
    return Error{"[render] airlight = \"gpu\" needs the GL surface pass: " + g.error().message};
  pass.fallback = g.error().message;
  return pass;
}

Result<std::unique_ptr<FramePipeline>> FramePipeline::create(ServiceConfig config, const Scene& world,
                                                             std::unique_ptr<GlSurfacePass> gl, bool awaitTables) {
  std::unique_ptr<FramePipeline> p(new FramePipeline());
  // The renderers keep a pointer to the configuration: it lives in the pipeline, which does
  // not move (held by unique_ptr).
  p->config_ = std::move(config);
  p->gl_ = std::move(gl);
  p->awaitTables_ = awaitTables;
  for (std::size_t c = 0; c < p->config_.channels.size(); ++c) {
    auto r = ChannelRenderer::create(p->config_, c, world, p->gl_.get());
    if (!r) return r.error();
    p->renderers_.push_back(std::move(r).value());
  }
  return p;
}

FramePipeline::~FramePipeline() = default;

Status FramePipeline::step(const ipc::SimSnapshot& state, ipc::Clock::time_point now, FrameBookkeeping book,
                           FrameSink& sink, std::size_t* failedChannel, std::span<const HostFrame* const> hosts) {
  // Input-to-frame latency starts at the arrival of the newest message the state holds.
  ipc::Clock::time_point newest{};
  for (const ipc::Stamp* s : {&state.ego.stamp, &state.lamps.stamp, &state.environment.stamp, &state.frame_request.stamp})
    if (s->valid) newest = std::max(newest, s->received);
  for (std::size_t c = 0; c < renderers_.size(); ++c) {
    const HostFrame* host = c < hosts.size() ? hosts[c] : nullptr;
    if (!host && !config_.channels[c].depth_from.empty()) continue;  // no host view yet
    Status s = renderers_[c]->render(state, now, awaitTables_, frame_, host);
    if (s) {
      book.latency_ms.reset();
      if (host) {
        // A host view's input is the host's depth frame: from its publish (CLOCK_MONOTONIC, the
        // clock of both sides) to the end of the render.
        book.latency_ms = static_cast<double>(ipc::monotonicNs() - host->view->publish_ns) * 1e-6;
      } else if (newest != ipc::Clock::time_point{}) {
        book.latency_ms = std::chrono::duration<double, std::milli>(ipc::Clock::now() - newest).count();
      }
      s = sink.consume(c, frame_, book);
    }
    if (!s) {
      if (failedChannel) *failedChannel = c;
      return s;
    }
  }
  return Ok{};
}

}  // namespace fogbeam::plugin
