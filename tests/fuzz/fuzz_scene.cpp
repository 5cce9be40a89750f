// libFuzzer target (issue 6): scene files (scene/scene.hpp).
// Built by the fuzz preset (clang, -fsanitize=fuzzer,address,undefined); run by scripts/fuzz.sh.
#include <fogbeam/scene/scene.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)text;
  // Relative paths resolve against the corpus directory of shipped files; absolute ones are
  // checked to be regular files before they are read (no /dev/zero).
  (void)fogbeam::parseScene(text, "fuzz.toml", FOGBEAM_FUZZ_CONFIG_DIR "/scenes");
  return 0;
}
