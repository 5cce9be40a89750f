// EULUMDAT reader: one fixture per symmetry indicator Isym 0–4 (values checked at mirrored
// directions), cd/klm → cd scaling, Windows line endings, decimal commas, and the error
// messages for malformed input (built by editing single lines of a valid file).
#include "photometry_test_util.hpp"

#include <fogbeam/physics/eulumdat.hpp>
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

constexpr PhotometricType C = PhotometricType::C;

// The fixtures share their planes (cd/klm at γ = 0, 45, 90°):
//   C0 100 50 10, C90 200 100 20, C180 300 150 30, C270 400 200 40,
// and lamp set 1 gives 2 × 1000 lm (or |−1| × 2000 lm), so cd = 2 × cd/klm.
Result<TabulatedProfile> parseFixture(const std::string& file) { return testing::parseFixtureWith(parseEulumdatFile, file); }

// A valid Isym 0 file, one field per entry; entry i is line i + 1. Lines 43–46 hold the C
// angles, 47–49 the γ angles, 50–61 the intensities.
std::vector<std::string> validLines() {
  std::vector<std::string> l = {"Example Lighting", "1", "0", "4", "90", "3", "45", "TR-1", "Name", "No", "f.ldt",
                                "2024", "100", "50", "30", "80", "40", "0", "0", "0", "0", "100", "85", "1", "0",
                                "1", "2", "LED", "1000", "3000K", "80", "12"};
  for (int i = 0; i < 10; ++i) l.push_back("0.5");
  for (const char* c : {"0", "90", "180", "270"}) l.push_back(c);
  for (const char* g : {"0", "45", "90"}) l.push_back(g);
  for (int plane = 1; plane <= 4; ++plane)
    for (int v : {100, 50, 10}) l.push_back(std::to_string(plane * v));
  return l;
}

std::string join(const std::vector<std::string>& lines) {
  std::string s;
  for (const std::string& l : lines) s += l + "\n";
  return s;
}

Result<TabulatedProfile> parseWith(std::size_t lineNumber, const std::string& value) {
  std::vector<std::string> l = validLines();
  l[lineNumber - 1] = value;
  return parseEulumdat(join(l), "bad.ldt");
}

TEST(Eulumdat, ParsesIsym0FullCircleAndScalesByLampFlux) {
  Result<TabulatedProfile> t = parseFixture("isym0_full.ldt");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->format, "EULUMDAT");
  EXPECT_EQ(t->type, C);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::None);
  EXPECT_EQ(t->horizontal.size(), 4U);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 45.0), 100.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 45.0), 200.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 45.0), 300.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 45.0), 400.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 315.0, 45.0), 250.0, kTol);  // between C270 and C360 = C0
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 67.5), 120.0, kTol);
  EXPECT_EQ(intensityAt(*p, C, 0.0, 120.0), 0.0);  // beyond the last γ angle
}

TEST(Eulumdat, ParsesIsym1RotationalWithCrLfAndNegativeLampCount) {
  Result<TabulatedProfile> t = parseFixture("isym1_rotational_crlf.ldt");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Rotational);
  // −1 lamps × 2000 lm: |n| is used, so cd = 2 × cd/klm as for the other fixtures.
  EXPECT_EQ(t->candela, (std::vector<double>{200.0, 100.0, 20.0}));
  auto p = wrap(*t);
  for (double c : {0.0, 33.0, 180.0, 290.0}) EXPECT_NEAR(intensityAt(*p, C, c, 45.0), 100.0, kTol) << c;
  // Text fields survive without the '\r'.
  bool sawCompany = false;
  for (const auto& [k, v] : t->keywords)
    if (k == "COMPANY") {
      sawCompany = true;
      EXPECT_EQ(v, "Example Lighting GmbH / fogbeam test data");
    }
  EXPECT_TRUE(sawCompany);
}

TEST(Eulumdat, ParsesIsym2HalfC0ToC180WithDecimalCommas) {
  Result<TabulatedProfile> t = parseFixture("isym2_half_c0_c180.ldt");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Half0To180);
  EXPECT_EQ(t->horizontal.size(), 3U);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 45.0), 200.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 45.0), 200.0, kTol);  // mirror of C90
  EXPECT_NEAR(intensityAt(*p, C, 225.0, 45.0), 250.0, kTol);  // mirror of C135
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 90.0), 60.0, kTol);
}

TEST(Eulumdat, ParsesIsym3HalfC90ToC270) {
  Result<TabulatedProfile> t = parseFixture("isym3_half_c90_c270.ldt");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Half90To270);
  ASSERT_EQ(t->horizontal.size(), 3U);
  EXPECT_NEAR(t->horizontal.front(), radians(90.0), 1e-15);
  EXPECT_NEAR(t->horizontal.back(), radians(270.0), 1e-15);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 45.0), 200.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 45.0), 400.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 45.0), 300.0, kTol);    // mirror of C180
  EXPECT_NEAR(intensityAt(*p, C, 45.0, 45.0), 250.0, kTol);   // mirror of C135
  EXPECT_NEAR(intensityAt(*p, C, 315.0, 45.0), 350.0, kTol);  // mirror of C225
  EXPECT_NEAR(atDegrees(*t, 180.0, 45.0), 300.0, kTol);
}

TEST(Eulumdat, ParsesIsym4Quadrant) {
  Result<TabulatedProfile> t = parseFixture("isym4_quadrant.ldt");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Quadrant);
  EXPECT_EQ(t->horizontal.size(), 2U);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 45.0), 100.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 45.0), 100.0, kTol);  // mirror of C0
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 45.0), 200.0, kTol);  // mirror of C90
  EXPECT_NEAR(intensityAt(*p, C, 135.0, 45.0), 150.0, kTol);  // mirror of C45
  EXPECT_NEAR(intensityAt(*p, C, 300.0, 90.0), 20.0 + 20.0 * 60.0 / 90.0, kTol);  // mirror of C60
}

TEST(Eulumdat, KeepsHeaderTextAsKeywords) {
  Result<TabulatedProfile> t = parseEulumdat(join(validLines()), "ok.ldt");
  ASSERT_TRUE(t) << t.error().message;
  auto find = [&](const std::string& key) {
    for (const auto& [k, v] : t->keywords)
      if (k == key) return v;
    return std::string("<missing>");
  };
  EXPECT_EQ(find("LUMINAIRE_NAME"), "Name");
  EXPECT_EQ(find("LAMP_FLUX"), "1000");
  EXPECT_EQ(find("CFLI"), "1");
  EXPECT_EQ(t->source, "ok.ldt");
}

TEST(Eulumdat, ReadsAllLampSetsButScalesByTheFirst) {
  std::vector<std::string> l = validLines();
  l[25] = "2";  // two lamp sets: insert the second after the first (lines 33–38)
  const std::vector<std::string> second = {"4", "Other", "5000", "4000K", "70", "30"};
  l.insert(l.begin() + 32, second.begin(), second.end());
  Result<TabulatedProfile> t = parseEulumdat(join(l), "two.ldt");
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_NEAR(t->candela[0], 200.0, kTol);
}

// ---------------------------------------------------------------------------------------
// Malformed input.

TEST(Eulumdat, RejectsEmptyFile) {
  EXPECT_TRUE(failsWith(parseEulumdat("", "bad.ldt"), {"bad.ldt:1:", "empty file"}));
  EXPECT_TRUE(failsWith(parseEulumdat("\r\n\r\n", "bad.ldt"), {"bad.ldt:1:", "empty file"}));
}

TEST(Eulumdat, ReportsTooFewLinesWithTheMissingField) {
  std::vector<std::string> l = validLines();
  l.resize(20);
  EXPECT_TRUE(failsWith(parseEulumdat(join(l), "bad.ldt"),
                        {"bad.ldt:20:", "expected the luminous area height in the C270 plane (line 21)",
                         "end of the file"}));
}

TEST(Eulumdat, ReportsTruncatedIntensitiesWithCount) {
  std::vector<std::string> l = validLines();
  l.pop_back();
  EXPECT_TRUE(failsWith(parseEulumdat(join(l), "bad.ldt"),
                        {"bad.ldt:60:", "expected 12 luminous intensities (4 C planes x 3 gamma angles)",
                         "found only 11"}));
}

TEST(Eulumdat, RejectsTrailingLines) {
  std::vector<std::string> l = validLines();
  l.push_back("");
  l.push_back("5");
  EXPECT_TRUE(failsWith(parseEulumdat(join(l), "bad.ldt"), {"bad.ldt:63:", "expected the end of the file", "'5'"}));
  l.pop_back();
  EXPECT_TRUE(parseEulumdat(join(l), "ok.ldt"));  // trailing blank lines are fine
}

TEST(Eulumdat, RejectsNonNumbersNamingFieldAndToken) {
  EXPECT_TRUE(failsWith(parseWith(4, "four"),
                        {"bad.ldt:4:", "expected Mc, the number of C planes (an integer from 1 to 3600)", "'four'"}));
  EXPECT_TRUE(failsWith(parseWith(29, "1000 lm"), {"bad.ldt:29:", "total luminous flux of lamp set 1", "'1000 lm'"}));
  EXPECT_TRUE(failsWith(parseWith(52, "abc"), {"bad.ldt:52:", "luminous intensity", "'abc'"}));
  EXPECT_TRUE(failsWith(parseWith(13, ""), {"bad.ldt:13:", "luminaire length", "found ''"}));
  EXPECT_TRUE(failsWith(parseWith(52, "nan"), {"bad.ldt:52:", "finite"}));
}

TEST(Eulumdat, RejectsCountsAndIndicatorsOutOfRange) {
  EXPECT_TRUE(failsWith(parseWith(3, "5"), {"bad.ldt:3:", "Isym, the symmetry indicator (an integer from 0 to 4)"}));
  EXPECT_TRUE(failsWith(parseWith(2, "9"), {"bad.ldt:2:", "Ityp"}));
  EXPECT_TRUE(failsWith(parseWith(6, "1"), {"bad.ldt:6:", "Ng", "from 2 to"}));
  EXPECT_TRUE(failsWith(parseWith(4, "0"), {"bad.ldt:4:", "Mc"}));
  EXPECT_TRUE(failsWith(parseWith(26, "0"), {"bad.ldt:26:", "number of standard sets of lamps"}));
  EXPECT_TRUE(failsWith(parseWith(27, "0"), {"bad.ldt:27:", "non-zero number of lamps"}));
  EXPECT_TRUE(failsWith(parseWith(29, "0"), {"bad.ldt:29:", "total luminous flux > 0 lm"}));
}

TEST(Eulumdat, RejectsPlaneCountThatDoesNotFitIsym) {
  std::vector<std::string> l = validLines();
  l[2] = "4";  // Isym 4 with Mc = 6
  l[3] = "6";
  EXPECT_TRUE(failsWith(parseEulumdat(join(l), "bad.ldt"),
                        {"bad.ldt:4:", "Mc, the number of C planes, divisible by 4 for Isym 4", "found 6"}));
}

TEST(Eulumdat, RejectsStoredPlanesNotWhereIsymPutsThem) {
  std::vector<std::string> l = validLines();
  l[2] = "3";  // Isym 3 stores C90–C270: planes 2–4 of C = 0 90 180 270 …
  l[45] = "260";
  l.resize(l.size() - 3);  // … so only 3 planes of intensities
  EXPECT_TRUE(failsWith(parseEulumdat(join(l), "bad.ldt"),
                        {"bad.ldt:46:", "expected C angle 270 for plane 4 with Isym 3", "found 260"}));
}

TEST(Eulumdat, RejectsAnglesOutOfRangeOrOrder) {
  EXPECT_TRUE(failsWith(parseWith(49, "185"), {"bad.ldt:49:", "gamma angles from 0 to 180 degrees", "'185'"}));
  EXPECT_TRUE(failsWith(parseWith(45, "80"), {"bad.ldt:45:", "C angles in ascending order after 90", "'80'"}));
  EXPECT_TRUE(failsWith(parseWith(43, "-10"), {"bad.ldt:43:", "C angles from 0 to 360"}));
}

TEST(Eulumdat, RejectsNegativeIntensity) {
  EXPECT_TRUE(failsWith(parseWith(55, "-1"), {"bad.ldt:55:", "luminous intensity >= 0", "'-1'"}));
}

TEST(Eulumdat, ReportsMissingFile) {
  EXPECT_TRUE(failsWith(parseEulumdatFile(photometryPath("no_such_file.ldt")), {"no_such_file.ldt", "cannot open"}));
}

}  // namespace
}  // namespace fogbeam
