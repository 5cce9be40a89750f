// fogbeam — automatic exposure (exposure.hpp: the rule, its units and its cost).
#include <fogbeam/render/exposure.hpp>

#include <algorithm>
#include <bit>
#include <cmath>

namespace fogbeam {

namespace {

constexpr int kTop = ExposureMeter::kBins - 1;
constexpr std::uint64_t kMaxSamples = 65536;

/// 0: black (below 2^kMinExponent, negative, NaN); kTop: 2^kMaxExponent and above (+inf); else
/// 16 bins per octave from the float's exponent and its top four mantissa bits.
int binOf(float y) noexcept {
  constexpr float kFloor = 1.0f / static_cast<float>(1u << -ExposureMeter::kMinExponent);
  if (!(y >= kFloor)) return 0;
  const auto bits = std::bit_cast<std::uint32_t>(y);
  const int e = static_cast<int>(bits >> 23) - 127;
  if (e >= ExposureMeter::kMaxExponent) return kTop;
  return 1 + (e - ExposureMeter::kMinExponent) * ExposureMeter::kBinsPerOctave + static_cast<int>((bits >> 19) & 15u);
}

}  // namespace

void ExposureMeter::clear() noexcept {
  counts_.fill(0);
  count_ = 0;
}

void ExposureMeter::add(float luminance) noexcept {
  const auto b = static_cast<std::size_t>(binOf(luminance));
  if (counts_[b] == 0) {
    lo_[b] = hi_[b] = luminance;
  } else {
    lo_[b] = std::min(lo_[b], luminance);
    hi_[b] = std::max(hi_[b], luminance);
  }
  ++counts_[b];
  ++count_;
}

void ExposureMeter::addRgb(const float* rgb, int width, int height, int step) noexcept {
  if (width <= 0 || height <= 0) return;
  if (step <= 0) step = meteringStep(width, height);
  int k = 0;
  for (int j = step / 2; j < height; j += step, ++k) {
    const float* row = rgb + 3 * static_cast<std::size_t>(j) * static_cast<std::size_t>(width);
    for (int i = k % step; i < width; i += step) {
      const float* p = row + 3 * static_cast<std::size_t>(i);
      add(luminanceOf(p[0], p[1], p[2]));
    }
  }
}

double ExposureMeter::percentileLuminance(double q) const noexcept {
  if (count_ == 0) return 0.0;
  const double rank = std::clamp(q, 0.0, 1.0) * static_cast<double>(count_);
  double before = 0.0;
  for (int b = 0; b < kBins; ++b) {
    const auto c = static_cast<double>(counts_[static_cast<std::size_t>(b)]);
    if (c == 0.0) continue;
    if (before + c >= rank || b == kTop) {
      if (b == 0) return 0.0;  // among the black samples
      const double lo = lo_[static_cast<std::size_t>(b)], hi = hi_[static_cast<std::size_t>(b)];
      if (!std::isfinite(hi)) return std::isfinite(lo) ? lo : std::ldexp(1.0, kMaxExponent);
      // Samples spread evenly in rank between the bin's smallest and largest value.
      const double f = std::clamp((rank - before) / c, 0.0, 1.0);
      return lo + f * (hi - lo);
    }
    before += c;
  }
  return 0.0;
}

double ExposureMeter::ev(const AutoExposureOptions& o) const noexcept {
  const double ref = percentileLuminance(o.percentile);
  if (!(ref > 0.0)) return o.max_ev;
  return std::clamp(std::log2(o.display_x / ref), o.min_ev, o.max_ev);
}

int meteringStep(int width, int height) noexcept {
  if (width <= 0 || height <= 0) return 1;
  int step = 1;
  auto samples = [&](int s) {
    return static_cast<std::uint64_t>((width + s - 1) / s) * static_cast<std::uint64_t>((height + s - 1) / s);
  };
  while (samples(step) > kMaxSamples) ++step;
  return step;
}

double autoExposureEv(const float* rgb, int width, int height, const AutoExposureOptions& o) {
  ExposureMeter m;
  m.addRgb(rgb, width, height);
  return m.ev(o);
}

double autoExposureEv(const std::vector<float>& rgb, int width, int height, const AutoExposureOptions& o) {
  if (width <= 0 || height <= 0 || rgb.size() < 3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    return o.max_ev;
  return autoExposureEv(rgb.data(), width, height, o);
}

double ExposureAdaptation::update(double targetEv, double dtSeconds) noexcept {
  if (!std::isfinite(targetEv)) return ev_;
  if (!started_) {
    ev_ = targetEv;
    started_ = true;
    return ev_;
  }
  if (!(dtSeconds > 0.0)) return ev_;
  const double tau = targetEv < ev_ ? o_.tau_down_s : o_.tau_up_s;
  ev_ = targetEv + (ev_ - targetEv) * std::exp(-dtSeconds / tau);
  return ev_;
}

}  // namespace fogbeam
