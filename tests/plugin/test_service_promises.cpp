// What docs/service.md promises about the frame loop and the status reply, checked on a running
// Service (issue 16, part 2): a lock-step request for frame 0 is refused; the status names the
// source of the newest input (not "scenario" once a host has taken over) and shows the CAN speed.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/plugin/service.hpp>
#include <fogbeam/plugin/service_config.hpp>

#include <gtest/gtest.h>

#include "service_test_support.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <regex>
#include <string>
#include <thread>
#include <vector>

namespace fogbeam::plugin {
namespace {

using test::holdTheTestFogsTables;
using test::Running;
using test::waitFor;

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

const std::string kData = FOGBEAM_TEST_DATA_DIR;

ServiceConfig configOf(std::vector<std::string> settings) {
  holdTheTestFogsTables();
  static std::atomic<int> calls{0};
  settings.insert(settings.begin(), "render.view_table_step_deg=4.0");
  auto c = loadServiceConfig(kData + "/service/small.toml", settings);
  EXPECT_TRUE(c) << (c ? "" : c.error().message);
  if (!c) return {};
  for (ChannelConfig& ch : c->channels)
    ch.name = "test-prom-" + std::to_string(::getpid()) + "-" + std::to_string(calls++) + "-" + ch.name;
  return std::move(c).value();
}

std::string field(const std::string& json, const std::string& name) {
  std::smatch m;
  if (!std::regex_search(json, m, std::regex("\"" + name + "\": (\"[^\"]*\"|[-0-9.a-z]+)"))) return "";
  return m[1].str();
}

TEST(ServicePromises, LockStepRefusesAFrameRequestForFrameZero) {
  auto created = Service::create(configOf({"timing.mode=\"lock-step\"", "status.interval_s=0.1"}));
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  // The loop sees the newest request only: the next one after the first has been looked at.
  test::LoopbackSender host(service.udpPort());
  host.send(ipc::FrameRequest{0});
  std::this_thread::sleep_for(300ms);
  host.send(ipc::FrameRequest{5});
  ASSERT_TRUE(waitFor([&] { return service.frames() == 1; }, 120'000ms));
  auto r = ipc::ShmReader::attach(service.config().channels[0].name);
  ASSERT_TRUE(r);
  ipc::FrameMeta m;
  std::vector<std::byte> px;
  ASSERT_EQ((*r)->latest(m, px), ipc::ReadStatus::Ok);
  EXPECT_EQ(m.frame, 5u);  // frame 0 was never published
  EXPECT_TRUE(waitFor([&] { return field(service.statusJson(), "frame_requests_refused") == "1"; }, 5000ms))
      << service.statusJson();
  EXPECT_TRUE(loop.finish());
}

TEST(ServicePromises, StatusNamesTheNewestInputsSourceAndTheCanSpeed) {
  // A scenario plays until the candump replay's first mapped frame; the replay starts with the
  // first frame published. Afterwards `input` names the replay (its lamp and speed updates are
  // newer than the scenario's last ego pose) and the speed is in the status.
  auto created = Service::create(configOf({"world.scenario=\"" + kData + "/scenarios/timing.toml\"",
                                           "input.can.source=\"candump\"", "input.can.candump=\"" + kData + "/can/drive.log\"",
                                           "input.can.mapping=\"" + kData + "/can/mapping.toml\"",
                                           "input.can.candump_speed=100.0", "status.interval_s=0.1", "timing.rate_hz=30"}));
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;
  Running loop(service);
  EXPECT_TRUE(waitFor([&] { return field(service.statusJson(), "input").rfind("\"candump", 0) == 0; }, 120'000ms))
      << service.statusJson();
  // The log's speed frame may come after its first lamp frame: the status line after it has it.
  std::string speed;
  EXPECT_TRUE(waitFor(
      [&] {
        speed = field(service.statusJson(), "vehicle_speed_m_s");
        return !speed.empty() && speed != "null";
      },
      10'000ms))
      << service.statusJson();
  ASSERT_FALSE(speed.empty() || speed == "null");
  EXPECT_GE(std::stod(speed), 0.0);
  EXPECT_TRUE(loop.finish());
}

}  // namespace
}  // namespace fogbeam::plugin
