// libFuzzer target (issue 6): CSV intensity tables (physics/photometry_io.hpp).
// Built by the fuzz preset (clang, -fsanitize=fuzzer,address,undefined); run by scripts/fuzz.sh.

#include <fogbeam/physics/csv_profile.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)text;
  (void)fogbeam::parseCsvProfile(text, "fuzz.csv");
  return 0;
}
