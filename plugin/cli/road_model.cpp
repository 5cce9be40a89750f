#include "road_model.hpp"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <numbers>

namespace fogbeam::road {

namespace {

using glm::dvec3;

constexpr dvec3 kUp{0.0, 0.0, 1.0};

// ---------------------------------------------------------------------------------------
// Centre line: straight (κ = 0) up to s1, clothoid (κ linear in s) up to s2, arc beyond.
// Heading θ(s) = ∫κ; position = ∫(cos θ, sin θ). The clothoid's Fresnel integrals are
// evaluated by composite Simpson (θ is a quadratic, so 256 intervals are exact to ~1e-12 m).
Pose clothoidEnd(const RoadParams& p, double u) {
  const double k = 1.0 / (p.bend_radius_m * p.transition_m);  // dκ/ds
  const auto theta = [k](double t) { return 0.5 * k * t * t; };
  Pose pose{p.straight_m, 0.5 * p.lane_width_m, theta(u)};
  if (u <= 0.0) return pose;
  constexpr int n = 256;
  const double h = u / n;
  double sx = 0.0, sy = 0.0;
  for (int i = 0; i <= n; ++i) {
    const double w = (i == 0 || i == n) ? 1.0 : (i % 2 == 1 ? 4.0 : 2.0);
    const double th = theta(h * i);
    sx += w * std::cos(th);
    sy += w * std::sin(th);
  }
  pose.x += sx * h / 3.0;
  pose.y += sy * h / 3.0;
  return pose;
}

// ---------------------------------------------------------------------------------------
// Mesh building: one builder per (group, material).
struct Builder {
  Primitive& prim;

  std::uint32_t vertex(const dvec3& pos, const dvec3& n) {
    prim.positions.push_back(pos);
    prim.normals.push_back(glm::normalize(n));
    return static_cast<std::uint32_t>(prim.positions.size() - 1);
  }
  // Triangle wound counter-clockwise as seen from the side its normals point to.
  void triangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    const dvec3& pa = prim.positions[a];
    const dvec3 face = glm::cross(prim.positions[b] - pa, prim.positions[c] - pa);
    const dvec3 nSum = prim.normals[a] + prim.normals[b] + prim.normals[c];
    if (glm::dot(face, nSum) < 0.0) std::swap(b, c);
    prim.indices.insert(prim.indices.end(), {a, b, c});
  }
  // Flat quad p0 p1 p2 p3 (in cyclic order) with normal n.
  void quad(const dvec3& p0, const dvec3& p1, const dvec3& p2, const dvec3& p3, const dvec3& n) {
    const auto a = vertex(p0, n), b = vertex(p1, n), c = vertex(p2, n), d = vertex(p3, n);
    triangle(a, b, c);
    triangle(a, c, d);
  }
  // Box standing on z = z0 up to z1, centred on `base` (z ignored), its "forward" edge
  // (length `along`) along heading θ, `across` wide. Six flat faces, outward normals.
  void box(const dvec3& base, double heading, double along, double across, double z0, double z1) {
    const dvec3 f{std::cos(heading), std::sin(heading), 0.0};
    const dvec3 l{-f.y, f.x, 0.0};
    const dvec3 c{base.x, base.y, 0.0};
    const auto corner = [&](double sf, double sl, double z) {
      return c + sf * 0.5 * along * f + sl * 0.5 * across * l + dvec3(0.0, 0.0, z);
    };
    quad(corner(-1, -1, z0), corner(1, -1, z0), corner(1, 1, z0), corner(-1, 1, z0), -kUp);
    quad(corner(-1, -1, z1), corner(1, -1, z1), corner(1, 1, z1), corner(-1, 1, z1), kUp);
    quad(corner(1, -1, z0), corner(1, 1, z0), corner(1, 1, z1), corner(1, -1, z1), f);
    quad(corner(-1, -1, z0), corner(-1, 1, z0), corner(-1, 1, z1), corner(-1, -1, z1), -f);
    quad(corner(-1, 1, z0), corner(1, 1, z0), corner(1, 1, z1), corner(-1, 1, z1), l);
    quad(corner(-1, -1, z0), corner(1, -1, z0), corner(1, -1, z1), corner(-1, -1, z1), -l);
  }
  // Vertical cylinder (smooth side normals) with a flat top cap.
  void cylinder(const dvec3& base, double r, double z0, double z1, int sides) {
    const auto n = static_cast<std::uint32_t>(sides);
    const std::uint32_t first = static_cast<std::uint32_t>(prim.positions.size());
    for (std::uint32_t k = 0; k < n; ++k) {
      const double phi = 2.0 * std::numbers::pi * k / n;
      const dvec3 radial{std::cos(phi), std::sin(phi), 0.0};
      vertex(dvec3(base.x, base.y, z0) + r * radial, radial);
      vertex(dvec3(base.x, base.y, z1) + r * radial, radial);
    }
    for (std::uint32_t k = 0; k < n; ++k) {
      const std::uint32_t b0 = first + 2 * k, t0 = b0 + 1;
      const std::uint32_t b1 = first + 2 * ((k + 1) % n), t1 = b1 + 1;
      triangle(b0, b1, t1);
      triangle(b0, t1, t0);
    }
    disc(base, r, z1, sides, kUp);
  }
  // Horizontal disc at height z facing n (±z).
  void disc(const dvec3& centre, double r, double z, int sides, const dvec3& n) {
    const auto count = static_cast<std::uint32_t>(sides);
    const auto mid = vertex(dvec3(centre.x, centre.y, z), n);
    for (std::uint32_t k = 0; k < count; ++k) {
      const double phi = 2.0 * std::numbers::pi * k / count;
      vertex(dvec3(centre.x + r * std::cos(phi), centre.y + r * std::sin(phi), z), n);
    }
    for (std::uint32_t k = 0; k < count; ++k) triangle(mid, mid + 1 + k, mid + 1 + (k + 1) % count);
  }
  // Vertical cone from a disc of radius r at z0 to the apex at z1 (smooth normals, one apex
  // vertex per facet so that each facet's apex normal points its own way), with a base disc.
  void cone(const dvec3& base, double r, double z0, double z1, int sides) {
    const auto n = static_cast<std::uint32_t>(sides);
    const double h = z1 - z0;
    const auto slantNormal = [&](double phi) { return dvec3(h * std::cos(phi), h * std::sin(phi), r); };
    const dvec3 apex{base.x, base.y, z1};
    for (std::uint32_t k = 0; k < n; ++k) {
      const double phi0 = 2.0 * std::numbers::pi * k / n;
      const double phi1 = 2.0 * std::numbers::pi * (k + 1) / n;
      const auto a = vertex(dvec3(base.x + r * std::cos(phi0), base.y + r * std::sin(phi0), z0), slantNormal(phi0));
      const auto b = vertex(dvec3(base.x + r * std::cos(phi1), base.y + r * std::sin(phi1), z0), slantNormal(phi1));
      const auto t = vertex(apex, slantNormal(0.5 * (phi0 + phi1)));
      triangle(a, b, t);
    }
    disc(base, r, z0, sides, -kUp);
  }
};

// Stations from s0 to s1 in equal steps no longer than `step`.
std::vector<double> stations(double s0, double s1, double step) {
  const auto n = static_cast<int>(std::max(1.0, std::ceil((s1 - s0) / step - 1e-9)));
  std::vector<double> s(static_cast<std::size_t>(n) + 1);
  for (int i = 0; i <= n; ++i) s[static_cast<std::size_t>(i)] = s0 + (s1 - s0) * i / n;
  return s;
}

class SceneBuilder {
 public:
  explicit SceneBuilder(const RoadParams& params) : p_(params) {}

  std::size_t material(const std::string& name, const Rgb& rho) {
    scene_.materials.push_back({name, rho});
    return scene_.materials.size() - 1;
  }
  // Starts a group; later builder() calls add to it.
  void group(const std::string& name) { scene_.groups.push_back({name, {}}); }
  Builder builder(std::size_t mat) {
    auto& prims = scene_.groups.back().primitives;
    const auto it = std::find_if(prims.begin(), prims.end(), [mat](const Primitive& pr) { return pr.material == mat; });
    if (it != prims.end()) return Builder{*it};
    prims.push_back(Primitive{mat, {}, {}, {}});
    return Builder{prims.back()};
  }

  // Horizontal ribbon between lateral offsets d0 < d1 from s0 to s1 at height z.
  void ribbon(std::size_t mat, double s0, double s1, double d0, double d1, double z) {
    Builder b = builder(mat);
    const auto s = stations(s0, s1, p_.step_m);
    const dvec3 lift{0.0, 0.0, z};
    const auto first = static_cast<std::uint32_t>(b.prim.positions.size());
    for (double si : s) {
      b.vertex(roadPoint(p_, si, d0) + lift, kUp);
      b.vertex(roadPoint(p_, si, d1) + lift, kUp);
    }
    for (std::uint32_t i = 0; i + 1 < s.size(); ++i) {
      const std::uint32_t r0 = first + 2 * i, l0 = r0 + 1, r1 = r0 + 2, l1 = r0 + 3;
      b.triangle(r0, r1, l1);
      b.triangle(r0, l1, l0);
    }
  }
  // Vertical band at lateral offset d from s0 to s1, z0..z1, facing the road centre.
  void wall(std::size_t mat, double s0, double s1, double d, double z0, double z1) {
    Builder b = builder(mat);
    const auto s = stations(s0, s1, p_.step_m);
    const auto first = static_cast<std::uint32_t>(b.prim.positions.size());
    for (double si : s) {
      const Pose c = centreLine(p_, si);
      const dvec3 towardsRoad = (d > 0.0 ? -1.0 : 1.0) * dvec3(-std::sin(c.heading), std::cos(c.heading), 0.0);
      const dvec3 q = roadPoint(p_, si, d);
      b.vertex(q + dvec3(0.0, 0.0, z0), towardsRoad);
      b.vertex(q + dvec3(0.0, 0.0, z1), towardsRoad);
    }
    for (std::uint32_t i = 0; i + 1 < s.size(); ++i) {
      const std::uint32_t b0 = first + 2 * i, t0 = b0 + 1, b1 = b0 + 2, t1 = b0 + 3;
      b.triangle(b0, b1, t1);
      b.triangle(b0, t1, t0);
    }
  }
  // Oriented box at (s, d) aligned with the road.
  void roadBox(std::size_t mat, double s, double d, double along, double across, double z0, double z1) {
    builder(mat).box(roadPoint(p_, s, d), centreLine(p_, s).heading, along, across, z0, z1);
  }

  RoadScene take() { return std::move(scene_); }

 private:
  const RoadParams& p_;
  RoadScene scene_;
};

}  // namespace

// ---------------------------------------------------------------------------------------
Pose centreLine(const RoadParams& p, double s) {
  const double y0 = 0.5 * p.lane_width_m;
  if (s <= p.straight_m) return {s, y0, 0.0};
  if (s <= p.straight_m + p.transition_m) return clothoidEnd(p, s - p.straight_m);
  const Pose e = clothoidEnd(p, p.transition_m);  // start of the arc
  const double R = p.bend_radius_m;
  const double theta = e.heading + (s - p.straight_m - p.transition_m) / R;
  // Left bend: the centre of curvature lies R to the left of the arc's start.
  return {e.x + R * (std::sin(theta) - std::sin(e.heading)), e.y - R * (std::cos(theta) - std::cos(e.heading)), theta};
}

dvec3 roadPoint(const RoadParams& p, double s, double d) {
  const Pose c = centreLine(p, s);
  return {c.x - d * std::sin(c.heading), c.y + d * std::cos(c.heading), 0.0};
}

dvec3 lampPosition(const RoadParams& p, const StreetLampPlacement& lamp) {
  const double d = lamp.side * (p.lane_width_m + p.lamp_pole_offset_m - p.lamp_arm_m);
  return roadPoint(p, lamp.s_m, d) + dvec3(0.0, 0.0, p.lamp_height_m);
}

std::size_t RoadScene::triangleCount() const {
  std::size_t n = 0;
  for (const auto& g : groups)
    for (const auto& pr : g.primitives) n += pr.indices.size() / 3;
  return n;
}

RoadScene buildRoadScene(const RoadParams& p) {
  assert(p.start_s_m < p.end_s_m && p.step_m > 0.0 && p.bend_radius_m > 0.0 && p.transition_m > 0.0);
  SceneBuilder sb(p);
  const auto asphalt = sb.material("asphalt", p.asphalt);
  const auto marking = sb.material("marking_white", p.marking);
  const auto gravel = sb.material("gravel", p.gravel);
  const auto grass = sb.material("grass", p.grass);
  const auto postWhite = sb.material("post_white", p.post_white);
  const auto postBlack = sb.material("post_black", p.post_black);
  const auto rail = sb.material("guard_rail_steel", p.rail);
  const auto signFace = sb.material("sign_face_white", p.sign_face);
  const auto signBorder = sb.material("sign_border_red", p.sign_border);
  const auto metal = sb.material("metal_grey", p.metal_grey);
  const auto trunk = sb.material("bark", p.trunk);
  const auto crown = sb.material("conifer_crown", p.crown);

  const double s0 = p.start_s_m, s1 = p.end_s_m;
  const double edge = p.lane_width_m;                 // edge-line centres at d = ±edge
  const double paved = edge + p.paved_margin_m;
  const double gravelOuter = paved + p.gravel_width_m;
  const double grassOuter = gravelOuter + p.grass_width_m;
  const double hw = 0.5 * p.marking_width_m;

  // Road surface and ground, all at z = 0, side by side (no overlaps).
  sb.group("road_surface");
  sb.ribbon(asphalt, s0, s1, -paved, paved, 0.0);
  sb.group("shoulders");
  sb.ribbon(gravel, s0, s1, -gravelOuter, -paved, 0.0);
  sb.ribbon(gravel, s0, s1, paved, gravelOuter, 0.0);
  sb.ribbon(grass, s0, s1, -grassOuter, -gravelOuter, 0.0);
  sb.ribbon(grass, s0, s1, gravelOuter, grassOuter, 0.0);

  // Markings: continuous edge lines, dashed centre line.
  sb.group("lane_markings");
  const double lift = p.marking_lift_m;
  sb.ribbon(marking, s0, s1, -edge - hw, -edge + hw, lift);
  sb.ribbon(marking, s0, s1, edge - hw, edge + hw, lift);
  const double period = p.dash_on_m + p.dash_off_m;
  for (double a = p.dash_phase_s_m + std::floor((s0 - p.dash_phase_s_m) / period) * period; a < s1; a += period) {
    const double from = std::max(a, s0), to = std::min(a + p.dash_on_m, s1);
    if (to > from) sb.ribbon(marking, from, to, -hw, hw, lift);
  }

  // Reflector posts, both sides: white body, black band, white cap.
  sb.group("reflector_posts");
  const double postD = edge + p.post_offset_m;
  for (double s = p.post_first_s_m; s <= s1 - 1.0; s += p.post_spacing_m) {
    if (s < s0) continue;
    for (double side : {-1.0, 1.0}) {
      const double d = side * postD;
      sb.roadBox(postWhite, s, d, p.post_depth_m, p.post_width_m, 0.0, p.post_band_bottom_m);
      sb.roadBox(postBlack, s, d, p.post_depth_m, p.post_width_m, p.post_band_bottom_m, p.post_band_top_m);
      sb.roadBox(postWhite, s, d, p.post_depth_m, p.post_width_m, p.post_band_top_m, p.post_height_m);
    }
  }

  // Guard rail on the outside (right) of the bend: a beam band and posts behind it.
  sb.group("guard_rail");
  const double railD = -(postD + p.rail_offset_m);
  sb.wall(rail, p.rail_from_s_m, p.rail_to_s_m, railD, p.rail_bottom_m, p.rail_top_m);
  const double railPostD = railD - 0.5 * p.rail_post_size_m - 0.05;  // 5 cm spacer behind the beam
  for (double s = p.rail_from_s_m; s <= p.rail_to_s_m + 1e-9; s += p.rail_post_spacing_m)
    sb.roadBox(metal, s, railPostD, p.rail_post_size_m, p.rail_post_size_m, 0.0, p.rail_top_m - 0.05);

  // Warning sign on the right, facing oncoming ego traffic: post, red plate, white face.
  sb.group("warning_sign");
  {
    const double d = -(edge + p.sign_offset_m);
    const double zc = p.sign_centre_height_m, half = 0.5 * p.sign_plate_size_m;
    const double inner = half - p.sign_border_m;
    sb.roadBox(metal, p.sign_s_m + 0.05, d, 0.06, 0.06, 0.0, zc + half - 0.05);  // post behind the plate
    sb.roadBox(signBorder, p.sign_s_m, d, 0.03, p.sign_plate_size_m, zc - half, zc + half);
    sb.roadBox(signFace, p.sign_s_m - 0.02, d, 0.01, 2.0 * inner, zc - inner, zc + inner);  // 5 mm proud
  }

  // Street-lamp poles: pole, arm towards the road, head just above the light point.
  sb.group("street_lamp_poles");
  for (const auto& lamp : p.street_lamps) {
    const double side = lamp.side >= 0 ? 1.0 : -1.0;
    const double poleD = side * (edge + p.lamp_pole_offset_m);
    const double headD = side * (edge + p.lamp_pole_offset_m - p.lamp_arm_m);
    const double top = p.lamp_height_m + 0.2;
    sb.builder(metal).cylinder(roadPoint(p, lamp.s_m, poleD), p.lamp_pole_radius_m, 0.0, top + 0.1, p.round_sides);
    sb.roadBox(metal, lamp.s_m, 0.5 * (poleD + headD), 0.08, p.lamp_arm_m + 0.1, top, top + 0.08);
    sb.roadBox(metal, lamp.s_m, headD, 0.3, 0.6, p.lamp_height_m + 0.02, top);
  }

  // Trees: trunk cylinder, cone crown.
  sb.group("trees");
  for (const auto& t : p.trees) {
    const dvec3 base = roadPoint(p, t.s_m, t.d_m);
    const double crownBase = p.crown_base_fraction * t.height_m;
    sb.builder(trunk).cylinder(base, p.trunk_radius_m, 0.0, crownBase + 0.3, p.round_sides);
    sb.builder(crown).cone(base, t.crown_radius_m, crownBase, t.height_m, p.round_sides);
  }

  return sb.take();
}

}  // namespace fogbeam::road
