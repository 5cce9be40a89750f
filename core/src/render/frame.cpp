#include <fogbeam/render/frame.hpp>

#include <algorithm>
#include <cmath>

namespace fogbeam {

void compositeFrame(const Medium& fog, const SurfaceBuffers& surface, const AirlightImage& airlight, FrameLayers& out) {
  out.width = surface.width;
  out.height = surface.height;
  const auto n = static_cast<std::size_t>(surface.width) * static_cast<std::size_t>(surface.height);
  out.composite.resize(3 * n);
  out.airlight.assign(airlight.rgb.begin(), airlight.rgb.end());
  out.surface.assign(surface.rgb.begin(), surface.rgb.end());
  out.overlay.resize(3 * n);
  out.transmittance.resize(n);
  out.distance.assign(surface.distance.begin(), surface.distance.end());
  const double kt = fog.extinction_per_m;
  const auto ia = static_cast<float>(fog.ambient_cd_m2);
  for (std::size_t k = 0; k < n; ++k) {
    const float d = surface.distance[k];
    const float t = std::isinf(d) ? 0.0f : static_cast<float>(std::exp(-kt * static_cast<double>(d)));
    out.transmittance[k] = t;
    for (std::size_t c = 0; c < 3; ++c) {
      out.composite[3 * k + c] = surface.rgb[3 * k + c] + airlight.rgb[3 * k + c];
      out.overlay[3 * k + c] = airlight.rgb[3 * k + c] + ia * (1.0f - t);
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
