// fogbeam — writes a TabulatedProfile as an IES LM-63-2002 file (the shipped lamps are made so).
// Thread-safety: reentrant.
#pragma once

#include <fogbeam/physics/profile.hpp>

#include <string>

namespace fogbeam {

/// Writes an IES LM-63-2002 file (absolute photometry, lumens = −1, TILT=NONE) with the
/// given keyword lines. Values are printed with enough digits to round-trip through
/// parseIes to 1e-6 relative.
[[nodiscard]] std::string writeIes(const TabulatedProfile& profile);

}  // namespace fogbeam
