// fogbeam — the veil of the road lit by the driver's own lamps (ground_veil.hpp).
#include "ground_veil.hpp"

#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/profile.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace fogbeam::ground_veil {

namespace {
constexpr double kTwoPi = 2.0 * kPi;
}  // namespace

RoadMap roadMap(const std::vector<Lamp>& lamps, const Medium& fog, const Ground& ground, const Vec3& eye, int rings,
                int sectors, ThreadPool* pool, const FogLightTable* fogLight) {
  RoadMap m;
  const double kt = fog.extinction_per_m;
  if (!(ground.reflectance > 0.0) || !(kt > 0.0) || lamps.empty() || rings < 2 || sectors < 1) return m;
  m.foot = Vec3(eye.x, eye.y, ground.z_m);
  const double r1 = std::max(1.0, std::min(300.0, 12.0 / kt));
  m.logStep = std::log(r1 / m.r0) / (rings - 1);
  m.rings = rings;
  m.sectors = sectors;
  m.rgb.assign(static_cast<std::size_t>(rings) * static_cast<std::size_t>(sectors) * 3, 0.0f);
  const std::size_t bins = fogLight != nullptr ? fogLight->bins() : 0;
  auto ring = [&](int a) {
    // The fog light's inputs per lamp and node (one allocation per ring, made only when the veil is).
    std::vector<double> means(bins), dipoles(3 * bins), dotN(bins);
    const double r = m.r0 * std::exp(a * m.logStep);
    for (int b = 0; b < sectors; ++b) {
      const double phi = b * kTwoPi / sectors;
      const Vec3 x(m.foot.x + r * std::cos(phi), m.foot.y + r * std::sin(phi), ground.z_m);
      double e[3] = {0.0, 0.0, 0.0};
      for (const Lamp& l : lamps) {
        const double h = l.position_m.z - ground.z_m;
        if (!(h > 0.0) || l.profile == nullptr) continue;  // a lamp on or below the road lights none of it
        const Vec3 d = x - l.position_m;
        const double dist = glm::length(d);
        const Vec3 wl = l.lampFromWorld * (d / dist);  // lamp → road point, lamp frame
        const double intensity = l.profile->intensity(wl);
        double lux = intensity * (h / dist) * std::exp(-kt * dist) / (dist * dist);
        if (fogLight != nullptr) {
          // The fog's scattered light on the road as the surface layer shows it (fog_light.hpp:
          // E = K_t² Σ_k Ī_k e_k(K_t R, μ) with the harmonics' part along the normal; μ the cosine
          // of the lamp's direction from the road's normal). A lamp without annulus means is
          // isotropic: every bin's mean is its intensity.
          if (l.annuli != nullptr) {
            l.annuli->lookup(wl, means.data(), dipoles.data());
            AnnulusMeanMap::dipolesAlong(dipoles.data(), bins, l.lampFromWorld * Vec3(0.0, 0.0, 1.0), dotN.data());
          } else {
            std::fill(means.begin(), means.end(), intensity);
            std::fill(dotN.begin(), dotN.end(), 0.0);
          }
          lux += kt * kt * fogLight->irradiance(kt * dist, h / dist, means.data(), dotN.data());
        }
        for (int k = 0; k < 3; ++k) e[k] += l.color[k] * lux;
      }
      float* out = m.rgb.data() + (static_cast<std::size_t>(a) * static_cast<std::size_t>(sectors) +
                                   static_cast<std::size_t>(b)) * 3;
      for (int k = 0; k < 3; ++k) out[k] = static_cast<float>(ground.reflectance * e[k] / kPi);
    }
  };
  if (pool != nullptr) {
    pool->parallelFor(static_cast<std::size_t>(rings), [&ring](std::size_t a) { ring(static_cast<int>(a)); });
  } else {
    for (int a = 0; a < rings; ++a) ring(a);
  }
  if (std::none_of(m.rgb.begin(), m.rgb.end(), [](float x) { return x > 0.0f; })) m.rgb.clear();
  return m;
}

void RoadMap::at(double x, double y, double out[3]) const noexcept {
  out[0] = out[1] = out[2] = 0.0;
  const double dx = x - foot.x, dy = y - foot.y;
  const double r = std::sqrt(dx * dx + dy * dy);
  const double fr = std::log(std::max(r, r0) / r0) / logStep;
  if (!(fr < rings - 1)) return;
  double fs = fastAtan2(dy, dx) / kTwoPi * sectors;
  if (fs < 0.0) fs += sectors;
  const int a = static_cast<int>(fr);
  int b = static_cast<int>(fs);
  if (b >= sectors) b = 0;
  const int b1 = b + 1 == sectors ? 0 : b + 1;
  const double ta = fr - a, tb = fs - b;
  const auto s = static_cast<std::size_t>(sectors);
  const float* p00 = rgb.data() + (static_cast<std::size_t>(a) * s + static_cast<std::size_t>(b)) * 3;
  const float* p01 = rgb.data() + (static_cast<std::size_t>(a) * s + static_cast<std::size_t>(b1)) * 3;
  const float* p10 = p00 + 3 * s;
  const float* p11 = p01 + 3 * s;
  for (int k = 0; k < 3; ++k) {
    const double lo = static_cast<double>(p00[k]) + tb * static_cast<double>(p01[k] - p00[k]);
    const double hi = static_cast<double>(p10[k]) + tb * static_cast<double>(p11[k] - p10[k]);
    out[k] = lo + ta * (hi - lo);
  }
}

double alongRay(const RoadMap& road, const Medium& fog, const Ground& ground, const Vec3& eye, const Vec3& w, int steps,
                double rgb[3], int angles, int azimuths) {
  const double kt = fog.extinction_per_m;
  const double height = eye.z - ground.z_m;
  const double end = w.z < 0.0 && height > 0.0 ? height / -w.z : std::numeric_limits<double>::infinity();
  if (road.empty() || !(kt > 0.0) || steps < 1 || angles < 1 || azimuths < 1 || !(height > 0.0)) return end;
  const double u0 = 0.05, u1 = std::min(end, 15.0 / kt);
  if (!(u1 > u0)) return end;
  // The directions: angles ψ from w (cell edges 0, 0.2° doubling to 12.8°, then equal steps to
  // 180°) × azimuths about w, each with its solid angle and the phase function at cos ψ (the same
  // for every step).
  const Vec3 a1 = glm::normalize(std::abs(w.z) < 0.9 ? glm::cross(w, Vec3(0, 0, 1)) : glm::cross(w, Vec3(1, 0, 0)));
  const Vec3 a2 = glm::cross(w, a1);
  struct Dir {
    Vec3 d;
    double weight;  // p(cos ψ) dΩ
  };
  thread_local std::vector<Dir> dirs;
  dirs.clear();
  // Cell edges: 0, then 0.2° doubling up to 12.8° (the phase function's forward peak, for rays
  // that meet the road: the road about where they meet it), then `angles` equal cells to 180°.
  const double peakEnd = radians(12.8);
  double psiA = 0.0;
  for (int i = 0; i < 7 + angles; ++i) {
    const double psiB = i < 7 ? radians(0.2) * std::exp2(i) : peakEnd + (kPi - peakEnd) * (i - 6) / angles;
    const double psi = 0.5 * (psiA + psiB);
    const double omega = (std::cos(psiA) - std::cos(psiB)) * kTwoPi / azimuths;
    const double weight = evalPhase(fog.phase, std::cos(psi)) * omega;
    for (int j = 0; j < azimuths; ++j) {
      const double az = (j + 0.5) * kTwoPi / azimuths;
      const Vec3 d = std::cos(psi) * w + std::sin(psi) * (std::cos(az) * a1 + std::sin(az) * a2);
      if (d.z < -1e-9) dirs.push_back({d, weight});
    }
    psiA = psiB;
  }
  // Step edges: log-spaced from the eye; for a ray that meets the road, half of them log-spaced
  // towards that end as well (there the ray runs over the road, seen in the phase function's
  // forward peak, and the light it gathers changes fastest).
  thread_local std::vector<double> edges;
  edges.assign(1, 0.0);
  const bool meets = end <= u1;
  const int near = meets ? std::max(1, steps / 2) : steps, far = steps - near;
  const double mid = meets ? 0.5 * u1 : u1;
  if (mid > u0) {
    for (int s = 1; s <= near; ++s) edges.push_back(u0 * std::pow(mid / u0, static_cast<double>(s) / near));
  } else {
    edges.push_back(mid);
  }
  if (meets && far > 0) {
    const double sMin = std::min(u0, 0.01 * u1), sMax = u1 - mid;
    for (int s = 1; s < far; ++s) edges.push_back(u1 - sMax * std::pow(sMin / sMax, static_cast<double>(s) / (far - 1)));
    edges.push_back(u1);
  }
  for (std::size_t s = 0; s + 1 < edges.size(); ++s) {
    const double ua = edges[s], ub = edges[s + 1];
    if (!(ub > ua)) continue;
    const double um = 0.5 * (ua + ub);
    const Vec3 p = eye + um * w;
    const double above = p.z - ground.z_m;
    if (above > 0.0) {
      double sum[3] = {0.0, 0.0, 0.0};
      for (const Dir& dir : dirs) {
        const double t = above / -dir.d.z;
        if (t > 30.0 / kt) continue;  // e^{−30}
        double l[3];
        road.at(p.x + t * dir.d.x, p.y + t * dir.d.y, l);
        const double g = dir.weight * std::exp(-kt * t);
        for (int k = 0; k < 3; ++k) sum[k] += g * l[k];
      }
      const double scale = fog.albedo * kt * std::exp(-kt * um) * (ub - ua);
      for (int k = 0; k < 3; ++k) rgb[k] += scale * sum[k];
    }
  }
  return end;
}

}  // namespace fogbeam::ground_veil
