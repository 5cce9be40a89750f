// fogbeam — parametric model of the default road scene (config/scenes/road.glb).
//
// A two-lane rural road for right-hand traffic: a straight, a clothoid transition and a left
// bend; asphalt, white lane markings, gravel and grass shoulders, reflector posts, trees, a
// warning sign, a guard rail on the outside of the bend and two street-lamp poles. Every
// dimension and reflectance is a parameter below, with unit, default and reason. Nothing is
// typed by hand as a vertex list and no third-party asset is used: fogbeam_scenegen samples
// this model and writes it as glTF 2.0 binary (its --check mode guards the shipped file).
//
// Frame: fogbeam's world frame (docs/physics.md): x forward, y left, z up, metres. The road
// surface is the plane z = 0. The alignment (the road's centre line, between the two lanes)
// starts heading +x through (0, lane_width_m / 2, 0), so the ego lane is centred on y = 0 and
// the oncoming lane on y = +lane_width_m while the road is straight.
// Stations s (metres along the centre line, 0 at x = 0) and lateral offsets d (metres from
// the centre line, positive left) place everything: point(s, d) = c(s) + d·n(s).
// Lambertian reflectances are linear RGB (the GL pass uses baseColorFactor.rgb as ρ); they
// are diffuse stand-ins: retroreflective sheeting and wet surfaces are not modelled.
//
// Thread-safety: pure functions.
#pragma once

#include <glm/vec3.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace fogbeam::road {

using Rgb = std::array<double, 3>;

/// A tree: trunk cylinder and cone crown.
struct TreePlacement {
  double s_m = 0.0;            ///< m; station.
  double d_m = 0.0;            ///< m; lateral offset from the centre line, positive left.
  double height_m = 8.0;       ///< m; total height (crown tip).
  double crown_radius_m = 1.5; ///< m; radius of the crown's base.
};

/// A street-lamp pole: a vertical pole beside the road and an arm reaching over it; the
/// lamp head hangs at the arm's end. The scene file puts its [[lamp]] at lampPosition().
struct StreetLampPlacement {
  double s_m = 0.0;            ///< m; station of the pole.
  int side = 1;                ///< +1 left of the road, −1 right.
};

struct RoadParams {
  // --- Alignment ----------------------------------------------------------------------
  double start_s_m = -10.0;         ///< m; station where the road starts: 10 m behind the eye
                                    ///< (x = 0), so a camera moved back a little, or one looking
                                    ///< down, still sees road (the default view meets the
                                    ///< ground ≈ 4 m ahead).
  double straight_m = 20.0;         ///< m; station where the straight ends. Short, so that the
                                    ///< bend lies inside what low beams show in 100 m fog (about
                                    ///< 50 m: beyond, lit surfaces fade into the airlight); the
                                    ///< centre line has moved 1.4 m left by station 60, 8.6 m
                                    ///< by station 100.
  double transition_m = 30.0;       ///< m; clothoid: curvature rises linearly from 0 to
                                    ///< 1/bend_radius_m (real roads use one so that the steering
                                    ///< rate stays finite; no kink in the edge lines).
  double bend_radius_m = 250.0;     ///< m; radius of the left bend (a rural road designed for
                                    ///< ≈ 80–90 km/h; RAL/RAA: R ≥ 250 m for 90 km/h).
  double end_s_m = 350.0;           ///< m; station where the road ends: 300 m of arc, 72° of
                                    ///< bend in all; 3.5 visibilities (100 m fog) hide the rest.
  double step_m = 1.0;              ///< m; longest strip segment along the road. Chord error in
                                    ///< the bend: step²/(8 R) = 0.5 mm.
  // --- Cross-section (offsets from the centre line) -----------------------------------
  double lane_width_m = 3.5;        ///< m; lane width between marking centres (EU rural road).
  double paved_margin_m = 0.25;     ///< m; asphalt beyond each edge line.
  double gravel_width_m = 1.25;     ///< m; gravel shoulder beyond the asphalt.
  double grass_width_m = 25.0;      ///< m; grass verge beyond the gravel (the ground model ends
                                    ///< there; a scene may add a [[plane]] just below z = 0).
  double marking_width_m = 0.15;    ///< m; width of edge and centre lines (EU: 0.12–0.15 m).
  double marking_lift_m = 0.01;     ///< m; markings float this far above the asphalt so that
                                    ///< the depth test never confuses them (no z-fighting).
  double dash_on_m = 3.0;           ///< m; centre-line dash length (German rural 1:3 pattern).
  double dash_off_m = 9.0;          ///< m; gap between centre-line dashes.
  double dash_phase_s_m = 0.0;      ///< m; a dash starts at this station (under the eye).
  // --- Reflector posts (delineators) --------------------------------------------------
  double post_spacing_m = 50.0;     ///< m; spacing along the road, both sides (EU practice).
  double post_first_s_m = 25.0;     ///< m; station of the first pair: 25 m ahead of the default
                                    ///< eye (a pair at 0 would stand beside it, out of view, and
                                    ///< the next, at 50 m, is all but lost in 100 m fog).
  double post_offset_m = 1.0;       ///< m; lateral distance from the edge line's centre.
  double post_width_m = 0.1;        ///< m; across the road (the face drivers see).
  double post_depth_m = 0.1;        ///< m; along the road.
  double post_height_m = 1.0;       ///< m; height above the road (German Leitpfosten: 1.0 m).
  double post_band_bottom_m = 0.70; ///< m; lower edge of the black band.
  double post_band_top_m = 0.95;    ///< m; upper edge of the black band (a white cap above).
  // --- Guard rail on the outside (right) of the bend ----------------------------------
  double rail_from_s_m = 30.0;      ///< m; start station (where the bend begins to bite: the
                                    ///< beams, aimed straight on, meet the rail).
  double rail_to_s_m = 200.0;       ///< m; end station.
  double rail_offset_m = 0.6;       ///< m; beam face beyond the reflector posts' line.
  double rail_bottom_m = 0.45;      ///< m; lower edge of the beam (a W-beam as a flat band).
  double rail_top_m = 0.75;         ///< m; upper edge of the beam (EN 1317 rails: ≈ 0.75 m).
  double rail_post_spacing_m = 2.0; ///< m; post spacing (standard steel rail: 2 m or 4 m).
  double rail_post_size_m = 0.1;    ///< m; square post section.
  // --- Warning sign (bend ahead) -------------------------------------------------------
  double sign_s_m = 12.0;           ///< m; station, on the right, facing traffic (inside the
                                    ///< default camera's view; real ones stand 150–250 m ahead).
  double sign_offset_m = 1.5;       ///< m; plate centre beyond the edge line's centre.
  double sign_plate_size_m = 0.9;   ///< m; square plate (stands in for a 900 mm triangle).
  double sign_border_m = 0.1;       ///< m; red border around the white face.
  double sign_centre_height_m = 1.9;///< m; plate centre above the road (lower edge ≈ 1.45 m).
  // --- Street-lamp poles ----------------------------------------------------------------
  std::vector<StreetLampPlacement> street_lamps{{35.0, +1}, {75.0, -1}};  ///< left by the
                                    ///< oncoming lane, and on the outside of the bend.
  double lamp_pole_offset_m = 2.0;  ///< m; pole beyond the edge line's centre.
  double lamp_arm_m = 1.75;         ///< m; arm towards the road: the head is over the edge line
                                    ///< + (pole offset − arm).
  double lamp_height_m = 8.0;       ///< m; light point above the road (rural roads: 8–10 m).
  double lamp_pole_radius_m = 0.08; ///< m; pole radius.
  // --- Trees (hand-placed, varied; none on the ground a car could drive on) -----------
  std::vector<TreePlacement> trees{
      {15.0, 11.0, 9.0, 1.8},  {28.0, -12.0, 7.5, 1.5}, {42.0, 16.0, 11.0, 2.2},
      {50.0, -9.0, 8.0, 1.6},  {60.0, -11.5, 9.5, 1.9}, {68.0, -8.5, 8.5, 1.7},
      {80.0, 13.0, 10.0, 2.0}, {88.0, -10.0, 10.5, 2.1}, {110.0, -12.5, 9.0, 1.8},
      {135.0, 10.0, 8.5, 1.7}, {160.0, -10.0, 11.0, 2.2}, {210.0, 12.0, 9.0, 1.8},
      {250.0, -9.5, 10.0, 2.0}, {300.0, 11.0, 8.0, 1.6}};  ///< several on the outside (right)
                                    ///< of the bend, where the beams meet them.
  double trunk_radius_m = 0.15;     ///< m; trunk radius.
  double crown_base_fraction = 0.25;///< the crown starts at this fraction of the tree's height.
  int round_sides = 16;             ///< facets of cylinders and cones (smooth normals).
  // --- Reflectances (linear RGB, Lambertian stand-ins) ---------------------------------
  Rgb asphalt{0.09, 0.09, 0.09};    ///< dry asphalt, medium age: 0.07–0.12.
  Rgb marking{0.55, 0.55, 0.55};    ///< white road paint, diffuse part (no glass beads).
  Rgb gravel{0.14, 0.13, 0.11};     ///< grey-brown gravel shoulder: 0.1–0.2.
  Rgb grass{0.06, 0.09, 0.04};      ///< green grass at night (luminance ≈ 0.08).
  Rgb post_white{0.75, 0.75, 0.75}; ///< white plastic delineator body.
  Rgb post_black{0.04, 0.04, 0.04}; ///< its black band.
  Rgb rail{0.35, 0.35, 0.35};       ///< galvanised steel, weathered (its gloss is not modelled).
  Rgb sign_face{0.80, 0.80, 0.80};  ///< white sign face (retroreflection not modelled).
  Rgb sign_border{0.45, 0.04, 0.04};///< red sign border.
  Rgb metal_grey{0.30, 0.30, 0.30}; ///< sign posts, lamp poles and heads.
  Rgb trunk{0.10, 0.07, 0.05};      ///< bark.
  Rgb crown{0.04, 0.07, 0.035};     ///< conifer needles (dark).
};

// ---------------------------------------------------------------------------------------
/// The road's centre line: c(s), heading θ(s) (radians, 0 = +x, positive left).
struct Pose {
  double x = 0.0, y = 0.0, heading = 0.0;
};
[[nodiscard]] Pose centreLine(const RoadParams& p, double s);
/// World point (z = 0) at station s and lateral offset d (positive left).
[[nodiscard]] glm::dvec3 roadPoint(const RoadParams& p, double s, double d);
/// Position of a street lamp's light point (where the scene file puts its [[lamp]]).
[[nodiscard]] glm::dvec3 lampPosition(const RoadParams& p, const StreetLampPlacement& lamp);

// ---------------------------------------------------------------------------------------
/// Triangle geometry in fogbeam's world frame, grouped by object and material.
struct Material {
  std::string name;
  Rgb reflectance{1.0, 1.0, 1.0};
};
struct Primitive {
  std::size_t material = 0;            ///< index into RoadScene::materials
  std::vector<glm::dvec3> positions;   ///< m, world frame
  std::vector<glm::dvec3> normals;     ///< unit, per vertex
  std::vector<std::uint32_t> indices;  ///< triangle list, counter-clockwise seen from the normal
};
struct Group {
  std::string name;                    ///< becomes the glTF node and mesh name
  std::vector<Primitive> primitives;   ///< one per material, in material order
};
struct RoadScene {
  std::vector<Material> materials;
  std::vector<Group> groups;
  [[nodiscard]] std::size_t triangleCount() const;
};

/// Builds the scene. Deterministic: the same parameters give the same vertices in the
/// same order.
[[nodiscard]] RoadScene buildRoadScene(const RoadParams& p = {});

}  // namespace fogbeam::road
