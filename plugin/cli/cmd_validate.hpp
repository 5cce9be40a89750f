// `fogbeam validate`: the three airlight methods against a reference, as a table
// (cmd_validate.cpp). The options are filled by main.cpp, the one translation unit that includes
// CLI11 (its option names, help texts and checks are there).
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/path_tracer.hpp>
#include <fogbeam/render/airlight_image.hpp>
#include <fogbeam/render/lamp_effects.hpp>
#include <fogbeam/scene/scene.hpp>
#include <fogbeam/util/result.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace fogbeam::cli {

struct ValidateOptions {
  /// --vectors: CSV of rays, lamps and fogs with expected airlight (columns as
  /// tests/data/airlight_vectors.csv). Empty (default): the built-in sweep, against the
  /// reference method.
  std::string vectors;
  /// --out: CSV written with one row per case and method; empty (default): none.
  std::string out;
  /// --methods: the methods run, by name (parseAirlightMethod); default all three.
  std::vector<std::string> methods{"seed", "accurate", "reference"};
  /// --headlamp: sweep only: headlamp profile file (.ies/.ldt/.csv); empty (default): the
  /// built-in low beam.
  std::string headlamp;
  /// --rays: sweep only: rays per situation (default 24).
  int rays = 24;
  /// --segments: accurate method: quadratic pieces per ray for tabulated profiles (default:
  /// the library's, 48).
  int segments = AirlightOptions{}.accurate_segments;
  /// false with --no-additions: skip the checks of issue 7's additions (default: run them).
  bool additions = true;
  /// --path-tracer: fogbeam's single scattering and glow against the all-orders path tracer in
  /// rings about a lamp (isotropic in several fogs, albedo 0.9, a road, the low beam from three
  /// sides; issue 18; docs/airlight.md, "Glow: multiple scattering around the lamps"). Off by
  /// default: it takes a few minutes.
  bool path_tracer = false;
  /// --pt-samples: paths per ring (and for the whole frame) and case (default 20 000).
  int pt_samples = 20000;
  /// --pt-road-only: of the path-tracer comparisons only the road's (the fog light, issue 18).
  bool pt_road_only = false;
  /// --pt-cases: of the ring comparisons only the cases whose name contains this text (e.g.
  /// "high beam"), and not the road's; empty (default): every case.
  std::string pt_cases;
  /// --pt-out: CSV of the ring figures (one row per case and ring); empty (default): none.
  std::string pt_out;
  /// --pt-pictures: a folder to write pictures of fogbeam (single, single + glow) beside the
  /// path tracer around an isotropic lamp, and their ring plot (SVG, CSV); empty (default): none.
  /// Takes --pt-samples paths per angle (18 angles, 2 cases).
  std::string pt_pictures;
};

/// Runs the validation; returns the exit status: 0, 1 when a bound is missed, 2 on bad input.
int runValidate(const ValidateOptions& o);

// ---- fogbeam against the all-orders path tracer around a lamp in view (`--path-tracer`) -------
// Header-only so that tests/plugin runs the same comparison without the executable.
//
// The scene: the eye at the origin looking along +x (square image, `pixels` wide, 35° field of
// view: the 16° ring fits, the image centre is the lamp's image), an isotropic lamp of
// `intensity_cd` (or a measured lamp, turned as the case says) on the axis at R = T / K_t,
// infinite fog (albedo as the case says, 1 by default), nothing but the night sky.
// Per ring of angles from the lamp's direction (pixel centres; the rings' pixels are the
// quadrature points of every column), the mean luminance of
//   * fogbeam single: the airlight layer's accurate method per ray (AirlightImageEvaluator);
//   * fogbeam glow: LampEffects' glow layer (the shipped fast path) for that lamp;
//   * the path tracer, single (order 1) and all orders (1 … 1000), each ± its standard error:
//     paths through pixel centres drawn uniformly among the ring's pixels, so it estimates the
//     same pixel mean as the fogbeam columns (its single part is the same integral as fogbeam
//     single: the plumbing check).
// "frame": every pixel at least the first ring's inner angle from the lamp.

struct RingComparisonCase {
  RingComparisonCase() = default;
  RingComparisonCase(std::string n, Phase p, double opticalDistance)
      : name(std::move(n)), phase(std::move(p)), optical_distance(opticalDistance) {}
  std::string name;
  Phase phase = HenyeyGreensteinPhase{0.85};
  double optical_distance = 1.8;  ///< T = K_t R
  double extinction_per_m = 0.06;
  double albedo = 1.0;
  double intensity_cd = 1000.0;
  /// A measured lamp instead of the isotropic one (null: isotropic of intensity_cd), its
  /// photometric axis along `lamp_axis` (world; the eye looks along +x at the lamp, so (−1, 0, 0)
  /// is head-on, (1, 0, 0) from behind, (0, 1, 0) from the side).
  std::shared_ptr<const Profile> profile;
  Vec3 lamp_axis{-1.0, 0.0, 0.0};
  /// A Lambertian ground `ground_below_m` under the eye (and the lamp) of reflectance
  /// `ground_reflectance`; 0: none. Rays below the horizon end on it (fogbeam's airlight and
  /// glow up to it, the path tracer's paths reflect off it).
  double ground_below_m = 0.0;
  double ground_reflectance = 0.1;
  /// The lamp this far above the eye's height (a street lamp's head: 8 m over the road for an eye
  /// 1.2 m above it is 6.8), still R = T / K_t from the eye; the rings are about its direction.
  double lamp_above_eye_m = 0.0;
  /// The lamp is the driver's own (mount = vehicle: LampEffects' own-lamp glow, and the veil of
  /// the road it lights when the case has a ground).
  bool own = false;
  /// Whether fogbeam's glow knows the ground (GlowOptions::ground_reflectance); false: the glow of
  /// infinite fog over the same ground, to show what the ground factor changes.
  bool glow_knows_ground = true;
};

/// The driver's own low beam over the road: the lamp `profile` 0.65 m over a road of reflectance
/// `rho`, 2 m ahead of an eye 1.2 m over it (K_t R = 0.12 in 50 m fog, HG 0.85), its beam along
/// the road: the road takes the beam's light at grazing incidence and sends back ρ of it.
inline RingComparisonCase ownLowBeamOverRoad(std::string name, std::shared_ptr<const Profile> profile, double rho) {
  RingComparisonCase c{std::move(name), HenyeyGreensteinPhase{0.85}, 0.12};
  c.profile = std::move(profile);
  c.lamp_axis = Vec3(1, 0, 0);
  c.ground_below_m = 1.2;
  c.ground_reflectance = rho;
  c.lamp_above_eye_m = -0.55;
  c.own = true;
  return c;
}

struct RingFigures {
  double lo_deg = 0.0, hi_deg = 0.0;  ///< hi = +inf: the frame
  std::size_t pixels = 0;
  double single = 0.0;  ///< fogbeam single scattering, cd/m²
  double glow = 0.0;    ///< fogbeam glow layer, cd/m²
  /// With a ground the glow knows: the glow of infinite fog over the same pixels (what the ground
  /// factor changed); else = glow.
  double glow_infinite = 0.0;
  McEstimate pt_single, pt_all;
  double mean_events = 0.0;
  [[nodiscard]] double ratio() const { return pt_all.mean > 0.0 ? (single + glow) / pt_all.mean : 0.0; }
  /// Standard error of ratio() from the path tracer's (fogbeam's figures are deterministic).
  [[nodiscard]] double ratioError() const { return pt_all.mean > 0.0 ? ratio() * pt_all.std_error / pt_all.mean : 0.0; }
};

struct RingComparison {
  RingComparisonCase c;
  double distance_m = 0.0;
  double glow_scale = 0.0;  ///< λ of the glow's energy match (0: no glow; 1: tables)
  bool glow_from_table = false;  ///< the glow came from the multiple-scattering tables
  bool lamp_visible = false;
  std::vector<RingFigures> rings;  ///< the rings, then the frame
  double fogbeam_seconds = 0.0, path_tracer_seconds = 0.0;
};

/// Where a view ray from the eye in direction `w` ends: on the case's ground below the horizon
/// when it has one, else +inf (the night sky).
inline double comparisonRayEnd(const RingComparisonCase& c, const Vec3& w) {
  if (c.ground_below_m > 0.0 && w.z < 0.0) return c.ground_below_m / -w.z;
  return std::numeric_limits<double>::infinity();
}

inline const std::vector<std::array<double, 2>>& comparisonRingsDeg() {
  static const std::vector<std::array<double, 2>> r = {{0.5, 1.0}, {1.0, 2.0}, {2.0, 4.0}, {4.0, 8.0}, {8.0, 16.0}};
  return r;
}

/// The case's scene (header comment above): `pixels` × `pixels`, the lamp on the +x axis at
/// R = T / K_t, and each pixel centre's ray end (the ground below the horizon, else +inf) in
/// `surface` (black surfaces).
inline Result<Scene> comparisonScene(const RingComparisonCase& c, int pixels, SurfaceBuffers& surface) {
  const double distance_m = c.optical_distance / c.extinction_per_m;
  Scene scene;
  scene.source = "validate --path-tracer";
  scene.fog.extinction_per_m = c.extinction_per_m;
  scene.fog.albedo = c.albedo;
  scene.fog.phase = c.phase;
  scene.camera.position_m = Vec3(0.0);
  scene.camera.worldFromCamera = Mat3(1.0);
  scene.camera.fov_x = radians(35.0);
  scene.camera.width = pixels;
  scene.camera.height = pixels;
  SceneLamp lamp;
  lamp.name = "lamp";
  const double rise = std::clamp(c.lamp_above_eye_m / distance_m, -1.0, 1.0);
  lamp.lamp.position_m = distance_m * Vec3(std::sqrt(1.0 - rise * rise), 0.0, rise);
  lamp.lamp.worldFromLamp = worldFromAxis(c.lamp_axis);
  if (c.own) lamp.mount = LampMount::Vehicle;
  if (c.profile) {
    lamp.lamp.profile = c.profile;
  } else {
    auto profile = makeProfile(IsotropicProfile{c.intensity_cd});
    if (!profile) return profile.error();
    lamp.lamp.profile = *profile;
  }
  scene.lamps.push_back(lamp);
  surface.resize(pixels, pixels);
  std::fill(surface.rgb.begin(), surface.rgb.end(), 0.0f);
  for (int j = 0; j < pixels; ++j)
    for (int i = 0; i < pixels; ++i)
      surface.distance[static_cast<std::size_t>(j * pixels + i)] =
          static_cast<float>(comparisonRayEnd(c, scene.camera.rayDirection(i + 0.5, j + 0.5)));
  return scene;
}

/// The comparison for one case; `samples` paths per ring and for the frame; `pixels` the image
/// width and height (odd: the lamp's image is a pixel centre).
inline Result<RingComparison> compareRings(const RingComparisonCase& c, std::uint64_t samples, std::uint64_t seed,
                                           const std::shared_ptr<ThreadPool>& pool, int pixels = 351) {
  using Clock = std::chrono::steady_clock;
  RingComparison out;
  out.c = c;
  out.distance_m = c.optical_distance / c.extinction_per_m;
  SurfaceBuffers surface;
  auto sc = comparisonScene(c, pixels, surface);
  if (!sc) return sc.error();
  const Scene& scene = *sc;
  const SceneLamp& lamp = scene.lamps.front();
  auto endOf = [&c](const Vec3& w) { return comparisonRayEnd(c, w); };

  // Pixels per region (rings, then the frame), by the angle of the pixel centre's ray.
  const auto& ringsDeg = comparisonRingsDeg();
  const std::size_t nRings = ringsDeg.size();
  std::vector<std::vector<std::uint32_t>> members(nRings + 1);
  const Vec3 toLamp = glm::normalize(lamp.lamp.position_m - scene.camera.position_m);
  const double frameFrom = radians(ringsDeg.front()[0]);
  for (int j = 0; j < pixels; ++j)
    for (int i = 0; i < pixels; ++i) {
      const Vec3 w = scene.camera.rayDirection(i + 0.5, j + 0.5);
      const double th = std::atan2(glm::length(glm::cross(w, toLamp)), glm::dot(w, toLamp));
      const auto k = static_cast<std::uint32_t>(j * pixels + i);
      for (std::size_t r = 0; r < nRings; ++r)
        if (th >= radians(ringsDeg[r][0]) && th < radians(ringsDeg[r][1])) members[r].push_back(k);
      if (th >= frameFrom) members[nRings].push_back(k);
    }

  // fogbeam: the airlight layer per ray and the glow layer.
  const auto t0 = Clock::now();
  auto air = AirlightImageEvaluator::build(scene, AirlightMethod::Accurate, AirlightOptions{}, pool);
  if (!air) return air.error();
  GlowOptions glowOn;
  glowOn.enabled = true;
  // The glow knows the case's ground (GlowOptions::ground_reflectance); without one, infinite fog.
  glowOn.ground_reflectance = c.ground_below_m > 0.0 && c.glow_knows_ground ? c.ground_reflectance : -1.0;
  glowOn.ground_height_m = -c.ground_below_m;
  auto fx = LampEffects::build(scene, glowOn, GlareOptions{}, pool);
  if (!fx) return fx.error();
  std::vector<float> glow, glare;
  LampEffectsReport report;
  fx->evaluate(scene, surface, glow, glare, report);
  std::vector<float> glowInf = glow;
  if (glowOn.ground_reflectance >= 0.0) {
    GlowOptions inf = glowOn;
    inf.ground_reflectance = -1.0;
    auto fxInf = LampEffects::build(scene, inf, GlareOptions{}, pool);
    if (!fxInf) return fxInf.error();
    LampEffectsReport unused;
    std::vector<float> glareInf;
    fxInf->evaluate(scene, surface, glowInf, glareInf, unused);
  }
  if (!report.lamps.empty()) {
    out.lamp_visible = report.lamps[0].visible;
    out.glow_scale = report.lamps[0].glow_scale;
    out.glow_from_table = report.lamps[0].glow_from_table;
  }
  out.rings.resize(nRings + 1);
  for (std::size_t r = 0; r <= nRings; ++r) {
    RingFigures& f = out.rings[r];
    f.lo_deg = r < nRings ? ringsDeg[r][0] : ringsDeg.front()[0];
    f.hi_deg = r < nRings ? ringsDeg[r][1] : std::numeric_limits<double>::infinity();
    f.pixels = members[r].size();
    if (members[r].empty()) return Error{"validate --path-tracer: ring without pixels (image too coarse)"};
    double s = 0.0, g = 0.0, gi = 0.0;
    for (std::uint32_t k : members[r]) {
      const int i = static_cast<int>(k % static_cast<std::uint32_t>(pixels));
      const int j = static_cast<int>(k / static_cast<std::uint32_t>(pixels));
      float rgb[3];
      const Vec3 w = scene.camera.rayDirection(i + 0.5, j + 0.5);
      air->evaluateRay(Ray{scene.camera.position_m, w, endOf(w)}, rgb);
      s += (static_cast<double>(rgb[0]) + static_cast<double>(rgb[1]) + static_cast<double>(rgb[2])) / 3.0;
      const std::size_t p = 3 * static_cast<std::size_t>(k);
      g += (static_cast<double>(glow[p]) + static_cast<double>(glow[p + 1]) + static_cast<double>(glow[p + 2])) / 3.0;
      gi += (static_cast<double>(glowInf[p]) + static_cast<double>(glowInf[p + 1]) + static_cast<double>(glowInf[p + 2])) / 3.0;
    }
    f.single = s / static_cast<double>(members[r].size());
    f.glow = g / static_cast<double>(members[r].size());
    f.glow_infinite = gi / static_cast<double>(members[r].size());
  }
  out.fogbeam_seconds = std::chrono::duration<double>(Clock::now() - t0).count();

  // The path tracer: one stream per region, pixels drawn uniformly among its members.
  const auto t1 = Clock::now();
  std::optional<GroundPlane> ground;
  if (c.ground_below_m > 0.0) ground = GroundPlane{-c.ground_below_m, c.ground_reflectance};
  auto pt = PathTracer::build({lamp.lamp}, scene.fog, ground);
  if (!pt) return pt.error();
  const auto est = pt->estimate(nRings + 1, samples, seed, pool.get(),
                                [&](std::uint64_t region, std::uint64_t, PathRng& rng) {
    const auto& m = members[region];
    const std::size_t pick = std::min(m.size() - 1, static_cast<std::size_t>(rng.uniform() * static_cast<double>(m.size())));
    const std::uint32_t k = m[pick];
    const int i = static_cast<int>(k % static_cast<std::uint32_t>(pixels));
    const int j = static_cast<int>(k / static_cast<std::uint32_t>(pixels));
    const Vec3 w = scene.camera.rayDirection(i + 0.5, j + 0.5);
    return pt->trace(Ray{scene.camera.position_m, w, endOf(w)}, rng);
  });
  for (std::size_t r = 0; r <= nRings; ++r) {
    out.rings[r].pt_single = est[r].single;
    out.rings[r].pt_all = est[r].all;
    out.rings[r].mean_events = est[r].mean_events;
  }
  out.path_tracer_seconds = std::chrono::duration<double>(Clock::now() - t1).count();
  return out;
}

}  // namespace fogbeam::cli
