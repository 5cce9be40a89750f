// fogbeam — the switchable additions beyond the paper's single scattering (issue 7) as a scene
// or service configuration holds them: glow (multiple scattering around lamps), disability glare,
// and where the airlight is computed (CPU evaluator or the GPU surface pass).
//
// Scene files: tables [glow], [glare], [render] (docs/scene.md); service configs: the same
// tables (docs/service.md). The physics behind glow and glare: fogbeam/physics/glow.hpp; the
// per-frame layers: fogbeam/render/lamp_effects.hpp.
//
// Thread-safety: plain values.
#pragma once

#include <string_view>

namespace fogbeam {

/// Where the glow's multiply scattered light comes from (lamp_effects.hpp).
enum class GlowModel {
  /// Tables of orders ≥ 2 estimated by path tracing per phase function
  /// (fogbeam/physics/multiple_scattering.hpp); for a phase with no shipped table, Apsf.
  Table,
  /// Narasimhan–Nayar APSF less the exact single scattering, energy-matched (before 2026-11-27).
  Apsf,
};
[[nodiscard]] std::string_view toString(GlowModel m);

/// Glow around lamps seen through fog: the light scattered more than once (lamp_effects.hpp).
struct GlowOptions {
  bool enabled = false;
  GlowModel model = GlowModel::Table;
  /// Apsf only: optical distance K_t R from which a lamp's glow counts fully; it fades in
  /// linearly from Apsf::minOpticalDistance() (1.1), where the series stops converging, so that
  /// an approaching car's glow does not pop. ≥ 1.1.
  double fade_in = 2.0;
  /// The fog's scattered light on the surfaces (fogbeam/render/fog_light.hpp): orders 1 and up of
  /// every lamp's light, scattered onto the surfaces by the fog around them, added to the surface
  /// layer (CPU or GPU shading). Needs a multiple-scattering table for the fog's phase function.
  /// Also the road's fog light in the veil of the road the driver's own lamps light
  /// (ground_reflectance > 0; off: that veil scatters the road's direct light alone).
  bool surfaces = true;
  /// The ground under the lamps and the eye (model = table): its Lambertian reflectance ρ ∈ [0, 1),
  /// or < 0 for none (infinite fog, the tables as they are). A dark road takes light that has
  /// diffused down to it (a lamp at K_t R = 8 over ρ = 0.1: 0.22–0.35 of infinite fog's light),
  /// snow sends it back up; the glow is multiplied by the path tracer's factor for ρ
  /// (fogbeam/physics/ground_correction.hpp, docs/airlight.md "The ground"). Not the fog light's.
  /// Above 0, the glow layer also holds the veil of the road the driver's own lamps light (their
  /// light, direct and, with `surfaces`, scattered onto the road by the fog, reflected by the
  /// road and scattered by the fog into the view: LampEffects, docs/physics.md).
  double ground_reflectance = 0.1;
  /// The ground's height, m: the plane z = ground_height_m of the scene's world frame (scene
  /// files and the service's rig stand on z = 0). The factor follows the optical height of the
  /// eye and each lamp above it (their mean).
  double ground_height_m = 0.0;
};

/// The driver's disability glare: CIE 146:2002 veiling luminance of the lamps in view.
struct GlareOptions {
  bool enabled = false;
  double age_years = 40.0;    ///< observer's age A, years, [0, 120]
  double pigmentation = 0.5;  ///< eye pigmentation p, [0, 1]: 0 very dark … 1 light blue eyes
};

/// Where the airlight layer is computed.
enum class AirlightDevice {
  Cpu,  ///< AirlightImageEvaluator (tables, SIMD, subsampling): the default
  Gpu,  ///< the accurate method as GLSL in the surface pass (GlSurfacePass::setAirlight)
};
[[nodiscard]] std::string_view toString(AirlightDevice d);

struct RenderSettings {
  AirlightDevice airlight = AirlightDevice::Cpu;
  int gpu_pieces = 64;  ///< GPU path: quadratic pieces per ray for measured profiles, [4, 1024]
};

/// A scene's or service's additions; all off (and the CPU path) by default.
struct SceneEffects {
  GlowOptions glow;
  GlareOptions glare;
  RenderSettings render;
};

}  // namespace fogbeam
