// `fogbeam validate --path-tracer` (plugin/cli/cmd_validate.hpp, compareRings): a small run of the
// comparison of fogbeam's single scattering and glow with the all-orders path tracer in rings
// about a lamp in view. First the plumbing: the path tracer's single scattering estimates exactly
// the integral that fogbeam's airlight layer evaluates, over the same pixel centres (camera rays,
// ring membership, units), so the two must agree within the Monte Carlo error (3σ) plus 1 % (the
// accurate method's own error bound is 0.5 % at p95). Then the glow model: single + glow within
// issue 18's 15 % of all orders.
#include "../../plugin/cli/cmd_validate.hpp"
#include "test_scale.hpp"

#include <fogbeam/physics/photometry_io.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace fogbeam::cli {
namespace {

TEST(ValidatePathTracer, PathTracerSingleScatteringMatchesFogbeamsInEveryRing) {
  auto pool = std::make_shared<ThreadPool>(2);
  const RingComparisonCase c{"HG 0.85, K_t R = 1.8", HenyeyGreensteinPhase{0.85}, 1.8};
  // 151 px over 35°: 0.23° pixels, ~40 pixel centres in the 0.5–1° ring.
  auto res = compareRings(c, 8000, 7, pool, 151);
  ASSERT_TRUE(res.has_value()) << res.error().message;
  EXPECT_TRUE(res->lamp_visible);
  EXPECT_NEAR(res->distance_m, 30.0, 1e-9);
  ASSERT_EQ(res->rings.size(), comparisonRingsDeg().size() + 1);
  std::size_t inRings = 0;
  for (const RingFigures& f : res->rings) {
    std::printf("  ring %4.1f-%4.1f: %6zu px, fogbeam single %.4g glow %.4g; path tracer single %.4g +- %.2g, all %.4g +- %.2g"
                "; ratio %.3f\n",
                f.lo_deg, f.hi_deg, f.pixels, f.single, f.glow, f.pt_single.mean, f.pt_single.std_error, f.pt_all.mean,
                f.pt_all.std_error, f.ratio());
    ASSERT_GT(f.pixels, 20u);
    // The plumbing: the same integral over the same pixels.
    EXPECT_LT(std::abs(f.pt_single.mean - f.single), 3.0 * f.pt_single.std_error + 0.01 * f.single)
        << f.lo_deg << "-" << f.hi_deg;
    // So that 3σ is a real bound in the rings (the frame's pixels span 0.5° to 24°: its σ is
    // larger, and only the agreement is checked there).
    if (std::isfinite(f.hi_deg)) {
      EXPECT_LT(f.pt_single.std_error, 0.03 * f.single) << f.lo_deg;
    }
    // Multiple scattering adds light in every ring (at K_t R = 1.8 it is 25 % at 0.5–1°).
    EXPECT_GT(f.pt_all.mean - f.pt_single.mean, 3.0 * f.pt_all.std_error) << f.lo_deg;
    if (std::isfinite(f.hi_deg)) inRings += f.pixels;
  }
  // The rings' pixel counts add up to the frame's within 16°, and each ring's share of the
  // image is about its solid angle (pixels of (35°/151)² each, to 10 %: pixel-centre counting).
  EXPECT_LT(inRings, res->rings.back().pixels);
  const double pixelSr = std::pow(2.0 * std::tan(radians(17.5)) / 151.0, 2.0);
  for (std::size_t r = 0; r + 1 < res->rings.size(); ++r) {
    const RingFigures& f = res->rings[r];
    const double sr = 2.0 * kPi * (std::cos(radians(f.lo_deg)) - std::cos(radians(f.hi_deg)));
    EXPECT_NEAR(static_cast<double>(f.pixels) * pixelSr / sr, 1.0, 0.1) << f.lo_deg;
  }
  // The glow layer (multiple-scattering tables, the default model) holds light in every ring,
  // and single + glow is the all-orders light within issue 18's 15 % (plus 3σ of the path tracer).
  for (const RingFigures& f : res->rings) {
    EXPECT_GT(f.glow, 0.0) << f.lo_deg;
    EXPECT_LT(std::abs(f.single + f.glow - f.pt_all.mean), 0.15 * f.pt_all.mean + 3.0 * f.pt_all.std_error) << f.lo_deg;
  }
}

// Single + glow against all orders in a thicker fog, another phase function and albedo 0.9:
// within issue 18's 15 % + 3σ in every ring and over the frame. The path tracer's paths per ring
// are fewer than `fogbeam validate --path-tracer`'s (σ up to 10 % here).
TEST(ValidatePathTracer, SingleAndGlowAreWithinFifteenPercentOfAllOrders) {
  auto pool = std::make_shared<ThreadPool>(2);
  RingComparisonCase grey{"HG 0.85, K_t R = 2.5, albedo 0.9", HenyeyGreensteinPhase{0.85}, 2.5};
  grey.albedo = 0.9;
  // (K_t R = 8 needs ~3× the paths for σ below 10 %: `fogbeam validate --path-tracer` runs it.)
  for (const RingComparisonCase& c : {RingComparisonCase{"HG 0.85, K_t R = 4.5", HenyeyGreensteinPhase{0.85}, 4.5},
                                      RingComparisonCase{"HG 0.75, K_t R = 3", HenyeyGreensteinPhase{0.75}, 3.0}, grey}) {
    // Under FOGBEAM_TEST_SCALE (the sanitizer pass) a share of the paths; the bound on σ then
    // does not apply (the 15 % + 3σ agreement does).
    auto res = compareRings(c, test::scaled(6000, 2000), 11, pool, 151);
    ASSERT_TRUE(res.has_value()) << res.error().message;
    std::printf("  %s\n", c.name.c_str());
    for (const RingFigures& f : res->rings) {
      std::printf("    ring %4.1f-%4.1f: single %.4g + glow %.4g; path tracer all %.4g +- %.2g; ratio %.3f +- %.3f\n",
                  f.lo_deg, f.hi_deg, f.single, f.glow, f.pt_all.mean, f.pt_all.std_error, f.ratio(), f.ratioError());
      // The bound has teeth in the rings (the frame's paths spread over 0.5–24°: its σ is larger).
      if (std::isfinite(f.hi_deg) && !test::reduced()) {
        EXPECT_LT(f.pt_all.std_error, 0.1 * f.pt_all.mean) << c.name << " " << f.lo_deg;
      }
      EXPECT_LT(std::abs(f.single + f.glow - f.pt_all.mean), 0.15 * f.pt_all.mean + 3.0 * f.pt_all.std_error)
          << c.name << " " << f.lo_deg;
    }
  }
}

// Fog-mie (10 µm droplets: a diffraction peak ~1° wide) at K_t R = 3: single + glow within issue
// 18's 15 % + 3σ of all orders in every ring and over the frame, and the path tracer's σ below
// 15 % in the rings at the full count (measured: 2.4–10.6 % at 20 000 paths on this 151 px
// image; the 1–2° ring's is the largest, its estimate 8.7 ± 0.9 against 8.0 ± 0.06 with a million
// paths on validate's 351 px: a heavy tail next to the peak). Until 2026-11-29 the path tracer's estimate here was
// spiked by one path in ~10⁶ (a guided direction exactly on the lamp: docs/physics.md), and its
// σ in the rings 4–16° was 2.5–5× larger before NEE's point came from the mixture with the phase
// function's angle density; `fogbeam validate --path-tracer` with 1 000 000 paths: 0.99–1.04 in
// the rings, 1.06 ± 0.02 over the frame.
TEST(ValidatePathTracer, FogMieSingleAndGlowAreWithinFifteenPercentOfAllOrders) {
  auto pool = std::make_shared<ThreadPool>(2);
  auto mie = makeFogMie(10.0);
  ASSERT_TRUE(mie.has_value());
  const RingComparisonCase c{"fog-mie 10 um, K_t R = 3", *mie, 3.0};
  auto res = compareRings(c, test::scaled(20000, 4000), 13, pool, 151);
  ASSERT_TRUE(res.has_value()) << res.error().message;
  for (const RingFigures& f : res->rings) {
    std::printf("    ring %4.1f-%4.1f: single %.4g + glow %.4g; path tracer all %.4g +- %.2g; ratio %.3f +- %.3f\n",
                f.lo_deg, f.hi_deg, f.single, f.glow, f.pt_all.mean, f.pt_all.std_error, f.ratio(), f.ratioError());
    if (std::isfinite(f.hi_deg) && !test::reduced()) {
      EXPECT_LT(f.pt_all.std_error, 0.15 * f.pt_all.mean) << f.lo_deg;
    }
    EXPECT_LT(std::abs(f.single + f.glow - f.pt_all.mean), 0.15 * f.pt_all.mean + 3.0 * f.pt_all.std_error)
        << f.lo_deg;
  }
}

// The ground (GlowOptions::ground_reflectance, physics/ground_correction.hpp): a road 1.2 m under
// the eye and the lamp, between the factor's nodes (K_t = 0.03 /m: 0.036 optical depths, between
// its 0.03 and 0.09; ρ 0.15 and 0.6 between its 0.1, 0.3 and 0.8; T = 6 between 4 and 8). With
// the factor, single + glow is closer to all orders than with the glow of infinite fog over the
// same road (mean |log ratio| over the rings: dark road 0.15 against 0.28, snow 0.09 against
// 0.13; the path tracer's figures are the same for both, so the comparison is deterministic),
// and within 25 % (+ 3σ) in every ring. Issue 18's 15 % is not met in every ring between the
// nodes (docs/airlight.md, "The ground": 0.83–1.24 here).
TEST(ValidatePathTracer, TheGlowKnowsTheGround) {
  auto pool = std::make_shared<ThreadPool>(2);
  RingComparisonCase dark{"HG 0.85, K_t R = 6, K_t 0.03, road rho 0.15", HenyeyGreensteinPhase{0.85}, 6.0};
  dark.extinction_per_m = 0.03;
  dark.ground_below_m = 1.2;
  dark.ground_reflectance = 0.15;
  RingComparisonCase snow{"HG 0.85, K_t R = 4.5, snow rho 0.6", HenyeyGreensteinPhase{0.85}, 4.5};
  snow.ground_below_m = 1.2;
  snow.ground_reflectance = 0.6;
  for (const RingComparisonCase& c : {dark, snow}) {
    auto res = compareRings(c, test::scaled(12000, 3000), 13, pool, 151);
    ASSERT_TRUE(res.has_value()) << res.error().message;
    std::printf("  %s\n", c.name.c_str());
    double logWith = 0.0, logWithout = 0.0;
    for (const RingFigures& f : res->rings) {
      const double blind = (f.single + f.glow_infinite) / f.pt_all.mean;
      std::printf("    ring %4.1f-%4.1f: single + glow %.4g (infinite fog's glow %.4g); path tracer %.4g +- %.2g; ratio "
                  "%.3f +- %.3f (without the ground factor %.3f)\n",
                  f.lo_deg, f.hi_deg, f.single + f.glow, f.single + f.glow_infinite, f.pt_all.mean, f.pt_all.std_error,
                  f.ratio(), f.ratioError(), blind);
      if (!std::isfinite(f.hi_deg)) continue;  // the frame's paths spread over 0.5–24°: σ up to 50 % here
      EXPECT_LT(std::abs(f.single + f.glow - f.pt_all.mean), 0.25 * f.pt_all.mean + 3.0 * f.pt_all.std_error)
          << c.name << " " << f.lo_deg;
      logWith += std::abs(std::log(f.ratio()));
      logWithout += std::abs(std::log(blind));
    }
    std::printf("    mean |log ratio| over the rings: %.3f with the ground factor, %.3f without\n", logWith / 5.0,
                logWithout / 5.0);
    // The factor's teeth: the same path-tracer figures, nearer with it (the full paths only: the
    // sanitizer pass's quarter is too noisy to order the two).
    if (!test::reduced()) {
      EXPECT_LT(logWith, logWithout) << c.name;
    }
  }
}

// What the ground does to the driver's own low beam (docs/airlight.md, "The ground": the own low
// beam over the road). The path tracer: a road of ρ = 0.1 adds light in the rings 4–16° against a
// black one (the beam reaches the road at grazing incidence 5–40 m ahead, the road sends part of
// it back and the fog scatters it into the view). fogbeam's glow layer holds that veil too
// (LampEffects: the road lit by the own lamps, single-scattered), so its figures rise with the
// road's ρ, and over both roads single + glow is within 15 % (+ 3σ) of the path tracer in every
// ring (200 000 paths: 0.99, 0.99, 0.97, 0.94, 0.85 over the road, 0.72–0.98 without the veil
// and with the own lamps' earlier occlusion ramp; 0.96–1.01 over the black road).
TEST(ValidatePathTracer, TheOwnBeamsLitRoadVeilsTheView) {
  auto pool = std::make_shared<ThreadPool>(2);
  auto beam = loadProfileFile(std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies");  // the shipped low beam
  ASSERT_TRUE(beam.has_value()) << beam.error().message;
  const RingComparisonCase road = ownLowBeamOverRoad("own low beam over the road", *beam, 0.1);
  RingComparisonCase black = road;
  black.ground_reflectance = 0.0;
  // 20 000 paths also under the sanitizers (~2 s here): a quarter would not separate the roads at 3σ.
  auto lit = compareRings(road, 20000, 17, pool, 151);
  auto dark = compareRings(black, 20000, 17, pool, 151);
  ASSERT_TRUE(lit.has_value()) << lit.error().message;
  ASSERT_TRUE(dark.has_value()) << dark.error().message;
  ASSERT_EQ(lit->rings.size(), dark->rings.size());
  for (std::size_t k = 0; k < lit->rings.size(); ++k) {
    const RingFigures& a = lit->rings[k];
    const RingFigures& b = dark->rings[k];
    std::printf("  ring %4.1f-%4.1f: path tracer %.4g +- %.2g (black road %.4g +- %.2g); fogbeam %.4g (%.4g); ratio %.3f "
                "+- %.3f (%.3f +- %.3f)\n",
                a.lo_deg, a.hi_deg, a.pt_all.mean, a.pt_all.std_error, b.pt_all.mean, b.pt_all.std_error,
                a.single + a.glow, b.single + b.glow, a.ratio(), a.ratioError(), b.ratio(), b.ratioError());
    if (!std::isfinite(a.hi_deg)) continue;  // the frame: its paths spread over 0.5–24°
    for (const RingFigures* f : {&a, &b})
      EXPECT_LT(std::abs(f->ratio() - 1.0), 0.15 + 3.0 * f->ratioError()) << "ring " << a.lo_deg;
    if (!(a.lo_deg >= 4.0)) continue;
    const double se = std::hypot(a.pt_all.std_error, b.pt_all.std_error);
    EXPECT_GT(a.pt_all.mean - b.pt_all.mean, 3.0 * se) << "the lit road adds light, ring " << a.lo_deg;
    EXPECT_GT(a.glow, 1.2 * b.glow) << "fogbeam's veil, ring " << a.lo_deg;
  }
}

}  // namespace
}  // namespace fogbeam::cli
