// fogbeam — CAN input (fogbeam/ipc/can_input.hpp).
#include <fogbeam/ipc/can_input.hpp>
#include <fogbeam/ipc/cannelloni.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <net/if.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/raw.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <system_error>
#include <thread>
#include <utility>

namespace fogbeam::ipc {

namespace {

constexpr std::array<const char*, kCanLampCount> kLampNames{"low beam", "high beam", "front fog", "rear fog",
                                                            "indicator left", "indicator right"};
constexpr int kPollMs = 50;  // stop latency and the hold/fallback tick

std::string sysError(const std::string& what) { return what + ": " + std::strerror(errno); }

}  // namespace

Result<CanDecoder> CanDecoder::create(const DbcDatabase& dbc, const CanMapping& mapping) {
  CanDecoder d;
  d.mapping_ = mapping;
  auto bind = [&](const std::optional<CanSignalRef>& ref, Bound& out) -> Status {
    if (!ref) return Ok{};
    auto msg = dbc.message(ref->message);
    if (!msg) return msg.error();
    auto sig = dbc.signal(ref->message, ref->signal);
    if (!sig) return sig.error();
    out.signal = **sig;
    out.id = (*msg)->id;
    out.extended = (*msg)->extended;
    out.present = true;
    const std::pair<std::uint32_t, bool> key{out.id, out.extended};
    if (std::find(d.ids_.begin(), d.ids_.end(), key) == d.ids_.end()) d.ids_.push_back(key);
    return Ok{};
  };
  for (std::size_t k = 0; k < kCanLampCount; ++k)
    if (Status s = bind(mapping.lamps[k], d.lamps_[k]); !s) return s.error();
  if (Status s = bind(mapping.speed, d.speed_); !s) return s.error();
  if (!d.speed_.present && std::none_of(d.lamps_.begin(), d.lamps_.end(), [](const Bound& b) { return b.present; }))
    return Error{"CAN mapping names no signal (lamps or speed)"};
  return d;
}

std::vector<std::pair<std::uint32_t, bool>> CanDecoder::ids() const { return ids_; }

bool CanDecoder::onFrame(const CanFrame& frame, Clock::time_point now) {
  ++stats_.frames;
  if (frame.remote) return false;
  if (std::find(ids_.begin(), ids_.end(), std::pair<std::uint32_t, bool>{frame.id, frame.extended}) == ids_.end())
    return false;
  ++stats_.matched;
  bool any = false;
  auto take = [&](Bound& b) {
    if (!b.present || b.id != frame.id || b.extended != frame.extended) return;
    const auto v = decodeSignalValue(b.signal, frame);
    if (!v) return;  // too short, or the multiplexor selects another signal
    if (v->out_of_range) {
      ++stats_.out_of_range;
      return;
    }
    b.value = v->physical;
    b.seen = now;
    any = true;
  };
  for (Bound& b : lamps_) take(b);
  take(speed_);
  return any;
}

CanDecoder::SignalState CanDecoder::stateOf(const Bound& b, Clock::time_point now) const {
  const auto hold = std::chrono::duration<double>(mapping_.hold_s);
  if (b.seen != Clock::time_point{}) return now - b.seen <= hold ? SignalState::Fresh : SignalState::Silent;
  // Never seen: silent once the source has run for hold_s without it, not at its start.
  return started_ != Clock::time_point{} && now - started_ > hold ? SignalState::Silent : SignalState::Unknown;
}

std::uint32_t CanDecoder::lights(Clock::time_point now) const {
  std::uint32_t bits = 0;
  for (std::size_t k = 0; k < kCanLampCount; ++k) {
    const Bound& b = lamps_[k];
    if (!b.present) continue;
    const SignalState st = stateOf(b, now);
    const bool on = st == SignalState::Fresh    ? b.value != 0.0
                    : st == SignalState::Silent ? (mapping_.fallback_lights & kCanLampBits[k]) != 0
                                                : false;
    if (on) bits |= kCanLampBits[k];
  }
  return bits;
}

void CanDecoder::publish(StateStore& store, Clock::time_point now, const std::string& source, bool force) {
  if (started_ == Clock::time_point{}) started_ = now;
  // Log each lamp signal's transition to and from "silent" once; collect the bits the mapping
  // owns, those known by now and the newest lamp frame's receipt.
  std::uint32_t owned = 0, known = 0;
  Clock::time_point newest{};
  for (std::size_t k = 0; k < kCanLampCount; ++k) {
    Bound& b = lamps_[k];
    if (!b.present) continue;
    owned |= kCanLampBits[k];
    const SignalState st = stateOf(b, now);
    if (st != SignalState::Unknown) known |= kCanLampBits[k];
    newest = std::max(newest, b.seen);
    const bool silent = st == SignalState::Silent;
    if (silent && !b.silentLogged) {
      ++stats_.fallbacks;
      spdlog::warn("can: {} signal {} silent for more than {} s: falling back to {}", kLampNames[k], b.signal.name,
                   mapping_.hold_s, (mapping_.fallback_lights & kCanLampBits[k]) ? "on" : "off");
      b.silentLogged = true;
    } else if (!silent && b.silentLogged) {
      spdlog::info("can: {} signal {} is back", kLampNames[k], b.signal.name);
      b.silentLogged = false;
    }
  }
  Stamp s;
  s.valid = true;
  s.received = now;
  s.source = source;
  const std::uint32_t bits = lights(now) & known;
  // A frame that repeats the lamp signals changes no bit but is the newest input the frame uses:
  // publish it for its stamp. A change that silence made (a fallback) has no new frame: its
  // stamp keeps the last frame's receipt (now, when no frame was ever seen).
  const bool newFrame = newest > lastLampSeen_;
  if (force || bits != lastLights_ || known != lastKnown_ || newFrame) {
    if (known != 0) {
      s.sequence = ++sequence_;
      if (newest != Clock::time_point{}) s.received = newest;
      ++stats_.published;
    }
    store.setBusLights(owned, known, bits, s);  // known 0: claims the bits, publishes nothing
    lastLights_ = bits;
    lastKnown_ = known;
    lastLampSeen_ = newest;
  }
  s.received = now;
  if (speed_.present && speed_.seen != Clock::time_point{}) {
    const double v = speed_.value * mapping_.speed_to_m_s;
    if (force || v != lastSpeed_) {
      s.sequence = ++sequence_;
      store.setVehicleSpeed(static_cast<float>(v), s);
      lastSpeed_ = v;
      ++stats_.published;
    }
  }
}

// ---------------------------------------------------------------------------------------------
namespace {

// A thread that runs `loop(*this)`, which feeds frames into the decoder and publishes after every
// frame batch and every poll tick (for the hold/fallback timing) until stopping(). The loop owns
// what it reads from (a socket's UniqueFd, moved into it): that is closed when the loop ends, or
// at once when the thread cannot be started.
class ThreadSource final : public CanSource {
 public:
  ThreadSource(CanDecoder decoder, StateStore& store, std::string source)
      : decoder_(std::move(decoder)), store_(store), source_(std::move(source)) {}
  ~ThreadSource() override { stop(); }

  template <class Loop>
  [[nodiscard]] Status run(Loop loop) {
    try {
      thread_ = std::thread([this, loop = std::move(loop)]() mutable {
        loop(*this);
        finished_ = true;
      });
    } catch (const std::system_error& e) {
      return Error{source_ + ": cannot start the receive thread: " + e.what()};
    }
    return Ok{};
  }
  void stop() override {
    stopping_ = true;
    if (thread_.joinable()) thread_.join();
  }
  [[nodiscard]] CanStats stats() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    CanStats s = decoder_.stats();
    s.receive_errors = receiveErrors_.load();
    return s;
  }
  [[nodiscard]] bool finished() const override { return finished_; }

  bool stopping() const { return stopping_; }
  void frame(const CanFrame& f) {
    std::lock_guard<std::mutex> lock(mutex_);
    decoder_.onFrame(f, Clock::now());
  }
  void tick() {
    std::lock_guard<std::mutex> lock(mutex_);
    decoder_.publish(store_, Clock::now(), source_);
  }
  // A poll/read/recv that failed for another reason than "nothing to read" or a signal: counted
  // and logged at most once per second with the count since the last line (as the UDP input's
  // drops); the loop goes on. Loop thread only.
  void receiveError(const char* call, int error) {
    ++receiveErrors_;
    ++errorsSinceLog_;
    const auto now = Clock::now();
    if (now - lastErrorLog_ >= std::chrono::seconds(1)) {
      spdlog::warn("{}: {} failed {} time(s): {}", source_, call, errorsSinceLog_, std::strerror(error));
      lastErrorLog_ = now;
      errorsSinceLog_ = 0;
    }
  }
  // poll() on `fd` for up to kPollMs; true when there is something to read. A failure is
  // counted and followed by a wait of kPollMs, so that a lasting one cannot spin the loop.
  bool waitReadable(int fd) {
    pollfd p{fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, kPollMs);
    if (ready < 0 && errno != EINTR) {
      receiveError("poll", errno);
      std::this_thread::sleep_for(std::chrono::milliseconds(kPollMs));
    }
    return ready > 0;
  }

 private:
  CanDecoder decoder_;
  StateStore& store_;
  std::string source_;
  mutable std::mutex mutex_;
  std::thread thread_;
  std::atomic<bool> stopping_{false}, finished_{false};
  std::atomic<std::uint64_t> receiveErrors_{0};
  Clock::time_point lastErrorLog_{};  // loop thread only
  std::uint64_t errorsSinceLog_ = 0;  // loop thread only
};

bool transientReadError(int error) { return error == EAGAIN || error == EWOULDBLOCK || error == EINTR; }

}  // namespace

Result<std::unique_ptr<CanSource>> startSocketCan(const std::string& interface, CanDecoder decoder, StateStore& store) {
  UniqueFd fd(::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW));
  if (!fd) return Error{sysError("SocketCAN unavailable: socket(PF_CAN, SOCK_RAW, CAN_RAW)")};
  auto fail = [](const std::string& what) -> Error { return Error{sysError(what)}; };
  if (interface.size() >= IFNAMSIZ) return Error{"SocketCAN interface name '" + interface + "' is too long"};
  const int one = 1;
  if (::setsockopt(fd.get(), SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &one, sizeof one) != 0) return fail("CAN_RAW_FD_FRAMES");
  // Kernel filters: only the mapped ids reach user space.
  std::vector<can_filter> filters;
  for (const auto& [id, ext] : decoder.ids())
    filters.push_back(can_filter{ext ? (id | CAN_EFF_FLAG) : id,
                                 ext ? (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_EFF_MASK) : (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_SFF_MASK)});
  if (::setsockopt(fd.get(), SOL_CAN_RAW, CAN_RAW_FILTER, filters.data(),
                   static_cast<socklen_t>(filters.size() * sizeof(can_filter))) != 0)
    return fail("CAN_RAW_FILTER");
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, interface.c_str(), IFNAMSIZ - 1);
  if (::ioctl(fd.get(), SIOCGIFINDEX, &ifr) != 0) return fail("SocketCAN interface " + interface);
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(fd.get(), reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) return fail("bind " + interface);
  auto src = std::make_unique<ThreadSource>(std::move(decoder), store, "can " + interface);
  const Status started = src->run([fd = std::move(fd)](ThreadSource& self) {
    canfd_frame raw{};
    while (!self.stopping()) {
      if (self.waitReadable(fd.get())) {
        const ssize_t n = ::read(fd.get(), &raw, sizeof raw);
        if (n < 0 && !transientReadError(errno)) self.receiveError("read", errno);
        if (n == CAN_MTU || n == CANFD_MTU) {
          CanFrame f;
          f.extended = (raw.can_id & CAN_EFF_FLAG) != 0;
          f.remote = (raw.can_id & CAN_RTR_FLAG) != 0;
          f.id = raw.can_id & (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
          f.fd = n == CANFD_MTU;
          f.len = std::min<std::uint8_t>(raw.len, f.fd ? 64 : 8);
          std::memcpy(f.data.data(), raw.data, f.len);
          if ((raw.can_id & CAN_ERR_FLAG) == 0) self.frame(f);
        }
      }
      self.tick();
    }
  });
  if (!started) return started.error();
  return std::unique_ptr<CanSource>(std::move(src));
}

Result<std::unique_ptr<CanSource>> startCannelloni(const std::string& bindAddress, std::uint16_t port, CanDecoder decoder,
                                                   StateStore& store, std::uint16_t* boundPort) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  if (inet_pton(AF_INET, bindAddress.c_str(), &a.sin_addr) != 1)
    return Error{"cannelloni bind address '" + bindAddress + "' is not an IPv4 address"};
  UniqueFd fd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  if (!fd) return Error{sysError("cannelloni socket")};
  const std::string where = bindAddress + ":" + std::to_string(port);
  if (::bind(fd.get(), reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
    return Error{sysError("cannelloni bind " + where)};
  // The port actually bound (port 0 = any free one).
  sockaddr_in bound{};
  socklen_t len = sizeof bound;
  if (::getsockname(fd.get(), reinterpret_cast<sockaddr*>(&bound), &len) != 0)
    return Error{sysError("cannelloni getsockname of " + where)};
  if (boundPort) *boundPort = ntohs(bound.sin_port);
  auto src = std::make_unique<ThreadSource>(std::move(decoder), store,
                                            "cannelloni " + bindAddress + ":" + std::to_string(ntohs(bound.sin_port)));
  const Status started = src->run([fd = std::move(fd)](ThreadSource& self) {
    std::vector<std::uint8_t> buf(65536);
    std::uint64_t bad = 0;
    auto lastLog = Clock::time_point{};
    while (!self.stopping()) {
      if (self.waitReadable(fd.get())) {
        const ssize_t n = ::recv(fd.get(), buf.data(), buf.size(), MSG_DONTWAIT);
        if (n < 0 && !transientReadError(errno)) self.receiveError("recv", errno);
        if (n > 0) {
          auto packet = decodeCannelloni(std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(n)));
          if (packet) {
            for (const CanFrame& f : packet->frames) self.frame(f);
          } else {
            ++bad;
            if (Clock::now() - lastLog > std::chrono::seconds(1)) {
              spdlog::warn("cannelloni: dropped {} bad packet(s): {}", bad, packet.error().message);
              lastLog = Clock::now();
              bad = 0;
            }
          }
        }
      }
      self.tick();
    }
  });
  if (!started) return started.error();
  return std::unique_ptr<CanSource>(std::move(src));
}

Result<std::unique_ptr<CanSource>> startCandumpReplay(const std::string& path, double speed, CanDecoder decoder,
                                                      StateStore& store) {
  auto lines = loadCandump(path);
  if (!lines) return lines.error();
  auto src = std::make_unique<ThreadSource>(std::move(decoder), store, "candump " + path);
  const Status started = src->run([lines = std::move(lines).value(), speed, path](ThreadSource& self) {
    replayCandump(lines, speed, [&](const CandumpLine& l) {
      self.frame(l.frame);
      self.tick();
      return !self.stopping();
    });
    self.tick();
    // The end of a log is not a silent bus: the thread ends here, so no hold_s passes, nothing
    // falls back and nothing is logged as silent; the state the log left stays (docs/can.md).
    if (!self.stopping())
      spdlog::info("can: candump {}: replay finished after {} frame(s); its last lamp states and speed are kept", path,
                   lines.size());
  });
  if (!started) return started.error();
  return std::unique_ptr<CanSource>(std::move(src));
}

}  // namespace fogbeam::ipc
