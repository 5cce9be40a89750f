// Settings that the docs name and the service must honour (issue 16): `[input.udp]
// max_traffic_objects` is a setting of the service config that reaches the state store, and the
// channel-name rule is one rule (ipc::kMaxChannelName), checked when the config is loaded and
// stated identically in docs/shm.md and docs/service.md.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/state_store.hpp>
#include <fogbeam/plugin/service.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>
#include <thread>
#include <vector>

namespace fogbeam::plugin {
namespace {

const std::string kSmall = std::string(FOGBEAM_TEST_DATA_DIR) + "/service/small.toml";

std::string errorOf(const std::vector<std::string>& settings) {
  auto c = loadServiceConfig(kSmall, settings);
  return c ? std::string("(loaded)") : c.error().message;
}

TEST(ServiceConfig, MaxTrafficObjectsIsASetting) {
  auto c = loadServiceConfig(kSmall, {});
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->max_traffic_objects, ipc::StateStoreOptions{}.max_traffic_objects);  // 256, docs/protocol.md
  EXPECT_EQ(c->max_traffic_objects, 256u);

  c = loadServiceConfig(kSmall, {"input.udp.max_traffic_objects=3"});
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->max_traffic_objects, 3u);
  // --print-config shows it, and what it prints loads back the same.
  const std::string printed = toToml(*c);
  EXPECT_NE(printed.find("\nmax_traffic_objects = 3\n"), std::string::npos) << printed;
  ServiceConfig again;
  ASSERT_TRUE(applyServiceLayer(again, printed, "printed", "/"));
  EXPECT_EQ(again.max_traffic_objects, 3u);

  EXPECT_NE(errorOf({"input.udp.max_traffic_objects=0"})
                .find("[input.udp] max_traffic_objects: expected an integer in [1, " +
                      std::to_string(kMaxTrafficObjectsLimit) + "], found 0"),
            std::string::npos)
      << errorOf({"input.udp.max_traffic_objects=0"});
  EXPECT_NE(errorOf({"input.udp.max_traffic_objects=" + std::to_string(kMaxTrafficObjectsLimit + 1)}).find("max_traffic_objects"),
            std::string::npos);
  EXPECT_EQ(errorOf({"input.udp.max_traffic_objects=" + std::to_string(kMaxTrafficObjectsLimit)}), "(loaded)");
}

// The setting reaches the running service's state store: with a bound of 2, a traffic list of
// three new cars is applied with one refused, and the next list of new cars, none of which fits,
// is dropped, so that every datagram is counted once.
TEST(ServiceConfig, MaxTrafficObjectsBoundsTheServicesTraffic) {
  auto c = loadServiceConfig(kSmall, {"input.udp.max_traffic_objects=2"});
  ASSERT_TRUE(c) << c.error().message;
  for (ChannelConfig& ch : c->channels) ch.name = "test-cap-" + std::to_string(::getpid()) + "-" + ch.name;
  auto created = Service::create(std::move(c).value());
  ASSERT_TRUE(created) << created.error().message;
  Service& service = **created;

  const UniqueFd fd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
  ASSERT_TRUE(fd);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(service.udpPort());
  inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
  std::uint32_t seq = 0;
  auto send = [&](const std::vector<std::uint32_t>& ids) {
    ipc::TrafficList list;
    for (std::uint32_t id : ids) {
      ipc::TrafficObject o;
      o.id = id;
      o.pose.position_m = {40.0, 3.5, 0.0};
      list.objects.push_back(o);
    }
    ipc::Message m;
    m.header.sequence = ++seq;
    m.payload = list;
    const auto bytes = ipc::encode(m);
    ::sendto(fd.get(), bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  };
  send({1, 2, 3});
  send({4, 5});
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (service.udpStats().datagrams < 2 && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const ipc::UdpStats st = service.udpStats();
  ASSERT_EQ(st.datagrams, 2u);
  EXPECT_EQ(st.traffic_refused, 3u);
  EXPECT_EQ(st.applied, 1u);
  EXPECT_EQ(st.dropped[static_cast<std::size_t>(ipc::DropReason::TooManyObjects)], 1u);
  EXPECT_EQ(st.datagrams, st.applied + st.droppedTotal());
  service.stop();
}

// ---- The channel-name rule ------------------------------------------------------------------------

std::string docText(const std::string& name) {
  auto text = readTextFile(std::string(FOGBEAM_CONFIG_DIR) + "/../docs/" + name);
  EXPECT_TRUE(text) << text.error().message;
  // Markdown wraps lines: one space for every run of white space, so a phrase reads as one.
  return text ? std::regex_replace(*text, std::regex("\\s+"), " ") : std::string();
}

// Every number "1–N characters from `[A-Za-z0-9_.-]`" in `text`.
std::vector<std::size_t> channelRuleLimits(const std::string& text) {
  std::vector<std::size_t> limits;
  const std::regex rule("1–([0-9]+) characters from `\\[A-Za-z0-9_\\.-\\]`");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), rule); it != std::sregex_iterator(); ++it)
    limits.push_back(std::stoul((*it)[1].str()));
  return limits;
}

TEST(ConfigDocs, ChannelNameRuleIsOneRuleInBothDocs) {
  const std::string shm = docText("shm.md"), service = docText("service.md");
  const std::vector<std::size_t> inShm = channelRuleLimits(shm), inService = channelRuleLimits(service);
  ASSERT_EQ(inShm.size(), 1u) << "docs/shm.md, Segment: the channel-name rule, as \"1–N characters from `[A-Za-z0-9_.-]`\"";
  ASSERT_EQ(inService.size(), 1u) << "docs/service.md, [[channel]] name: the same words as docs/shm.md";
  EXPECT_EQ(inShm.front(), ipc::kMaxChannelName);
  EXPECT_EQ(inService.front(), ipc::kMaxChannelName);
  // Both say that the segment's "/fogbeam." prefix does not count.
  EXPECT_NE(shm.find("the `/fogbeam.` prefix not counted"), std::string::npos);
  EXPECT_NE(service.find("the `/fogbeam.` prefix not counted"), std::string::npos);
  // --channel-prefix: the prefixed name has the same limit.
  EXPECT_NE(service.find("a prefixed name longer than " + std::to_string(ipc::kMaxChannelName) + " characters is an error"),
            std::string::npos);

  // The rule is the config's, checked at load (file and line), at exactly that length.
  const std::string longest(ipc::kMaxChannelName, 'c');
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("fogbeam-channel-rule-" + std::to_string(::getpid()) + ".toml");
  auto load = [&](const std::string& name) {
    std::ofstream(file) << "# a channel\n[[channel]]\nname = \"" << name << "\"\n";
    auto c = loadServiceConfig(file.string(), {});
    return c ? std::string("(loaded)") : c.error().message;
  };
  EXPECT_EQ(load(longest), "(loaded)");
  const std::string tooLong = load(longest + "c");
  EXPECT_NE(tooLong.find(file.string() + ":3: [[channel]] #1 name: expected 1–" + std::to_string(ipc::kMaxChannelName)),
            std::string::npos)
      << tooLong;
  std::filesystem::remove(file);
  EXPECT_TRUE(ipc::validChannelName(longest));
  EXPECT_FALSE(ipc::validChannelName(longest + "c"));
}

}  // namespace
}  // namespace fogbeam::plugin
