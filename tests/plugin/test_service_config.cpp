// The service configuration: the built-in default, layering (built-in < file < --set), every
// section's keys, errors with file and line, and --print-config output that loads back the same.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/plugin/service_config.hpp>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace fogbeam::plugin {
namespace {

namespace fs = std::filesystem;

struct TempDir {
  fs::path path = fs::temp_directory_path() / ("fogbeam_service_config_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()));
  TempDir() { fs::create_directories(path); }
  ~TempDir() { fs::remove_all(path); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(path / name) << text;
    return (path / name).string();
  }
};

TEST(ServiceConfig, BuiltInDefaultIsACompleteCab) {
  auto c = loadServiceConfig("", {});
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->layers.size(), 1u);
  EXPECT_TRUE(fs::exists(c->scene_path)) << c->scene_path;
  EXPECT_TRUE(fs::exists(c->scenario_path)) << c->scenario_path;
  ASSERT_EQ(c->channels.size(), 1u);
  EXPECT_EQ(c->channels[0].name, "main");
  EXPECT_FALSE(c->lock_step);
  EXPECT_EQ(c->udp_bind, "127.0.0.1");  // loopback unless a cab opts in
  std::size_t low = 0, high = 0, fog = 0;
  for (const RigLamp& l : c->ego.lamps) {
    low += l.light_bit == ipc::light::kLowBeam;
    high += l.light_bit == ipc::light::kHighBeam;
    fog += l.light_bit == ipc::light::kFrontFog;
    EXPECT_EQ(l.lamp.mount, LampMount::Vehicle);
  }
  EXPECT_EQ(low, 2u);
  EXPECT_EQ(high, 2u);
  EXPECT_EQ(fog, 2u);
  ASSERT_NE(c->rigFor(0), nullptr);
  EXPECT_EQ(c->rigFor(42), c->rigFor(0));  // classes without a rig use class 0's
}

TEST(ServiceConfig, LayersWinInOrder) {
  TempDir d;
  const std::string file = d.write("cab.toml", R"(
[timing]
rate_hz = 60.0

[[channel]]
name = "left"
width = 64
height = 36
yaw_deg = 45.0
eye_offset_m = [0.0, 0.1, 0.0]

[[channel]]
name = "centre"
width = 64
height = 36
format = "rgba16f-overlay"

[[traffic_class]]
class = 0
[[traffic_class.lamp]]
role = "low-beam"
position_m = [3.7, 0.7, 0.65]
profile = "spot"
intensity_cd = 20000.0
inner_deg = 4.0
outer_deg = 14.0

[[traffic_class]]
class = 3
name = "truck"
[[traffic_class.lamp]]
role = "position"
position_m = [-8.0, 1.2, 1.0]
yaw_deg = 180.0
profile = "isotropic"
intensity_cd = 5.0
)");
  auto c = loadServiceConfig(file, {"timing.mode=\"lock-step\"", "render.method=\"seed\"", "input.udp.port=0"});
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->layers.size(), 5u);
  EXPECT_DOUBLE_EQ(c->rate_hz, 60.0);            // file over built-in
  EXPECT_TRUE(c->lock_step);                     // --set over file
  EXPECT_EQ(c->method, "seed");
  EXPECT_EQ(c->udp_port, 0);
  EXPECT_EQ(c->status_udp_port, 47801);          // untouched: built-in
  ASSERT_EQ(c->channels.size(), 2u);             // [[channel]] replaces the built-in list
  EXPECT_EQ(c->channels[0].name, "left");
  EXPECT_DOUBLE_EQ(c->channels[0].yaw_deg, 45.0);
  EXPECT_DOUBLE_EQ(c->channels[0].eye_offset_m.y, 0.1);
  EXPECT_EQ(c->channels[1].format, "rgba16f-overlay");
  EXPECT_EQ(c->ego.lamps.size(), 6u);            // [ego] not in the file: built-in rig
  ASSERT_EQ(c->traffic.size(), 2u);
  EXPECT_EQ(c->rigFor(3)->name, "truck");
  EXPECT_EQ(c->rigFor(3)->lamps[0].light_bit, ipc::light::kPosition);
  EXPECT_EQ(c->rigFor(7)->lamps[0].light_bit, ipc::light::kLowBeam);
}

TEST(ServiceConfig, PrintedConfigLoadsBackTheSame) {
  TempDir d;
  auto a = loadServiceConfig("", {"timing.rate_hz=45", "render.subsampling=false"});
  ASSERT_TRUE(a) << a.error().message;
  const std::string printed = toToml(*a);
  const std::string file = d.write("printed.toml", printed);
  auto b = loadServiceConfig(file, {});
  ASSERT_TRUE(b) << b.error().message << "\n" << printed;
  EXPECT_EQ(toToml(*b).substr(toToml(*b).find("[world]")), printed.substr(printed.find("[world]")));
  EXPECT_DOUBLE_EQ(b->rate_hz, 45.0);
  EXPECT_FALSE(b->subsampling);
}

TEST(ServiceConfig, ErrorsNameTheLayerLineAndKey) {
  TempDir d;
  auto errorOf = [&](const std::string& text, std::vector<std::string> set = {}) {
    const std::string f = d.write("bad.toml", text);
    auto c = loadServiceConfig(f, set);
    return c ? std::string("(loaded)") : c.error().message;
  };
  EXPECT_NE(errorOf("[timing]\nrate_hz = 30\nmode = \"lockstep\"\n").find("bad.toml:3: [timing] mode: expected \"free-running\" or \"lock-step\", found \"lockstep\""),
            std::string::npos)
      << errorOf("[timing]\nmode = \"lockstep\"\n");
  EXPECT_NE(errorOf("[render]\nmoving_lamps = \"table\"\n").find("bad.toml:2: [render] moving_lamps: expected \"pencil\" or \"per-ray\", found \"table\""),
            std::string::npos)
      << errorOf("[render]\nmoving_lamps = \"table\"\n");
  EXPECT_NE(errorOf("[render]\nthreds = 2\n").find("bad.toml:2: [render]: unknown key 'threds' (did you mean 'threads'?)"),
            std::string::npos)
      << errorOf("[render]\nthreds = 2\n");
  EXPECT_NE(errorOf("[[channel]]\nname = \"a\"\n[[channel]]\nname = \"a\"\n").find("bad.toml:4: [[channel]] #2 name: expected a unique name"),
            std::string::npos);
  EXPECT_NE(errorOf("[[channel]]\nname = \"../etc\"\n").find("expected letters, digits"), std::string::npos);
  EXPECT_NE(errorOf("[ego]\n[[ego.lamp]]\nposition_m = [1, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 1\n")
                .find("[ego] [[lamp]] #1 role: missing"),
            std::string::npos)
      << errorOf("[ego]\n[[ego.lamp]]\nposition_m = [1, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 1\n");
  EXPECT_NE(errorOf("[[traffic_class]]\nclass = 0\n[[traffic_class.lamp]]\nrole = \"low-beam\"\nbending = true\n"
                    "position_m = [1, 0, 0]\nprofile = \"isotropic\"\nintensity_cd = 1\n")
                .find("bending: only the ego's lamps bend"),
            std::string::npos);
  EXPECT_NE(errorOf("[world]\nscene = \"nowhere.toml\"\n").find("bad.toml:2: [world] scene: file not found"), std::string::npos);
  EXPECT_NE(errorOf("[input.can]\nsource = \"candump\"\n").find("needs mapping"), std::string::npos);
  EXPECT_NE(errorOf("", {"timing.rate_hz=-3"}).find("--set timing.rate_hz=-3:1: [timing] rate_hz: expected a number in (0, 1000]"),
            std::string::npos)
      << errorOf("", {"timing.rate_hz=-3"});
  EXPECT_NE(errorOf("", {"rate"}).find("expected key.path=value"), std::string::npos);
  EXPECT_NE(errorOf("[status]\nudp_port = 47800\n").find("[status] udp_port equals [input.udp] port 47800"),
            std::string::npos);
}

}  // namespace
}  // namespace fogbeam::plugin
