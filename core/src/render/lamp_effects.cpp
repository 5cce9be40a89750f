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

// Φ[L] R² / (2π) pieces: the trapezoid rule in θ over the nodes of f(θ) = L cos θ sin θ, the
// first interval [0, θ₁] as f(θ₁) θ₁ (L sin θ tends to a constant as θ → 0: S₁ ∝ 1/h).
double fluxOver(const std::vector<double>& theta, const std::vector<double>& L) {
  double sum = 0.0;
  auto f = [&](std::size_t i) { return L[i] * std::cos(theta[i]) * std::sin(theta[i]); };
  if (theta.size() > 1) sum += f(1) * theta[1];
  for (std::size_t i = 2; i < theta.size(); ++i) sum += 0.5 * (f(i - 1) + f(i)) * (theta[i] - theta[i - 1]);
  return 2.0 * kPi * sum;
}

}  // namespace

Result<GlowCurve> glowCurve(const kernels::IsoTable& table, const Medium& fog, double distance_m, int nodes) {
  const double kt = fog.extinction_per_m, R = distance_m, T = kt * R;
  if (nodes < 16) return Error{"glow: at least 16 nodes"};
  const double q = std::clamp(meanCosine(fog.phase), 0.0, 0.99);
  auto apsf = Apsf::build(T, q);
  if (!apsf) return apsf.error();
  GlowCurve c;
  c.terms = apsf->terms();
  const auto n = static_cast<std::size_t>(nodes);
  c.theta.resize(n);
  c.single.resize(n);
  c.apsf.resize(n);
  c.glow.assign(n, 0.0);
  std::vector<double> excess(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    const double u = static_cast<double>(i) / static_cast<double>(n - 1);
    const double theta = 2.0 * std::asin(std::min(u * u, 1.0));
    c.theta[i] = theta;
    const double cosT = std::cos(theta), sinT = std::sin(theta);
    // S₁ for the sky ray at θ from the source (eq. 3 with the F table, Ω = 1, I = 1 cd):
    // K_t e^{−K_t R cos θ} / h · [F(k, π/2) − F(k, θ0)], h = R sin θ, k = K_t h, θ0 = θ − π/2.
    // Rays looking away from the source (θ0 > 0): the tail integral directly (the table's
    // difference of two O(1) values would be amplified by e^{K_t R |cos θ|}).
    // At θ = 0 (towards the source) S₁ ~ 1/θ: +inf; at θ = π it is finite and weighs nothing
    // in the flux (sin θ = 0) nor on screen: 0.
    double single = theta < 0.5 * kPi ? std::numeric_limits<double>::infinity() : 0.0;
    if (sinT > 1e-12) {
      const double h = R * sinT, k = kt * h, th0 = theta - 0.5 * kPi;
      const double bracket = th0 > 0.0 ? table.tailIntegral(k, th0)
                                       : table.lookup(k, std::numeric_limits<double>::infinity()) -
                                             table.lookup(k, -cosT / sinT);
      single = kt * std::exp(-kt * R * cosT) / h * std::max(bracket, 0.0);
    }
    c.single[i] = single;
    c.apsf[i] = apsf->radiance(cosT, 1.0, kt);
    excess[i] = std::max(0.0, c.apsf[i] - single);
  }
  // Energy (header comment): R² Φ[S₁ + λ·excess] = 1 − e^{−T} for 1 cd; the multiple part then
  // × Ω², the single part × Ω (as the airlight layer has it).
  const double R2 = R * R;
  const double singleFlux1 = R2 * fluxOver(c.theta, c.single);
  const double excessFlux = R2 * fluxOver(c.theta, excess);
  const double multipleFlux1 = (1.0 - std::exp(-T)) - singleFlux1;
  const double omega = fog.albedo;
  c.single_flux = omega * singleFlux1;
  if (multipleFlux1 > 0.0 && excessFlux > 0.0) {
    c.scale = multipleFlux1 / excessFlux;
    for (std::size_t i = 0; i < n; ++i) c.glow[i] = omega * omega * c.scale * excess[i];
    c.multiple_flux = omega * omega * multipleFlux1;
  }
  return c;
}

double glowSourceIntensity(const Lamp& lamp, const Vec3& eye, double opticalDistance, double q) {
  const Vec3 d = eye - lamp.position_m;
  const double len = glm::length(d);
  if (!(len > 0.0)) return 0.0;
  const Mat3 lampFromWorld = glm::transpose(lamp.worldFromLamp);
  const Vec3 axis = lampFromWorld * (d / len);  // towards the eye, lamp frame
  const double cosPsi = std::max(std::pow(std::clamp(q, 0.0, 1.0), opticalDistance), 0.5);
  // Equal solid angles: 8 bands uniform in cos ψ' × 16 azimuths, one sample at each band's
  // middle (a lamp's profile is smooth on this scale; the cone is ≥ 6° wide for T ≥ 1.1, q ≤ 0.99).
  const Vec3 helper = std::abs(axis.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
  const Vec3 u = glm::normalize(glm::cross(axis, helper)), v = glm::cross(axis, u);
  constexpr int kBands = 8, kAzimuths = 16;
  double sum = 0.0;
  for (int b = 0; b < kBands; ++b) {
    const double c = 1.0 - (static_cast<double>(b) + 0.5) / kBands * (1.0 - cosPsi);
    const double sn = std::sqrt(std::max(0.0, 1.0 - c * c));
    for (int a = 0; a < kAzimuths; ++a) {
      const double phi = 2.0 * kPi * (static_cast<double>(a) + 0.5 * (b & 1)) / kAzimuths;
      sum += lamp.profile->intensity(c * axis + sn * (std::cos(phi) * u + std::sin(phi) * v));
    }
  }
  return sum / (kBands * kAzimuths);
}

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
  // The single-scattering table of the frame's phase function (the fog may change between
  // frames): IsoTable::get returns the cached one while the phase stays (a map look-up), and
  // builds a new one (~0.2 s) when it changes.
  if (glow_.enabled) t.iso = kernels::IsoTable::get(fog.phase);

  // The scene may hold more lamps than at build() (traffic arriving): they start switched on;
  // the buffers grow only then, so a steady scene allocates nothing per frame.
  if (enabled_.size() < scene.lamps.size()) enabled_.resize(scene.lamps.size(), 1);
  if (t.glowTables.size() < static_cast<std::size_t>(kNodes) * scene.lamps.size())
    t.glowTables.resize(static_cast<std::size_t>(kNodes) * scene.lamps.size());

  // Per lamp: where it is, whether a surface hides it, its light towards the eye.
  const auto tGlow = std::chrono::steady_clock::now();
  for (std::size_t li = 0; li < scene.lamps.size(); ++li) {
    if (!enabled_[li]) continue;
    const SceneLamp& sl = scene.lamps[li];
    // The driver's own lamps (mount = vehicle) sit ahead of and below the eye, behind the
    // bonnet and inside their housings: their direct light does not reach the eye, so they have
    // neither glow nor glare (their veil is the airlight layer's). Their profiles may still hold
    // candela values backwards (a measured file's rear hemisphere), which would otherwise count.
    if (sl.mount == LampMount::Vehicle) continue;
    const Lamp& lamp = sl.lamp;
    const Vec3 toLamp = lamp.position_m - cam.position_m;
    const double R = glm::length(toLamp);
    if (!(R > 1e-6)) continue;
    const Vec3 eCam = camFromWorld * (toLamp / R);
    LampEffectsReport::Lamp rep;
    rep.name = sl.name;
    rep.distance_m = R;
    rep.optical_distance = kt * R;
    // The layers carry colour × the profile's values; the report gives luminous figures, the
    // profile's × the colour's mean (1 for white; the point lamps of an aperture carry their
    // quadrature weight in the colour, so theirs add up to the lamp's).
    const double luminous = (lamp.color.x + lamp.color.y + lamp.color.z) / 3.0;
    const double intensity = lamp.profile->intensity(glm::transpose(lamp.worldFromLamp) * (-toLamp / R));
    const double illuminance = intensity * std::exp(-kt * R) / (R * R);  // profile's, lux
    rep.intensity_cd = luminous * intensity;
    rep.eye_illuminance_lx = luminous * illuminance;
    // Hidden: its image is in the frame and the surfaces there are nearer than the lamp. The
    // 2 × 2 pixels around the image point are read, and one that reaches the lamp keeps it
    // visible: a distant lamp is smaller than a pixel, whose centre ray may meet the road just
    // in front of it (at 104 m a 320 px wide, 60° view's pixel spans 0.34 m, half a low beam's
    // height above the road), and a single pixel made lamps flicker between hidden and seen.
    bool visible = eCam.x > 0.0;
    if (visible) {
      const double x = c.x - f * eCam.y / eCam.x, y = c.y - f * eCam.z / eCam.x;
      if (x >= 0.0 && y >= 0.0 && x < cam.width && y < cam.height) {
        const int i0 = std::clamp(static_cast<int>(std::floor(x - 0.5)), 0, cam.width - 1);
        const int j0 = std::clamp(static_cast<int>(std::floor(y - 0.5)), 0, cam.height - 1);
        bool reaches = false;
        for (int j = j0; j <= std::min(j0 + 1, cam.height - 1); ++j)
          for (int i = i0; i <= std::min(i0 + 1, cam.width - 1); ++i) {
            const std::size_t k = static_cast<std::size_t>(j) * static_cast<std::size_t>(cam.width) + static_cast<std::size_t>(i);
            reaches = reaches || !(static_cast<double>(surface.distance[k]) < 0.98 * R);
          }
        visible = reaches;
      }
    }
    rep.visible = visible && intensity > 0.0;
    Tables::Radial rad;
    for (int k = 0; k < 3; ++k) rad.e[k] = static_cast<float>(eCam[k]);
    rad.distance = static_cast<float>(R);
    if (rep.visible) report.eye_illuminance_lx += rep.eye_illuminance_lx;
    if (glare_.enabled && rep.visible) {
      for (int k = 0; k < 3; ++k) rad.color[k] = static_cast<float>(lamp.color[k] * illuminance);
      rad.table = t.cieGlare.data();
      t.glare.push_back(rad);
      // At the image centre: the camera's +x.
      report.veiling_luminance_cd_m2 += rep.eye_illuminance_lx *
                                        veilingLuminancePerLux(std::acos(std::clamp(eCam.x, -1.0, 1.0)) * 180.0 / kPi,
                                                               glare_.age_years, glare_.pigmentation);
    }
    if (glow_.enabled && rep.visible && rep.optical_distance >= Apsf::minOpticalDistance()) {
      auto curve = glowCurve(*t.iso, fog, R, kNodes);
      if (curve) {
        rep.apsf_terms = curve->terms;
        rep.glow_scale = curve->scale;
        const double total = curve->single_flux + curve->multiple_flux;
        rep.glow_share = total > 0.0 ? curve->multiple_flux / total : 0.0;
        const double source = glowSourceIntensity(lamp, cam.position_m, rep.optical_distance, q);
        rep.glow_source_cd = luminous * source;
        const double fade = std::clamp((rep.optical_distance - Apsf::minOpticalDistance()) /
                                           (glow_.fade_in - Apsf::minOpticalDistance() + 1e-12),
                                       0.0, 1.0);
        float* table = t.glowTables.data() + static_cast<std::size_t>(kNodes) * li;
        for (int i = 0; i < kNodes; ++i) {
          const double g = fade * source * curve->glow[static_cast<std::size_t>(i)];
          table[i] = static_cast<float>(g);
          rep.glow_peak_cd_m2 = std::max(rep.glow_peak_cd_m2, luminous * g);
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
