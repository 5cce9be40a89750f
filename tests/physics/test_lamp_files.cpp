// The shipped lamp files (config/lamps/*.ies, written by fogbeam_lampgen) load through the
// public path and have the photometric shape their names promise. Angles are IES type B in
// degrees: H positive to the lamp's right, V positive up (right-hand traffic low beam).
// Reference values: ECE R112 (passing beam: horizontal cut-off at 0.57° down on the left,
// 15° rise on the right, a few hundred cd above it), ECE R7 (tail lamp 4–17 cd on the axis).
#include "photometry_test_util.hpp"

#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/physics/profile.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <string>
#include <variant>

namespace fogbeam {
namespace {

std::shared_ptr<const Profile> loadLamp(const std::string& file) {
  const std::string path = std::string(FOGBEAM_CONFIG_DIR) + "/lamps/" + file;
  Result<std::shared_ptr<const Profile>> p = loadProfileFile(path);
  EXPECT_TRUE(p.has_value()) << (p ? std::string() : p.error().message);
  return p ? *p : nullptr;
}

double cd(const Profile& p, double hDeg, double vDeg) {
  return testing::intensityAt(p, PhotometricType::B, hDeg, vDeg);
}

FileAngles peakAnglesDeg(const Profile& p) {
  const FileAngles a = anglesFromDirection(PhotometricType::B, p.peak().direction);
  return {degrees(a.h), degrees(a.v)};
}

TEST(LampFiles, AllShippedFilesAreTypeBIesWithTheFullHorizontalRange) {
  for (const char* file : {"low_beam.ies", "high_beam.ies", "front_fog.ies", "tail_lamp.ies"}) {
    const auto p = loadLamp(file);
    ASSERT_TRUE(p) << file;
    const auto* tab = std::get_if<TabulatedProfile>(&p->model());
    ASSERT_NE(tab, nullptr) << file;
    EXPECT_EQ(tab->format, "IES LM-63-2002") << file;
    EXPECT_EQ(tab->type, PhotometricType::B) << file;
    EXPECT_EQ(tab->symmetry, PlaneSymmetry::None) << file;
    EXPECT_NEAR(degrees(tab->horizontal.front()), -90.0, 1e-9) << file;
    EXPECT_NEAR(degrees(tab->horizontal.back()), 90.0, 1e-9) << file;
  }
}

TEST(LampFiles, LowBeamPeaksBelowTheCutOffRightOfTheAxis) {
  const auto p = loadLamp("low_beam.ies");
  ASSERT_TRUE(p);
  const double peak = p->peak().intensity_cd;
  EXPECT_GE(peak, 20000.0);
  EXPECT_LE(peak, 40000.0);
  const FileAngles at = peakAnglesDeg(*p);
  EXPECT_GT(at.h, 0.0) << "hot spot right of the axis";
  EXPECT_LT(at.h, 4.0);
  EXPECT_LT(at.v, -0.57) << "hot spot below the cut-off";
  EXPECT_GT(at.v, -3.0) << "hot spot close under the cut-off";
}

TEST(LampFiles, LowBeamKeepsTheGlareZoneDarkAndTheRoadBright) {
  const auto p = loadLamp("low_beam.ies");
  ASSERT_TRUE(p);
  // Above the left cut-off (towards oncoming drivers): a few hundred cd at most.
  EXPECT_LT(cd(*p, -3.0, 0.5), 500.0);
  EXPECT_LT(cd(*p, -3.43, 0.57), 500.0);  // B50L
  EXPECT_LT(cd(*p, -10.0, 2.0), 500.0);
  EXPECT_GT(cd(*p, -3.0, 0.5), 50.0) << "some light above the cut-off for overhead signs";
  // Below it: the road, including the oncoming lane at close range.
  EXPECT_GT(cd(*p, -3.0, -2.0), 5000.0);
  EXPECT_GT(cd(*p, 1.15, -0.57), 10000.0);  // 75R: own lane at 75 m
  EXPECT_GT(cd(*p, 0.0, -0.86), 5000.0);    // 50V
  EXPECT_GT(cd(*p, -9.0, -1.72), 1700.0);   // 25L
  EXPECT_GT(cd(*p, 9.0, -1.72), 1700.0);    // 25R
  // Broad spread and foreground.
  EXPECT_GT(cd(*p, -40.0, -3.0), 200.0);
  EXPECT_GT(cd(*p, 40.0, -3.0), 200.0);
  EXPECT_GT(cd(*p, 0.0, -10.0), 500.0);
}

TEST(LampFiles, LowBeamCutOffIsSharpAndRisesOnTheRight) {
  const auto p = loadLamp("low_beam.ies");
  ASSERT_TRUE(p);
  // Sharp: across 1° of the horizontal cut-off on the left, more than a factor 10.
  EXPECT_GT(cd(*p, -5.0, -1.07), 10.0 * cd(*p, -5.0, -0.07));
  // Rising 15° line: 0.5° above the horizon is lit on the right, dark on the left.
  EXPECT_GT(cd(*p, 5.0, 0.5), 10.0 * cd(*p, -5.0, 0.5));
  EXPECT_GT(cd(*p, 8.0, 0.5), 3000.0);
  EXPECT_LT(cd(*p, -8.0, 0.5), 500.0);
  // The rise is capped: far above the shoulder it is dark on the right too.
  EXPECT_LT(cd(*p, 10.0, 3.0), 500.0);
}

TEST(LampFiles, HighBeamPeaksOnTheAxisAndIsSymmetric) {
  const auto p = loadLamp("high_beam.ies");
  ASSERT_TRUE(p);
  const double peak = p->peak().intensity_cd;
  EXPECT_GE(peak, 40000.0);
  EXPECT_LE(peak, 100000.0);
  const FileAngles at = peakAnglesDeg(*p);
  EXPECT_NEAR(at.h, 0.0, 0.5);
  EXPECT_NEAR(at.v, 0.0, 0.5);
  EXPECT_GE(cd(*p, 0.0, 0.0), 0.8 * peak);  // R112: HV ≥ 0.8 Imax
  for (double h : {3.0, 9.0, 20.0}) EXPECT_NEAR(cd(*p, -h, 0.0), cd(*p, h, 0.0), 1e-6 * peak) << h;
  EXPECT_GT(cd(*p, 12.0, 0.0), 1500.0);
  EXPECT_LT(cd(*p, 0.0, 5.0), cd(*p, 5.0, 0.0)) << "narrower vertically than horizontally";
}

TEST(LampFiles, FrontFogIsWideFlatAndDarkAboveTheHorizon) {
  const auto p = loadLamp("front_fog.ies");
  ASSERT_TRUE(p);
  const double peak = p->peak().intensity_cd;
  EXPECT_GE(peak, 6000.0);
  EXPECT_LE(peak, 12000.0);
  EXPECT_LT(peakAnglesDeg(*p).v, -1.5);
  double maxAbove = 0.0;
  for (double v = 0.0; v <= 10.0; v += 0.5)
    for (double h = -45.0; h <= 45.0; h += 1.0) maxAbove = std::max(maxAbove, cd(*p, h, v));
  EXPECT_LT(maxAbove, 1000.0) << "R19: little light above the horizon";
  EXPECT_GT(cd(*p, -40.0, -3.0), 1000.0);
  EXPECT_GT(cd(*p, 40.0, -3.0), 1000.0);
}

TEST(LampFiles, TailLampIsWithinR7OnTheAxisAndVisibleFromTheSide) {
  const auto p = loadLamp("tail_lamp.ies");
  ASSERT_TRUE(p);
  EXPECT_GE(cd(*p, 0.0, 0.0), 4.0);
  EXPECT_LE(p->peak().intensity_cd, 17.0);
  EXPECT_GT(cd(*p, 80.0, 0.0), 0.05);
  EXPECT_GT(cd(*p, -80.0, 0.0), 0.05);
  EXPECT_GT(cd(*p, 0.0, 15.0), 1.0);
}

}  // namespace
}  // namespace fogbeam
