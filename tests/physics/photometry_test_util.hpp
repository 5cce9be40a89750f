// Helpers shared by the photometric parser tests (test_ies.cpp, test_eulumdat.cpp,
// test_csv_profile.cpp, test_photometry_io.cpp).
#pragma once

#include <fogbeam/physics/eulumdat.hpp>
#include <fogbeam/physics/ies.hpp>
#include <fogbeam/physics/profile.hpp>

#include <gtest/gtest.h>

#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>

namespace fogbeam::testing {

inline std::string photometryPath(const std::string& file) {
  return std::string(FOGBEAM_TEST_DATA_DIR) + "/photometry/" + file;
}

/// Parses a fixture with `parse` (parseIesFile, parseEulumdatFile, …), expecting success.
inline Result<TabulatedProfile> parseFixtureWith(Result<TabulatedProfile> (*parse)(const std::string&),
                                                 const std::string& file) {
  Result<TabulatedProfile> r = parse(photometryPath(file));
  EXPECT_TRUE(r.has_value()) << (r ? std::string() : r.error().message);
  return r;
}

/// Wraps a parsed profile through the public path (makeProfile validates it again).
inline std::shared_ptr<const Profile> wrap(const TabulatedProfile& tab) {
  Result<std::shared_ptr<const Profile>> p = makeProfile(tab);
  EXPECT_TRUE(p.has_value()) << (p ? std::string() : p.error().message);
  return p ? *p : std::make_shared<const Profile>(IsotropicProfile{-1.0});
}

/// I (cd) in the lamp-frame direction of file angles (degrees) of the given type.
inline double intensityAt(const Profile& p, PhotometricType type, double hDeg, double vDeg) {
  return p.intensity(directionFromAngles(type, radians(hDeg), radians(vDeg)));
}

/// TabulatedProfile::atAngles with angles in degrees.
inline double atDegrees(const TabulatedProfile& t, double hDeg, double vDeg) {
  return t.atAngles(radians(hDeg), radians(vDeg));
}

/// Succeeds when `r` failed with a message containing every one of `parts`.
template <class T>
::testing::AssertionResult failsWith(const Result<T>& r, std::initializer_list<std::string_view> parts) {
  if (r.has_value()) return ::testing::AssertionFailure() << "parsed successfully, expected an error";
  const std::string& m = r.error().message;
  for (std::string_view part : parts)
    if (m.find(part) == std::string::npos)
      return ::testing::AssertionFailure() << "message \"" << m << "\" lacks \"" << part << "\"";
  return ::testing::AssertionSuccess() << m;
}

/// Intensities in tests are exact up to rounding of the direction round trip.
inline constexpr double kTol = 1e-6;

}  // namespace fogbeam::testing
