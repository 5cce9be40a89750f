// The ground's factor on the multiple-scattering tables (physics/ground_correction.hpp): a small
// build against the path tracer (a dark road takes light, a bright one gives it), the text form
// (round trip, errors with file and line), the fade below K_t R = 1, the weighted fit that keeps
// a heavy-tailed node out of what the glow reads, and the shipped factors.
#include <fogbeam/physics/ground_correction.hpp>
#include <fogbeam/physics/math.hpp>
#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

namespace fogbeam {
namespace {

constexpr double kDeg = kPi / 180.0;

// Two reflectances at K_t R = 8 (HG 0.85), three rings: against infinite fog's glow a black road
// leaves well under its light (the path tracer through `fogbeam validate`: ~0.4–0.6 at this
// distance) and ρ = 0.8 more than ρ = 0 in every ring. 4 000 paths per node: σ ~10–20 %, far
// below the gaps checked.
TEST(GroundCorrection, ADarkRoadTakesLightAndABrightOneGivesIt) {
  const Phase phase = HenyeyGreensteinPhase{0.85};
  const auto ms = shippedMultipleScatteringTable(phase);
  ASSERT_NE(ms, nullptr);
  GroundCorrectionOptions o = GroundCorrectionOptions::defaults();
  o.optical_distances = {8.0};
  o.ring_edges_deg = {1.0, 4.0, 16.0, 64.0};
  o.reflectances = {0.0, 0.8};
  o.heights_optical = {0.072};
  o.paths = 4000;
  ThreadPool pool(2);
  auto t = GroundCorrectionTable::build(phase, *ms, o, &pool);
  ASSERT_TRUE(t) << t.error().message;
  double dark = 0.0;
  for (std::size_t j = 0; j < 3; ++j) {
    std::printf("  ring %g-%g: rho 0 %.3f +- %.3f, rho 0.8 %.3f +- %.3f\n", o.ring_edges_deg[j], o.ring_edges_deg[j + 1],
                t->node(0, 0, j), t->nodeStdError(0, 0, j), t->node(1, 0, j), t->nodeStdError(1, 0, j));
    EXPECT_GT(t->node(1, 0, j), t->node(0, 0, j)) << j;
    EXPECT_GT(t->nodeStdError(0, 0, j), 0.0);
    dark += t->node(0, 0, j) / 3.0;
  }
  EXPECT_LT(dark, 0.75);
  EXPECT_GT(dark, 0.1);
  // factor() reads the fitted nodes: between them in ρ, linear.
  const double th = std::sqrt(4.0 * 16.0) * kDeg;
  EXPECT_NEAR(t->factor(8.0, th, 0.4, 0.072), 0.5 * (t->nodeFitted(0, 0, 1) + t->nodeFitted(1, 0, 1)), 1e-12);
}

TEST(GroundCorrection, TheTextFormRoundTripsAndNamesTheLineOfAnError) {
  const auto shipped = shippedGroundCorrection(HenyeyGreensteinPhase{0.85});
  ASSERT_NE(shipped, nullptr);
  const auto path = std::filesystem::temp_directory_path() / "fogbeam_ground_roundtrip.gnd";
  ASSERT_TRUE(shipped->save(path));
  auto back = GroundCorrectionTable::load(path);
  ASSERT_TRUE(back) << back.error().message;
  for (double T : {0.7, 1.0, 3.0, 8.0, 20.0})
    for (double th : {0.001, 0.05, 0.5, 2.0})
      for (double rho : {0.0, 0.15, 0.8})
        for (double H : {0.01, 0.05, 0.2, 1.0})
          EXPECT_NEAR(back->factor(T, th, rho, H), shipped->factor(T, th, rho, H), 1e-5);
  std::filesystem::remove(path);

  const std::string good =
      "fogbeam-ground-correction 1\nphase hg\nphase_identity 1 0.85 0 0\npaths 10 seed 1\n"
      "optical_distances 1 2\nring_edges_deg 3 1 2 4\nreflectances 1 0\nheights_optical 1 0.1\n0.5 0.1  0.6 0.1\n";
  ASSERT_TRUE(GroundCorrectionTable::parse(good, "g.gnd"));
  auto err = [&](std::string text) {
    auto r = GroundCorrectionTable::parse(text, "g.gnd");
    return r ? std::string("(parsed)") : r.error().message;
  };
  EXPECT_EQ(err("fogbeam-ground-correction 2\n").substr(0, 7), "g.gnd:1");
  std::string bad = good;
  bad.replace(bad.find("0.6 0.1"), 7, "0.6 -1");
  EXPECT_NE(err(bad).find("g.gnd:9: pair 2"), std::string::npos) << err(bad);
  bad = good;
  bad.replace(bad.find("3 1 2 4"), 7, "3 1 4 2");
  EXPECT_NE(err(bad).find("g.gnd:6"), std::string::npos) << err(bad);
  EXPECT_NE(err(good.substr(0, good.rfind("0.5 0.1"))).find("ends early"), std::string::npos);
  EXPECT_NE(err(good + "1 1\n").find("(parsed)"), std::string::npos);  // lines after the nodes are not read
}

TEST(GroundCorrection, NearLampsKeepInfiniteFogAndTheFactorFadesInUpToOneOpticalDepth) {
  const auto t = shippedGroundCorrection(HenyeyGreensteinPhase{0.85});
  ASSERT_NE(t, nullptr);
  for (double th : {0.01, 0.3, 2.5}) {
    EXPECT_EQ(t->factor(0.12, th, 0.1, 0.05), 1.0);
    EXPECT_EQ(t->factor(GroundCorrectionTable::kFadeFrom, th, 0.8, 0.05), 1.0);
    // Continuous at both ends of the fade, and the whole factor from T = 1 (ρ = 0.8 at T = 1 adds
    // light in every ring: ≥ 1.1 in the shipped HG 0.85 factor).
    EXPECT_NEAR(t->factor(0.505, th, 0.8, 0.05), 1.0, 0.05);
    EXPECT_NEAR(t->factor(0.9999, th, 0.8, 0.05), t->factor(1.0, th, 0.8, 0.05), 1e-3);
    EXPECT_GT(t->factor(1.0, th, 0.8, 0.05), 1.1);
  }
}

// factors() (a glow curve's 512 angles at once) is factor() angle by angle.
TEST(GroundCorrection, FactorsAtManyAnglesAreTheFactorAtEach) {
  const auto t = shippedGroundCorrection(HenyeyGreensteinPhase{0.8});
  ASSERT_NE(t, nullptr);
  std::vector<double> th, out;
  for (int k = 0; k < 300; ++k) th.push_back(1e-4 * std::pow(1.03, k));  // 0.0057° … 180°+
  out.resize(th.size());
  for (double T : {0.7, 1.0, 3.3, 12.0, 30.0})
    for (double rho : {0.0, 0.2, 0.95})
      for (double H : {0.01, 0.05, 0.4}) {
        t->factors(T, rho, H, th.data(), th.size(), out.data());
        for (std::size_t k = 0; k < th.size(); ++k)
          ASSERT_NEAR(out[k], t->factor(T, th[k], rho, H), 1e-12) << T << " " << rho << " " << H << " " << th[k];
      }
}

TEST(GroundCorrection, TheFitKeepsAHeavyTailedNodeOutOfWhatTheGlowReads) {
  // One node 1000× its neighbours with σ as large as itself (what one path next to the lamp does).
  std::string text =
      "fogbeam-ground-correction 1\nphase hg\nphase_identity 1 0.85 0 0\npaths 10 seed 1\n"
      "optical_distances 1 2\nring_edges_deg 7 0.5 1 2 4 8 16 32\nreflectances 1 0\nheights_optical 1 0.1\n"
      "0.80 0.05  0.82 0.05  1000 999  0.86 0.05  0.88 0.05  0.90 0.05\n";
  auto t = GroundCorrectionTable::parse(text, "g.gnd");
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(t->node(0, 0, 2), 1000.0);
  for (std::size_t j = 0; j < 6; ++j) {
    EXPECT_GT(t->nodeFitted(0, 0, j), 0.75) << j;
    EXPECT_LT(t->nodeFitted(0, 0, j), 0.95) << j;
  }
}

TEST(GroundCorrection, EveryShippedPhaseFunctionHasItsFactor) {
  for (const Phase& p : {Phase{HenyeyGreensteinPhase{0.75}}, Phase{HenyeyGreensteinPhase{0.8}},
                         Phase{HenyeyGreensteinPhase{0.85}}, Phase{HenyeyGreensteinPhase{0.875}},
                         Phase{HenyeyGreensteinPhase{0.9}}}) {
    const auto t = shippedGroundCorrection(p);
    ASSERT_NE(t, nullptr) << describe(p);
    // A dark road far from the lamp in thick fog takes light (the reason for the factor).
    EXPECT_LT(t->factor(8.0, 10.0 * kDeg, 0.1, 0.05), 0.9) << describe(p);
  }
  auto fm = makeFogMie(10.0);
  ASSERT_TRUE(fm);
  EXPECT_NE(shippedGroundCorrection(*fm), nullptr);
  EXPECT_EQ(shippedGroundCorrection(IsotropicPhase{}), nullptr);
}

}  // namespace
}  // namespace fogbeam
