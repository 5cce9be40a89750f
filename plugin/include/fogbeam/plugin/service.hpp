// fogbeam — the cab service (`fogbeam serve`, docs/service.md) as one object: it owns what a
// running service is made of and runs its frame loop. `fogbeam serve` is option parsing, config
// loading and a Service; tests and other hosts create one the same way.
//
// What it owns, and the threads it runs (all started by create(), all joined by stop()):
//  * inputs: the state store, fed by the UDP receiver (docs/protocol.md; a thread), the CAN
//    source (docs/can.md; a thread, when [input.can] source is set) and the scenario player
//    (docs/scenario.md; a thread, until a host's first message). Nothing from the network can
//    stop or crash them: bad input is counted, logged rate-limited and dropped.
//  * the host watch: once per frame, purges traffic not updated for traffic_timeout_s and logs
//    a host that went silent (once per transition) and the purges (at most once per second).
//  * frames: the frame pipeline (frame_pipeline.hpp: every channel rendered from one snapshot,
//    the same step `fogbeam replay` runs) into one shared-memory writer per channel
//    (docs/shm.md), each frame's metadata made by wireMeta. A heartbeat thread marks every
//    channel alive every 250 ms, so a frame that waits for tables does not look like a dead
//    writer.
//  * status: the status board (figures for the log line every [status] interval_s) and the
//    status server (a thread answering "status" datagrams with statusJson()).
//
// The frame loop (run(), on the caller's thread): free-running, frames paced at rate_hz on a
// steady clock (a frame late by more than a period restarts the pace from now instead of
// bursting to catch up); or lock-step, one frame per new frame request (a request counts as new
// when its sequence number differs from the last), tables awaited so runs are deterministic.
// With overlapped frames (FramePipeline::submit, [render] overlap_frames) a frame is published
// with the next one's surface pass when the loop is behind its rate or the next request is
// already there, and at once otherwise; at the loop's end the frame in flight is published.
//
// Thread-safety: create(), run() and stop() from one owner (run() may be on a thread of its
// own; stop() then waits for it). requestStop() from anywhere, signal handlers included. The
// read-only accessors (ports, frames(), udpStats(), statusJson()) from any thread.
#pragma once

#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/ipc/udp_receiver.hpp>
#include <fogbeam/plugin/frame_pipeline.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/util/result.hpp>

#include <cstdint>
#include <memory>
#include <string>

namespace fogbeam::plugin {

/// The wire metadata of one published frame (shm_layout.h, FOGBEAM_SLOT_*): what the renderer
/// knows (view, inputs, stage times) and the frame loop's bookkeeping (frame number, request,
/// input-to-publish latency, 0 when the state held no input). publish_ns is left 0: the shm
/// writer stamps it. A pure function.
[[nodiscard]] ipc::FrameMeta wireMeta(const RenderedFrame& frame, const FrameBookkeeping& book);

struct ServiceOptions {
  /// [status] udp_port = 0 binds the status server to any free port (statusPort() says which)
  /// instead of turning it off: for tests and for hosts that start several services.
  bool any_status_port = false;
};

/// When run() returns by itself (0 = no limit).
struct RunLimits {
  double duration_s = 0.0;   ///< wall-clock seconds from the call, checked between frames
  std::uint64_t frames = 0;  ///< frames rendered by this call
};

class Service {
 public:
  /// Starts everything but the frame loop: loads the scenario and the world scene (a scenario's
  /// own scene when [world] scenario is set, else [world] scene), binds UDP (and CAN), opens the
  /// GL surface pass per [render] surface, creates every channel's renderer and shared-memory
  /// segment, starts the status server, the scenario player and the heartbeat, and logs the
  /// channels and ports. `config` is as loadServiceConfig gives it (validated). Errors are
  /// complete messages (a bad scenario or scene file, a port in use, a channel whose segment
  /// cannot be created or whose writer is alive in another process …); nothing is left running.
  [[nodiscard]] static Result<std::unique_ptr<Service>> create(ServiceConfig config,
                                                               const ServiceOptions& options = {});
  ~Service();  ///< stop()
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  /// The frame loop on the calling thread, until requestStop() or stop(), a limit, or a frame
  /// that fails (a renderer's own failure: logged as "serve: channel NAME: …" and returned; the
  /// service then stops). Ok at once after a stop; an error when already running elsewhere.
  /// May be called again after it returned for a limit: frame numbers go on.
  [[nodiscard]] Status run(const RunLimits& limits = {});
  /// Asks the frame loop to end after the frame in progress (a free-running loop waiting for
  /// its next frame ends within 50 ms). Async-signal-safe: one lock-free atomic store.
  void requestStop() noexcept;
  /// requestStop(), then waits for run() to return, joins every thread (scenario player, status
  /// server, heartbeat, CAN, UDP, table builds) and closes and unlinks the channels. Idempotent;
  /// afterwards run() returns at once and the accessors give the final figures.
  void stop();

  /// The bound UDP input port ([input.udp] port, or the one 0 picked); kept after stop().
  [[nodiscard]] std::uint16_t udpPort() const noexcept;
  /// The bound status port; 0 = no status server.
  [[nodiscard]] std::uint16_t statusPort() const noexcept;
  /// Frames published since create() (a frame on every channel counts once).
  [[nodiscard]] std::uint64_t frames() const noexcept;
  /// The UDP receiver's counts (final ones after stop()).
  [[nodiscard]] ipc::UdpStats udpStats() const;
  /// The status reply (docs/service.md, [status]): frame and stage figures as of the last
  /// status interval, current UDP counts. A JSON object.
  [[nodiscard]] std::string statusJson() const;
  /// The configuration the service runs (as given to create()).
  [[nodiscard]] const ServiceConfig& config() const noexcept;
  /// The world scene file rendered.
  [[nodiscard]] const std::string& worldPath() const noexcept;

  struct Impl;

 private:
  explicit Service(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace fogbeam::plugin
