// CSV grid reader: transposition of the V-row table into type B blocks, the symmetry
// directive, ';' separators with decimal commas, and the error messages.
#include "photometry_test_util.hpp"

#include <fogbeam/physics/csv_profile.hpp>
#include <fogbeam/physics/profile.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace fogbeam {
namespace {

using testing::atDegrees;
using testing::failsWith;
using testing::intensityAt;
using testing::kTol;
using testing::photometryPath;
using testing::wrap;

constexpr PhotometricType B = PhotometricType::B;

Result<TabulatedProfile> parseFixture(const std::string& file) { return testing::parseFixtureWith(parseCsvProfileFile, file); }

TEST(Csv, ParsesGridAsTypeBAndTransposesRows) {
  Result<TabulatedProfile> t = parseFixture("headlamp_grid.csv");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->format, "CSV grid");
  EXPECT_EQ(t->type, B);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::None);
  ASSERT_EQ(t->horizontal.size(), 3U);
  ASSERT_EQ(t->vertical.size(), 3U);
  // Rows V = −5, 0, 5 of columns H = −10, 0, 10 become one block per H.
  EXPECT_EQ(t->candela, (std::vector<double>{100, 50, 5, 400, 300, 10, 200, 150, 20}));
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, B, 10.0, -5.0), 200.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -10.0, 5.0), 5.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, 0.0, 0.0), 300.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, 5.0, -2.5), 262.5, kTol);
  EXPECT_EQ(intensityAt(*p, B, 20.0, 0.0), 0.0);  // outside the measured H range
  EXPECT_NEAR(atDegrees(*t, -10.0, -5.0), 100.0, kTol);
}

TEST(Csv, DoesNotMirrorGridStartingAtZeroWithoutDirective) {
  Result<TabulatedProfile> t = parseFixture("one_sided_grid.csv");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::None);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, B, 10.0, -5.0), 80.0, kTol);
  EXPECT_EQ(intensityAt(*p, B, -10.0, -5.0), 0.0);
}

TEST(Csv, MirrorsWithDirectiveAndAcceptsSemicolonsWithDecimalCommas) {
  Result<TabulatedProfile> t = parseFixture("mirror_grid.csv");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::MirrorH);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, B, 10.0, -5.0), 80.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -10.0, -5.0), 80.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -20.0, 0.0), 7.5, kTol);
  EXPECT_NEAR(intensityAt(*p, B, 0.0, 5.0), 50.5, kTol);  // "50,5"
  EXPECT_NEAR(intensityAt(*p, B, -5.0, -5.0), 90.0, kTol);
}

TEST(Csv, AcceptsExplicitNoneDirectiveCrLfAndTrailingSeparators) {
  Result<TabulatedProfile> t =
      parseCsvProfile("# Symmetry : NONE\r\nV\\H,0,10,\r\n-5,1,2,\r\n\r\n5,3,4\r\n", "ok.csv");
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(t->symmetry, PlaneSymmetry::None);
  EXPECT_EQ(t->candela, (std::vector<double>{1, 3, 2, 4}));
}

TEST(Csv, RejectsEmptyFileAndCommentsOnly) {
  EXPECT_TRUE(failsWith(parseCsvProfile("", "bad.csv"), {"bad.csv:1:", "header row", "empty file"}));
  EXPECT_TRUE(failsWith(parseCsvProfile("# a\n# b\n", "bad.csv"), {"bad.csv:2:", "only comments"}));
}

TEST(Csv, RejectsTooFewRowsOrColumns) {
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0\n0,1\n5,2\n", "bad.csv"), {"bad.csv:1:", "at least 2 H angles"}));
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10\n0,1,2\n", "bad.csv"),
                        {"bad.csv:2:", "expected at least 2 rows", "found 1"}));
}

TEST(Csv, RejectsRaggedRows) {
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10\n0,1,2\n5,1\n", "bad.csv"),
                        {"bad.csv:3:", "expected 3 cells (a V angle and 2 values), found 2"}));
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10\n0,1,2\n5,1,2,3\n", "bad.csv"), {"bad.csv:3:", "found 4"}));
}

TEST(Csv, RejectsNonNumbersNamingLineAndColumn) {
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,abc\n0,1,2\n5,1,2\n", "bad.csv"),
                        {"bad.csv:1:", "the H angle in column 3", "'abc'"}));
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10\n0,1,x\n5,1,2\n", "bad.csv"),
                        {"bad.csv:2:", "a candela value in column 3", "'x'"}));
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10\n0,1,2\n5,inf,2\n", "bad.csv"), {"bad.csv:3:", "finite"}));
}

TEST(Csv, RejectsAnglesOutOfRangeOrOrder) {
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10,5\n0,1,2,3\n5,1,2,3\n", "bad.csv"),
                        {"bad.csv:1:", "H angles in ascending order", "'5'"}));
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,95\n0,1,2\n5,1,2\n", "bad.csv"),
                        {"bad.csv:1:", "from -90 to 90 degrees", "'95'"}));
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10\n5,1,2\n0,1,2\n", "bad.csv"),
                        {"bad.csv:3:", "V angles in ascending order", "'0'"}));
}

TEST(Csv, RejectsNegativeValues) {
  EXPECT_TRUE(failsWith(parseCsvProfile("V\\H,0,10\n0,1,-2\n5,1,2\n", "bad.csv"),
                        {"bad.csv:2:", "column 3 >= 0", "'-2'"}));
}

TEST(Csv, RejectsMirrorDirectiveForGridNotStartingAtZero) {
  EXPECT_TRUE(failsWith(parseCsvProfile("# symmetry: mirror-h\nV\\H,-10,0\n0,1,2\n5,1,2\n", "bad.csv"),
                        {"bad.csv:2:", "first H angle to be 0", "found -10"}));
}

TEST(Csv, RejectsUnknownSymmetryDirective) {
  EXPECT_TRUE(failsWith(parseCsvProfile("# symmetry: quadrant\nV\\H,0,10\n0,1,2\n5,1,2\n", "bad.csv"),
                        {"bad.csv:1:", "'mirror-h' or 'none'", "'quadrant'"}));
}

}  // namespace
}  // namespace fogbeam
