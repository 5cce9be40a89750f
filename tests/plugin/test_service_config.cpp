// The service configuration: the built-in default, layering (built-in < file < --set), every
// section's keys, errors with file and line, and --print-config output that loads back the same.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/files.hpp>

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
  // Every issue 7 key away from its default, and a traffic lamp with an aperture.
  const std::string layer = d.write("fx.toml", R"(
[[traffic_class]]
class = 0
[[traffic_class.lamp]]
role = "low-beam"
name = "left low beam"
position_m = [3.7, 0.7, 0.65]
profile = "spot"
intensity_cd = 20000.0
inner_deg = 4.0
outer_deg = 14.0
aperture = "rectangle"
aperture_size_m = [0.25, 0.1]
aperture_samples = 2
)");
  auto a = loadServiceConfig(layer, {"timing.rate_hz=45", "render.subsampling=false", "glow.enabled=true",
                                     "glow.fade_in=3.5", "glare.age_years=67", "glare.pigmentation=0.25",
                                     "render.airlight=\"gpu\"", "render.gpu_pieces=32",
                                     "render.moving_lamp_cutoff_cd_m2=0.0002"});
  ASSERT_TRUE(a) << a.error().message;
  const std::string printed = toToml(*a);
  const std::string file = d.write("printed.toml", printed);
  auto b = loadServiceConfig(file, {});
  ASSERT_TRUE(b) << b.error().message << "\n" << printed;
  EXPECT_EQ(toToml(*b).substr(toToml(*b).find("[world]")), printed.substr(printed.find("[world]")));
  EXPECT_DOUBLE_EQ(b->rate_hz, 45.0);
  EXPECT_FALSE(b->subsampling);
  EXPECT_TRUE(b->effects.glow.enabled);
  EXPECT_DOUBLE_EQ(b->effects.glow.fade_in, 3.5);
  EXPECT_TRUE(b->effects.glare.enabled);  // --set glare.age_years alone turns glare on, as the table would
  EXPECT_DOUBLE_EQ(b->effects.glare.age_years, 67.0);
  EXPECT_DOUBLE_EQ(b->effects.glare.pigmentation, 0.25);
  EXPECT_EQ(b->effects.render.airlight, AirlightDevice::Gpu);
  EXPECT_EQ(b->effects.render.gpu_pieces, 32);
  EXPECT_DOUBLE_EQ(b->moving_lamp_cutoff_cd_m2, 0.0002);
  const RigLamp& l = b->rigFor(0)->lamps.at(0);
  EXPECT_EQ(l.lamp.aperture.shape, ApertureShape::Rectangle);
  EXPECT_DOUBLE_EQ(l.lamp.aperture.width_m, 0.25);
  EXPECT_DOUBLE_EQ(l.lamp.aperture.height_m, 0.1);
  EXPECT_EQ(l.lamp.aperture.samples, 2);
}

TEST(ServiceConfig, ExposureIsAutoOrAFixedEv) {
  TempDir d;
  // Built in: the automatic night exposure, printed as such.
  auto builtIn = loadServiceConfig("", {});
  ASSERT_TRUE(builtIn) << builtIn.error().message;
  EXPECT_TRUE(builtIn->channels.at(0).autoExposure());
  EXPECT_NE(toToml(*builtIn).find("exposure_ev = \"auto\""), std::string::npos);
  // Left out: auto on rgba8-srgb views of fogbeam's own, fixed 0 on linear formats and host views.
  auto c = loadServiceConfig(d.write("ev.toml", R"(
[[channel]]
name = "plain"
[[channel]]
name = "fixed"
exposure_ev = -1.5
[[channel]]
name = "whole"
exposure_ev = 3
[[channel]]
name = "said"
exposure_ev = "auto"
[[channel]]
name = "linear"
format = "rgba16f-linear"
[[channel]]
name = "hosted"
depth_from = "host-depth"
[[channel]]
name = "hosted-fixed"
depth_from = "host-depth-2"
exposure_ev = 1.25
)"),
                             {});
  ASSERT_TRUE(c) << c.error().message;
  const auto& ch = c->channels;
  ASSERT_EQ(ch.size(), 7u);
  EXPECT_TRUE(ch[0].autoExposure());
  EXPECT_FALSE(ch[1].autoExposure());
  EXPECT_DOUBLE_EQ(ch[1].exposure_ev, -1.5);
  EXPECT_FALSE(ch[2].autoExposure());
  EXPECT_DOUBLE_EQ(ch[2].exposure_ev, 3.0);
  EXPECT_TRUE(ch[3].autoExposure());
  EXPECT_FALSE(ch[4].autoExposure());
  EXPECT_DOUBLE_EQ(ch[4].exposure_ev, 0.0);
  EXPECT_FALSE(ch[5].autoExposure());
  EXPECT_DOUBLE_EQ(ch[5].exposure_ev, 0.0);
  EXPECT_FALSE(ch[6].autoExposure());
  EXPECT_DOUBLE_EQ(ch[6].exposure_ev, 1.25);
  // --print-config loads back the same: "auto" and the numbers.
  const std::string printed = toToml(*c);
  auto back = loadServiceConfig(d.write("printed.toml", printed), {});
  ASSERT_TRUE(back) << back.error().message << "\n" << printed;
  for (std::size_t k = 0; k < ch.size(); ++k) {
    EXPECT_EQ(back->channels[k].autoExposure(), ch[k].autoExposure()) << k;
    EXPECT_DOUBLE_EQ(back->channels[k].exposure_ev, ch[k].exposure_ev) << k;
  }

  // Anything else: the file, the line, the key, what was expected and what was found.
  auto errorOf = [&](const std::string& text, std::vector<std::string> set = {}) {
    auto r = loadServiceConfig(d.write("bad.toml", text), set);
    return r ? std::string("(loaded)") : r.error().message;
  };
  auto expectError = [&](const std::string& text, const std::string& want) {
    const std::string got = errorOf(text);
    EXPECT_NE(got.find(want), std::string::npos) << "expected: " << want << "\ngot: " << got;
  };
  expectError("[[channel]]\nname = \"a\"\nexposure_ev = \"automatic\"\n",
              "bad.toml:3: [[channel]] #1 exposure_ev: expected \"auto\" or a number in [-20, 20] (EV), found the string "
              "\"automatic\"");
  expectError("[[channel]]\nname = \"a\"\nexposure_ev = 25\n",
              "bad.toml:3: [[channel]] #1 exposure_ev: expected \"auto\" or a number in [-20, 20] (EV), found 25");
  expectError("[[channel]]\nname = \"a\"\nexposure_ev = true\n",
              "bad.toml:3: [[channel]] #1 exposure_ev: expected \"auto\" or a number in [-20, 20] (EV), found the boolean true");
  expectError("[[channel]]\nname = \"a\"\nexposure_ev = nan\n", "bad.toml:3: [[channel]] #1 exposure_ev: expected \"auto\"");
  expectError("[[channel]]\nname = \"a\"\nformat = \"rgba16f-overlay\"\nexposure_ev = \"auto\"\n",
              "bad.toml:4: [[channel]] #1 exposure_ev: \"auto\" applies to rgba8-srgb channels only, and format = "
              "\"rgba16f-overlay\"");
  expectError("[[channel]]\nname = \"a\"\ndepth_from = \"h\"\nexposure_ev = \"auto\"\n",
              "bad.toml:4: [[channel]] #1 exposure_ev: expected a number with depth_from");
  expectError("[[channel]]\nname = \"a\"\nformat = \"rgba16f-overlay\"\nexposure_ev = 1\n",
              "exposure_ev applies to rgba8-srgb only");
}

TEST(ServiceConfig, EffectsAreOffByDefaultAndMergeKeyByKey) {
  auto c = loadServiceConfig("", {});
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_FALSE(c->effects.glow.enabled);
  EXPECT_FALSE(c->effects.glare.enabled);
  EXPECT_EQ(c->effects.render.airlight, AirlightDevice::Cpu);
  // The service's defaults are the scene's (effects.hpp).
  EXPECT_DOUBLE_EQ(c->effects.glow.fade_in, GlowOptions{}.fade_in);
  EXPECT_DOUBLE_EQ(c->effects.glare.age_years, GlareOptions{}.age_years);
  EXPECT_DOUBLE_EQ(c->effects.glare.pigmentation, GlareOptions{}.pigmentation);
  EXPECT_EQ(c->effects.render.gpu_pieces, RenderSettings{}.gpu_pieces);

  TempDir d;
  const std::string file = d.write("old_driver.toml", "[glare]\nage_years = 70.0\npigmentation = 0.9\n");
  auto m = loadServiceConfig(file, {"glare.pigmentation=0.1", "glow.enabled=true"});
  ASSERT_TRUE(m) << m.error().message;
  EXPECT_TRUE(m->effects.glare.enabled);                  // the file's table turns it on
  EXPECT_DOUBLE_EQ(m->effects.glare.age_years, 70.0);     // kept from the file under the --set
  EXPECT_DOUBLE_EQ(m->effects.glare.pigmentation, 0.1);   // --set over the file
  EXPECT_TRUE(m->effects.glow.enabled);
  EXPECT_DOUBLE_EQ(m->effects.glow.fade_in, 2.0);
  auto off = loadServiceConfig(file, {"glare.enabled=false"});
  ASSERT_TRUE(off) << off.error().message;
  EXPECT_FALSE(off->effects.glare.enabled);
  EXPECT_DOUBLE_EQ(off->effects.glare.age_years, 70.0);
}

// The service reads [render] airlight and gpu_pieces itself (its [render] table also holds the
// service's keys, which config::parseRenderSettings would reject): it must accept exactly what a
// scene file accepts.
TEST(ServiceConfig, RenderKeysTakeTheSceneFilesValues) {
  const std::string sceneFile = std::string(FOGBEAM_TEST_DATA_DIR) + "/scenes/serve_world.toml";
  auto sceneText = readTextFile(sceneFile);
  ASSERT_TRUE(sceneText) << sceneText.error().message;
  for (const std::string value : {"3", "4", "64", "1024", "1025", "0", "-8", "12.5", "\"64\""}) {
    auto scene = parseScene(*sceneText + "\n[render]\ngpu_pieces = " + value + "\n", "scene.toml",
                            fs::path(sceneFile).parent_path().string());
    auto service = loadServiceConfig("", {"render.gpu_pieces=" + value});
    EXPECT_EQ(scene.has_value(), service.has_value()) << "gpu_pieces = " << value;
    if (scene && service) {
      EXPECT_EQ(scene->effects.render.gpu_pieces, service->effects.render.gpu_pieces);
    }
  }
  for (const std::string value : {"\"cpu\"", "\"gpu\"", "\"GPU\"", "\"vulkan\"", "1"}) {
    auto scene = parseScene(*sceneText + "\n[render]\nairlight = " + value + "\n", "scene.toml",
                            fs::path(sceneFile).parent_path().string());
    auto service = loadServiceConfig("", {"render.airlight=" + value});
    EXPECT_EQ(scene.has_value(), service.has_value()) << "airlight = " << value;
    if (scene && service) {
      EXPECT_EQ(scene->effects.render.airlight, service->effects.render.airlight);
    }
  }
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
  EXPECT_NE(errorOf("[render]\nmoving_lamps = \"table\"\n").find("bad.toml:2: [render] moving_lamps: expected \"pencil\", \"map\" or \"per-ray\", found \"table\""),
            std::string::npos)
      << errorOf("[render]\nmoving_lamps = \"table\"\n");
  EXPECT_NE(errorOf("[render]\nmoving_lamp_cutoff_cd_m2 = -0.001\n").find("bad.toml:2: [render] moving_lamp_cutoff_cd_m2: expected a number in [0, 1]"),
            std::string::npos)
      << errorOf("[render]\nmoving_lamp_cutoff_cd_m2 = -0.001\n");
  EXPECT_NE(errorOf("[render]\nthreds = 2\n").find("bad.toml:2: [render]: unknown key 'threds' (did you mean 'threads'?)"),
            std::string::npos)
      << errorOf("[render]\nthreds = 2\n");
  EXPECT_NE(errorOf("[[channel]]\nname = \"a\"\n[[channel]]\nname = \"a\"\n").find("bad.toml:4: [[channel]] #2 name: expected a unique name"),
            std::string::npos);
  EXPECT_NE(errorOf("[[channel]]\nname = \"../etc\"\n").find("bad.toml:2: [[channel]] #1 name: expected 1–48 letters, digits"),
            std::string::npos)
      << errorOf("[[channel]]\nname = \"../etc\"\n");
  // The shared-memory name rule (48 characters) is the config's: a longer name fails at its line,
  // not when the service creates the segment.
  const std::string longName = "[[channel]]\nname = \"" + std::string(49, 'c') + "\"\n";
  EXPECT_NE(errorOf(longName).find("bad.toml:2: [[channel]] #1 name: expected 1–48"), std::string::npos) << errorOf(longName);
  EXPECT_EQ(errorOf("[[channel]]\nname = \"" + std::string(48, 'c') + "\"\n").find("name:"), std::string::npos);
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

  // Issue 7: [glow], [glare], [render] airlight / gpu_pieces, rig lamp apertures.
  auto expectError = [&](const std::string& text, const std::vector<std::string>& set, const std::string& want) {
    const std::string got = errorOf(text, set);
    EXPECT_NE(got.find(want), std::string::npos) << "expected: " << want << "\ngot: " << got;
  };
  expectError("[glow]\nenabled = true\nfade_in = 0.5\n", {}, "bad.toml:3: [glow] fade_in: expected a number >= 1.1, found 0.5");
  expectError("[glare]\nage_years = 30\npigmentation = 1.5\n", {},
              "bad.toml:3: [glare] pigmentation: expected a number in [0, 1], found 1.5");
  expectError("[glare]\nage_yeras = 30\n", {}, "bad.toml:2: [glare]: unknown key 'age_yeras' (did you mean 'age_years'?)");
  expectError("", {"glare.age_years=150"}, "--set glare.age_years=150:1: [glare] age_years: expected a number in [0, 120]");
  expectError("", {"glow.enabled=1"}, "--set glow.enabled=1:1: [glow] enabled: expected");
  expectError("[render]\nmethod = \"accurate\"\nairlight = \"vulkan\"\n", {},
              "bad.toml:3: [render] airlight: expected \"cpu\" or \"gpu\", found \"vulkan\"");
  expectError("", {"render.gpu_pieces=2048"}, "--set render.gpu_pieces=2048:1: [render] gpu_pieces: expected an integer in [4, 1024]");
  expectError("[render]\ngpu_piece = 8\n", {}, "bad.toml:2: [render]: unknown key 'gpu_piece' (did you mean 'gpu_pieces'?)");
  expectError("[render]\nairlight = \"gpu\"\nsurface = \"cpu\"\n", {},
              "[render] airlight = \"gpu\" needs the GL surface pass, but surface = \"cpu\"");
  expectError("[render]\nairlight = \"gpu\"\n", {"render.method=\"seed\""},
              "[render] airlight = \"gpu\" computes the accurate method, but method = \"seed\"");
  expectError("[[traffic_class]]\nclass = 0\n[[traffic_class.lamp]]\nrole = \"low-beam\"\nposition_m = [1, 0, 0]\n"
              "profile = \"isotropic\"\nintensity_cd = 1\naperture = \"disc\"\naperture_size_m = [0.1, 0.1]\n",
              {}, "bad.toml:9: [[traffic_class]] #1 [[lamp]] #1 aperture_size_m: expected the diameter");
  expectError("[[traffic_class]]\nclass = 0\n[[traffic_class.lamp]]\nrole = \"low-beam\"\nposition_m = [1, 0, 0]\n"
              "profile = \"isotropic\"\nintensity_cd = 1\naperture_samples = 4\n",
              {}, "aperture_samples: only allowed with aperture = \"rectangle\" or \"disc\"");
}

}  // namespace
}  // namespace fogbeam::plugin
