#include <fogbeam/render/lamp_effects.hpp>

#include <fogbeam/physics/glow.hpp>
#include <fogbeam/render/airlight_kernels.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

namespace fogbeam {

namespace {

// Radial tables over the half-chord s = |ω − e|/2 = sin(θ/2) between a pixel's ray ω and the
// lamp's direction e: nodes s_i = (i / (n − 1))², dense near the lamp (θ of the first node: 2e-5
// rad at n = 512), every θ up to π.
constexpr int kNodes = 512;
double sOfNode(int i) {
  const double u = static_cast<double>(i) / (kNodes - 1);
  return u * u;
}
double thetaOfS(double s) { return 2.0 * std::asin(std::min(s, 1.0)); }

double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

struct LampEffects::Tables {
  std::shared_ptr<const kernels::IsoTable> iso;  // single scattering of the glow's isotropic source
  std::vector<float> cieGlare;                   // CIE 146 L_v/E per node, (cd/m²)/lux
  struct Radial {
    float e[3] = {1, 0, 0};      // lamp direction, camera frame
    float color[3] = {1, 1, 1};  // glow: colour × table; glare: colour × E
    float distance = 0.0f;       // R, metres (glow's occlusion weight)
    const float* table = nullptr;
  };
  std::vector<Radial> glow, glare;
  std::vector<float> glowTables;  // kNodes per glowing lamp
};

Result<LampEffects> LampEffects::build(const Scene& scene, const GlowOptions& glow, const GlareOptions& glare,
                                       std::shared_ptr<ThreadPool> pool) {
  if (glow.enabled && !(glow.fade_in >= Apsf::minOpticalDistance()))
    return Error{"glow: fade_in must be at least " + std::to_string(Apsf::minOpticalDistance())};
  if (glare.enabled && !(glare.age_years >= 0.0 && glare.age_years <= 120.0))
    return Error{"glare: age_years must be in [0, 120]"};
  if (glare.enabled && !(glare.pigmentation >= 0.0 && glare.pigmentation <= 1.0))
    return Error{"glare: pigmentation must be in [0, 1]"};
  LampEffects fx;
  fx.glow_ = glow;
  fx.glare_ = glare;
  fx.pool_ = std::move(pool);
  fx.enabled_.assign(scene.lamps.size(), 1);
  fx.tables_ = std::make_shared<Tables>();
  if (glow.enabled) fx.tables_->iso = kernels::IsoTable::get(scene.fog.phase);
  if (glare.enabled) {
    fx.tables_->cieGlare.resize(kNodes);
    for (int i = 0; i < kNodes; ++i)
      fx.tables_->cieGlare[static_cast<std::size_t>(i)] = static_cast<float>(
          veilingLuminancePerLux(thetaOfS(sOfNode(i)) * 180.0 / kPi, glare.age_years, glare.pigmentation));
  }
  fx.tables_->glowTables.resize(static_cast<std::size_t>(kNodes) * scene.lamps.size());
  fx.tables_->glow.reserve(scene.lamps.size());
  fx.tables_->glare.reserve(scene.lamps.size());
  return fx;
}

void LampEffects::setLampEnabled(std::size_t index, bool on) {
  if (index < enabled_.size()) enabled_[index] = on ? 1 : 0;
}

void LampEffects::evaluate(const Scene& scene, const SurfaceBuffers& surface, std::vector<float>& glowOut,
                           std::vector<float>& glareOut, LampEffectsReport& report) {
  Tables& t = *tables_;
  const Camera& cam = scene.camera;
  const Medium& fog = scene.fog;
  const double kt = fog.extinction_per_m;
  const std::size_t n = static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height);
  const Mat3 camFromWorld = glm::transpose(cam.worldFromCamera);
  const double f = cam.focalLengthPixels();
  const Vec2 c = cam.principalPoint();
  report.lamps.clear();
  report.eye_illuminance_lx = report.veiling_luminance_cd_m2 = 0.0;
  report.glow_seconds = report.glare_seconds = 0.0;
  t.glow.clear();
  t.glare.clear();
  const double q = std::clamp(meanCosine(fog.phase), 0.0, 0.99);

  // Per lamp: where it is, whether a surface hides it, its light towards the eye.
  const auto tGlow = std::chrono::steady_clock::now();
  for (std::size_t li = 0; li < scene.lamps.size() && li < enabled_.size(); ++li) {
    if (!enabled_[li]) continue;
    const SceneLamp& sl = scene.lamps[li];
    const Lamp& lamp = sl.lamp;
    const Vec3 toLamp = lamp.position_m - cam.position_m;
    const double R = glm::length(toLamp);
    if (!(R > 1e-6)) continue;
    const Vec3 eCam = camFromWorld * (toLamp / R);
    LampEffectsReport::Lamp rep;
    rep.name = sl.name;
    rep.distance_m = R;
    rep.optical_distance = kt * R;
    rep.intensity_cd = lamp.profile->intensity(glm::transpose(lamp.worldFromLamp) * (-toLamp / R));
    rep.eye_illuminance_lx = rep.intensity_cd * std::exp(-kt * R) / (R * R);
    // Hidden: its image is in the frame and the surface there is nearer than the lamp.
    bool visible = eCam.x > 0.0;
    if (visible) {
      const double x = c.x - f * eCam.y / eCam.x, y = c.y - f * eCam.z / eCam.x;
      if (x >= 0.0 && y >= 0.0 && x < cam.width && y < cam.height) {
        const std::size_t k = static_cast<std::size_t>(y) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(x);
        visible = !(static_cast<double>(surface.distance[k]) < 0.98 * R);
      }
    }
    rep.visible = visible && rep.intensity_cd > 0.0;
    Tables::Radial rad;
    for (int k = 0; k < 3; ++k) rad.e[k] = static_cast<float>(eCam[k]);
    rad.distance = static_cast<float>(R);
    if (rep.visible) report.eye_illuminance_lx += rep.eye_illuminance_lx;
    if (glare_.enabled && rep.visible) {
      for (int k = 0; k < 3; ++k) rad.color[k] = static_cast<float>(lamp.color[k] * rep.eye_illuminance_lx);
      rad.table = t.cieGlare.data();
      t.glare.push_back(rad);
      // At the image centre: the camera's +x.
      report.veiling_luminance_cd_m2 += rep.eye_illuminance_lx *
                                        veilingLuminancePerLux(std::acos(std::clamp(eCam.x, -1.0, 1.0)) * 180.0 / kPi,
                                                               glare_.age_years, glare_.pigmentation);
    }
    if (glow_.enabled && rep.visible && rep.optical_distance >= Apsf::minOpticalDistance()) {
      auto apsf = Apsf::build(rep.optical_distance, q);
      if (apsf) {
        rep.apsf_terms = apsf->terms();
        const double fade = std::clamp((rep.optical_distance - Apsf::minOpticalDistance()) /
                                           (glow_.fade_in - Apsf::minOpticalDistance() + 1e-12),
                                       0.0, 1.0);
        float* table = t.glowTables.data() + static_cast<std::size_t>(kNodes) * li;
        const double I = rep.intensity_cd, weight = fog.albedo * kt * I;
        for (int i = 0; i < kNodes; ++i) {
          const double s = sOfNode(i), theta = thetaOfS(s);
          const double cosT = std::cos(theta), sinT = std::sin(theta);
          // Single scattering of the same isotropic source along this sky ray (eq. 3, F table):
          // Ω K_t I e^{−K_t R cos θ} / (R sin θ) · [F(k, π/2) − F(k, θ − π/2)], k = K_t R sin θ.
          double single = std::numeric_limits<double>::infinity();
          if (sinT > 1e-9) {
            const double h = R * sinT, k = kt * h;
            single = weight * std::exp(-kt * R * cosT) / h *
                     (t.iso->lookup(k, std::numeric_limits<double>::infinity()) - t.iso->lookup(k, -cosT / sinT));
          }
          const double total = fog.albedo * apsf->radiance(cosT, I, kt);
          const double g = fade * std::max(0.0, total - single);
          table[i] = static_cast<float>(g);
          rep.glow_peak_cd_m2 = std::max(rep.glow_peak_cd_m2, g);
        }
        for (int k = 0; k < 3; ++k) rad.color[k] = static_cast<float>(lamp.color[k]);
        rad.table = table;
        t.glow.push_back(rad);
      }
    }
    report.lamps.push_back(rep);
  }

  // Per pixel: Σ over lamps of the radial tables at the pixel's half-chord to each lamp.
  auto fill = [&](const std::vector<Tables::Radial>& lamps, bool occlusion, std::vector<float>& out) {
    out.assign(3 * n, 0.0f);
    if (lamps.empty()) return;
    struct Job {
      const std::vector<Tables::Radial>* lamps;
      const SurfaceBuffers* surf;
      std::vector<float>* out;
      int w;
      double f, cx, cy;
      bool occlusion;
    } job{&lamps, &surface, &out, cam.width, f, c.x, c.y, occlusion};
    const Job* jp = &job;
    pool_->parallelFor(static_cast<std::size_t>(cam.height), [jp](std::size_t j) {
      const auto w = static_cast<std::size_t>(jp->w);
      float* row = jp->out->data() + 3 * w * j;
      const float* dist = jp->surf->distance.data() + w * j;
      const double b = (jp->cy - (static_cast<double>(j) + 0.5)) / jp->f;
      for (std::size_t i = 0; i < w; ++i) {
        const double a = (jp->cx - (static_cast<double>(i) + 0.5)) / jp->f;
        const double inv = 1.0 / std::sqrt(1.0 + a * a + b * b);
        const float wx = static_cast<float>(inv), wy = static_cast<float>(a * inv), wz = static_cast<float>(b * inv);
        for (const Tables::Radial& L : *jp->lamps) {
          float weight = 1.0f;
          if (jp->occlusion) {
            const float d = dist[i];
            weight = std::isinf(d) ? 1.0f : std::clamp((d - 0.5f * L.distance) / (0.5f * L.distance), 0.0f, 1.0f);
            if (weight <= 0.0f) continue;
          }
          const float vx = wx - L.e[0], vy = wy - L.e[1], vz = wz - L.e[2];
          const float s = 0.5f * std::sqrt(vx * vx + vy * vy + vz * vz);
          const float g = std::sqrt(std::min(s, 1.0f)) * static_cast<float>(kNodes - 1);
          const int k0 = std::min(static_cast<int>(g), kNodes - 2);
          const float tt = g - static_cast<float>(k0);
          const float v = weight * (L.table[k0] + tt * (L.table[k0 + 1] - L.table[k0]));
          row[3 * i] += v * L.color[0];
          row[3 * i + 1] += v * L.color[1];
          row[3 * i + 2] += v * L.color[2];
        }
      }
    });
  };
  if (glow_.enabled) fill(t.glow, true, glowOut);
  else glowOut.clear();
  report.glow_seconds = since(tGlow);
  const auto tGlare = std::chrono::steady_clock::now();
  if (glare_.enabled) fill(t.glare, false, glareOut);
  else glareOut.clear();
  report.glare_seconds = since(tGlare);
}

}  // namespace fogbeam
