// writeIes: LM-63-2002 output that parseIes reads back to the same profile (1e-6 relative),
// with the required keywords, short lines and no exponent notation.
#include <fogbeam/physics/ies.hpp>
#include <fogbeam/physics/ies_writer.hpp>
#include <fogbeam/physics/profile.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

namespace fogbeam {
namespace {

std::vector<double> radiansOf(const std::vector<double>& deg) {
  std::vector<double> r;
  for (double d : deg) r.push_back(radians(d));
  return r;
}

// A profile whose values span eight decades and whose angles need many digits.
TabulatedProfile makeTestProfile(PhotometricType type, const std::vector<double>& hDeg,
                                 const std::vector<double>& vDeg) {
  TabulatedProfile t;
  t.type = type;
  t.horizontal = radiansOf(hDeg);
  t.vertical = radiansOf(vDeg);
  for (std::size_t ih = 0; ih < hDeg.size(); ++ih)
    for (std::size_t iv = 0; iv < vDeg.size(); ++iv) {
      const double k = static_cast<double>(ih * vDeg.size() + iv);
      t.candela.push_back(k == 3.0 ? 0.0 : 1.234567891e-3 * std::pow(10.0, std::fmod(k * 0.731, 8.0)) * (1.0 + 0.1 * std::sin(k)));
    }
  t.keywords = {{"TEST", "T-42"}, {"TESTLAB", "lab"}, {"ISSUEDATE", "2026-11-21"}, {"MANUFAC", "ACME"},
                {"LUMCAT", "X1"}, {"LUMINAIRE", "test lamp"}, {"OTHER", "first"}, {"OTHER", "second"}};
  return t;
}

void expectSameProfile(const TabulatedProfile& a, const TabulatedProfile& b) {
  EXPECT_EQ(a.type, b.type);
  ASSERT_EQ(a.horizontal.size(), b.horizontal.size());
  ASSERT_EQ(a.vertical.size(), b.vertical.size());
  ASSERT_EQ(a.candela.size(), b.candela.size());
  for (std::size_t i = 0; i < a.horizontal.size(); ++i)
    EXPECT_NEAR(b.horizontal[i], a.horizontal[i], 1e-6 * std::max(1e-3, std::abs(a.horizontal[i]))) << "H " << i;
  for (std::size_t i = 0; i < a.vertical.size(); ++i)
    EXPECT_NEAR(b.vertical[i], a.vertical[i], 1e-6 * std::max(1e-3, std::abs(a.vertical[i]))) << "V " << i;
  for (std::size_t i = 0; i < a.candela.size(); ++i)
    EXPECT_NEAR(b.candela[i], a.candela[i], 1e-6 * a.candela[i]) << "candela " << i;
}

TEST(IesWriter, TypeBRoundTripsThroughParseIesToOnePartPerMillion) {
  const TabulatedProfile original =
      makeTestProfile(PhotometricType::B, {-90, -12.3456789, -0.1, 0, 0.123456789, 45.5, 90},
                      {-90, -3.3333333, -0.57, 0, 0.05, 1.5, 17.25, 90});
  const Result<TabulatedProfile> parsed = parseIes(writeIes(original), "roundtrip.ies");
  ASSERT_TRUE(parsed) << parsed.error().message;
  expectSameProfile(original, *parsed);
  EXPECT_EQ(parsed->symmetry, PlaneSymmetry::None);
  EXPECT_EQ(parsed->format, "IES LM-63-2002");
  EXPECT_EQ(parsed->keywords, original.keywords);
}

TEST(IesWriter, TypeCAndTypeARoundTrip) {
  const TabulatedProfile c = makeTestProfile(PhotometricType::C, {0, 30, 90, 180, 270, 330}, {0, 5, 45, 90, 135, 180});
  const Result<TabulatedProfile> pc = parseIes(writeIes(c), "c.ies");
  ASSERT_TRUE(pc) << pc.error().message;
  expectSameProfile(c, *pc);

  const TabulatedProfile a = makeTestProfile(PhotometricType::A, {-90, -10, 0, 10, 90}, {-90, -1, 0, 1, 90});
  const Result<TabulatedProfile> pa = parseIes(writeIes(a), "a.ies");
  ASSERT_TRUE(pa) << pa.error().message;
  expectSameProfile(a, *pa);
}

TEST(IesWriter, MirroredTypeBKeepsItsHalfRange) {
  TabulatedProfile half = makeTestProfile(PhotometricType::B, {0, 5, 90}, {-90, 0, 90});
  half.symmetry = PlaneSymmetry::MirrorH;
  const Result<TabulatedProfile> parsed = parseIes(writeIes(half), "half.ies");
  ASSERT_TRUE(parsed) << parsed.error().message;
  EXPECT_EQ(parsed->symmetry, PlaneSymmetry::MirrorH);
  expectSameProfile(half, *parsed);
}

TEST(IesWriter, WritesHeaderRequiredKeywordsAndShortLinesWithoutExponents) {
  TabulatedProfile t = makeTestProfile(PhotometricType::B, {-90, 0, 90}, {-90, 0, 90});
  t.keywords = {{"OTHER", "only this"}};
  t.candela[0] = 1.5e-7;  // tiny and huge values: fixed notation, still 7 significant digits
  t.candela[1] = 2.5e9;
  const std::string text = writeIes(t);
  std::istringstream in(text);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "IESNA:LM-63-2002");
  for (const char* k : {"[TEST]", "[TESTLAB]", "[ISSUEDATE]", "[MANUFAC]", "[LUMCAT]", "[LUMINAIRE]", "[OTHER] only this"})
    EXPECT_NE(text.find(std::string("\n") + k), std::string::npos) << k;
  EXPECT_NE(text.find("\nTILT=NONE\n1 -1 1 3 3 2 2 0 0 0\n1 1 0\n"), std::string::npos);
  std::size_t lineNo = 1;
  while (std::getline(in, line)) {
    ++lineNo;
    EXPECT_LT(line.size(), 80U) << "line " << lineNo;
    if (line.rfind("[", 0) != 0 && line != "TILT=NONE") {
      EXPECT_EQ(line.find_first_of("eE"), std::string::npos) << "line " << lineNo << ": " << line;
    }
  }
  const Result<TabulatedProfile> parsed = parseIes(text, "t.ies");
  ASSERT_TRUE(parsed) << parsed.error().message;
  EXPECT_NEAR(parsed->candela[0], 1.5e-7, 1e-6 * 1.5e-7);
  EXPECT_NEAR(parsed->candela[1], 2.5e9, 1e-6 * 2.5e9);
}

TEST(IesWriter, LongKeywordValuesContinueOnMoreLines) {
  TabulatedProfile t = makeTestProfile(PhotometricType::B, {-90, 0, 90}, {-90, 0, 90});
  std::string longText;
  for (int i = 0; i < 30; ++i) longText += "word" + std::to_string(i) + (i < 29 ? " " : "");
  t.keywords.emplace_back("OTHER", longText);
  const std::string text = writeIes(t);
  EXPECT_NE(text.find("\n[MORE] "), std::string::npos);
  const Result<TabulatedProfile> parsed = parseIes(text, "long.ies");
  ASSERT_TRUE(parsed) << parsed.error().message;
  EXPECT_EQ(parsed->keywords.back().second, longText);
}

}  // namespace
}  // namespace fogbeam
