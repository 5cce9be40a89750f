// `fogbeam send` (issue 5): a host stand-in. Plays a scenario (docs/scenario.md) into a running
// `fogbeam serve` over UDP (docs/protocol.md) in real time, or lets a person drive with the
// keyboard; optionally also the lamp states and speed as CAN frames (cannelloni over UDP, or a
// candump -L log) through a CAN mapping (docs/can.md). For demos and end-to-end tests: --log
// writes every ego message sent (sequence, time, pose, lights) so a test can check the frames'
// metadata against it; --lock-step sends a frame request after each state.
#include "cmd_send.hpp"

#include <fogbeam/ipc/can_config.hpp>
#include <fogbeam/ipc/can_encode.hpp>
#include <fogbeam/ipc/candump.hpp>
#include <fogbeam/ipc/cannelloni.hpp>
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/plugin/scenario.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace fogbeam::cli {

namespace {

using Clock = std::chrono::steady_clock;

std::atomic<bool> gStop{false};
extern "C" void onSendSignal(int) { gStop.store(true); }

struct Target {
  int fd = -1;
  sockaddr_in addr{};
  ~Target() {
    if (fd >= 0) ::close(fd);
  }
};

Result<sockaddr_in> parseHostPort(const std::string& s) {
  const std::size_t colon = s.rfind(':');
  if (colon == std::string::npos) return Error{"expected HOST:PORT (IPv4), found \"" + s + "\""};
  sockaddr_in a{};
  a.sin_family = AF_INET;
  const std::string host = s.substr(0, colon);
  int port = 0;
  try {
    port = std::stoi(s.substr(colon + 1));
  } catch (...) {
    port = -1;
  }
  if (port <= 0 || port > 65535) return Error{"expected a port in [1, 65535] in \"" + s + "\""};
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::inet_pton(AF_INET, host.c_str(), &a.sin_addr) != 1) return Error{"expected an IPv4 address, found \"" + host + "\""};
  return a;
}

Result<std::unique_ptr<Target>> open(const std::string& hostPort) {
  auto a = parseHostPort(hostPort);
  if (!a) return a.error();
  auto t = std::make_unique<Target>();
  t->fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (t->fd < 0) return Error{"socket: " + std::string(std::strerror(errno))};
  t->addr = *a;
  return t;
}

/// Raw terminal mode for the keyboard driver, restored on exit.
class RawTerminal {
 public:
  RawTerminal() {
    if (::tcgetattr(STDIN_FILENO, &saved_) != 0) return;
    termios raw = saved_;
    raw.c_lflag &= ~static_cast<tcflag_t>(ICANON | ECHO);
    raw.c_cc[VMIN] = 0;
    raw.c_cc[VTIME] = 0;
    ok_ = ::tcsetattr(STDIN_FILENO, TCSANOW, &raw) == 0;
  }
  ~RawTerminal() {
    if (ok_) ::tcsetattr(STDIN_FILENO, TCSANOW, &saved_);
  }
  [[nodiscard]] bool ok() const { return ok_; }

 private:
  termios saved_{};
  bool ok_ = false;
};

int fail(const std::string& what) {
  std::fprintf(stderr, "fogbeam send: %s\n", what.c_str());
  return 2;
}

}  // namespace

int runSend(const SendOptions& o) {
  if (o.scenario.empty() == !o.keyboard) return fail("give --scenario FILE or --keyboard");
  std::optional<plugin::Scenario> scenario;
  if (!o.scenario.empty()) {
    auto s = plugin::loadScenario(o.scenario);
    if (!s) return fail(s.error().message);
    scenario = std::move(s).value();
  }
  auto udp = open(o.to);
  if (!udp) return fail("--to: " + udp.error().message);

  // CAN: the lamp states and speed through the mapping, as cannelloni or a candump log.
  std::optional<ipc::CanEncoder> canEncoder;
  std::unique_ptr<Target> cannelloni;
  std::ofstream candump;
  if (!o.canConfig.empty()) {
    auto cfg = ipc::loadCanConfig(o.canConfig);
    if (!cfg) return fail(cfg.error().message);
    auto enc = ipc::makeEncoder(*cfg);
    if (!enc) return fail(enc.error().message);
    canEncoder = std::move(enc).value();
    if (!o.canCannelloni.empty()) {
      auto t = open(o.canCannelloni);
      if (!t) return fail("--can-cannelloni: " + t.error().message);
      cannelloni = std::move(t).value();
    }
    if (!o.canCandump.empty()) {
      candump.open(o.canCandump);
      if (!candump) return fail("--can-candump: cannot write " + o.canCandump);
    }
    if (!cannelloni && !candump.is_open()) return fail("--can-config needs --can-cannelloni HOST:PORT or --can-candump FILE");
  } else if (!o.canCannelloni.empty() || !o.canCandump.empty()) {
    return fail("--can-cannelloni and --can-candump need --can-config (the CAN mapping)");
  }


  std::ofstream log;
  if (!o.log.empty()) {
    log.open(o.log);
    if (!log) return fail("--log: cannot write " + o.log);
    log << "wall_s,t_s,ego_sequence,lamp_sequence,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg,lights,traffic,frame_request\n";
    log.setf(std::ios::fixed);
    log.precision(6);
  }
  std::signal(SIGINT, onSendSignal);
  std::signal(SIGTERM, onSendSignal);

  std::uint32_t sequence = 1;
  std::uint8_t cannelloniSeq = 0;
  std::uint64_t datagrams = 0, ticks = 0, sendErrors = 0;
  std::uint64_t canFrames = 0;
  std::optional<RawTerminal> term;
  // Keyboard driving state: a car on the plane, yaw rate from a/d, speed from w/s.
  plugin::ScenarioState kb;
  kb.ego_lamps.lights = ipc::light::kLowBeam | ipc::light::kPosition;
  kb.environment.visibility_m = 80.0f;
  double kbSpeed = 10.0, kbYawRate = 0.0;
  if (o.keyboard) {
    if (::isatty(STDIN_FILENO) == 0) return fail("--keyboard needs a terminal on stdin");
    term.emplace();
    if (!term->ok()) return fail("--keyboard: cannot put the terminal in raw mode");
    std::fprintf(stderr, "fogbeam send: keyboard: w/s speed ±2 m/s, a/d steer, space straight, l low beam, h high beam, "
                         "f front fog, r rear fog, +/- visibility ×/÷ 1.25, q quit\n");
  }
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / o.rate_hz));
  const auto start = Clock::now();
  auto next = start;
  while (!gStop.load()) {
    const double wall = std::chrono::duration<double>(Clock::now() - start).count();
    if (o.duration_s > 0.0 && wall > o.duration_s) break;
    plugin::ScenarioState st;
    if (scenario) {
      double t = wall * o.speed;
      if (t > scenario->duration_s) {
        if (!o.loop) break;
        t = std::fmod(t, scenario->duration_s);
      }
      st = plugin::evaluate(*scenario, t);
    } else {
      char c = 0;
      while (::read(STDIN_FILENO, &c, 1) == 1) {
        switch (c) {
          case 'w': kbSpeed += 2.0; break;
          case 's': kbSpeed = std::max(0.0, kbSpeed - 2.0); break;
          case 'a': kbYawRate += 3.0; break;
          case 'd': kbYawRate -= 3.0; break;
          case ' ': kbYawRate = 0.0; break;
          case 'l': kb.ego_lamps.lights ^= ipc::light::kLowBeam; break;
          case 'h': kb.ego_lamps.lights ^= ipc::light::kHighBeam; break;
          case 'f': kb.ego_lamps.lights ^= ipc::light::kFrontFog; break;
          case 'r': kb.ego_lamps.lights ^= ipc::light::kRearFog; break;
          case '+': kb.environment.visibility_m = std::min(2000.0f, kb.environment.visibility_m * 1.25f); break;
          case '-': kb.environment.visibility_m = std::max(10.0f, kb.environment.visibility_m / 1.25f); break;
          case 'q': gStop = true; break;
          default: break;
        }
      }
      const double dt = 1.0 / o.rate_hz;
      kb.t_s += dt;
      kb.ego.pose.yaw_deg += static_cast<float>(kbYawRate * dt);
      const double yaw = static_cast<double>(kb.ego.pose.yaw_deg) * std::numbers::pi / 180.0;
      kb.ego.pose.position_m[0] += kbSpeed * dt * std::cos(yaw);
      kb.ego.pose.position_m[1] += kbSpeed * dt * std::sin(yaw);
      kb.ego.speed_m_s = static_cast<float>(kbSpeed);
      kb.traffic.complete = true;
      st = kb;
    }
    const std::uint32_t firstSeq = sequence;
    for (const auto& d : plugin::encodeState(st, sequence)) {
      if (::sendto((*udp)->fd, d.data(), d.size(), 0, reinterpret_cast<const sockaddr*>(&(*udp)->addr),
                   sizeof(*udp)->addr) < 0) {
        ++sendErrors;
      } else {
        ++datagrams;
      }
    }
    // encodeState sends environment, lamps, traffic (one or more), ego: ego is the last one.
    const std::uint32_t egoSeq = sequence - 1;
    const std::uint32_t lampSeq = firstSeq + 1;
    std::uint64_t request = 0;
    if (o.lockStep) {
      request = ticks + 1;
      ipc::Message m;
      m.header.sequence = sequence++;
      m.header.sim_time_s = st.t_s;
      m.payload = ipc::FrameRequest{request};
      const auto d = ipc::encode(m);
      if (::sendto((*udp)->fd, d.data(), d.size(), 0, reinterpret_cast<const sockaddr*>(&(*udp)->addr),
                   sizeof(*udp)->addr) >= 0)
        ++datagrams;
    }
    if (canEncoder) {
      auto frames = canEncoder->encode(st.ego_lamps.lights, static_cast<double>(st.ego.speed_m_s));
      if (frames) {
        if (cannelloni) {
          ipc::CannelloniPacket p;
          p.sequence = cannelloniSeq++;
          p.frames = *frames;
          const auto bytes = ipc::encodeCannelloni(p);
          if (::sendto(cannelloni->fd, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&cannelloni->addr),
                       sizeof cannelloni->addr) >= 0)
            canFrames += frames->size();
        }
        if (candump.is_open()) {
          for (const ipc::CanFrame& f : *frames) candump << ipc::formatCandumpLine(wall, o.canInterface, f) << "\n";
          canFrames += frames->size();
        }
      }
    }
    if (log.is_open()) {
      log << wall << "," << st.t_s << "," << egoSeq << "," << lampSeq << "," << st.ego.pose.position_m[0] << ","
          << st.ego.pose.position_m[1] << "," << st.ego.pose.position_m[2] << "," << st.ego.pose.yaw_deg << ","
          << st.ego.pose.pitch_deg << "," << st.ego.pose.roll_deg << "," << st.ego_lamps.lights << ","
          << st.traffic.objects.size() << "," << request << "\n";
    }
    if (o.keyboard && ticks % static_cast<std::uint64_t>(std::max(1.0, o.rate_hz / 4)) == 0) {
      std::fprintf(stderr, "\r  x %7.1f m  y %7.1f m  yaw %6.1f°  %4.1f m/s  lights %-28s  visibility %5.0f m ",
                   kb.ego.pose.position_m[0], kb.ego.pose.position_m[1], static_cast<double>(kb.ego.pose.yaw_deg), kbSpeed,
                   plugin::lightNames(kb.ego_lamps.lights).c_str(), static_cast<double>(kb.environment.visibility_m));
    }
    ++ticks;
    next += period;
    std::this_thread::sleep_until(next);
  }
  const double wall = std::chrono::duration<double>(Clock::now() - start).count();
  std::printf("%sfogbeam send: %llu states in %.2f s (%.1f Hz), %llu datagrams to %s, %llu send errors%s\n",
              o.keyboard ? "\n" : "", static_cast<unsigned long long>(ticks), wall, static_cast<double>(ticks) / wall,
              static_cast<unsigned long long>(datagrams), o.to.c_str(), static_cast<unsigned long long>(sendErrors),
              canEncoder ? (", " + std::to_string(canFrames) + " CAN frames").c_str() : "");
  return sendErrors == 0 ? 0 : 1;
}

}  // namespace fogbeam::cli
