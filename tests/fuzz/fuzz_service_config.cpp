// libFuzzer target (issue 6): service config layers (plugin/service_config.hpp).
// Built by the fuzz preset (clang, -fsanitize=fuzzer,address,undefined); run by scripts/fuzz.sh.
#include <fogbeam/plugin/service_config.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)text;
  fogbeam::plugin::ServiceConfig c;
  (void)fogbeam::plugin::applyServiceLayer(c, text, "fuzz.toml", FOGBEAM_FUZZ_CONFIG_DIR "/service");
  return 0;
}
