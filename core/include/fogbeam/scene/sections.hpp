// fogbeam — the scene sections every configuration format embeds: [fog], lamps, [glow],
// [glare], [render], and the vector and orientation keys they use. Scene files (docs/scene.md),
// scenarios (docs/scenario.md) and the service config (docs/service.md) parse them through these
// functions, so that they are read by the same code and fail with the same messages. Built on the
// generic TOML access of fogbeam/util/toml_section.hpp; errors are thrown as config::ConfigError
// and turned into an Error by the format's entry point (config::parseTomlFile).
//
// Thread-safety: plain functions; a ProfileCache belongs to one parse.
#pragma once

#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/physics/profile.hpp>
#include <fogbeam/scene/effects.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/toml_section.hpp>

#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::config {

/// [x, y, z]: an array of exactly three numbers, each within `r`, in section `s`.
[[nodiscard]] std::optional<Vec3> optVec3(const Section& s, std::string_view key, const Range& r = kAnyFinite);
[[nodiscard]] Vec3 vec3(const Section& s, std::string_view key, const Range& r = kAnyFinite);

/// worldFromBody from the section's yaw_deg, pitch_deg, roll_deg (degrees, each default 0;
/// ISO 8855 z-y'-x'', worldFromYawPitchRoll).
[[nodiscard]] Mat3 orientation(const Section& s);

/// Profiles loaded while reading one file, so that lamps with equal parameters (the same file
/// and scale, the same spot) share one Profile and hence one set of airlight tables.
class ProfileCache {
 public:
  using Ptr = std::shared_ptr<const Profile>;
  /// A closed-form model; `key` identifies its parameters exactly.
  Result<Ptr> model(const std::string& key, Profile::Model m);
  /// A profile file (already resolved and checked to exist), every candela value × scale.
  Result<Ptr> file(const std::string& path, double scale);

 private:
  std::map<std::string, Ptr> files_;  // resolved path → unscaled profile
  std::map<std::string, Ptr> byKey_;
};

/// The keys of a scene [fog] table and of a lamp table (docs/scene.md).
[[nodiscard]] std::span<const KeySpec> fogKeys();
[[nodiscard]] std::span<const KeySpec> lampKeys();

/// A [fog] table (docs/scene.md). `extraKeys` are accepted and left to the caller.
[[nodiscard]] Medium parseFog(const Section& s, std::span<const KeySpec> extraKeys = {});
/// A lamp table (docs/scene.md [[lamp]]); `ordinal` names unnamed lamps "lamp[N]"; profile
/// paths resolve against `baseDir`. `extraKeys` are accepted and left to the caller.
[[nodiscard]] SceneLamp parseLamp(const Section& s, std::size_t ordinal, const std::string& baseDir,
                                  ProfileCache& cache, std::span<const KeySpec> extraKeys = {});

/// A [bonnet] table (docs/scene.md): the keys, and the bonnet (its defaults where a key is
/// left out; left of right, rear behind front).
[[nodiscard]] std::span<const KeySpec> bonnetKeys();
/// `extraKeys` are accepted and left to the caller (the service's `enabled`).
[[nodiscard]] Bonnet parseBonnet(const Section& s, std::span<const KeySpec> extraKeys = {});

/// The [glow], [glare] and [render] tables (fogbeam/scene/effects.hpp; docs/scene.md), shared by
/// scene files and service configs. parseEffects reads whichever of the three `top` holds.
/// A key left out keeps its value in `fallback` (a service layer's lower layers), except
/// `enabled`: a [glow] or [glare] table turns its effect on unless it says `enabled = false`.
/// parseRenderSettings accepts `extraKeys` too and leaves them to the caller (the service's
/// [render] holds its own keys beside these).
[[nodiscard]] std::span<const KeySpec> glowKeys();
[[nodiscard]] std::span<const KeySpec> glareKeys();
[[nodiscard]] std::span<const KeySpec> renderKeys();
[[nodiscard]] GlowOptions parseGlow(const Section& s, const GlowOptions& fallback = {});
[[nodiscard]] GlareOptions parseGlare(const Section& s, const GlareOptions& fallback = {});
[[nodiscard]] RenderSettings parseRenderSettings(const Section& s, const RenderSettings& fallback = {},
                                                 std::span<const KeySpec> extraKeys = {});
[[nodiscard]] SceneEffects parseEffects(const Section& top);

/// The scene format's key tables in docs/scene.md (config::KeyTable): the top level, [fog],
/// [camera], [[lamp]], [[plane]], [glow], [glare] and [render]. The scenario and the service
/// config embed [fog], [[lamp]], [glow], [glare] and [render], so these entries document those
/// sections there too. Defined in scene.cpp, beside the scene's own lists.
[[nodiscard]] std::vector<KeyTable> sceneKeyTables();

}  // namespace fogbeam::config
