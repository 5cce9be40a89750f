#include <fogbeam/render/frame.hpp>

#include <algorithm>
#include <cmath>

namespace fogbeam {

void compositeFrame(const Medium& fog, const SurfaceBuffers& surface, const AirlightImage& airlight, FrameLayers& out,
                    const EffectLayers& effects) {
  out.width = surface.width;
  out.height = surface.height;
  const auto n = static_cast<std::size_t>(surface.width) * static_cast<std::size_t>(surface.height);
  out.composite.resize(3 * n);
  out.airlight.assign(airlight.rgb.begin(), airlight.rgb.end());
  out.surface.assign(surface.rgb.begin(), surface.rgb.end());
  out.overlay.resize(3 * n);
  out.transmittance.resize(n);
  out.distance.assign(surface.distance.begin(), surface.distance.end());
  // A layer of the wrong size (an effect switched on after the buffers were sized) is left out
  // rather than read out of bounds.
  auto usable = [&](const std::vector<float>* v) { return v != nullptr && v->size() == 3 * n; };
  const bool glow = usable(effects.glow), glare = usable(effects.glare);
  if (glow) out.glow.assign(effects.glow->begin(), effects.glow->end());
  else out.glow.clear();
  if (glare) out.glare.assign(effects.glare->begin(), effects.glare->end());
  else out.glare.clear();
  const double kt = fog.extinction_per_m;
  const auto ia = static_cast<float>(fog.ambient_cd_m2);
  for (std::size_t k = 0; k < n; ++k) {
    const float d = surface.distance[k];
    const float t = std::isinf(d) ? 0.0f : static_cast<float>(std::exp(-kt * static_cast<double>(d)));
    out.transmittance[k] = t;
    for (std::size_t c = 0; c < 3; ++c) {
      float front = airlight.rgb[3 * k + c];
      if (glow) front += (*effects.glow)[3 * k + c];
      if (glare) front += (*effects.glare)[3 * k + c];
      out.composite[3 * k + c] = surface.rgb[3 * k + c] + front;
      out.overlay[3 * k + c] = front + ia * (1.0f - t);
    }
  }
}

std::vector<std::uint8_t> toneMapSrgb8(const std::vector<float>& rgb, double exposureEv) {
  const double scale = std::exp2(exposureEv);
  std::vector<std::uint8_t> out(rgb.size());
  for (std::size_t k = 0; k < rgb.size(); ++k) {
    const double x = std::max(0.0, static_cast<double>(rgb[k]) * scale);
    const double lin = x / (1.0 + x);
    const double s = lin <= 0.0031308 ? 12.92 * lin : 1.055 * std::pow(lin, 1.0 / 2.4) - 0.055;
    out[k] = static_cast<std::uint8_t>(std::clamp(std::lround(255.0 * s), 0L, 255L));
  }
  return out;
}

}  // namespace fogbeam
