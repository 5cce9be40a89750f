// fogbeam — EULUMDAT (.ldt) photometric files → TabulatedProfile.
//
// A pure function of the text (no I/O but in the *File variant) that never returns a half-parsed
// profile and reports errors as "file:line: what was expected". Thread-safety: reentrant.
#pragma once

#include <fogbeam/physics/profile.hpp>
#include <fogbeam/util/result.hpp>

#include <string>
#include <string_view>

namespace fogbeam {

/// EULUMDAT (.ldt), with its symmetry indicator Isym 0–4. Intensities given in cd/klm are
/// converted to cd with the first lamp set's flux times its lamp count.
[[nodiscard]] Result<TabulatedProfile> parseEulumdat(std::string_view text, const std::string& name);
[[nodiscard]] Result<TabulatedProfile> parseEulumdatFile(const std::string& path);

}  // namespace fogbeam
