// fogbeam — automatic exposure for the display mapping (toneMapSrgb8, packRgba8Srgb, `fogbeam
// view`): the EV at which a night drive in fog looks like one.
//
// The rule: a high percentile of luminance goes to a fixed display value.
//
//   L_ref = the luminance below which `percentile` (99.5 %) of the metered pixels lie, cd/m²
//   EV    = log2(display_x / L_ref), display_x = 4: L_ref shows at x = L·2^EV = 4, Reinhard
//           x/(1 + x) = 0.8, sRGB code 231 of 255; clamped to [min_ev, max_ev] = [−16, +6]
//
// Why this and not a log-average (Reinhard's "key"): a night frame in fog is mostly dark (unlit
// road, sky, trees at 0.005–0.1 cd/m²) with a bright veil in front of the low beams (0.5–20
// cd/m²) and lamp images of 1e4–1e6 cd/m² covering a few pixels. An average, even in log, is set
// by the dark majority: it lifts the dark road to mid-grey and pushes the veil into the
// Reinhard shoulder (the washed-out grey of EV 0). The eye at night adapts to the brightest
// extended field in view, the veil and the lit road; so the meter anchors on the bright end: the
// veil's brightest extended part lands at 0.8 of the display, below the shoulder, so its gradient
// and the beam pattern keep their structure (the rest of the veil spreads over the middle of the
// range), and everything darker keeps its ratio to it: the dark road stays dark. The brightest
// 0.5 % of the pixels (at 1280×720, 4 608 pixels: lamp images, their glare cores, glints) are
// left out, so that a few pixels of lamp cannot drive the exposure; they show white, as lamps
// should. A uniform frame shows at 0.8 (code 231) unless the clamp applies.
//
// The clamp: +6 EV is the most a frame is lifted: a frame whose brightest extended light is below
// 4·2^−6 = 1/16 cd/m² (deep mesopic: an unlit road without a veil) is not brightened further, so
// that an unlit night stays dark instead of becoming grey; an all-black frame gets +6. −16 EV
// (L_ref = 2.6e5 cd/m²: a frame filled by lamp faces) is the other end; neither is reached by a
// night scene.
//
// Cost: a histogram of luminance with 16 bins per octave from 2^−20 to 2^24 cd/m², indexed by the
// float's exponent and top four mantissa bits (no log); each bin keeps its smallest and largest
// value, so the percentile is interpolated inside the bin and is exact for a uniform frame
// (otherwise within the bin's width, < 0.09 EV). autoExposureEv meters every step-th pixel in
// both directions (meteringStep: at most 65 536 samples; 1280×720: every 4th, 57 600 samples),
// rows staggered so that a regular pattern is not aliased: ~0.1 ms at 1280×720.
//
// Temporal adaptation (ExposureAdaptation, for frame sequences: `replay`, the service's
// rgba8-srgb channels, `view`): exponential smoothing of the EV towards each frame's target,
//   EV ← target + (EV − target)·exp(−Δt/τ),
// with Δt the frame interval in seconds, so that it is frame-rate independent (two steps of Δt
// are one step of 2Δt). τ = 0.5 s when the EV goes down (the scene got brighter: oncoming
// headlamps; the eye's light adaptation is fast) and 1.0 s when it goes up (the scene got darker:
// recovery after they pass is slower); after τ, 63 % of a step is done, after 3τ 95 %. The first
// frame takes its target at once.
//
// Luminance of an RGB pixel: Rec. 709 weights (0.2126 R + 0.7152 G + 0.0722 B) of linear cd/m²;
// negative and NaN values count as black, +inf as brightest.
//
// Thread-safety: ExposureMeter and ExposureAdaptation are plain values (one owner at a time);
// autoExposureEv is a pure function.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace fogbeam {

struct AutoExposureOptions {
  /// Fraction of the metered pixels at or below the reference luminance; 1 − percentile of the
  /// brightest pixels are left out (lamp images).
  double percentile = 0.995;
  /// x = L_ref·2^EV the reference luminance is mapped to (Reinhard x/(1 + x) = 0.8).
  double display_x = 4.0;
  double min_ev = -16.0;  ///< EV range of the result
  double max_ev = 6.0;
};

/// A histogram of luminance (cd/m²), for one frame or several (a tiled view).
class ExposureMeter {
 public:
  static constexpr int kMinExponent = -20;  ///< lowest bin: 2^−20 cd/m²; below it: black
  static constexpr int kMaxExponent = 24;   ///< 2^24 cd/m² and above: the top bin
  static constexpr int kBinsPerOctave = 16;
  static constexpr int kBins = 2 + (kMaxExponent - kMinExponent) * kBinsPerOctave;

  ExposureMeter() { clear(); }
  void clear() noexcept;
  /// One sample: a luminance in cd/m².
  void add(float luminance) noexcept;
  /// Every step-th pixel of each step-th row of an RGB image (3 floats per pixel, linear cd/m²),
  /// rows staggered; step from meteringStep when 0.
  void addRgb(const float* rgb, int width, int height, int step = 0) noexcept;
  [[nodiscard]] std::uint64_t count() const noexcept { return count_; }
  /// The luminance below which a fraction q ∈ [0, 1] of the samples lie (0 when none, or when
  /// the rank falls among the black samples).
  [[nodiscard]] double percentileLuminance(double q) const noexcept;
  /// The automatic exposure of what was metered, EV (the rule above); max_ev when nothing was.
  [[nodiscard]] double ev(const AutoExposureOptions& o = {}) const noexcept;

 private:
  std::array<std::uint32_t, kBins> counts_{};
  std::array<float, kBins> lo_{}, hi_{};  // smallest and largest sample of each bin
  std::uint64_t count_ = 0;
};

/// The pixel step autoExposureEv meters a width × height frame with: at most 65 536 samples.
[[nodiscard]] int meteringStep(int width, int height) noexcept;

/// Luminance of a linear RGB pixel, cd/m² (Rec. 709 weights).
[[nodiscard]] inline float luminanceOf(float r, float g, float b) noexcept {
  return 0.2126f * r + 0.7152f * g + 0.0722f * b;
}

/// The automatic exposure of one frame: `rgb` holds width × height pixels, 3 floats each, linear
/// cd/m² (FrameLayers::composite). EV, within [o.min_ev, o.max_ev].
[[nodiscard]] double autoExposureEv(const float* rgb, int width, int height, const AutoExposureOptions& o = {});
[[nodiscard]] double autoExposureEv(const std::vector<float>& rgb, int width, int height,
                                    const AutoExposureOptions& o = {});

struct ExposureAdaptationOptions {
  double tau_down_s = 0.5;  ///< time constant when the EV decreases (the scene got brighter), s
  double tau_up_s = 1.0;    ///< time constant when the EV increases (the scene got darker), s
};

/// Eye-like adaptation of the exposure over a frame sequence (the smoothing above).
class ExposureAdaptation {
 public:
  explicit ExposureAdaptation(ExposureAdaptationOptions o = {}) : o_(o) {}
  /// The EV to use for a frame whose own target is `targetEv`, `dtSeconds` after the previous
  /// frame. The first call (or after reset) returns the target; dt ≤ 0 keeps the EV; a
  /// non-finite target is ignored.
  double update(double targetEv, double dtSeconds) noexcept;
  [[nodiscard]] double ev() const noexcept { return ev_; }
  [[nodiscard]] bool started() const noexcept { return started_; }
  /// Starts from `ev` (the first update then adapts from it instead of jumping).
  void startFrom(double ev) noexcept {
    ev_ = ev;
    started_ = true;
  }
  void reset() noexcept { started_ = false; }

 private:
  ExposureAdaptationOptions o_;
  double ev_ = 0.0;
  bool started_ = false;
};

}  // namespace fogbeam
