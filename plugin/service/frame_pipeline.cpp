// fogbeam — the per-frame step shared by serve and replay (frame_pipeline.hpp).
#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/plugin/frame_pipeline.hpp>
#include <fogbeam/render/airlight_image.hpp>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <utility>

namespace fogbeam::plugin {

Result<SurfacePass> openSurfacePass(const ServiceConfig& config) {
  SurfacePass pass;
  if (config.surface == "cpu") return pass;
  GlOptions options;
  options.table_cache_dir = tableCacheDirFor(config.table_cache);  // the fog light's table and annulus maps
  auto g = GlSurfacePass::create(options);
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

bool overlapsFrames(const ServiceConfig& config) {
  if (std::any_of(config.channels.begin(), config.channels.end(), [](const ChannelConfig& c) { return !c.depth_from.empty(); }))
    return false;
  if (config.overlap_frames == "on") return true;
  if (config.overlap_frames == "off") return false;
  // "auto": where cores are left over while the frame in sequence keeps its cores busy. On 2
  // cores it does not pay (docs/service.md, "Overlapped frames": no more frames per second,
  // latency ×1.8, the two halves' thread pools contending for the same cores); the estimate for
  // 8 cores is ~30 % more frames. threads = 1 asks for one core.
  return std::thread::hardware_concurrency() >= kOverlapMinCores && config.threads != 1;
}

namespace {

/// The arrival of the newest message a state holds (input-to-frame latency starts there);
/// the epoch when it holds none.
ipc::Clock::time_point newestInput(const ipc::SimSnapshot& state) {
  ipc::Clock::time_point newest{};
  for (const ipc::Stamp* s : {&state.ego.stamp, &state.lamps.stamp, &state.environment.stamp, &state.frame_request.stamp})
    if (s->valid) newest = std::max(newest, s->received);
  return newest;
}

/// The fog light's maps for every lamp the configuration can show, made on a thread of their
/// own while the channels start (FogLightPrewarm): the ego's lamps first (the first frame shows
/// them), then the world's, then each traffic class's, so that the first car of a lamp file
/// never seen before (no map in the table cache) does not hold its frame for the map's ~1 s.
/// Null when the fog light is off ([glow] enabled and surfaces), the fog scatters nothing, or
/// every channel takes the host's depth (no surfaces of fogbeam's own to light).
std::unique_ptr<FogLightPrewarm> startFogLightPrewarm(const ServiceConfig& config, const Scene& world) {
  const GlowOptions& glow = config.effects.glow;
  if (!glow.enabled || !glow.surfaces || !(config.fog.albedo > 0.0)) return nullptr;
  if (std::all_of(config.channels.begin(), config.channels.end(),
                  [](const ChannelConfig& c) { return !c.depth_from.empty(); }))
    return nullptr;
  std::vector<FogLightPrewarm::Lamp> lamps;
  for (const RigLamp& r : config.ego.lamps) lamps.push_back({r.lamp.lamp.profile, true});
  for (const SceneLamp& l : world.lamps)
    if (l.mount == LampMount::World) lamps.push_back({l.lamp.profile, false});
  for (const auto& [cls, rig] : config.traffic)
    for (const RigLamp& r : rig.lamps) lamps.push_back({r.lamp.lamp.profile, false});
  return std::make_unique<FogLightPrewarm>(
      std::move(lamps), config.fog.phase, config.fog.albedo, config.threads, tableCacheDirFor(config.table_cache),
      [](const FogLightPrewarm::Summary& s) {
        spdlog::info("fog light: {} annulus map(s) ready in {:.2f} s ahead of the frames ({} from the table cache)",
                     s.maps.size(), s.seconds, s.loaded);
        if (!s.error.empty())
          spdlog::warn("fog light, maps made ahead: {} (a map not made is made by the frame that needs it; one "
                       "not stored, by the next start)",
                       s.error);
      });
}

}  // namespace

Result<std::unique_ptr<FramePipeline>> FramePipeline::create(ServiceConfig config, const Scene& world,
                                                             std::unique_ptr<GlSurfacePass> gl, bool awaitTables) {
  std::unique_ptr<FramePipeline> p(new FramePipeline());
  // The renderers keep a pointer to the configuration: it lives in the pipeline, which does
  // not move (held by unique_ptr).
  p->config_ = std::move(config);
  p->gl_ = std::move(gl);
  p->awaitTables_ = awaitTables;
  p->fogPrewarm_ = startFogLightPrewarm(p->config_, world);
  for (std::size_t c = 0; c < p->config_.channels.size(); ++c) {
    auto r = ChannelRenderer::create(p->config_, c, world, p->gl_.get());
    if (!r) return r.error();
    p->renderers_.push_back(std::move(r).value());
  }
  p->overlap_ = overlapsFrames(p->config_);
  if (p->overlap_) {
    for (auto& set : p->frames_) set.resize(p->renderers_.size());
    p->worker_ = std::thread([q = p.get()] { q->workerLoop(); });
  }
  return p;
}

FramePipeline::~FramePipeline() {
  if (worker_.joinable()) {
    {
      std::lock_guard lock(mutex_);
      quit_ = true;
    }
    wake_.notify_all();
    worker_.join();  // after the frame in flight's finish(), when one runs
  }
}

void FramePipeline::workerLoop() {
  std::unique_lock lock(mutex_);
  while (true) {
    wake_.wait(lock, [&] { return quit_ || jobQueued_; });
    if (!jobQueued_) return;  // quit, nothing queued
    std::vector<RenderedFrame>& frames = frames_[flightBuffer_];
    lock.unlock();
    // Stages 4–6 of the frame in flight, channel by channel, into its set of buffers; stops at
    // the first error. No GL, no sink here (ChannelRenderer::finish).
    std::optional<Error> error;
    std::size_t channel = 0;
    for (std::size_t c = 0; c < renderers_.size() && !error; ++c) {
      try {
        if (Status s = renderers_[c]->finish(frames[c]); !s) error = s.error();
      } catch (const std::exception& e) {
        // On this thread an exception would end the process; in sequence it reaches the caller.
        error = Error{std::string("frame renderer: ") + e.what()};
      }
      if (error) channel = c;
    }
    lock.lock();
    jobError_ = std::move(error);
    jobChannel_ = channel;
    jobQueued_ = false;
    wake_.notify_all();
  }
}

void FramePipeline::waitForWorker() {
  if (!worker_.joinable()) return;
  std::unique_lock lock(mutex_);
  wake_.wait(lock, [&] { return !jobQueued_; });
}

Status FramePipeline::stopWith(Error e, std::size_t channel, std::size_t* failedChannel) {
  waitForWorker();
  if (!stopped_) {
    stopped_ = e;
    stoppedChannel_ = channel;
  }
  if (failedChannel) *failedChannel = channel;
  return e;
}

Status FramePipeline::handOver(std::size_t buffer, FrameBookkeeping book, ipc::Clock::time_point newest,
                               FrameSink& sink, std::size_t* failedChannel) {
  for (std::size_t c = 0; c < renderers_.size(); ++c) {
    // Latency to the frame's hand-over: in flight it also waited for the next frame's surfaces.
    book.latency_ms.reset();
    if (newest != ipc::Clock::time_point{})
      book.latency_ms = std::chrono::duration<double, std::milli>(ipc::Clock::now() - newest).count();
    if (Status s = sink.consume(c, frames_[buffer][c], book); !s) return stopWith(s.error(), c, failedChannel);
  }
  ++handed_;
  return Ok{};
}

Status FramePipeline::flush(FrameSink& sink, std::size_t* failedChannel) {
  if (stopped_) return stopWith(*stopped_, stoppedChannel_, failedChannel);
  if (!inFlight_) return Ok{};
  waitForWorker();
  inFlight_ = false;
  if (jobError_) return stopWith(*jobError_, jobChannel_, failedChannel);
  return handOver(flightBuffer_, flightBook_, flightNewest_, sink, failedChannel);
}

Status FramePipeline::submit(const ipc::SimSnapshot& state, ipc::Clock::time_point now, FrameBookkeeping book,
                             FrameSink& sink, std::size_t* failedChannel, std::span<const HostFrame* const> hosts) {
  if (!overlap_) return step(state, now, book, sink, failedChannel, hosts);
  if (stopped_) return stopWith(*stopped_, stoppedChannel_, failedChannel);
  // overlapsFrames() is false with depth_from channels: no host views here.
  if (std::any_of(hosts.begin(), hosts.end(), [](const HostFrame* h) { return h != nullptr; }))
    return stopWith(Error{"FramePipeline::submit: host views are not overlapped (a depth_from channel)"}, 0,
                    failedChannel);
  // 1. This state's stages 1–3 (tables, scenes, surfaces) here, on the GL thread, beside the
  // frame in flight's stages 4–6 on the worker.
  std::optional<Error> beginError;
  std::size_t beginChannel = 0;
  for (std::size_t c = 0; c < renderers_.size() && !beginError; ++c) {
    if (Status s = renderers_[c]->begin(state, now, awaitTables_); !s) {
      beginError = s.error();
      beginChannel = c;
    }
  }
  // 2. The frame in flight done; its errors come first (an earlier frame).
  const bool previous = inFlight_;
  const std::size_t previousBuffer = flightBuffer_;
  const FrameBookkeeping previousBook = flightBook_;
  const ipc::Clock::time_point previousNewest = flightNewest_;
  waitForWorker();
  inFlight_ = false;
  if (previous && jobError_) return stopWith(*jobError_, jobChannel_, failedChannel);
  // 3. This frame's stages 4–6 on the worker, into the other set of buffers; it reaches the
  // sink at the next submit or flush.
  if (!beginError) {
    flightBuffer_ = previous ? 1 - previousBuffer : previousBuffer;
    flightBook_ = book;
    flightNewest_ = newestInput(state);
    inFlight_ = true;
    {
      std::lock_guard lock(mutex_);
      jobQueued_ = true;
      jobError_.reset();
    }
    wake_.notify_all();
  }
  // 4. Meanwhile the previous frame to the sink (an error there waits for the worker and stops).
  if (previous) {
    if (Status s = handOver(previousBuffer, previousBook, previousNewest, sink, failedChannel); !s) {
      inFlight_ = false;
      return s;
    }
  }
  if (beginError) return stopWith(*beginError, beginChannel, failedChannel);
  return Ok{};
}

Status FramePipeline::step(const ipc::SimSnapshot& state, ipc::Clock::time_point now, FrameBookkeeping book,
                           FrameSink& sink, std::size_t* failedChannel, std::span<const HostFrame* const> hosts) {
  if (Status s = flush(sink, failedChannel); !s) return s;  // the frame in flight first (and a stopped pipeline)
  // Input-to-frame latency starts at the arrival of the newest message the state holds.
  const ipc::Clock::time_point newest = newestInput(state);
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
    if (!s) return stopWith(s.error(), c, failedChannel);
  }
  ++handed_;
  return Ok{};
}

}  // namespace fogbeam::plugin
