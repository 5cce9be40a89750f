// fogbeam — the veil of the road lit by the driver's own lamps (issue 18, "the ground"; internal
// to LampEffects, docs/airlight.md "The driver's own low beam over the road").
//
// The own low beams light the road 5–60 m ahead at grazing incidence; a Lambertian road of
// reflectance ρ sends L_r = ρ E / π back up, and the fog scatters that light into every view ray
// above and in front of it. The path tracer puts that veil at +35 % of the light 8–16° about the
// own low beam over a road of ρ = 0.1 (50 m fog), where the lamps' airlight and glow do not have
// it (they start at the lamps). Single scattering of the road's light from its direct
// illumination, along the view ray from the eye O in direction ω up to where it meets the road
// (or 15 mean free paths):
//
//   L_v(ω) = Ω K_t ∫_0^U e^{−K_t u} ∫_{d·ẑ<0} p(d · ω) L_r(x(P, d)) e^{−K_t t(P, d)} dΩ_d du,
//
// P = O + u ω, d a direction from P down to the road, t = (P_z − z_g) / (−d_z) the way to it,
// x = P + t d, and d · ω the cosine of the scattering angle (the light comes up along −d and
// leaves towards the eye along −ω). The inner integral runs over directions, not over the road's
// area: the road next to a point just above it fills a hemisphere, which cells of area would
// make singular. The directions are a polar grid about ω itself (angles 0.2° doubling to 12.8°,
// then equal steps to 180°, × azimuths), dense where the phase function's forward peak is: for
// a ray that meets the road, the road about where it meets it. L_r = ρ E / π, E = Σ_lamps I(x − S) cos i
// e^{−K_t |x − S|} / |x − S|² the lamps' direct light, plus (when the surface layer shows it) the
// fog's scattered light on the road (the fog light, fog_light.hpp), from a polar map about the
// eye's foot (log-spaced radii, bilinear). Left out: the orders ≥ 2 of the road's light
// (docs/airlight.md: what the path tracer says they add).
//
// Units: metres, cd, lux, cd/m² per channel (lamp colour). Reentrant (no shared state).
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/medium.hpp>
#include <fogbeam/render/fog_light.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <memory>
#include <vector>

namespace fogbeam::ground_veil {

struct Lamp {
  Vec3 position_m{0.0};
  Mat3 lampFromWorld{1.0};
  std::shared_ptr<const Profile> profile;  ///< null: the lamp lights nothing
  double color[3] = {1.0, 1.0, 1.0};
  /// The profile's annulus means for the fog light (render/fog_light.hpp; null: the road's
  /// direct light alone).
  std::shared_ptr<const AnnulusMeanMap> annuli;
};

/// The road plane z = z_m (world), Lambertian of reflectance ρ.
struct Ground {
  double z_m = 0.0;
  double reflectance = 0.1;
};

/// L_r (cd/m² per channel) of the road lit by the lamps, on a polar grid about the eye's foot:
/// `rings` radii log-spaced from 0.2 m to min(300 m, 12 / K_t), `sectors` azimuths.
struct RoadMap {
  Vec3 foot{0.0};
  double r0 = 0.2, logStep = 1.0;
  int rings = 0, sectors = 0;
  std::vector<float> rgb;  ///< (ring × sectors + sector) × 3
  [[nodiscard]] bool empty() const noexcept { return rgb.empty(); }
  /// L_r at road point (x, y): bilinear in (log r, azimuth); 0 beyond the last ring.
  void at(double x, double y, double out[3]) const noexcept;
};
/// `pool` (optional): its rings on the pool (a profile look-up per lamp and node: ~17 000 nodes).
/// `fogLight` (optional): the road's light also holds the fog's scattered light on it (the
/// surface layer's fog light, FogLightTable with each lamp's `annuli`).
[[nodiscard]] RoadMap roadMap(const std::vector<Lamp>& lamps, const Medium& fog, const Ground& ground, const Vec3& eye,
                              int rings = 96, int sectors = 180, ThreadPool* pool = nullptr,
                              const FogLightTable* fogLight = nullptr);

/// L_v (cd/m² per channel, added to rgb[0..3)) along the ray from `eye` in unit direction `w`:
/// `steps` log-spaced steps from 5 cm (half of them log-spaced towards the road's end when the ray
/// meets it), (7 + `angles`) × `azimuths` directions per step (header
/// comment: `angles` equal cells from 12.8° to 180°). Returns where the ray meets the ground (m; +inf when it does not).
double alongRay(const RoadMap& road, const Medium& fog, const Ground& ground, const Vec3& eye, const Vec3& w, int steps,
                double rgb[3], int angles = 24, int azimuths = 24);

}  // namespace fogbeam::ground_veil
