// Scenario files: interpolation (through the keys, C¹, heading along the path), fog over time,
// lamp events, traffic lifetimes, esmini CSV, the messages a state encodes to, and bad files.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/plugin/scenario.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

namespace fogbeam::plugin {
namespace {

const std::string kScene = std::string(FOGBEAM_CONFIG_DIR) + "/scenes/night_road.toml";

std::string header() { return "scene = \"" + kScene + "\"\nduration_s = 10\n"; }

Scenario parse(const std::string& body) {
  auto s = parseScenario(header() + body, "t.toml", "");
  EXPECT_TRUE(s) << (s ? "" : s.error().message);
  return s ? std::move(s).value() : Scenario{};
}

std::string errorOf(const std::string& text) {
  auto s = parseScenario(text, "bad.toml", "");
  return s ? std::string("(parsed)") : s.error().message;
}

TEST(Trajectory, PassesThroughItsKeysWithContinuousVelocity) {
  std::vector<PoseKey> keys{{0.0, Vec3(0, 0, 0)}, {2.0, Vec3(30, 0, 0)}, {3.0, Vec3(40, 5, 0)}, {6.0, Vec3(60, 30, 1)}};
  auto t = Trajectory::make(keys, false, "test");
  ASSERT_TRUE(t);
  for (const PoseKey& k : keys) {
    const auto s = t->at(k.t_s);
    EXPECT_NEAR(s.pose.position_m[0], k.position_m.x, 1e-9);
    EXPECT_NEAR(s.pose.position_m[1], k.position_m.y, 1e-9);
  }
  // C¹: the velocity just before and just after an inner key agree (finite differences).
  for (double tk : {2.0, 3.0}) {
    const double e = 1e-4;
    auto pos = [&](double x) {
      const auto p = t->at(x).pose.position_m;
      return Vec3(p[0], p[1], p[2]);
    };
    const Vec3 before = (pos(tk) - pos(tk - e)) / e;
    const Vec3 after = (pos(tk + e) - pos(tk)) / e;
    EXPECT_LT(glm::length(before - after), 1e-2 * glm::length(before)) << "at t = " << tk;
    // Catmull–Rom tangent at the key: (p_{k+1} − p_{k−1}) / (t_{k+1} − t_{k−1}).
    EXPECT_NEAR(t->at(tk).speed_m_s, glm::length(before), 1e-2 * glm::length(before));
  }
  // No yaw keys: heading along the velocity. Mid-way along a straight x segment: heading 0.
  auto straight = Trajectory::make({{0.0, Vec3(0, 0, 0)}, {1.0, Vec3(10, 0, 0)}, {2.0, Vec3(20, 0, 0)}}, false, "s");
  ASSERT_TRUE(straight);
  EXPECT_NEAR(straight->at(0.7).pose.yaw_deg, 0.0, 1e-6);
  EXPECT_NEAR(straight->at(0.7).speed_m_s, 10.0, 1e-9);
  auto north = Trajectory::make({{0.0, Vec3(0, 0, 0)}, {1.0, Vec3(0, 10, 0)}}, false, "n");
  EXPECT_NEAR(north->at(0.5).pose.yaw_deg, 90.0, 1e-6);  // +y is left: heading +90°
  // Clamped outside the keys, standing still.
  EXPECT_EQ(straight->at(-5.0).pose.position_m[0], 0.0);
  EXPECT_EQ(straight->at(50.0).pose.position_m[0], 20.0);
  EXPECT_EQ(straight->at(50.0).speed_m_s, 0.0);
}

TEST(Trajectory, YawTakesTheShortWayRound) {
  std::vector<PoseKey> keys{{0.0, Vec3(0), 170.0}, {1.0, Vec3(1, 0, 0), -170.0}};
  auto t = Trajectory::make(keys, true, "wrap");
  ASSERT_TRUE(t);
  EXPECT_NEAR(std::abs(t->at(0.5).pose.yaw_deg), 180.0, 1e-6);  // not 0
}

TEST(Trajectory, RejectsKeysOutOfOrder) {
  auto t = Trajectory::make({{1.0, Vec3(0)}, {1.0, Vec3(1, 0, 0)}}, false, "[[vehicle]] #1");
  ASSERT_FALSE(t);
  EXPECT_NE(t.error().message.find("key 2 at t = 1 s is not after key 1"), std::string::npos) << t.error().message;
}

TEST(Scenario, FogLightsAndTrafficOverTime) {
  const Scenario s = parse(R"(
[fog]
visibility_m = 300
albedo = 0.9
g = 0.8
[[fog_key]]
t_s = 2
visibility_m = 300
[[fog_key]]
t_s = 6
visibility_m = 40
[ego]
lights = ["low-beam", "position"]
[[ego.key]]
t_s = 0
position_m = [0, -1.75, 0]
[[ego.key]]
t_s = 10
position_m = [150, -1.75, 0]
[[ego.event]]
t_s = 4
lights = ["high-beam", "position"]
[[ego.event]]
t_s = 7
lights = ["low-beam", "position"]
bending_deg = 5
[[vehicle]]
id = 7
class = 1
lights = ["low-beam"]
[[vehicle.key]]
t_s = 3
position_m = [200, 1.75, 0]
yaw_deg = 180
[[vehicle.key]]
t_s = 9
position_m = [20, 1.75, 0]
yaw_deg = 180
)");
  // Fog: constant before the first key, log-linear between (geometric mean half way), held after.
  EXPECT_FLOAT_EQ(evaluate(s, 1.0).environment.visibility_m, 300.0f);
  EXPECT_NEAR(evaluate(s, 4.0).environment.visibility_m, std::sqrt(300.0 * 40.0), 1e-3);
  EXPECT_FLOAT_EQ(evaluate(s, 8.0).environment.visibility_m, 40.0f);
  EXPECT_FLOAT_EQ(evaluate(s, 1.0).environment.albedo, 0.9f);
  EXPECT_FLOAT_EQ(evaluate(s, 1.0).environment.g, 0.8f);
  // Lights: the initial state, then each event from its time on.
  EXPECT_EQ(evaluate(s, 3.9).ego_lamps.lights, ipc::light::kLowBeam | ipc::light::kPosition);
  EXPECT_EQ(evaluate(s, 4.0).ego_lamps.lights, ipc::light::kHighBeam | ipc::light::kPosition);
  EXPECT_EQ(evaluate(s, 7.5).ego_lamps.lights, ipc::light::kLowBeam | ipc::light::kPosition);
  EXPECT_FLOAT_EQ(evaluate(s, 7.5).ego_lamps.bending_deg, 5.0f);
  // Ego: 15 m/s along x.
  EXPECT_NEAR(evaluate(s, 5.0).ego.pose.position_m[0], 75.0, 1e-9);
  EXPECT_NEAR(evaluate(s, 5.0).ego.speed_m_s, 15.0, 1e-5);
  // Traffic exists only within its keys.
  EXPECT_TRUE(evaluate(s, 2.9).traffic.objects.empty());
  const auto mid = evaluate(s, 6.0).traffic;
  ASSERT_EQ(mid.objects.size(), 1u);
  EXPECT_TRUE(mid.complete);
  EXPECT_EQ(mid.objects[0].id, 7u);
  EXPECT_EQ(mid.objects[0].vehicle_class, 1);
  EXPECT_EQ(mid.objects[0].lights, ipc::light::kLowBeam);
  EXPECT_NEAR(mid.objects[0].pose.position_m[0], 110.0, 1e-9);
  EXPECT_NEAR(std::abs(mid.objects[0].pose.yaw_deg), 180.0, 1e-6);
  EXPECT_TRUE(evaluate(s, 9.5).traffic.objects.empty());
}

TEST(Scenario, StepFogAndSceneFogDefault) {
  const Scenario step = parse(R"(
[fog]
visibility_m = 100
interpolation = "step"
[[fog_key]]
t_s = 0
visibility_m = 100
[[fog_key]]
t_s = 5
visibility_m = 50
[ego]
[[ego.key]]
t_s = 0
position_m = [0, 0, 0]
)");
  EXPECT_FLOAT_EQ(evaluate(step, 4.99).environment.visibility_m, 100.0f);
  EXPECT_FLOAT_EQ(evaluate(step, 5.0).environment.visibility_m, 50.0f);
  // Without [fog], the scene file's fog (night_road.toml) is used.
  const Scenario def = parse("[ego]\n[[ego.key]]\nt_s = 0\nposition_m = [0, 0, 0]\n");
  EXPECT_GT(def.fog.visibility_m + def.fog.extinction_per_m, 0.0f);
}

// Every shipped scenario loads; fog_bank's fog follows its keys (log-linear between them).
TEST(Scenario, ShippedScenariosLoad) {
  int count = 0;
  for (const auto& e : std::filesystem::directory_iterator(std::string(FOGBEAM_CONFIG_DIR) + "/scenarios")) {
    if (e.path().extension() != ".toml") continue;
    auto s = loadScenario(e.path().string());
    EXPECT_TRUE(s) << e.path() << ": " << (s ? "" : s.error().message);
    ++count;
  }
  EXPECT_GE(count, 5);
  auto bank = loadScenario(std::string(FOGBEAM_CONFIG_DIR) + "/scenarios/fog_bank.toml");
  ASSERT_TRUE(bank) << bank.error().message;
  EXPECT_FLOAT_EQ(evaluate(*bank, 2.0).environment.visibility_m, 200.0f);
  EXPECT_NEAR(evaluate(*bank, 6.5).environment.visibility_m, 100.0f, 0.01f);  // 200 · (50/200)^0.5
  EXPECT_FLOAT_EQ(evaluate(*bank, 10.0).environment.visibility_m, 50.0f);
}

TEST(Scenario, StateEncodesToMessagesThatDecode) {
  const Scenario s = parse(R"(
[ego]
[[ego.key]]
t_s = 0
position_m = [0, 0, 0]
[[ego.key]]
t_s = 10
position_m = [100, 0, 0]
[[vehicle]]
id = 3
[[vehicle.key]]
t_s = 0
position_m = [100, 2, 0]
[[vehicle.key]]
t_s = 10
position_m = [0, 2, 0]
)");
  std::uint32_t seq = 100;
  const auto datagrams = encodeState(evaluate(s, 5.0), seq);
  ASSERT_EQ(datagrams.size(), 4u);
  EXPECT_EQ(seq, 104u);
  bool sawEgo = false, sawTraffic = false;
  for (const auto& d : datagrams) {
    const ipc::DecodeResult r = ipc::decode(d);
    ASSERT_TRUE(r.ok) << ipc::toString(r.reason);
    EXPECT_DOUBLE_EQ(r.message.header.sim_time_s, 5.0);
    if (const auto* e = std::get_if<ipc::EgoState>(&r.message.payload)) {
      sawEgo = true;
      EXPECT_NEAR(e->pose.position_m[0], 50.0, 1e-9);
    }
    if (const auto* t = std::get_if<ipc::TrafficList>(&r.message.payload)) {
      sawTraffic = true;
      ASSERT_EQ(t->objects.size(), 1u);
      EXPECT_EQ(t->objects[0].id, 3u);
      EXPECT_NEAR(std::abs(t->objects[0].pose.yaw_deg), 180.0, 1e-4);  // heading along −x
    }
  }
  EXPECT_TRUE(sawEgo && sawTraffic);
}

TEST(Scenario, EsminiCsvTrajectory) {
  const auto dir = std::filesystem::temp_directory_path() / "fogbeam_scenario_test";
  std::filesystem::create_directories(dir);
  {
    std::ofstream f(dir / "run.csv");
    f << "Version: 2.37.4, OpenSCENARIO: x.xosc, OpenDRIVE: y.xodr, Model: \n"
         "time, id, name, x, y, z, h, p, r, speed, wheel_angle, wheel_rot\n"
         "0.000, 0, Ego, 10.000, -1.535, 0.000, 0.000, 0.000, 0.000, 20.000, 0.000, 0.000\n"
         "0.000, 1, Target, 200.000, 1.535, 0.000, 3.14159265, 0.000, 0.000, 20.000, 0.000, 0.000\n"
         "1.000, 0, Ego, 30.000, -1.535, 0.000, 0.000, 0.000, 0.000, 20.000, 0.000, 0.000\n"
         "1.000, 1, Target, 180.000, 1.535, 0.000, 3.14159265, 0.000, 0.000, 20.000, 0.000, 0.000\n"
         "2.000, 0, Ego, 50.000, -1.535, 0.000, 0.0500, 0.000, 0.000, 20.000, 0.000, 0.000\n";
  }
  std::ofstream(dir / "s.toml") << header() << "[ego]\ncsv = \"run.csv\"\ncsv_name = \"Ego\"\n"
                                << "[[vehicle]]\nid = 9\ncsv = \"run.csv\"\ncsv_id = 1\n";
  auto s = loadScenario((dir / "s.toml").string());
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_NEAR(evaluate(*s, 1.0).ego.pose.position_m[0], 30.0, 1e-9);
  EXPECT_NEAR(evaluate(*s, 2.0).ego.pose.yaw_deg, 0.05 * 180.0 / 3.14159265358979, 1e-4);  // radians → degrees
  const auto tr = evaluate(*s, 0.5).traffic;
  ASSERT_EQ(tr.objects.size(), 1u);
  EXPECT_EQ(tr.objects[0].id, 9u);  // the scenario's id, not the CSV's
  EXPECT_NEAR(std::abs(tr.objects[0].pose.yaw_deg), 180.0, 1e-4);

  auto bad = parseEsminiCsv("time, id, name, x, y, z, h, p, r\n0, 0, Ego, 1, 2, 3, 0, 0, nan\n", "bad.csv");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("bad.csv:2: expected column r (a finite number)"), std::string::npos)
      << bad.error().message;
  auto noHeader = parseEsminiCsv("0, 0, Ego, 1, 2, 3\n", "nh.csv");
  ASSERT_FALSE(noHeader);
  EXPECT_NE(noHeader.error().message.find("no header row"), std::string::npos);
  auto missingColumn = parseEsminiCsv("time, id, name, x, y, z, h, p\n", "mc.csv");
  ASSERT_FALSE(missingColumn);
  EXPECT_NE(missingColumn.error().message.find("mc.csv:1: the header has no column \"r\""), std::string::npos)
      << missingColumn.error().message;
  std::filesystem::remove_all(dir);
}

TEST(Scenario, BadFilesSayWhereAndWhat) {
  const std::string ego = "[ego]\n[[ego.key]]\nt_s = 0\nposition_m = [0, 0, 0]\n";
  const std::string colour = header() + "[ego]\ncolour = 1\n[[ego.key]]\nt_s = 0\nposition_m = [0, 0, 0]\n";
  EXPECT_NE(errorOf(colour).find("bad.toml:4: [ego]: unknown key 'colour'"), std::string::npos) << errorOf(colour);
  EXPECT_NE(errorOf(header()).find("missing table [ego]"), std::string::npos);
  EXPECT_NE(errorOf("duration_s = 1\n" + ego).find("scene: missing"), std::string::npos) << errorOf("duration_s = 1\n" + ego);
  EXPECT_NE(errorOf("scene = \"nope.toml\"\nduration_s = 1\n" + ego).find("bad.toml:1: scene: file not found"),
            std::string::npos);
  const std::string lights = header() + "[ego]\nlights = [\"low-beam\", \"hi-beam\"]\n[[ego.key]]\nt_s = 0\nposition_m = [0, 0, 0]\n";
  EXPECT_NE(errorOf(lights).find("bad.toml:4: [ego] lights: unknown light \"hi-beam\""), std::string::npos)
      << errorOf(lights);
  const std::string order = header() + "[ego]\n[[ego.key]]\nt_s = 2\nposition_m = [0, 0, 0]\n[[ego.key]]\nt_s = 1\nposition_m = [1, 0, 0]\n";
  EXPECT_NE(errorOf(order).find("bad.toml:8: [ego] [[key]] #2 t_s: expected a time after the previous key's 2 s"),
            std::string::npos)
      << errorOf(order);
  const std::string yaw = header() + "[ego]\n[[ego.key]]\nt_s = 0\nposition_m = [0, 0, 0]\nyaw_deg = 3\n[[ego.key]]\nt_s = 1\nposition_m = [1, 0, 0]\n";
  EXPECT_NE(errorOf(yaw).find("yaw_deg is given in 1 of 2 keys"), std::string::npos) << errorOf(yaw);
  const std::string dup = header() + ego + "[[vehicle]]\nid = 1\n[[vehicle.key]]\nt_s = 0\nposition_m = [0, 0, 0]\n" +
                          "[[vehicle]]\nid = 1\n[[vehicle.key]]\nt_s = 0\nposition_m = [0, 0, 0]\n";
  EXPECT_NE(errorOf(dup).find("expected a unique id, found 1 again"), std::string::npos) << errorOf(dup);
  EXPECT_NE(errorOf(header() + ego + "[fog]\nvisibility_m = -3\n").find("[fog] visibility_m: expected a number > 0"),
            std::string::npos);
  EXPECT_NE(errorOf(header() + ego + "[fog]\nvisibility_m = 30\ninterpolation = \"cubic\"\n")
                .find("interpolation: expected \"log-linear\" or \"step\", found \"cubic\""),
            std::string::npos);
}

TEST(Scenario, LightNamesRoundTrip) {
  auto bits = lightsFromNames({"low-beam", "front-fog", "position"});
  ASSERT_TRUE(bits);
  EXPECT_EQ(*bits, ipc::light::kLowBeam | ipc::light::kFrontFog | ipc::light::kPosition);
  EXPECT_EQ(lightNames(*bits), "position+low-beam+front-fog");
  EXPECT_EQ(lightNames(0), "off");
}

}  // namespace
}  // namespace fogbeam::plugin
