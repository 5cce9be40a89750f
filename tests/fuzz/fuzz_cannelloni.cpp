// libFuzzer target (issue 6): cannelloni UDP packets (ipc/cannelloni.hpp).
// Built by the fuzz preset (clang, -fsanitize=fuzzer,address,undefined); run by scripts/fuzz.sh.
#include <fogbeam/ipc/cannelloni.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <span>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)text;
  const auto r = fogbeam::ipc::decodeCannelloni(std::span<const std::uint8_t>(data, size));
  if (r) (void)fogbeam::ipc::encodeCannelloni(*r);
  return 0;
}
