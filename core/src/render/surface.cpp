#include <fogbeam/render/surface.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>

namespace fogbeam {

void SurfaceBuffers::resize(int w, int h) {
  width = w;
  height = h;
  const auto n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  rgb.assign(3 * n, 0.0f);
  distance.assign(n, std::numeric_limits<float>::infinity());
}

double lambertianLuminance(const Lamp& lamp, const Medium& fog, const Vec3& point, const Vec3& normal,
                           double reflectance) noexcept {
  const Vec3 toPoint = point - lamp.position_m;
  const double r2 = glm::dot(toPoint, toPoint);
  if (r2 <= 0.0) return 0.0;
  const double r = std::sqrt(r2);
  const Vec3 w = toPoint / r;
  const double cosInc = -glm::dot(w, normal);  // light arrives against the normal
  if (cosInc <= 0.0) return 0.0;
  const Vec3 wLamp = glm::transpose(lamp.worldFromLamp) * w;
  const double e = lamp.profile->intensity(wLamp) * cosInc * std::exp(-fog.extinction_per_m * r) / r2;  // lux
  return reflectance / kPi * e;
}

void renderSurfacesCpu(const Scene& scene, SurfaceBuffers& out) {
  const Camera& cam = scene.camera;
  out.resize(cam.width, cam.height);
  const double kt = scene.fog.extinction_per_m, ia = scene.fog.ambient_cd_m2;
  auto rows = [&](int j0, int j1) {
    for (int j = j0; j < j1; ++j) {
      for (int i = 0; i < cam.width; ++i) {
        const Vec3 d = cam.rayDirection(i + 0.5, j + 0.5);
        double best = std::numeric_limits<double>::infinity();
        const Plane* hit = nullptr;
        for (const Plane& p : scene.planes) {
          const double denom = glm::dot(d, p.normal);
          if (std::abs(denom) < 1e-12) continue;
          const double t = glm::dot(p.point_m - cam.position_m, p.normal) / denom;
          if (t > 0.0 && t < best) {
            best = t;
            hit = &p;
          }
        }
        const auto px = static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
        double rgb[3] = {0.0, 0.0, 0.0};
        if (hit) {
          const Vec3 x = cam.position_m + best * d;
          const Vec3 n = glm::dot(hit->normal, d) < 0.0 ? hit->normal : -hit->normal;  // faces the eye
          for (const SceneLamp& sl : scene.lamps) {
            const double l = lambertianLuminance(sl.lamp, scene.fog, x, n, hit->reflectance);
            for (int c = 0; c < 3; ++c) rgb[c] += l * sl.lamp.color[c];
          }
        }
        const double t = hit ? std::exp(-kt * best) : 0.0;
        for (int c = 0; c < 3; ++c) out.rgb[3 * px + static_cast<std::size_t>(c)] = static_cast<float>(rgb[c] * t + ia * (1.0 - t));
        out.distance[px] = hit ? static_cast<float>(best) : std::numeric_limits<float>::infinity();
      }
    }
  };
  const int nThreads = std::max(1, std::min(static_cast<int>(std::thread::hardware_concurrency()), cam.height));
  std::vector<std::thread> pool;
  for (int k = 0; k < nThreads; ++k)
    pool.emplace_back(rows, cam.height * k / nThreads, cam.height * (k + 1) / nThreads);
  for (auto& th : pool) th.join();
}

}  // namespace fogbeam
