// IES LM-63 reader: one fixture per version, photometric type and symmetry layout,
// tilt handling, and the error messages for malformed input.
// Values are checked through makeProfile → Profile::intensity(directionFromAngles(...)) and
// TabulatedProfile::atAngles; the fixtures in tests/data/photometry are small enough to
// compute the expectations by hand (see the comments next to each check).
#include "photometry_test_util.hpp"

#include <fogbeam/physics/ies.hpp>
#include <fogbeam/physics/profile.hpp>

#include <gtest/gtest.h>

#include <string>
#include <string_view>

namespace fogbeam {
namespace {

using testing::atDegrees;
using testing::failsWith;
using testing::intensityAt;
using testing::kTol;
using testing::photometryPath;
using testing::wrap;

constexpr PhotometricType C = PhotometricType::C;
constexpr PhotometricType B = PhotometricType::B;
constexpr PhotometricType A = PhotometricType::A;

// An LM-63-2002 file around `data` (the lines after TILT=NONE). Line numbers: 1 header,
// 2 [TEST], 3 TILT, 4 photometric line, 5 ballast line, 6 vertical angles, 7 horizontal
// angles, 8… candela values.
std::string ies2002(std::string_view data, std::string_view tilt = "NONE") {
  return "IESNA:LM-63-2002\n[TEST] inline\nTILT=" + std::string(tilt) + "\n" + std::string(data);
}

// Type C, rotational, 3 vertical angles, candela 100 50 10.
constexpr std::string_view kRotational = "1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n100 50 10\n";

Result<TabulatedProfile> parseFixture(const std::string& file) { return testing::parseFixtureWith(parseIesFile, file); }

// ---------------------------------------------------------------------------------------
// Versions, types and symmetry layouts.

TEST(Ies, ParsesVersion1986WithoutHeaderAndAppliesBallastLampFactor) {
  Result<TabulatedProfile> t = parseFixture("lm63_1986_rotational.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->format, "IES LM-63-1986");
  EXPECT_EQ(t->type, C);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Rotational);
  ASSERT_EQ(t->keywords.size(), 2U);
  EXPECT_EQ(t->keywords[0].first, "TEXT");
  EXPECT_EQ(t->keywords[1].second, "ACME LIGHTING CO. CATALOG 1234");
  EXPECT_EQ(t->source, photometryPath("lm63_1986_rotational.ies"));
  // 100 80 20 cd × multiplier 1 × ballast 1 × ballast-lamp factor 0.5; lumens 1000 are
  // relative photometry, used as given.
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 0.0), 50.0, kTol);
  for (double c : {0.0, 77.0, 200.0, 300.0}) EXPECT_NEAR(intensityAt(*p, C, c, 45.0), 40.0, kTol) << c;
  EXPECT_NEAR(intensityAt(*p, C, 120.0, 22.5), 45.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 10.0, 67.5), 25.0, kTol);
  EXPECT_EQ(intensityAt(*p, C, 0.0, 120.0), 0.0);  // beyond the last vertical angle
}

TEST(Ies, ParsesVersion1991KeywordsMoreContinuationAndQuadrantSymmetry) {
  Result<TabulatedProfile> t = parseFixture("lm63_1991_quadrant.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->format, "IES LM-63-1991");
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Quadrant);
  ASSERT_EQ(t->keywords.size(), 2U);
  EXPECT_EQ(t->keywords[0], (std::pair<std::string, std::string>{"TEST", "Q-1991"}));
  EXPECT_EQ(t->keywords[1].second, "Example Optics second line of the manufacturer");
  // Scale = multiplier 2 × ballast 0.9 × ballast-lamp factor 0.5 = 0.9; at γ = 45°:
  // C0 8 → 7.2, C45 16 → 14.4, C90 24 → 21.6, mirrored into the other quadrants.
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 45.0), 7.2, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 45.0), 21.6, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 45.0), 7.2, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 45.0), 21.6, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 135.0, 45.0), 14.4, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 315.0, 45.0), 14.4, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 22.5, 45.0), 10.8, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 202.5, 45.0), 10.8, kTol);  // mirrors to C22.5
  EXPECT_NEAR(atDegrees(*t, 90.0, 90.0), 10.8, kTol);
}

TEST(Ies, ParsesVersion1995HalfPlaneAndIgnoresFutureUseField) {
  Result<TabulatedProfile> t = parseFixture("lm63_1995_half.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->format, "IES LM-63-1995");
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Half0To180);
  // The 0.5 in the "future use" field must not scale anything (it did in 1986/1991).
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 90.0), 2.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 90.0), 5.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 90.0), 8.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 90.0), 5.0, kTol);               // mirror of C90
  EXPECT_NEAR(intensityAt(*p, C, 200.0, 90.0), 5.0 + 3.0 * 70.0 / 90.0, kTol);  // mirror of C160
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 135.0), 2.5, kTol);
}

TEST(Ies, ParsesType2002HeadlampTypeBWithWrappedCommaSeparatedNumbers) {
  Result<TabulatedProfile> t = parseFixture("lm63_2002_type_b_headlamp.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->format, "IES LM-63-2002");
  EXPECT_EQ(t->type, B);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::None);
  ASSERT_EQ(t->vertical.size(), 5U);
  ASSERT_EQ(t->horizontal.size(), 5U);
  EXPECT_NEAR(t->vertical[1], radians(-5.0), 1e-15);
  EXPECT_EQ(t->keywords.size(), 6U);
  // Scale = multiplier 1.5 × ballast 0.8 = 1.2. Not symmetric: left (H < 0) ≠ right.
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, B, 0.0, -5.0), 4000.0 * 1.2, kTol);
  EXPECT_NEAR(intensityAt(*p, B, 10.0, 0.0), 1500.0 * 1.2, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -10.0, 5.0), 100.0 * 1.2, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -10.0, -5.0), 1000.0 * 1.2, kTol);
  EXPECT_NEAR(intensityAt(*p, B, 10.0, -5.0), 3000.0 * 1.2, kTol);
  // Bilinear between H 0/10 and V −5/0: mean of 4000, 2000, 3000, 1500 = 2625.
  EXPECT_NEAR(intensityAt(*p, B, 5.0, -2.5), 2625.0 * 1.2, kTol);
  // Between H 10 (1500) and H 90 (0) at V 0.
  EXPECT_NEAR(intensityAt(*p, B, 50.0, 0.0), 750.0 * 1.2, kTol);
  EXPECT_NEAR(atDegrees(*t, 0.0, -5.0), 4800.0, kTol);
  // H = +10° is the lamp's right, −y in the lamp frame.
  EXPECT_LT(directionFromAngles(B, radians(10.0), 0.0).y, 0.0);
}

TEST(Ies, ParsesVersion2019TypeAMirroredWithUncoveredLowerHalf) {
  Result<TabulatedProfile> t = parseFixture("lm63_2019_type_a_mirror.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->format, "IES LM-63-2019");
  EXPECT_EQ(t->type, A);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::MirrorH);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, A, 30.0, 10.0), 40.0, kTol);
  EXPECT_NEAR(intensityAt(*p, A, -30.0, 10.0), 40.0, kTol);  // I(−H, V) = I(H, V)
  EXPECT_NEAR(intensityAt(*p, A, 15.0, 0.0), 90.0, kTol);
  EXPECT_NEAR(intensityAt(*p, A, -15.0, 5.0), 67.5, kTol);
  EXPECT_EQ(intensityAt(*p, A, 0.0, -10.0), 0.0);  // V 0–90 file: the lower half reads 0 cd
  EXPECT_EQ(atDegrees(*t, 20.0, -1.0), 0.0);
}

TEST(Ies, MirrorsTypeBHorizontalAnglesFromZeroToNinety) {
  Result<TabulatedProfile> t = parseFixture("lm63_2002_type_b_mirror.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::MirrorH);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, B, 45.0, 0.0), 300.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -45.0, 0.0), 300.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -22.5, 0.0), 450.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, -67.5, 0.0), 200.0, kTol);
  EXPECT_NEAR(intensityAt(*p, B, 0.0, 45.0), 300.0, kTol);
  EXPECT_NEAR(atDegrees(*t, -45.0, -45.0), 150.0, kTol);
}

TEST(Ies, ParsesTypeCHalf90To270) {
  Result<TabulatedProfile> t = parseFixture("lm63_2002_type_c_half90.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::Half90To270);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 90.0), 20.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 90.0), 40.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 90.0), 60.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 90.0), 40.0, kTol);    // mirror of C180
  EXPECT_NEAR(intensityAt(*p, C, 45.0, 90.0), 30.0, kTol);   // mirror of C135
  EXPECT_NEAR(intensityAt(*p, C, 315.0, 90.0), 50.0, kTol);  // mirror of C225
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 45.0), 25.0, kTol);
}

TEST(Ies, ParsesTypeCFullCircleWithVerticalNinetyTo180) {
  Result<TabulatedProfile> t = parseFixture("lm63_2002_type_c_full.ies");
  ASSERT_TRUE(t);
  EXPECT_EQ(t->symmetry, PlaneSymmetry::None);
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 90.0), 4.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 90.0), 8.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 180.0, 90.0), 12.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 270.0, 90.0), 16.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 315.0, 90.0), 10.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 45.0, 90.0), 6.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 90.0, 112.5), 5.0, kTol);
  EXPECT_NEAR(intensityAt(*p, C, 200.0, 135.0), 2.0, kTol);
  EXPECT_EQ(intensityAt(*p, C, 0.0, 45.0), 0.0);  // γ below the first vertical angle
}

TEST(Ies, MapsTypeCHorizontalRangesToSymmetry) {
  struct Case {
    const char* horizontal;
    int count;
    PlaneSymmetry symmetry;
  };
  const Case cases[] = {
      {"0", 1, PlaneSymmetry::Rotational},          {"0 45 90", 3, PlaneSymmetry::Quadrant},
      {"0 90 180", 3, PlaneSymmetry::Half0To180},   {"90 180 270", 3, PlaneSymmetry::Half90To270},
      {"0 120 240 360", 4, PlaneSymmetry::None},    {"0 90 180 270", 4, PlaneSymmetry::None},
  };
  for (const Case& c : cases) {
    std::string candela;
    for (int i = 0; i < c.count; ++i) candela += "3 2 1\n";
    const std::string data =
        "1 -1 1 3 " + std::to_string(c.count) + " 1 2 0 0 0\n1 1 10\n0 45 90\n" + c.horizontal + "\n" + candela;
    Result<TabulatedProfile> t = parseIes(ies2002(data), "sym.ies");
    ASSERT_TRUE(t) << c.horizontal << ": " << t.error().message;
    EXPECT_EQ(t->symmetry, c.symmetry) << c.horizontal;
  }
}

TEST(Ies, RelativePhotometryValuesAreUsedAsGiven) {
  // Lumens per lamp 1000 (relative) and −1 (absolute) give the same candela: LM-63 values
  // are already candela for the rated lamp lumens.
  Result<TabulatedProfile> rel = parseIes(ies2002("1 1000 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n100 50 10\n"), "r.ies");
  Result<TabulatedProfile> abs = parseIes(ies2002(kRotational), "a.ies");
  ASSERT_TRUE(rel);
  ASSERT_TRUE(abs);
  EXPECT_EQ(rel->candela, abs->candela);
  EXPECT_EQ(rel->candela, (std::vector<double>{100.0, 50.0, 10.0}));
}

TEST(Ies, AcceptsCrLfLineEndingsSignedExponentsAndCtrlZ) {
  const std::string text =
      "IESNA:LM-63-2002\r\n[TEST] dos\r\nTILT=NONE\r\n1 -1 +1.0 3 1 1 2 0 0 0\r\n1 1 10\r\n0 4.5e1 90\r\n0\r\n"
      "1E2 50.0 +10\r\n\x1a";
  Result<TabulatedProfile> t = parseIes(text, "dos.ies");
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(t->candela, (std::vector<double>{100.0, 50.0, 10.0}));
  EXPECT_EQ(t->keywords[0].second, "dos");
}

TEST(Ies, FindsVersionLineAfterLeadingBlankLines) {
  // Misreading a 2002 file as 1986 would apply its "future use" field as a factor.
  const std::string text = "\n  \nIESNA:LM-63-2002\nTILT=NONE\n1 -1 1 3 1 1 2 0 0 0\n1 0.5 10\n0 45 90\n0\n100 50 10\n";
  Result<TabulatedProfile> t = parseIes(text, "blank.ies");
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(t->format, "IES LM-63-2002");
  EXPECT_EQ(t->candela[0], 100.0);
  EXPECT_TRUE(failsWith(parseIes("\nIESNA:LM-63-1900\nTILT=NONE\n", "bad.ies"), {"bad.ies:2:", "header line"}));
}

// ---------------------------------------------------------------------------------------
// TILT.

TEST(Ies, AppliesTiltIncludeFactorAtZeroDegrees) {
  Result<TabulatedProfile> t = parseFixture("lm63_2002_tilt_include.ies");
  ASSERT_TRUE(t);
  // Geometry 1, factors 0.8 0.6 0.4 at 0 45 90°: the luminaire as photometered (0°) → 0.8.
  EXPECT_EQ(t->candela, (std::vector<double>{80.0, 40.0, 8.0}));
  auto p = wrap(*t);
  EXPECT_NEAR(intensityAt(*p, C, 0.0, 45.0), 40.0, kTol);
}

TEST(Ies, InterpolatesTiltFactorAtZeroBetweenTabulatedAngles) {
  const std::string tilt = "1\n2\n-30 30\n0.5 1.0\n";
  Result<TabulatedProfile> t = parseIes(ies2002(tilt + std::string(kRotational), "INCLUDE"), "tilt.ies");
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_NEAR(t->candela[0], 75.0, kTol);
}

TEST(Ies, AppliesTiltFileRelativeToIesDirectory) {
  Result<TabulatedProfile> t = parseFixture("lm63_2002_tilt_file.ies");
  ASSERT_TRUE(t);
  // lamp_vertical.tilt: geometry 1, factors 0.5 0.25 at 0 90° → 0.5.
  EXPECT_EQ(t->candela, (std::vector<double>{50.0, 25.0, 5.0}));
}

TEST(Ies, LoadsTiltFileThroughGivenLoader) {
  std::string asked;
  IesTiltLoader loader = [&](const std::string& name) -> Result<std::string> {
    asked = name;
    return std::string("1 1 0 0.25\n");
  };
  Result<TabulatedProfile> t = parseIes(ies2002(kRotational, "custom tilt.dat"), "t.ies", loader);
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(asked, "custom tilt.dat");
  EXPECT_EQ(t->candela, (std::vector<double>{25.0, 12.5, 2.5}));
}

TEST(Ies, RejectsTiltGeometryOtherThanVerticalLamp) {
  const std::string tilt = "2\n2\n0 90\n1 0.5\n";
  EXPECT_TRUE(failsWith(parseIes(ies2002(tilt + std::string(kRotational), "INCLUDE"), "bad.ies"),
                        {"bad.ies:4:", "lamp-to-luminaire geometry 1", "found '2'"}));
}

TEST(Ies, RejectsTiltFileWithoutLoader) {
  EXPECT_TRUE(failsWith(parseIes(ies2002(kRotational, "lamp.tilt"), "bad.ies"),
                        {"bad.ies:3:", "lamp.tilt", "no tilt file loader"}));
}

TEST(Ies, ReportsUnreadableTiltFile) {
  IesTiltLoader loader = [](const std::string& name) -> Result<std::string> {
    return Error{name + ": cannot open (No such file or directory)"};
  };
  EXPECT_TRUE(failsWith(parseIes(ies2002(kRotational, "gone.tilt"), "bad.ies", loader),
                        {"bad.ies:3:", "cannot read TILT file 'gone.tilt'", "No such file"}));
  EXPECT_TRUE(failsWith(parseIesFile(photometryPath("lm63_2002_tilt_missing.ies")),
                        {"lm63_2002_tilt_missing.ies:3:", "cannot read TILT file 'does_not_exist.tilt'"}));
}

TEST(Ies, ReportsMalformedTiltFileByItsName) {
  IesTiltLoader truncated = [](const std::string&) -> Result<std::string> { return std::string("1\n2\n0 90\n0.5\n"); };
  EXPECT_TRUE(failsWith(parseIes(ies2002(kRotational, "x.tilt"), "bad.ies", truncated),
                        {"x.tilt:4:", "expected 2 TILT multiplying factors", "found only 1"}));
  IesTiltLoader trailing = [](const std::string&) -> Result<std::string> { return std::string("1\n1\n0\n0.5\n7\n"); };
  EXPECT_TRUE(failsWith(parseIes(ies2002(kRotational, "x.tilt"), "bad.ies", trailing),
                        {"x.tilt:5:", "expected the end of the file", "'7'"}));
}

TEST(Ies, RejectsTiltAnglesOutOfOrder) {
  const std::string tilt = "1\n3\n0 60 30\n1 1 1\n";
  EXPECT_TRUE(failsWith(parseIes(ies2002(tilt + std::string(kRotational), "INCLUDE"), "bad.ies"),
                        {"bad.ies:6:", "TILT angles in ascending order", "'30'"}));
}

// ---------------------------------------------------------------------------------------
// Malformed input: every error names the file, the line and what was expected.

TEST(Ies, RejectsEmptyFile) {
  EXPECT_TRUE(failsWith(parseIes("", "bad.ies"), {"bad.ies:1:", "empty file"}));
  EXPECT_TRUE(failsWith(parseIes("  \n\r\n\t\n", "bad.ies"), {"bad.ies:1:", "empty file"}));
}

TEST(Ies, ReportsTruncatedCandelaValuesWithLineAndCount) {
  const std::string data = "1 -1 1 3 2 1 2 0 0 0\n1 1 10\n0 45 90\n0 90\n1 2 3\n4 5\n";
  EXPECT_TRUE(failsWith(parseIes(ies2002(data), "bad.ies"),
                        {"bad.ies:9:", "expected 6 candela values (2 horizontal x 3 vertical angles)", "found only 5",
                         "end of the file"}));
}

TEST(Ies, ReportsDataEndingInsidePhotometricLine) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1\n"), "bad.ies"),
                        {"bad.ies:4:", "expected the number of vertical angles", "end of the file"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002(""), "bad.ies"), {"bad.ies:3:", "expected the number of lamps"}));
}

TEST(Ies, DetectsDeclaredVerticalCountLargerThanData) {
  // #vertical says 4 but 3 are given: the first horizontal angle is read as a 4th vertical one.
  const std::string data = "1 -1 1 4 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n100 50 10\n";
  EXPECT_TRUE(failsWith(parseIes(ies2002(data), "bad.ies"),
                        {"bad.ies:7:", "vertical angles in ascending order", "number of vertical angles, 4", "'0'"}));
  EXPECT_TRUE(failsWith(parseIesFile(photometryPath("bad_vertical_count.ies")), {"bad_vertical_count.ies:7:"}));
}

TEST(Ies, RejectsTrailingExtraValues) {
  const std::string data = std::string(kRotational) + "100\n";
  EXPECT_TRUE(failsWith(parseIes(ies2002(data), "bad.ies"),
                        {"bad.ies:9:", "expected the end of the file after 3 candela values", "found '100'",
                         "1 horizontal x 3 vertical angles"}));
}

TEST(Ies, RejectsNonNumbersNamingTheToken) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 abc\n0\n100 50 10\n"), "bad.ies"),
                        {"bad.ies:6:", "expected a vertical angle in degrees (a number)", "found 'abc'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n100 5O 10\n"), "bad.ies"),
                        {"bad.ies:8:", "candela value", "'5O'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1x 10\n0 45 90\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:5:", "'future use'", "'1x'"}));
}

TEST(Ies, RejectsNanAndInfinity) {
  for (const char* bad : {"nan", "inf", "-inf", "1e999"}) {
    const std::string data = "1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n100 " + std::string(bad) + " 10\n";
    EXPECT_TRUE(failsWith(parseIes(ies2002(data), "bad.ies"), {"bad.ies:8:", "finite", bad})) << bad;
  }
}

TEST(Ies, RejectsNegativeCandela) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n100 -50 10\n"), "bad.ies"),
                        {"bad.ies:8:", "expected a candela value >= 0", "found '-50'"}));
}

TEST(Ies, RejectsAnglesOutOfRangeForType) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n-5 45 90\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:6:", "vertical angles from 0 to 180 degrees for photometric type C", "'-5'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 90 185\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:6:", "from 0 to 180", "'185'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 2 1 2 0 0 0\n1 1 10\n0 45 90\n-10 90\n1 2 3 4 5 6\n"), "bad.ies"),
                        {"bad.ies:7:", "horizontal angles from 0 to 360", "'-10'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 2 2 2 0 0 0\n1 1 10\n-90 0 95\n0 90\n1 2 3 4 5 6\n"), "bad.ies"),
                        {"bad.ies:6:", "from -90 to 90 degrees for photometric type B", "'95'"}));
}

TEST(Ies, RejectsDescendingAngles) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 90 45\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:6:", "ascending order after 90", "'45'"}));
}

TEST(Ies, RejectsAngleRangesThatLm63DoesNotDefine) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 2 1 2 0 0 0\n1 1 10\n0 45 90\n0 120\n1 2 3 4 5 6\n"), "bad.ies"),
                        {"bad.ies:7:", "expected type C horizontal angles 0 (rotational), 0 to 90", "found 0 to 120"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n30\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:7:", "found 30 to 30"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 2 2 2 0 0 0\n1 1 10\n-90 0 90\n-45 45\n1 2 3 4 5 6\n"), "bad.ies"),
                        {"bad.ies:7:", "type B horizontal angles from 0 to 90 (mirrored) or -90 to 90", "found -45 to 45"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 2 2 2 0 0 0\n1 1 10\n-20 0 20\n0 90\n1 2 3 4 5 6\n"), "bad.ies"),
                        {"bad.ies:6:", "type B vertical angles from -90 or 0 to 90", "found -20 to 20"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 85\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:6:", "type C vertical angles from 0 or 90 to 90 or 180", "found 0 to 85"}));
}

TEST(Ies, RejectsUnknownPhotometricType) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 4 2 0 0 0\n1 1 10\n0 45 90\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:4:", "photometric type, 1 (C), 2 (B) or 3 (A)", "found '4'"}));
}

TEST(Ies, RejectsOutOfRangePhotometricLineFields) {
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 0 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:4:", "lumens per lamp > 0, or -1", "found '0'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 0 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:4:", "candela multiplier > 0"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 1 1 1 2 0 0 0\n1 1 10\n0\n0\n1\n"), "bad.ies"),
                        {"bad.ies:4:", "number of vertical angles (an integer from 2", "found '1'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 2.5 1 1 2 0 0 0\n1 1 10\n0 90\n0\n1 2\n"), "bad.ies"),
                        {"bad.ies:4:", "number of vertical angles", "'2.5'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 3 0 0 0\n1 1 10\n0 45 90\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:4:", "units type", "found '3'"}));
  EXPECT_TRUE(failsWith(parseIes(ies2002("1 -1 1 3 1 1 2 0 0 0\n0 1 10\n0 45 90\n0\n1 2 3\n"), "bad.ies"),
                        {"bad.ies:5:", "ballast factor > 0"}));
}

TEST(Ies, RejectsMissingTiltLine) {
  const std::string noTilt = "IESNA:LM-63-2002\n[TEST] x\n1 -1 1 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n1 2 3\n";
  EXPECT_TRUE(failsWith(parseIes(noTilt, "bad.ies"), {"bad.ies:3:", "expected a TILT= line", "before the photometric data"}));
  EXPECT_TRUE(failsWith(parseIes("a 1986 label\nanother label\n", "bad.ies"),
                        {"bad.ies:2:", "expected a TILT= line", "end of the file"}));
  EXPECT_TRUE(failsWith(parseIes("IESNA:LM-63-2002\nTILT=\n", "bad.ies"), {"bad.ies:2:", "TILT=NONE, TILT=INCLUDE"}));
}

TEST(Ies, RejectsUnknownHeaderVersionAndBrokenKeywordLine) {
  EXPECT_TRUE(failsWith(parseIes("IESNA:LM-63-2030\nTILT=NONE\n" + std::string(kRotational), "bad.ies"),
                        {"bad.ies:1:", "IESNA:LM-63-2002", "'IESNA:LM-63-2030'"}));
  EXPECT_TRUE(failsWith(parseIes("IESNA:LM-63-2002\n[TEST no bracket\nTILT=NONE\n" + std::string(kRotational), "bad.ies"),
                        {"bad.ies:2:", "keyword line"}));
}

TEST(Ies, ReportsMissingFile) {
  EXPECT_TRUE(failsWith(parseIesFile(photometryPath("no_such_file.ies")), {"no_such_file.ies", "cannot open"}));
}

}  // namespace
}  // namespace fogbeam
