// The docs' key tables are the one description of every configuration key (type, unit, default,
// range, meaning); the parsers keep key names only (config::KeySpec). These tests hold the two
// to each other through the registry plugin::configKeyTables(): the table under each entry's
// heading lists exactly the keys the parser accepts there, and every key table of the format
// docs is an entry, so that no table goes unchecked. They live here because the service library
// links every format.
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/scene/sections.hpp>
#include <fogbeam/util/files.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstddef>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace fogbeam::plugin {
namespace {

/// The pages whose key tables the registry binds: each format's own page.
constexpr std::array<std::string_view, 4> kFormatDocs{"scene.md", "scenario.md", "service.md", "can.md"};

std::string docsPath(std::string_view doc) { return std::string(FOGBEAM_CONFIG_DIR) + "/../docs/" + std::string(doc); }

std::string trim(std::string_view s) {
  const std::size_t b = s.find_first_not_of(" \t");
  if (b == std::string_view::npos) return {};
  const std::size_t e = s.find_last_not_of(" \t\r");
  return std::string(s.substr(b, e - b + 1));
}

/// A Markdown table: the heading it is under, the line of its header row, its header's first
/// cell, and each body row's first cell with its line.
struct DocTable {
  std::string heading;
  std::size_t line = 0;
  std::string firstHeader;
  std::vector<std::pair<std::string, std::size_t>> rows;
};

/// The first cell of a table row "| a | b |". Pipes inside cells are escaped ("\|") in these
/// docs, and no key holds one, so the first unescaped '|' after the leading one ends it.
std::string firstCell(std::string_view row) {
  row.remove_prefix(1);
  std::size_t bar = 0;
  while ((bar = row.find('|', bar)) != std::string_view::npos && bar > 0 && row[bar - 1] == '\\') ++bar;
  return trim(row.substr(0, bar));
}

/// Every table of a Markdown text with the heading it is under. Fenced code blocks are skipped:
/// a TOML comment there starts with '#' like a heading.
std::vector<DocTable> tablesOf(std::string_view text) {
  std::vector<DocTable> tables;
  std::string heading;
  bool inCode = false, inTable = false;
  std::size_t lineNo = 0;
  while (!text.empty()) {
    const std::size_t nl = text.find('\n');
    const std::string_view line = text.substr(0, nl);
    text.remove_prefix(nl == std::string_view::npos ? text.size() : nl + 1);
    ++lineNo;
    if (line.starts_with("```")) {
      inCode = !inCode;
      inTable = false;
    } else if (inCode) {
      continue;
    } else if (line.starts_with('#')) {
      heading = trim(line.substr(line.find_first_not_of('#')));
      inTable = false;
    } else if (!line.starts_with('|')) {
      inTable = false;
    } else if (!inTable) {
      tables.push_back(DocTable{heading, lineNo, firstCell(line), {}});
      inTable = true;
    } else if (const std::string cell = firstCell(line); cell.find_first_not_of("-: ") != std::string::npos) {
      tables.back().rows.emplace_back(cell, lineNo);  // not the |---|---| separator
    }
  }
  return tables;
}

/// A table of keys: its header's first cell is "Key" (other tables list options, fields, columns).
bool isKeyTable(const DocTable& t) { return t.firstHeader == "Key"; }

/// What is wrong with the docs table of `entry` in `text` (the page entry.doc): one message per
/// problem, each naming the page, the heading and the key. Empty when the table lists exactly
/// entry.keys, each once.
std::vector<std::string> problemsOf(std::string_view text, const config::KeyTable& entry) {
  const std::string where = "docs/" + std::string(entry.doc) + ", key table under \"" + std::string(entry.heading) +
                            "\" (" + std::string(entry.sections) + ")";
  std::vector<DocTable> found;
  for (DocTable& t : tablesOf(text)) {
    if (t.heading == entry.heading && isKeyTable(t)) found.push_back(std::move(t));
  }
  if (found.empty()) return {where + ": no such table (a heading with this text, then | Key | … |)"};
  if (found.size() > 1) {
    std::string lines;
    for (const DocTable& t : found) lines += (lines.empty() ? "" : ", ") + std::to_string(t.line);
    return {where + ": " + std::to_string(found.size()) + " key tables under this heading text (lines " + lines +
            "): give each table a heading of its own"};
  }
  std::vector<std::string> problems;
  std::map<std::string, std::size_t, std::less<>> listed;  // key → its row's line
  for (const auto& [cell, line] : found.front().rows) {
    const std::string at = where + ", line " + std::to_string(line) + ": ";
    const bool oneKey = cell.size() > 2 && cell.front() == '`' && cell.find('`', 1) == cell.size() - 1;
    if (!oneKey) {
      problems.push_back(at + "first column " + cell + " is not one key in backticks");
      continue;
    }
    const std::string key = cell.substr(1, cell.size() - 2);
    if (!listed.emplace(key, line).second) problems.push_back(at + "key `" + key + "` listed twice");
  }
  for (std::string_view key : entry.keys) {
    if (!listed.contains(key)) {
      problems.push_back(where + ": missing key `" + std::string(key) +
                         "`: the parser accepts it, the table has no row for it");
    }
  }
  for (const auto& [key, line] : listed) {
    if (std::find(entry.keys.begin(), entry.keys.end(), key) == entry.keys.end()) {
      problems.push_back(where + ", line " + std::to_string(line) + ": extra key `" + key +
                         "`: the table lists it, the parser does not accept it");
    }
  }
  return problems;
}

/// The text of a docs page (empty, with a test failure, when it cannot be read).
std::string docText(std::string_view doc) {
  auto text = readTextFile(docsPath(doc));
  if (!text) {
    ADD_FAILURE() << text.error().message;
    return {};
  }
  return std::move(text).value();
}

TEST(ConfigDocs, EveryKeyTableListsExactlyTheParsersKeys) {
  const std::vector<config::KeyTable> registry = configKeyTables();
  ASSERT_FALSE(registry.empty());
  std::map<std::string_view, std::string> pages;
  for (const config::KeyTable& entry : registry) {
    EXPECT_FALSE(entry.keys.empty()) << entry.doc << " \"" << entry.heading << "\": no keys";
    auto it = pages.find(entry.doc);
    if (it == pages.end()) it = pages.emplace(entry.doc, docText(entry.doc)).first;
    for (const std::string& problem : problemsOf(it->second, entry)) ADD_FAILURE() << problem;
  }
}

TEST(ConfigDocs, EveryKeyTableOfTheFormatDocsIsInTheRegistry) {
  const std::vector<config::KeyTable> registry = configKeyTables();
  std::set<std::pair<std::string_view, std::string_view>> entries;
  std::set<std::string_view> docs;
  for (const config::KeyTable& e : registry) {
    EXPECT_TRUE(entries.emplace(e.doc, e.heading).second)
        << "two registry entries for docs/" << e.doc << " \"" << e.heading << "\": one table, one entry (union the lists)";
    docs.insert(e.doc);
  }
  EXPECT_EQ(docs, std::set<std::string_view>(kFormatDocs.begin(), kFormatDocs.end()));
  std::size_t keyTables = 0;
  for (std::string_view doc : kFormatDocs) {
    for (const DocTable& t : tablesOf(docText(doc))) {
      if (!isKeyTable(t)) continue;
      ++keyTables;
      EXPECT_TRUE(entries.contains({doc, t.heading}))
          << "docs/" << doc << ":" << t.line << ": the key table under \"" << t.heading
          << "\" is in no registry entry (configKeyTables()), so nothing checks it against a parser";
    }
  }
  EXPECT_EQ(keyTables, registry.size());
}

// The check itself fails, naming page, heading and key, on the real scene.md with the [fog]
// table's albedo row deleted and a bogus row, a duplicate and a row without backticks added.
TEST(ConfigDocs, TheCheckNamesAMissingRowAndABogusOne) {
  const std::vector<config::KeyTable> scene = config::sceneKeyTables();
  const auto fog = std::find_if(scene.begin(), scene.end(), [](const config::KeyTable& t) {
    return t.heading == "`[fog]`: homogeneous medium";
  });
  ASSERT_NE(fog, scene.end());
  const std::string real = docText("scene.md");
  ASSERT_TRUE(problemsOf(real, *fog).empty());

  std::string doc = real;
  const std::size_t albedo = doc.find("| `albedo` |");
  ASSERT_NE(albedo, std::string::npos);
  doc.erase(albedo, doc.find('\n', albedo) + 1 - albedo);
  doc.insert(albedo, "| `albedoo` | number | | | | bogus |\n| `phase` | again |\n| albedo | no backticks |\n");
  const std::vector<std::string> problems = problemsOf(doc, *fog);
  ASSERT_EQ(problems.size(), 4u) << ::testing::PrintToString(problems);
  const std::string where = "docs/scene.md, key table under \"`[fog]`: homogeneous medium\"";
  auto has = [&](const std::string& what) {
    return std::any_of(problems.begin(), problems.end(), [&](const std::string& p) {
      return p.starts_with(where) && p.find(what) != std::string::npos;
    });
  };
  EXPECT_TRUE(has("missing key `albedo`: the parser accepts it")) << ::testing::PrintToString(problems);
  EXPECT_TRUE(has("extra key `albedoo`: the table lists it, the parser does not accept it"));
  EXPECT_TRUE(has("key `phase` listed twice"));
  EXPECT_TRUE(has("first column albedo is not one key in backticks"));

  // A heading that is not there, or two key tables under one heading text.
  config::KeyTable elsewhere = *fog;
  elsewhere.heading = "`[fogg]`";
  ASSERT_EQ(problemsOf(real, elsewhere).size(), 1u);
  EXPECT_NE(problemsOf(real, elsewhere).front().find("no such table"), std::string::npos);
  const std::string twice = "## `[fog]`: homogeneous medium\n\n| Key |\n|---|\n| `g` |\n\ntext\n\n| Key |\n|---|\n| `g` |\n";
  ASSERT_EQ(problemsOf(twice, *fog).size(), 1u);
  EXPECT_NE(problemsOf(twice, *fog).front().find("2 key tables under this heading text (lines 3, 9)"),
            std::string::npos)
      << problemsOf(twice, *fog).front();
}

}  // namespace
}  // namespace fogbeam::plugin
