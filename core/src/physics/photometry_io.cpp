// fogbeam — a lamp's photometric file by its extension (photometry_io.hpp).
#include <fogbeam/physics/csv_profile.hpp>
#include <fogbeam/physics/eulumdat.hpp>
#include <fogbeam/physics/ies.hpp>
#include <fogbeam/physics/photometry_io.hpp>

#include <algorithm>
#include <cctype>

namespace fogbeam {

Result<std::shared_ptr<const Profile>> loadProfileFile(const std::string& path) {
  std::string ext;
  if (auto dot = path.find_last_of('.'); dot != std::string::npos) ext = path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  Result<TabulatedProfile> tab = Error{""};
  if (ext == "ies") {
    tab = parseIesFile(path);
  } else if (ext == "ldt") {
    tab = parseEulumdatFile(path);
  } else if (ext == "csv") {
    tab = parseCsvProfileFile(path);
  } else {
    return Error{path + ": unknown profile format '." + ext + "' (expected .ies, .ldt or .csv)"};
  }
  if (!tab) return tab.error();
  return makeProfile(std::move(tab).value());
}

}  // namespace fogbeam
