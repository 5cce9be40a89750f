// Helpers shared by the tests that run a plugin::Service (tests/plugin/test_service*.cpp,
// test_host_loop.cpp): the test fog's tables held for the whole binary, polling with a timeout,
// a service's frame loop on a thread of its own, and a loopback UDP sender.
#pragma once

#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/plugin/service.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <thread>
#include <vector>

namespace fogbeam::plugin::test {

/// The accurate method's G-moment table for the test configs' fog (Henyey–Greenstein g = 0.85;
/// tests/data/service/small.toml and timing.toml) takes about a second to build here and ten
/// times that under ThreadSanitizer, and AirlightEvaluator's cache keeps a table only while an
/// evaluator holds it. Holding one for the whole binary lets every Service of these tests reuse
/// it, as a running service reuses its own from frame to frame; what is tested there is the
/// Service, not the table.
inline void holdTheTestFogsTables() {
  static const Result<AirlightEvaluator> held = [] {
    Medium fog;
    fog.extinction_per_m = extinctionFromVisibility(80.0);
    fog.phase = makeHenyeyGreenstein(0.85).value();
    Lamp lamp;
    lamp.profile = makeProfile(IsotropicProfile{1.0}).value();
    return AirlightEvaluator::build(lamp, fog, AirlightMethod::Accurate);
  }();
  ASSERT_TRUE(held) << held.error().message;
}

/// Polls `done` every millisecond until it holds or `timeout` has passed; its last answer.
inline bool waitFor(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return done();
}

/// A service's frame loop on a thread of its own; stops the service and joins on destruction.
class Running {
 public:
  explicit Running(Service& s, RunLimits limits = {}) : s_(s) {
    thread_ = std::thread([this, limits] { result_ = s_.run(limits); });
  }
  ~Running() { (void)finish(); }  // a test that returned early: its failure is reported already
  Running(const Running&) = delete;
  Running& operator=(const Running&) = delete;
  /// stop(), then the loop's thread joined; run()'s result.
  Status finish() {
    if (thread_.joinable()) {
      s_.stop();
      thread_.join();
    }
    return result_;
  }

 private:
  Service& s_;
  std::thread thread_;
  Status result_ = Ok{};
};

/// Sends protocol messages to 127.0.0.1:port, sequence numbers from 1.
class LoopbackSender {
 public:
  explicit LoopbackSender(std::uint16_t port) : fd_(::socket(AF_INET, SOCK_DGRAM, 0)) {
    to_.sin_family = AF_INET;
    to_.sin_port = htons(port);
    ::inet_pton(AF_INET, "127.0.0.1", &to_.sin_addr);
  }
  ~LoopbackSender() { ::close(fd_); }
  LoopbackSender(const LoopbackSender&) = delete;
  LoopbackSender& operator=(const LoopbackSender&) = delete;
  /// Returns the message's sequence number.
  std::uint32_t send(ipc::Payload p) {
    ipc::Message m;
    m.header.sequence = seq_++;
    m.payload = std::move(p);
    raw(ipc::encode(m));
    return m.header.sequence;
  }
  void raw(const std::vector<std::uint8_t>& bytes) {
    ASSERT_EQ(::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to_), sizeof to_),
              static_cast<ssize_t>(bytes.size()));
  }

 private:
  int fd_;
  sockaddr_in to_{};
  std::uint32_t seq_ = 1;
};

}  // namespace fogbeam::plugin::test
