// libFuzzer target (issue 6): UDP protocol v1 datagrams (ipc/protocol.hpp).
// Built by the fuzz preset (clang, -fsanitize=fuzzer,address,undefined); run by scripts/fuzz.sh.
#include <fogbeam/ipc/protocol.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <span>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)text;
  // Any datagram decodes without reading out of bounds; what decodes encodes back to itself.
  const auto r = fogbeam::ipc::decode(std::span<const std::uint8_t>(data, size));
  if (r.ok) {
    const auto again = fogbeam::ipc::encode(r.message);
    const auto r2 = fogbeam::ipc::decode(again);
    if (!r2.ok || again.size() != size) __builtin_trap();
  }
  return 0;
}
