// fogbeam — status on request over UDP (status_server.hpp).
#include <fogbeam/ipc/status_server.hpp>

#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <string_view>
#include <system_error>
#include <thread>

namespace fogbeam::ipc {

namespace {

constexpr int kPollMs = 100;  // stop() latency bound

std::string sysError(const std::string& what) { return what + ": " + std::strerror(errno); }

Result<sockaddr_in> addressOf(const std::string& address, std::uint16_t port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  if (::inet_pton(AF_INET, address.c_str(), &a.sin_addr) != 1) {
    return Error{"status: expected an IPv4 address, found \"" + address + "\""};
  }
  return a;
}

}  // namespace

Result<std::unique_ptr<StatusServer>> StatusServer::start(const StatusServerOptions& options,
                                                          std::function<std::string()> reply) {
  auto addr = addressOf(options.bind_address, options.port);
  if (!addr) return addr.error();
  std::unique_ptr<StatusServer> s(new StatusServer());
  s->options_ = options;
  s->reply_ = std::move(reply);
  s->fd_.reset(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (!s->fd_) return Error{sysError("status socket")};
  const std::string where = options.bind_address + ":" + std::to_string(options.port);
  if (::bind(s->fd_.get(), reinterpret_cast<const sockaddr*>(&*addr), sizeof *addr) != 0) {
    return Error{sysError("status bind " + where)};
  }
  // The port actually bound (options.port 0 = any free one).
  sockaddr_in bound{};
  socklen_t len = sizeof bound;
  if (::getsockname(s->fd_.get(), reinterpret_cast<sockaddr*>(&bound), &len) != 0)
    return Error{sysError("status getsockname of " + where)};
  s->port_ = ntohs(bound.sin_port);
  try {
    s->thread_ = std::thread([raw = s.get()] { raw->run(); });
  } catch (const std::system_error& e) {
    return Error{"status " + where + ": cannot start the server thread: " + e.what()};
  }
  return s;
}

// Joins the thread before the members go (the socket is closed by fd_, declared before thread_).
StatusServer::~StatusServer() { stop(); }

void StatusServer::stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

StatusServerStats StatusServer::stats() const {
  return {requests_.load(), replies_.load(), ignored_.load(), limited_.load(), errors_.load()};
}

void StatusServer::socketError(const char* call, int error) {
  ++errors_;
  ++errorsSinceLog_;
  const auto now = std::chrono::steady_clock::now();
  if (now - lastErrorLog_ >= std::chrono::seconds(1)) {
    spdlog::warn("status: {} failed {} time(s) on port {}: {}", call, errorsSinceLog_, port_, std::strerror(error));
    lastErrorLog_ = now;
    errorsSinceLog_ = 0;
  }
}

void StatusServer::run() {
  using Clock = std::chrono::steady_clock;
  auto windowStart = Clock::now();
  int inWindow = 0;
  char buf[64];
  while (!stop_.load()) {
    pollfd p{fd_.get(), POLLIN, 0};
    const int ready = ::poll(&p, 1, kPollMs);  // 0.1 s: stop() returns promptly
    if (ready < 0 && errno != EINTR) {
      socketError("poll", errno);
      // It returned at once: wait as long as a timeout would, so a lasting failure cannot spin.
      std::this_thread::sleep_for(std::chrono::milliseconds(kPollMs));
    }
    if (ready <= 0) continue;
    sockaddr_in from{};
    socklen_t fromLen = sizeof from;
    const ssize_t n = ::recvfrom(fd_.get(), buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &fromLen);
    if (n < 0) {
      if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) socketError("recvfrom", errno);
      continue;
    }
    std::string_view req(buf, static_cast<std::size_t>(n));
    while (!req.empty() && (req.back() == '\n' || req.back() == '\r')) req.remove_suffix(1);
    if (req != "status") {
      ++ignored_;
      continue;
    }
    ++requests_;
    const auto now = Clock::now();
    if (now - windowStart >= std::chrono::seconds(1)) {
      windowStart = now;
      inWindow = 0;
    }
    if (++inWindow > options_.max_replies_per_s) {
      ++limited_;
      continue;
    }
    std::string r = reply_ ? reply_() : std::string("{}");
    if (r.size() > options_.max_reply_bytes) r = "{\"error\": \"status larger than the reply limit\"}";
    if (::sendto(fd_.get(), r.data(), r.size(), 0, reinterpret_cast<const sockaddr*>(&from), fromLen) >= 0)
      ++replies_;
    else
      socketError("sendto", errno);
  }
}

Result<std::string> requestStatus(const std::string& address, std::uint16_t port, double timeout_s) {
  auto addr = addressOf(address, port);
  if (!addr) return addr.error();
  const UniqueFd fd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (!fd) return Error{sysError("status socket")};
  constexpr std::string_view kRequest = "status";
  if (::sendto(fd.get(), kRequest.data(), kRequest.size(), 0, reinterpret_cast<const sockaddr*>(&*addr), sizeof *addr) <
      0) {
    return Error{sysError("status send")};
  }
  pollfd p{fd.get(), POLLIN, 0};
  const int ready = ::poll(&p, 1, static_cast<int>(timeout_s * 1000));
  if (ready < 0) return Error{sysError("status poll for the reply from " + address + ":" + std::to_string(port))};
  if (ready == 0) {
    return Error{"no status reply from " + address + ":" + std::to_string(port) + " within " +
                 std::to_string(timeout_s) + " s"};
  }
  std::string reply(65536, '\0');
  const ssize_t n = ::recv(fd.get(), reply.data(), reply.size(), 0);
  if (n < 0) return Error{sysError("status recv")};
  reply.resize(static_cast<std::size_t>(n));
  return reply;
}

}  // namespace fogbeam::ipc
