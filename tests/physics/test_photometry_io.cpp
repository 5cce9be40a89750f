// loadProfileFile: the parser is picked from the file extension, and parser errors reach
// the caller unchanged (file, line, what was expected).
#include "photometry_test_util.hpp"

#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/physics/profile.hpp>

#include <gtest/gtest.h>

#include <string>
#include <variant>

namespace fogbeam {
namespace {

using testing::failsWith;
using testing::photometryPath;

std::string formatOf(const std::string& file) {
  Result<std::shared_ptr<const Profile>> p = loadProfileFile(photometryPath(file));
  if (!p) return "error: " + p.error().message;
  const auto* tab = std::get_if<TabulatedProfile>(&(*p)->model());
  return tab ? tab->format : "not tabulated";
}

TEST(Photometry, LoadProfileFileDispatchesByExtension) {
  EXPECT_EQ(formatOf("lm63_2002_type_b_headlamp.ies"), "IES LM-63-2002");
  EXPECT_EQ(formatOf("isym0_full.ldt"), "EULUMDAT");
  EXPECT_EQ(formatOf("headlamp_grid.csv"), "CSV grid");
  EXPECT_EQ(formatOf("upper_case_extension.IES"), "IES LM-63-1986");
}

TEST(Photometry, LoadProfileFileRejectsUnknownExtension) {
  EXPECT_TRUE(failsWith(loadProfileFile(photometryPath("lamp_vertical.tilt")),
                        {"lamp_vertical.tilt", "unknown profile format '.tilt'"}));
}

TEST(Photometry, LoadProfileFileReportsMissingFile) {
  EXPECT_TRUE(failsWith(loadProfileFile(photometryPath("missing.ldt")), {"missing.ldt", "cannot open"}));
}

TEST(Photometry, LoadProfileFilePassesParserErrorsThrough) {
  EXPECT_TRUE(failsWith(loadProfileFile(photometryPath("bad_vertical_count.ies")),
                        {"bad_vertical_count.ies:7:", "vertical angles in ascending order"}));
}

TEST(Photometry, LoadedHeadlampPeaksBelowTheAxis) {
  Result<std::shared_ptr<const Profile>> p = loadProfileFile(photometryPath("lm63_2002_type_b_headlamp.ies"));
  ASSERT_TRUE(p) << p.error().message;
  const Profile::Peak peak = (*p)->peak();
  EXPECT_NEAR(peak.intensity_cd, 4800.0, 1e-9);
  // H = 0, V = −5°: straight ahead, below the horizon (−z).
  EXPECT_NEAR(peak.direction.y, 0.0, 1e-12);
  EXPECT_NEAR(peak.direction.z, -std::sin(radians(5.0)), 1e-12);
}

}  // namespace
}  // namespace fogbeam
