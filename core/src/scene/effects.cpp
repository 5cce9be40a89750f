// fogbeam — the [glow], [glare] and [render] tables of scene files and service configs
// (fogbeam/scene/effects.hpp; docs/scene.md, docs/service.md). Shared so both formats accept
// exactly the same keys with the same checks.
#include <fogbeam/physics/glow.hpp>
#include <fogbeam/scene/effects.hpp>
#include <fogbeam/scene/toml_config.hpp>

#include <array>

namespace fogbeam {

std::string_view toString(AirlightDevice d) { return d == AirlightDevice::Gpu ? "gpu" : "cpu"; }

namespace config {

namespace {

constexpr std::array kGlowKeys{
    KeySpec{"enabled", "boolean, default true (the table's presence turns glow on)"},
    KeySpec{"fade_in", "number, optical distance K_t R, default 2.0, >= 1.1: glow counts fully from here, "
                       "fading in linearly from K_t R = 1.1"},
};
constexpr std::array kGlareKeys{
    KeySpec{"enabled", "boolean, default true (the table's presence turns glare on)"},
    KeySpec{"age_years", "number, years, default 40, [0, 120]: the observer's age (CIE 146:2002)"},
    KeySpec{"pigmentation", "number, default 0.5, [0, 1]: eye pigmentation, 0 very dark ... 1 light blue"},
};
constexpr std::array kRenderKeys{
    KeySpec{"airlight", "string, default \"cpu\": \"cpu\" (table evaluator) | \"gpu\" (GLSL in the surface pass)"},
    KeySpec{"gpu_pieces", "integer, default 64, [4, 1024]: GPU path, quadratic pieces per ray for measured lamps"},
};

constexpr std::array<std::string_view, 2> kDevices{"cpu", "gpu"};

}  // namespace

std::span<const KeySpec> glowKeys() { return kGlowKeys; }
std::span<const KeySpec> glareKeys() { return kGlareKeys; }
std::span<const KeySpec> renderKeys() { return kRenderKeys; }

GlowOptions parseGlow(const Section& s, const GlowOptions& fallback) {
  s.checkKeys(kGlowKeys);
  GlowOptions g = fallback;
  g.enabled = s.boolean("enabled", true);
  g.fade_in = s.number("fade_in", Range{Apsf::minOpticalDistance(), kInf, false, false}, g.fade_in);
  return g;
}

GlareOptions parseGlare(const Section& s, const GlareOptions& fallback) {
  s.checkKeys(kGlareKeys);
  GlareOptions g = fallback;
  g.enabled = s.boolean("enabled", true);
  g.age_years = s.number("age_years", Range{0.0, 120.0, false, false}, g.age_years);
  g.pigmentation = s.number("pigmentation", kUnit, g.pigmentation);
  return g;
}

RenderSettings parseRenderSettings(const Section& s, const RenderSettings& fallback, std::span<const KeySpec> extraKeys) {
  s.checkKeys(kRenderKeys, extraKeys);
  RenderSettings r = fallback;
  r.airlight = s.choice("airlight", kDevices, toString(r.airlight)) == "gpu" ? AirlightDevice::Gpu : AirlightDevice::Cpu;
  r.gpu_pieces = static_cast<int>(s.integer("gpu_pieces", 4, 1024, r.gpu_pieces));
  return r;
}

SceneEffects parseEffects(const Section& top) {
  SceneEffects fx;
  const std::string& file = top.file();
  const std::string prefix = top.label().empty() ? "" : top.label() + " ";
  if (const toml::table* t = top.optTable("glow")) fx.glow = parseGlow(Section(file, *t, prefix + "[glow]"));
  if (const toml::table* t = top.optTable("glare")) fx.glare = parseGlare(Section(file, *t, prefix + "[glare]"));
  if (const toml::table* t = top.optTable("render")) fx.render = parseRenderSettings(Section(file, *t, prefix + "[render]"));
  return fx;
}

}  // namespace config
}  // namespace fogbeam
