// fogbeam — a lamp's photometric file, whatever its format: picks the parser from the file's
// extension (ies.hpp, eulumdat.hpp, csv_profile.hpp) and wraps the result as a Profile.
// Thread-safety: reentrant.
#pragma once

#include <fogbeam/physics/profile.hpp>
#include <fogbeam/util/result.hpp>

#include <memory>
#include <string>

namespace fogbeam {

/// Loads a profile from a file, picking the parser from the extension (any case):
/// .ies (IES LM-63), .ldt (EULUMDAT), .csv (H–V grid). Errors name file, line and field.
[[nodiscard]] Result<std::shared_ptr<const Profile>> loadProfileFile(const std::string& path);

}  // namespace fogbeam
