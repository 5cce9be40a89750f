// fogbeam — candela grids exported as CSV by optics tools (type B angles) → TabulatedProfile.
//
// A pure function of the text (no I/O but in the *File variant) that never returns a half-parsed
// profile and reports errors as "file:line: what was expected". Thread-safety: reentrant.
#pragma once

#include <fogbeam/physics/profile.hpp>
#include <fogbeam/util/result.hpp>

#include <string>
#include <string_view>

namespace fogbeam {

/// CSV grid exported from optics tools (type B angles, degrees):
///   first non-comment row:  a label cell, then H angles ascending
///   each following row:     a V angle, then one candela value per H angle
/// Lines starting with '#' are comments; separators ',' or ';'.
[[nodiscard]] Result<TabulatedProfile> parseCsvProfile(std::string_view text, const std::string& name);
[[nodiscard]] Result<TabulatedProfile> parseCsvProfileFile(const std::string& path);

}  // namespace fogbeam
