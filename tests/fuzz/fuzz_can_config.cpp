// libFuzzer target (issue 6): CAN mapping files (ipc/can_config.hpp).
// Built by the fuzz preset (clang, -fsanitize=fuzzer,address,undefined); run by scripts/fuzz.sh.
#include <fogbeam/ipc/can_config.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)text;
  (void)fogbeam::ipc::parseCanConfig(text, "fuzz.toml", FOGBEAM_FUZZ_CONFIG_DIR);
  return 0;
}
