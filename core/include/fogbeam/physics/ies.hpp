// fogbeam — IES LM-63 photometric files (type C photometry) → TabulatedProfile.
//
// A pure function of the text (no I/O but in the *File variant) that never returns a half-parsed
// profile and reports errors as "file:line: what was expected". Thread-safety: reentrant.
#pragma once

#include <fogbeam/physics/profile.hpp>
#include <fogbeam/util/result.hpp>

#include <functional>
#include <string>
#include <string_view>

namespace fogbeam {

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

}  // namespace fogbeam
