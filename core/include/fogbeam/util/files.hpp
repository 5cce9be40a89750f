// fogbeam — whole text files and the paths that configuration files name. Used by every parser
// of a file (photometry, scenes, scenarios, the service config, DBC and CAN mappings, candump
// logs), which is why it lives here and not with any of them.
// Thread-safety: reentrant.
#pragma once

#include <fogbeam/util/result.hpp>

#include <string>

namespace fogbeam {

/// Reads a whole file as bytes. Error: "path: cannot open (reason)" or "path: read error".
[[nodiscard]] Result<std::string> readTextFile(const std::string& path);

/// `relative` resolved against `baseDir` (unless absolute or baseDir is empty), normalised
/// lexically (no file-system access).
[[nodiscard]] std::string resolvePath(const std::string& baseDir, const std::string& relative);

/// Empty when `path` names a readable regular file, else what is wrong with it ("file not
/// found: …", "not a regular file: …"): a profile or glTF path must not name /dev/zero. A
/// relative `path` is named absolute (against the working directory), so that the message says
/// where the file was looked for.
[[nodiscard]] std::string checkFile(const std::string& path);

}  // namespace fogbeam
