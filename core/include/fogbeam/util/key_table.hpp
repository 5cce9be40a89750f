// fogbeam — the keys a configuration format accepts, by name, and where the documentation
// describes them. Every format (docs/scene.md, docs/scenario.md, docs/service.md, docs/can.md)
// checks each table of a file against a list of KeySpec (config::Section::checkKeys in
// toml_section.hpp); what a key means (type, unit, default, range) is written in one place only,
// a row of the format's key table in docs/. KeyTable binds a list to its docs table, so that a
// test (tests/plugin/test_config_docs.cpp) can hold the two to each other. Kept apart from
// toml_section.hpp so that a format's public header can offer its key tables without TOML.
//
// Thread-safety: plain values and a pure function.
#pragma once

#include <initializer_list>
#include <span>
#include <string_view>
#include <vector>

namespace fogbeam::config {

/// One accepted key, by name only: its description is its row in the docs.
struct KeySpec {
  std::string_view name;
};

/// A key table of the documentation and the keys it must list: the registry entry that binds a
/// parser's key lists to the docs (plugin::configKeyTables() gathers every format's). A list
/// several sections share (the scene's [fog] in scenarios and service configs) has one entry,
/// at the table that documents it; a section whose keys are the union of two lists
/// (checkKeys(allowed, alsoAllowed)) has an entry per table, or one with the union when its docs
/// table lists both.
struct KeyTable {
  std::string_view doc;       ///< the docs page, relative to docs/: "scene.md"
  std::string_view heading;   ///< the heading the table is under, as written after the #s
  std::string_view sections;  ///< which sections of which formats accept these keys (for messages)
  std::vector<std::string_view> keys;  ///< exactly the keys the table lists, in any order
};

/// The names of `lists`, concatenated in order: a KeyTable's keys.
[[nodiscard]] std::vector<std::string_view> keyNames(std::initializer_list<std::span<const KeySpec>> lists);

}  // namespace fogbeam::config
