// fogbeam — status on request over UDP (docs/service.md): a host or a person sends the datagram
// "status" (6 bytes, or with a trailing newline) to the service's status port and gets one
// datagram back: a JSON object with frame rate, stage times, input ages and drop counts.
//
// The reply is produced by a callback on the server's thread; anything else received is counted
// and ignored. Replies are rate-limited (at most `max_replies_per_s`, the rest counted), so the
// port cannot be used to amplify traffic; a reply is never larger than `max_reply_bytes`.
//
// Thread-safety: start()/stop() from one thread; the callback runs on the server thread and
// must be thread-safe with respect to the frame loop (copy a mutex-protected summary).
#pragma once

#include <fogbeam/util/result.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

namespace fogbeam::ipc {

struct StatusServerOptions {
  std::string bind_address = "127.0.0.1";
  std::uint16_t port = 47801;       ///< 0 = any free port (see port())
  int max_replies_per_s = 50;
  std::size_t max_reply_bytes = 8192;
};

struct StatusServerStats {
  std::uint64_t requests = 0, replies = 0, ignored = 0, rate_limited = 0;
  /// poll/recvfrom/sendto failures (other than "nothing to read" or a signal), logged at most once
  /// per second; the server goes on.
  std::uint64_t errors = 0;
};

class StatusServer {
 public:
  [[nodiscard]] static Result<std::unique_ptr<StatusServer>> start(const StatusServerOptions& options,
                                                                   std::function<std::string()> reply);
  ~StatusServer();
  StatusServer(const StatusServer&) = delete;
  StatusServer& operator=(const StatusServer&) = delete;
  void stop();
  [[nodiscard]] std::uint16_t port() const noexcept { return port_; }
  [[nodiscard]] StatusServerStats stats() const;

 private:
  StatusServer() = default;
  void run();
  void socketError(const char* call, int error);  // server thread: count, rate-limited log
  StatusServerOptions options_;
  std::function<std::string()> reply_;
  UniqueFd fd_;
  std::uint16_t port_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> requests_{0}, replies_{0}, ignored_{0}, limited_{0}, errors_{0};
  std::chrono::steady_clock::time_point lastErrorLog_{};  // server thread only
  std::uint64_t errorsSinceLog_ = 0;                      // server thread only
  std::thread thread_;
};

/// Asks a status server once (loopback tools and tests): sends "status", waits up to
/// `timeout_s` for the reply.
[[nodiscard]] Result<std::string> requestStatus(const std::string& address, std::uint16_t port, double timeout_s = 1.0);

}  // namespace fogbeam::ipc
