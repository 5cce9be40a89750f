// Automatic exposure (render/exposure.hpp): a night frame in fog (dark road, bright veil, tiny
// lamp images) shown through toneMapSrgb8 at the automatic EV keeps the veil's structure below
// the shoulder and the road dark; lamp images do not move it; a uniform frame shows at the
// documented display value; black frames give the clamp; the temporal adaptation has the
// documented time constants and does not depend on the frame rate.
#include <fogbeam/render/exposure.hpp>
#include <fogbeam/render/frame.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace fogbeam {
namespace {

constexpr int kW = 1280, kH = 720;

struct Pixel {
  int i, j;
};

/// A night frame in fog: everything at a dark 0.02 cd/m² (unlit road, sky), a veil in front of
/// the low beams over the lower middle quarter of the frame whose luminance rises geometrically
/// from 1 cd/m² at its top to 20 cd/m² at its bottom (the range of the shipped night_road
/// scene's veil), and two 3×3 lamp images at 1e5 cd/m². Records each group's pixels.
struct NightFrame {
  std::vector<float> rgb = std::vector<float>(3 * static_cast<std::size_t>(kW) * kH, 0.02f);
  std::vector<Pixel> dark, veil, lamps;

  NightFrame() {
    for (int j = 0; j < kH; ++j)
      for (int i = 0; i < kW; ++i) {
        const bool inVeil = j >= kH / 2 && i >= kW / 4 && i < 3 * kW / 4;
        if (inVeil) {
          const double f = static_cast<double>(j - kH / 2) / (kH / 2 - 1);
          set(i, j, static_cast<float>(std::pow(20.0, f)));
          veil.push_back({i, j});
        } else {
          dark.push_back({i, j});
        }
      }
    for (const Pixel c : {Pixel{500, 300}, Pixel{780, 300}})
      for (int dj = -1; dj <= 1; ++dj)
        for (int di = -1; di <= 1; ++di) {
          set(c.i + di, c.j + dj, 1e5f);
          lamps.push_back({c.i + di, c.j + dj});
          std::erase_if(dark, [&](const Pixel& p) { return p.i == c.i + di && p.j == c.j + dj; });
        }
  }
  void set(int i, int j, float l) {
    const std::size_t k = 3 * (static_cast<std::size_t>(j) * kW + static_cast<std::size_t>(i));
    rgb[k] = rgb[k + 1] = rgb[k + 2] = l;
  }
};

/// The 8-bit display codes (green channel; the frames are grey) of a pixel group at `ev`.
std::vector<int> codes(const std::vector<float>& rgb, const std::vector<Pixel>& group, double ev) {
  const std::vector<std::uint8_t> bytes = toneMapSrgb8(rgb, ev);
  std::vector<int> out;
  for (const Pixel& p : group) out.push_back(bytes[3 * (static_cast<std::size_t>(p.j) * kW + static_cast<std::size_t>(p.i)) + 1]);
  std::sort(out.begin(), out.end());
  return out;
}

TEST(AutoExposure, NightFrameKeepsTheVeilsStructureAndTheRoadDark) {
  const NightFrame f;
  const double ev = autoExposureEv(f.rgb, kW, kH);
  ASSERT_TRUE(std::isfinite(ev));
  const std::vector<int> veil = codes(f.rgb, f.veil, ev), dark = codes(f.rgb, f.dark, ev), lamps = codes(f.rgb, f.lamps, ev);
  // The veil: not clipped (its brightest rows below the Reinhard shoulder, < 240 of 255), its
  // gradient spread over more than a third of the range (structure, not grey mush), its middle
  // in the upper middle of the range.
  EXPECT_LT(veil.back(), 240) << "EV " << ev;
  EXPECT_GE(veil.back() - veil.front(), 96) << "EV " << ev;
  EXPECT_GE(veil[veil.size() / 2], 128) << "EV " << ev;
  EXPECT_LE(veil[veil.size() / 2], 224) << "EV " << ev;
  // The dark road stays dark (below an eighth of the range); the lamp images show white.
  EXPECT_LE(dark.back(), 32) << "EV " << ev;
  EXPECT_GE(lamps.front(), 250) << "EV " << ev;

  // The old default, EV 0, fails the same criteria (washed out): the veil in the shoulder, the
  // road lifted.
  const std::vector<int> veil0 = codes(f.rgb, f.veil, 0.0), dark0 = codes(f.rgb, f.dark, 0.0);
  EXPECT_TRUE(veil0.back() >= 240 || veil0.back() - veil0.front() < 96 || dark0.back() > 32);
}

TEST(AutoExposure, LampImagesDoNotDriveTheExposure) {
  NightFrame f;
  const double before = autoExposureEv(f.rgb, kW, kH);
  ExposureMeter allPixels;
  allPixels.addRgb(f.rgb.data(), kW, kH, 1);
  const double beforeAll = allPixels.ev();
  // 20 more pixels of lamp at 1e6 cd/m², scattered over the frame (some on metered pixels).
  for (int k = 0; k < 20; ++k) f.set(37 + 61 * k, 40 + 33 * k, 1e6f);
  const double after = autoExposureEv(f.rgb, kW, kH);
  allPixels.clear();
  allPixels.addRgb(f.rgb.data(), kW, kH, 1);
  EXPECT_LT(std::abs(after - before), 0.1) << before << " → " << after;
  EXPECT_LT(std::abs(allPixels.ev() - beforeAll), 0.1) << beforeAll << " → " << allPixels.ev();
  // Whereas a bright area of 2 % of the frame (not a lamp image: an extended light) does move it.
  for (int j = 0; j < 72; ++j)
    for (int i = 0; i < 256; ++i) f.set(i, j, 1e3f);
  EXPECT_LT(autoExposureEv(f.rgb, kW, kH), before - 3.0);
}

TEST(AutoExposure, UniformFrameShowsAtTheDocumentedDisplayValue) {
  // L·2^EV = display_x = 4 → Reinhard 0.8 → sRGB 0.906 → code 231, whatever the luminance.
  for (const float l : {0.1f, 0.5f, 3.0f, 100.0f, 2.5e4f}) {
    const std::vector<float> rgb(3 * 64 * 36, l);
    const double ev = autoExposureEv(rgb, 64, 36);
    EXPECT_NEAR(ev, std::log2(4.0 / static_cast<double>(l)), 1e-6) << l;
    const std::vector<std::uint8_t> bytes = toneMapSrgb8(rgb, ev);
    EXPECT_EQ(bytes[0], 231) << l;
  }
  // Darker than 1/16 cd/m²: the clamp at +6 EV (not lifted further; shows darker).
  const std::vector<float> dim(3 * 64 * 36, 0.01f);
  EXPECT_EQ(autoExposureEv(dim, 64, 36), 6.0);
  EXPECT_LT(toneMapSrgb8(dim, 6.0)[0], 231);
}

TEST(AutoExposure, BlackAndBrokenFramesGiveAFiniteClampedEv) {
  const AutoExposureOptions o;
  EXPECT_EQ(autoExposureEv(std::vector<float>(3 * 1280 * 720, 0.0f), 1280, 720), o.max_ev);
  EXPECT_EQ(autoExposureEv(std::vector<float>(3 * 16 * 9, -1.0f), 16, 9), o.max_ev);
  EXPECT_EQ(autoExposureEv(std::vector<float>(3 * 16 * 9, std::numeric_limits<float>::quiet_NaN()), 16, 9), o.max_ev);
  EXPECT_EQ(autoExposureEv(std::vector<float>(3 * 16 * 9, std::numeric_limits<float>::infinity()), 16, 9), o.min_ev);
  EXPECT_EQ(autoExposureEv(std::vector<float>(3 * 16 * 9, 1e30f), 16, 9), o.min_ev);
  EXPECT_EQ(autoExposureEv(std::vector<float>{}, 0, 0), o.max_ev);
  EXPECT_EQ(autoExposureEv(std::vector<float>(5, 1.0f), 16, 9), o.max_ev);  // too short: not read
}

TEST(AutoExposure, PercentileIsWithinABinsWidth) {
  ExposureMeter m;
  for (int k = 1; k <= 10000; ++k) m.add(0.001f * static_cast<float>(k));  // 0.001 … 10 cd/m²
  EXPECT_EQ(m.count(), 10000u);
  for (const double q : {0.1, 0.5, 0.9, 0.995}) {
    const double want = 10.0 * q;
    EXPECT_NEAR(m.percentileLuminance(q), want, want * 0.0625) << q;  // a bin is 1/16 of an octave
  }
  EXPECT_NEAR(m.percentileLuminance(1.0), 10.0, 1e-6);
  EXPECT_NEAR(m.percentileLuminance(0.0), 0.001, 1e-9);
}

TEST(AutoExposure, MetersASubsampleOfLargeFrames) {
  // The cost: at most 65 536 samples; 1280×720 every 4th pixel and row.
  EXPECT_EQ(meteringStep(1280, 720), 4);
  EXPECT_EQ(meteringStep(320, 180), 1);
  EXPECT_EQ(meteringStep(7680, 4320), 23);
  const NightFrame f;
  ExposureMeter m;
  m.addRgb(f.rgb.data(), kW, kH);
  EXPECT_EQ(m.count(), 57600u);
  // The subsample meters what the whole frame does (the veil's percentile, within a bin).
  ExposureMeter all;
  all.addRgb(f.rgb.data(), kW, kH, 1);
  EXPECT_NEAR(m.ev(), all.ev(), 0.1);
  const auto t0 = std::chrono::steady_clock::now();
  constexpr int kRuns = 20;
  double sink = 0.0;
  for (int r = 0; r < kRuns; ++r) sink += autoExposureEv(f.rgb, kW, kH);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() / kRuns;
  EXPECT_TRUE(std::isfinite(sink));
  RecordProperty("ms_per_1280x720_frame", std::to_string(ms));
  std::printf("autoExposureEv at 1280x720: %.3f ms\n", ms);
}

TEST(ExposureAdaptation, FirstFrameTakesItsTarget) {
  ExposureAdaptation a;
  EXPECT_FALSE(a.started());
  EXPECT_EQ(a.update(-2.5, 0.0), -2.5);
  EXPECT_TRUE(a.started());
  EXPECT_EQ(a.update(1.0, 0.0), -2.5);  // no time passed: no change
  EXPECT_EQ(a.update(std::numeric_limits<double>::quiet_NaN(), 0.1), -2.5);
  a.reset();
  EXPECT_EQ(a.update(3.0, 0.1), 3.0);
}

/// EV after `seconds` of frames every `dt` seconds towards a constant `target`, from `from`.
double adaptFor(double from, double target, double seconds, double dt) {
  ExposureAdaptation a;
  a.startFrom(from);
  const int n = static_cast<int>(std::lround(seconds / dt));
  double ev = from;
  for (int k = 0; k < n; ++k) ev = a.update(target, dt);
  return ev;
}

TEST(ExposureAdaptation, ConvergesWithTheDocumentedTimeConstants) {
  const ExposureAdaptationOptions o;
  EXPECT_EQ(o.tau_down_s, 0.5);
  EXPECT_EQ(o.tau_up_s, 1.0);
  // Brighter scene (EV goes down 4): after τ_down, 1/e of the step is left; after 5τ < 1 %.
  EXPECT_NEAR(adaptFor(0.0, -4.0, 0.5, 1.0 / 60), -4.0 + 4.0 * std::exp(-1.0), 1e-9);
  EXPECT_NEAR(adaptFor(0.0, -4.0, 2.5, 1.0 / 60), -4.0, 4.0 * 0.01);
  // Darker scene (EV goes up 3): τ_up.
  EXPECT_NEAR(adaptFor(-4.0, -1.0, 1.0, 1.0 / 60), -1.0 - 3.0 * std::exp(-1.0), 1e-9);
  EXPECT_NEAR(adaptFor(-4.0, -1.0, 0.5, 1.0 / 60), -1.0 - 3.0 * std::exp(-0.5), 1e-9);
  // Half a step is not done in 0.1 s: no flicker from one frame's change.
  EXPECT_GT(adaptFor(0.0, -4.0, 0.1, 1.0 / 60), -2.0);
}

TEST(ExposureAdaptation, IsFrameRateIndependent) {
  for (const double target : {-6.0, 2.0}) {
    const double at60 = adaptFor(-2.0, target, 0.5, 1.0 / 60);
    EXPECT_NEAR(adaptFor(-2.0, target, 0.5, 1.0 / 10), at60, 1e-9) << target;
    EXPECT_NEAR(adaptFor(-2.0, target, 0.5, 1.0 / 144), at60, 1e-9) << target;
    EXPECT_NEAR(adaptFor(-2.0, target, 0.5, 0.5), at60, 1e-9) << target;
  }
}

}  // namespace
}  // namespace fogbeam
