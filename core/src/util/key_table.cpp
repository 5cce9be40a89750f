// fogbeam — key lists and their docs tables (key_table.hpp).
#include <fogbeam/util/key_table.hpp>

namespace fogbeam::config {

std::vector<std::string_view> keyNames(std::initializer_list<std::span<const KeySpec>> lists) {
  std::vector<std::string_view> names;
  for (std::span<const KeySpec> list : lists) {
    for (const KeySpec& k : list) names.push_back(k.name);
  }
  return names;
}

}  // namespace fogbeam::config
