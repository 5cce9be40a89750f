// fogbeam — UdpReceiver (fogbeam/ipc/udp_receiver.hpp).
#include <fogbeam/ipc/udp_receiver.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <mutex>
#include <system_error>
#include <thread>
#include <utility>

namespace fogbeam::ipc {

std::uint64_t UdpStats::droppedTotal() const noexcept {
  std::uint64_t n = 0;
  for (std::uint64_t d : dropped) n += d;
  return n;
}

namespace {

constexpr std::size_t kMaxSenders = 64;  // sequence trackers kept; the oldest is evicted beyond
constexpr int kPollMs = 100;             // stop() latency bound

std::string sysError(const std::string& what) { return what + ": " + std::strerror(errno); }

std::string endpoint(const sockaddr_in& a) {
  char buf[INET_ADDRSTRLEN] = {};
  // Cannot fail for AF_INET into INET_ADDRSTRLEN bytes; if it did, the log still names the port.
  const char* host = ::inet_ntop(AF_INET, &a.sin_addr, buf, sizeof buf) ? buf : "?";
  return std::string(host) + ":" + std::to_string(ntohs(a.sin_port));
}

// A count logged at most once per second: add() counts, and returns the count since the last line
// when a line is due (0 when not), so that nothing the network does floods the log.
struct LogLimit {
  Clock::time_point last{};
  std::uint64_t since = 0;
  std::uint64_t add(std::uint64_t n = 1) {
    since += n;
    const auto now = Clock::now();
    if (now - last < std::chrono::seconds(1)) return 0;
    last = now;
    return std::exchange(since, 0);
  }
};

}  // namespace

struct UdpReceiver::Impl {
  UdpReceiverOptions options;
  StateStore* store = nullptr;
  UniqueFd fd;                   // closed after the thread is joined (~UdpReceiver stops first)
  std::uint16_t port = 0;        // bound (options.port may be 0), for the log
  std::vector<in_addr_t> allow;  // network byte order
  std::atomic<bool> stopping{false};
  std::thread thread;

  mutable std::mutex statsMutex;
  UdpStats stats;

  // Per sender (address, port) and message type: the newest sequence number applied.
  struct Tracker {
    std::array<bool, 6> seen{};
    std::array<std::uint32_t, 6> last{};
    std::uint64_t lastUse = 0;
  };
  std::map<std::uint64_t, Tracker> trackers;
  std::uint64_t useCounter = 0;

  // Rate-limited logs: drops per reason; failing system calls in the loop (receiveError());
  // traffic objects refused by a full store (refusedObjects()); sender restarts (a sender whose
  // sequence keeps jumping back by more than restart_window, e.g. random sequence numbers,
  // restarts again and again).
  std::array<LogLimit, kDropReasonCount> dropLog{};
  LogLimit errorLog, refusedLog, restartLog;

  void drop(DropReason r, std::string_view field, const sockaddr_in& from) {
    const auto i = static_cast<std::size_t>(r);
    {
      std::lock_guard<std::mutex> lock(statsMutex);
      ++stats.datagrams;  // with its outcome, so every snapshot holds datagrams = applied + drops
      ++stats.dropped[i];
    }
    if (const std::uint64_t n = dropLog[i].add())
      spdlog::warn("udp: dropped {} datagram(s) for {} (last from {}, field '{}')", n, toString(r), endpoint(from),
                   field);
  }

  // A poll or recvfrom that failed for another reason than "nothing (more) to read" or a signal:
  // counted and logged like a drop (at most once per second, with the count since the last line);
  // the loop goes on, as it does for anything the network sends.
  void receiveError(const char* call, int error) {
    {
      std::lock_guard<std::mutex> lock(statsMutex);
      ++stats.receive_errors;
    }
    if (const std::uint64_t n = errorLog.add())
      spdlog::warn("udp: {} failed {} time(s) on port {}: {}", call, n, port, std::strerror(error));
  }

  // Classifies the sequence number; returns false (and counts) when the datagram is dropped.
  bool acceptSequence(const sockaddr_in& from, const Header& h) {
    const std::uint64_t key = (static_cast<std::uint64_t>(from.sin_addr.s_addr) << 16) | from.sin_port;
    auto it = trackers.find(key);
    if (it == trackers.end()) {
      if (trackers.size() >= kMaxSenders) {
        auto oldest = std::min_element(trackers.begin(), trackers.end(),
                                       [](const auto& a, const auto& b) { return a.second.lastUse < b.second.lastUse; });
        trackers.erase(oldest);
      }
      it = trackers.emplace(key, Tracker{}).first;
    }
    Tracker& t = it->second;
    t.lastUse = ++useCounter;
    const auto type = static_cast<std::size_t>(h.type);
    if (t.seen[type]) {
      const std::int64_t d = sequenceDistance(h.sequence, t.last[type]);
      if (d == 0) {
        drop(DropReason::Duplicate, "sequence", from);
        return false;
      }
      if (d < 0) {
        if (-d <= static_cast<std::int64_t>(options.restart_window)) {
          drop(DropReason::OutOfOrder, "sequence", from);
          return false;
        }
        {
          std::lock_guard<std::mutex> lock(statsMutex);
          ++stats.restarts;
        }
        // Counted each time, logged at most once per second with the count since the last line.
        if (const std::uint64_t n = restartLog.add())
          spdlog::info("udp: sender {} restarted (sequence {} after {}; {} restart(s) since the last line)",
                       endpoint(from), h.sequence, t.last[type], n);
      }
    }
    t.seen[type] = true;
    t.last[type] = h.sequence;
    return true;
  }

  void apply(const Message& m, const sockaddr_in& from, Clock::time_point now) {
    Stamp s;
    s.valid = true;
    s.sim_time_s = m.header.sim_time_s;
    s.sequence = m.header.sequence;
    s.received = now;
    s.source = "udp " + endpoint(from);
    std::size_t refused = 0, carried = 0;
    std::visit(
        [&](const auto& p) {
          using T = std::decay_t<decltype(p)>;
          if constexpr (std::is_same_v<T, EgoState>) store->setEgo(p, s);
          else if constexpr (std::is_same_v<T, LampState>) store->setLamps(p, s);
          else if constexpr (std::is_same_v<T, Environment>) store->setEnvironment(p, s);
          else if constexpr (std::is_same_v<T, FrameRequest>) store->setFrameRequest(p, s);
          else if constexpr (std::is_same_v<T, TrafficList>) {
            refused = store->applyTraffic(p, s);
            carried = p.objects.size();
          }
        },
        m.payload);
    // Every datagram counts once, as applied or under one drop reason (datagrams = applied + the
    // drops). Objects the full store refused are counted one by one; a datagram of which it took
    // nothing (every object refused) is a drop, one of which it took some is applied.
    if (refused > 0) refusedObjects(refused, from);
    if (refused > 0 && refused == carried) {
      drop(DropReason::TooManyObjects, "count", from);
      return;
    }
    std::lock_guard<std::mutex> lock(statsMutex);
    ++stats.datagrams;  // with its outcome (see drop())
    ++stats.applied;
    ++stats.applied_by_type[static_cast<std::size_t>(m.header.type)];
  }

  // Traffic objects refused by the store's bound (StateStoreOptions::max_traffic_objects):
  // counted, and logged at most once per second with the count since the last line.
  void refusedObjects(std::size_t n, const sockaddr_in& from) {
    {
      std::lock_guard<std::mutex> lock(statsMutex);
      stats.traffic_refused += n;
    }
    if (const std::uint64_t count = refusedLog.add(n))
      spdlog::warn("udp: refused {} traffic object(s): the state holds its maximum of {} (last from {})", count,
                   store->options().max_traffic_objects, endpoint(from));
  }

  void run() {
    std::vector<std::uint8_t> buf(kMaxDatagram + 1);  // one more: an oversized datagram is detectable
    while (!stopping.load(std::memory_order_relaxed)) {
      pollfd p{fd.get(), POLLIN, 0};
      const int ready = ::poll(&p, 1, kPollMs);
      if (ready < 0 && errno != EINTR) {
        receiveError("poll", errno);
        // It returned at once: wait as long as a timeout would, so a lasting failure cannot spin.
        std::this_thread::sleep_for(std::chrono::milliseconds(kPollMs));
      }
      if (ready <= 0) {
        if (store) store->expire(Clock::now());
        continue;
      }
      for (;;) {
        sockaddr_in from{};
        socklen_t len = sizeof from;
        const ssize_t n =
            ::recvfrom(fd.get(), buf.data(), buf.size(), MSG_DONTWAIT, reinterpret_cast<sockaddr*>(&from), &len);
        if (n < 0) {  // EAGAIN: drained; EINTR or another error: poll again
          if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) receiveError("recvfrom", errno);
          break;
        }
        const auto now = Clock::now();
        // A datagram is counted when its outcome is (drop() or apply()), under one lock, so that a
        // stats() snapshot never shows one received but neither applied nor dropped.
        if (!allow.empty() && std::find(allow.begin(), allow.end(), from.sin_addr.s_addr) == allow.end()) {
          drop(DropReason::SenderNotAllowed, "source", from);
          continue;
        }
        const std::size_t size = std::min(static_cast<std::size_t>(n), kMaxDatagram + 1);
        const DecodeResult d = decode(std::span<const std::uint8_t>(buf.data(), size));
        if (!d.ok) {
          drop(d.reason, d.field, from);
          continue;
        }
        if (!acceptSequence(from, d.message.header)) continue;
        apply(d.message, from, now);
      }
    }
  }
};

UdpReceiver::UdpReceiver(std::unique_ptr<Impl> impl, std::uint16_t port) : impl_(std::move(impl)), port_(port) {}

UdpReceiver::~UdpReceiver() { stop(); }

void UdpReceiver::stop() {
  if (!impl_) return;
  impl_->stopping.store(true);
  if (impl_->thread.joinable()) impl_->thread.join();
}

UdpStats UdpReceiver::stats() const {
  std::lock_guard<std::mutex> lock(impl_->statsMutex);
  return impl_->stats;
}

Result<std::unique_ptr<UdpReceiver>> UdpReceiver::start(const UdpReceiverOptions& options, StateStore& store) {
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->store = &store;
  for (const std::string& a : options.allow) {
    in_addr addr{};
    if (inet_pton(AF_INET, a.c_str(), &addr) != 1)
      return Error{"udp allow-list: '" + a + "' is not an IPv4 address"};
    impl->allow.push_back(addr.s_addr);
  }
  sockaddr_in bindAddr{};
  bindAddr.sin_family = AF_INET;
  bindAddr.sin_port = htons(options.port);
  // With a multicast group the socket binds to the group (or any) address so that it receives
  // the group's datagrams; bind_address then only names the interface (multicast_interface).
  const std::string bindHost = options.multicast_group.empty() ? options.bind_address : options.multicast_group;
  if (inet_pton(AF_INET, bindHost.c_str(), &bindAddr.sin_addr) != 1)
    return Error{"udp bind address '" + bindHost + "' is not an IPv4 address"};
  impl->fd.reset(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (!impl->fd) return Error{sysError("udp socket")};
  const std::string where = bindHost + ":" + std::to_string(options.port);
  // Several members of one multicast group may run on one machine (one process per screen):
  // they share the port. A unicast port is exclusive, so that a second instance fails loudly
  // instead of silently taking half of the datagrams.
  if (!options.multicast_group.empty()) {
    const int one = 1;
    if (::setsockopt(impl->fd.get(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) != 0)
      return Error{sysError("udp SO_REUSEADDR on " + where)};
  }
  // The kernel caps the request at net.core.rmem_max without failing; a failure is a real one.
  if (::setsockopt(impl->fd.get(), SOL_SOCKET, SO_RCVBUF, &options.receive_buffer_bytes,
                   sizeof options.receive_buffer_bytes) != 0)
    return Error{sysError("udp SO_RCVBUF of " + std::to_string(options.receive_buffer_bytes) + " bytes on " + where)};
  if (::bind(impl->fd.get(), reinterpret_cast<const sockaddr*>(&bindAddr), sizeof bindAddr) != 0)
    return Error{sysError("udp bind " + where)};
  if (!options.multicast_group.empty()) {
    ip_mreq mreq{};
    mreq.imr_multiaddr = bindAddr.sin_addr;
    if (inet_pton(AF_INET, options.multicast_interface.c_str(), &mreq.imr_interface) != 1)
      return Error{"udp multicast interface '" + options.multicast_interface + "' is not an IPv4 address"};
    if (::setsockopt(impl->fd.get(), IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof mreq) != 0)
      return Error{sysError("udp join " + options.multicast_group + " on " + options.multicast_interface)};
  }
  // The port actually bound (options.port 0 = any free one).
  sockaddr_in bound{};
  socklen_t len = sizeof bound;
  if (::getsockname(impl->fd.get(), reinterpret_cast<sockaddr*>(&bound), &len) != 0)
    return Error{sysError("udp getsockname of " + where)};
  const std::uint16_t port = ntohs(bound.sin_port);
  Impl* raw = impl.get();
  raw->port = port;
  try {
    raw->thread = std::thread([raw] { raw->run(); });
  } catch (const std::system_error& e) {
    return Error{"udp " + where + ": cannot start the receive thread: " + e.what()};
  }
  spdlog::info("udp: listening on {}:{}{}", bindHost, port,
               options.allow.empty() ? "" : " (allow-list of " + std::to_string(options.allow.size()) + ")");
  return std::unique_ptr<UdpReceiver>(new UdpReceiver(std::move(impl), port));
}

}  // namespace fogbeam::ipc
