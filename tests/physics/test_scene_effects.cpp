// Scene files: the issue-7 keys ([glow], [glare], [render], lamp apertures) and their errors.
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/scene/scene.hpp>

#include <gtest/gtest.h>

#include <string>

namespace fogbeam {
namespace {

const std::string kScenes = std::string(FOGBEAM_TEST_DATA_DIR) + "/scenes";

bool Contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

std::string errorOf(const std::string& text) {
  const Result<Scene> r = parseScene(text, "bad.toml", kScenes);
  if (r) {
    ADD_FAILURE() << "parsed without error:\n" << text;
    return {};
  }
  return r.error().message;
}

Scene parse(const std::string& text) {
  Result<Scene> r = parseScene(text, "good.toml", kScenes);
  if (!r) {
    ADD_FAILURE() << r.error().message;
    return {};
  }
  return std::move(r).value();
}

// A valid fog and camera on lines 1–6, so that a snippet appended to it starts on line 7.
const std::string kFogAndCamera =
    "[fog]\n"
    "extinction_per_m = 0.04\n"
    "[camera]\n"
    "position_m = [0, 0, 1.2]\n"
    "width = 64\n"
    "height = 36\n";

const std::string kLamp =
    "[[lamp]]\n"
    "name = \"head\"\n"
    "position_m = [2, 0.7, 0.65]\n"
    "profile = \"spot\"\n"
    "intensity_cd = 20000\n"
    "inner_deg = 4\n"
    "outer_deg = 14\n"
    "color = [1, 0.5, 0.25]\n";

TEST(SceneEffects, OffAndCpuByDefault) {
  const Scene s = parse(kFogAndCamera);
  EXPECT_FALSE(s.effects.glow.enabled);
  EXPECT_FALSE(s.effects.glare.enabled);
  EXPECT_EQ(s.effects.render.airlight, AirlightDevice::Cpu);
  EXPECT_EQ(s.effects.render.gpu_pieces, 64);
}

TEST(SceneEffects, EveryKeyIntoItsField) {
  const Scene s = parse(kFogAndCamera +
                        "[glow]\nfade_in = 3.5\n"
                        "[glare]\nage_years = 65\npigmentation = 0.2\n"
                        "[render]\nairlight = \"gpu\"\ngpu_pieces = 128\n");
  EXPECT_TRUE(s.effects.glow.enabled);  // the table's presence turns it on
  EXPECT_DOUBLE_EQ(s.effects.glow.fade_in, 3.5);
  EXPECT_TRUE(s.effects.glare.enabled);
  EXPECT_DOUBLE_EQ(s.effects.glare.age_years, 65.0);
  EXPECT_DOUBLE_EQ(s.effects.glare.pigmentation, 0.2);
  EXPECT_EQ(s.effects.render.airlight, AirlightDevice::Gpu);
  EXPECT_EQ(s.effects.render.gpu_pieces, 128);
  const Scene off = parse(kFogAndCamera + "[glow]\nenabled = false\n[glare]\nenabled = false\n");
  EXPECT_FALSE(off.effects.glow.enabled);
  EXPECT_FALSE(off.effects.glare.enabled);
}

TEST(SceneEffects, BadValuesSayWhereAndWhat) {
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glow]\nfade_in = 0.5\n"), "bad.toml:8: [glow] fade_in");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glow]\nradius = 2\n"), "bad.toml:8: [glow]: unknown key 'radius'");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glare]\nage_years = 130\n"), "bad.toml:8: [glare] age_years");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glare]\npigmentation = -0.1\n"), "bad.toml:8: [glare] pigmentation");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[glare]\nenabled = 1\n"), "bad.toml:8: [glare] enabled");
  const std::string device = errorOf(kFogAndCamera + "[render]\nairlight = \"cuda\"\n");
  EXPECT_PRED2(Contains, device, "bad.toml:8: [render] airlight");
  EXPECT_PRED2(Contains, device, "\"gpu\"");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + "[render]\ngpu_pieces = 2\n"), "bad.toml:8: [render] gpu_pieces");
}

TEST(SceneEffects, ApertureLampsBecomeTheirPointLamps) {
  const Scene s = parse(kFogAndCamera + kLamp + "aperture = \"rectangle\"\naperture_size_m = [0.2, 0.1]\n");
  ASSERT_EQ(s.lamps.size(), 9u);  // 3 × 3 by default
  Vec3 color{0.0};
  for (const SceneLamp& l : s.lamps) {
    EXPECT_EQ(l.lamp.profile, s.lamps[0].lamp.profile);  // one shared profile
    color += l.lamp.color;
    EXPECT_NEAR(std::abs(l.lamp.position_m.y - 0.7), 0.0, 0.1 + 1e-12);
    EXPECT_NEAR(std::abs(l.lamp.position_m.z - 0.65), 0.0, 0.05 + 1e-12);
    EXPECT_DOUBLE_EQ(l.lamp.position_m.x, 2.0);  // the face is ⟂ to the lamp's +x
  }
  EXPECT_NEAR(color.x, 1.0, 1e-14);
  EXPECT_NEAR(color.y, 0.5, 1e-14);
  EXPECT_NEAR(color.z, 0.25, 1e-14);
  EXPECT_EQ(s.lamps[0].name, "head [1/9]");
  const Scene disc = parse(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = 0.15\naperture_samples = 2\n");
  EXPECT_EQ(disc.lamps.size(), 4u);  // 1 ring × 4 angles
  const Scene point = parse(kFogAndCamera + kLamp + "aperture = \"point\"\n");
  EXPECT_EQ(point.lamps.size(), 1u);
  EXPECT_EQ(point.lamps[0].name, "head");
}

TEST(SceneEffects, BadAperturesSayWhereAndWhat) {
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"square\"\n"), "[[lamp]] #1 aperture");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"rectangle\"\n"),
               "bad.toml:7: [[lamp]] #1 aperture_size_m: missing (expected [width, height]");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"rectangle\"\naperture_size_m = 0.2\n"),
               "bad.toml:16: [[lamp]] #1 aperture_size_m: expected [width, height]");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = [0.2, 0.1]\n"),
               "bad.toml:16: [[lamp]] #1 aperture_size_m: expected the diameter");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = 0\n"),
               "[[lamp]] #1 aperture_size_m");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture = \"rectangle\"\naperture_size_m = [0.2, 3]\n"),
               "[[lamp]] #1 aperture_size_m[1]");
  EXPECT_PRED2(Contains,
               errorOf(kFogAndCamera + kLamp + "aperture = \"disc\"\naperture_size_m = 0.1\naperture_samples = 9\n"),
               "bad.toml:17: [[lamp]] #1 aperture_samples");
  EXPECT_PRED2(Contains, errorOf(kFogAndCamera + kLamp + "aperture_size_m = 0.1\n"),
               "bad.toml:15: [[lamp]] #1 aperture_size_m: only allowed with aperture = \"rectangle\" or \"disc\"");
}

TEST(SceneEffects, NewKeysAreDocumented) {
  const auto doc = readTextFile(std::string(FOGBEAM_CONFIG_DIR) + "/../docs/scene.md");
  ASSERT_TRUE(doc) << doc.error().message;
  for (const char* key : {"[glow]", "fade_in", "[glare]", "age_years", "pigmentation", "[render]", "airlight",
                          "gpu_pieces", "aperture", "aperture_size_m", "aperture_samples"})
    EXPECT_PRED2(Contains, doc.value(), "`" + std::string(key) + "`");
}

}  // namespace
}  // namespace fogbeam
