// fogbeam — readers and writers of photometric data files.
//
// All parsers are pure functions of the text (no I/O except the *File variants), never
// return a half-parsed profile, and report errors as "file:line: what was expected".
// Thread-safety: reentrant.
#pragma once

#include <fogbeam/physics/profile.hpp>
#include <fogbeam/util/result.hpp>

#include <functional>
#include <optional>
#include <string>
#include <string_view>

namespace fogbeam {

/// Reads a whole text file. Error: "path: cannot open (reason)".
[[nodiscard]] Result<std::string> readTextFile(const std::string& path);

/// Resolves a TILT=<file> reference of an IES file to the tilt file's text;
/// returns an Error when it cannot be read.
using IesTiltLoader = std::function<Result<std::string>(const std::string& tiltName)>;

/// IES LM-63 (1986, 1991, 1995, 2002, 2019). `name` is used in messages.
/// TILT=NONE is accepted; TILT=INCLUDE and TILT=<file> are applied when the lamp-to-
/// luminaire geometry is 1 (vertical base-up/down), where the tilt factor multiplies all
/// values at the luminaire's mounted tilt angle of 0°, and rejected with a clear message otherwise;
/// `tiltLoader` may be empty (then TILT=<file> is an error).
[[nodiscard]] Result<TabulatedProfile> parseIes(std::string_view text, const std::string& name,
                                                const IesTiltLoader& tiltLoader = {});
[[nodiscard]] Result<TabulatedProfile> parseIesFile(const std::string& path);

/// EULUMDAT (.ldt), with its symmetry indicator Isym 0–4. Intensities given in cd/klm are
/// converted to cd with the first lamp set's flux times its lamp count.
[[nodiscard]] Result<TabulatedProfile> parseEulumdat(std::string_view text, const std::string& name);
[[nodiscard]] Result<TabulatedProfile> parseEulumdatFile(const std::string& path);

/// CSV grid exported from optics tools (type B angles, degrees):
///   first non-comment row:  a label cell, then H angles ascending
///   each following row:     a V angle, then one candela value per H angle
/// Lines starting with '#' are comments; separators ',' or ';'.
[[nodiscard]] Result<TabulatedProfile> parseCsvProfile(std::string_view text, const std::string& name);
[[nodiscard]] Result<TabulatedProfile> parseCsvProfileFile(const std::string& path);

/// Writes an IES LM-63-2002 file (absolute photometry, lumens = −1, TILT=NONE) with the
/// given keyword lines. Values are printed with enough digits to round-trip through
/// parseIes to 1e-6 relative.
[[nodiscard]] std::string writeIes(const TabulatedProfile& profile);

}  // namespace fogbeam
