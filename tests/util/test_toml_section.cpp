// The generic TOML access every configuration format is read with (util/toml_section.hpp): typed,
// range-checked values whose errors name file, line, section and key; unknown keys with a "did
// you mean"; TOML syntax errors with line and column. The scene, scenario and service parsers'
// own tests check their keys; these check the messages the module builds for all of them.
#include <fogbeam/util/toml_section.hpp>

#include <gtest/gtest.h>

#include <array>
#include <string>

namespace fogbeam::config {
namespace {

/// Runs `f(section)` on [s] of `text` (file "t.toml") and returns the error message, or "" when
/// nothing failed.
template <class F>
std::string errorOf(const std::string& text, F&& f) {
  const Result<Ok> r = parseTomlFile<Ok>(text, "t.toml", [&](const toml::table& root) -> Result<Ok> {
    const Section top("t.toml", root, "");
    const Section s("t.toml", top.requiredTable("s"), "[s]");
    f(s);
    return Ok{};
  });
  return r ? std::string() : r.error().message;
}

constexpr std::array kKeys{KeySpec{"visibility_m"}, KeySpec{"albedo"}};

TEST(TomlSection, ValuesWithinTheirRangeAndFallbacks) {
  const std::string none = errorOf("[s]\nvisibility_m = 60\nalbedo = 0.9\n", [](const Section& s) {
    s.checkKeys(kKeys);
    EXPECT_EQ(s.number("visibility_m", kPositive), 60.0);  // an integer is a number
    EXPECT_EQ(s.number("albedo", kUnit, 1.0), 0.9);
    EXPECT_EQ(s.number("absent", kUnit, 0.25), 0.25);
    EXPECT_FALSE(s.optNumber("absent", kUnit).has_value());
    EXPECT_EQ(s.integer("visibility_m", 1, 100), 60);
  });
  EXPECT_EQ(none, "");
}

TEST(TomlSection, OutOfRangeNamesFileLineSectionKeyAndTheRange) {
  EXPECT_EQ(errorOf("[s]\n\nalbedo = 2\n", [](const Section& s) { (void)s.number("albedo", kUnit); }),
            "t.toml:3: [s] albedo: expected a number in [0, 1], found 2");
  EXPECT_EQ(errorOf("[s]\nvisibility_m = 0\n", [](const Section& s) { (void)s.number("visibility_m", kPositive); }),
            "t.toml:2: [s] visibility_m: expected a number > 0, found 0");
  EXPECT_EQ(errorOf("[s]\nalbedo = \"x\"\n", [](const Section& s) { (void)s.number("albedo", kUnit); }),
            "t.toml:2: [s] albedo: expected a number in [0, 1], found the string \"x\"");
}

TEST(TomlSection, MissingKeysSayWhatWasExpected) {
  const std::string e = errorOf("[s]\nalbedo = 1\n", [](const Section& s) { (void)s.number("visibility_m", kPositive); });
  EXPECT_NE(e.find("t.toml:1: [s] visibility_m: missing (expected"), std::string::npos) << e;
}

TEST(TomlSection, UnknownKeysAreErrorsWithTheNearestKnownKey) {
  EXPECT_EQ(errorOf("[s]\nalbedo = 1\nvisibilty_m = 50\n", [](const Section& s) { s.checkKeys(kKeys); }),
            "t.toml:3: [s]: unknown key 'visibilty_m' (did you mean 'visibility_m'?)");
  // Far from every known key: no suggestion.
  EXPECT_EQ(errorOf("[s]\nzzz = 1\n", [](const Section& s) { s.checkKeys(kKeys); }),
            "t.toml:2: [s]: unknown key 'zzz'");
  // Keys the caller accepts on top of the section's own.
  constexpr std::array kExtra{KeySpec{"zzz"}};
  EXPECT_EQ(errorOf("[s]\nzzz = 1\n", [&](const Section& s) { s.checkKeys(kKeys, kExtra); }), "");
}

TEST(TomlSection, ChoicesArraysAndTables) {
  constexpr std::array<std::string_view, 3> kPhases{"isotropic", "henyey-greenstein", "fog-mie"};
  EXPECT_EQ(errorOf("[s]\nphase = \"mie\"\n", [&](const Section& s) { (void)s.choice("phase", kPhases, "isotropic"); }),
            "t.toml:2: [s] phase: expected \"isotropic\", \"henyey-greenstein\" or \"fog-mie\", found \"mie\"");
  EXPECT_EQ(errorOf("[s]\nv = [1, 2]\n", [](const Section& s) { (void)s.optNumbers("v", 3); }),
            "t.toml:2: [s] v: expected an array of 3 numbers, found an array of 2 elements");
  EXPECT_EQ(errorOf("[s]\nv = [1, 2, 3]\n", [](const Section& s) {
              const auto v = s.optNumbers("v", 3, kNonNegative);
              ASSERT_TRUE(v.has_value());
              EXPECT_EQ((*v)[2], 3.0);
            }),
            "");
  EXPECT_EQ(errorOf("[s]\nt = 1\n", [](const Section& s) { (void)s.optTable("t"); }),
            "t.toml:2: [s] t: expected a table [t], found 1");
}

TEST(TomlSection, ArraysOfTablesAreNumberedFromOne) {
  std::vector<std::string> labels;
  const std::string e = errorOf("[s]\n[[s.lamp]]\nx = 1\n[[s.lamp]]\nx = 2\n", [&](const Section& s) {
    s.forEachEntry("lamp", [&](const toml::table&, const std::string& label, std::size_t) { labels.push_back(label); });
  });
  EXPECT_EQ(e, "");
  EXPECT_EQ(labels, (std::vector<std::string>{"[s] [[lamp]] #1", "[s] [[lamp]] #2"}));
}

TEST(TomlSection, SyntaxErrorsGiveLineAndColumn) {
  const Result<Ok> r = parseTomlFile<Ok>("a = 1\nb = = 2\n", "bad.toml", [](const toml::table&) -> Result<Ok> { return Ok{}; });
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().message.rfind("bad.toml:2:", 0), 0u) << r.error().message;
}

TEST(TomlSection, RangesDescribeThemselves) {
  EXPECT_EQ(kAnyFinite.expectation(), "a finite number");
  EXPECT_EQ((Range{0.0, 1.0, true, true}).expectation(), "a number in (0, 1)");
  EXPECT_EQ((Range{-kInf, 5.0, false, false}).expectation(), "a number <= 5");
  EXPECT_FALSE(kAnyFinite.contains(kInf));
  EXPECT_FALSE(kPositive.contains(0.0));
  EXPECT_TRUE(kNonNegative.contains(0.0));
  EXPECT_EQ(formatNumber(0.1), "0.1");
}

}  // namespace
}  // namespace fogbeam::config
