// fogbeam — typed, checked access to TOML configuration files, shared by every file format
// fogbeam reads: scene files (docs/scene.md), scenarios (docs/scenario.md), the service config
// (docs/service.md) and the CAN mapping (docs/can.md). Generic: it knows TOML tables, keys,
// numbers and ranges, nothing of scenes (the scene sections those formats embed, [fog] and
// lamps, are fogbeam/scene/sections.hpp).
//
// Errors read "file:line: [section] key: expected …, found …". A failure is thrown as
// ConfigError from inside a parser so that the checks read as straight-line code; every public
// entry point of a file format (parseScene, parseScenario, …) catches it and returns an Error.
// Unknown keys are always errors, with a "did you mean" for near misses.
//
// Thread-safety: plain functions and values; a Section refers to a table it does not own.
#pragma once

#include <fogbeam/util/key_table.hpp>
#include <fogbeam/util/result.hpp>

#include <toml++/toml.h>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::config {

/// What a parser throws; turned into Result's Error at the file format's entry point.
struct ConfigError {
  Error error;
};

inline constexpr double kInf = std::numeric_limits<double>::infinity();

/// Shortest round-trip decimal form of x.
[[nodiscard]] std::string formatNumber(double x);
[[nodiscard]] std::string inQuotes(std::string_view s);
/// What a node holds, for "found …": a value as written, or its kind.
[[nodiscard]] std::string describeNode(const toml::node& n);
[[nodiscard]] inline std::size_t lineOf(const toml::source_region& r) { return r.begin.line; }

/// A closed or open interval for numeric keys; infinite ends are unbounded.
struct Range {
  double lo = -kInf;
  double hi = kInf;
  bool loOpen = false;
  bool hiOpen = false;

  [[nodiscard]] bool contains(double x) const;
  [[nodiscard]] std::string expectation() const;
};

inline constexpr Range kAnyFinite{};
inline constexpr Range kPositive{0.0, kInf, true, false};
inline constexpr Range kNonNegative{0.0, kInf, false, false};
inline constexpr Range kUnit{0.0, 1.0, false, false};

/// Typed, range-checked access to one TOML table; every failure names file, line, section and
/// key. `file` must outlive the Section.
class Section {
 public:
  Section(const std::string& file, const toml::table& table, std::string label)
      : file_(file), table_(table), label_(std::move(label)) {}

  [[noreturn]] void fail(std::size_t line, std::string_view key, const std::string& what) const;
  [[noreturn]] void failAt(const toml::node& n, std::string_view key, const std::string& what) const;

  /// Rejects every key that is in neither list, suggesting the closest accepted one.
  void checkKeys(std::span<const KeySpec> allowed, std::span<const KeySpec> alsoAllowed = {}) const;

  [[nodiscard]] const toml::node* find(std::string_view key) const { return table_.get(key); }
  [[nodiscard]] std::size_t line() const { return lineOf(table_.source()); }
  [[nodiscard]] const std::string& label() const { return label_; }
  [[nodiscard]] const std::string& file() const { return file_; }
  [[nodiscard]] const toml::table& table() const { return table_; }

  [[noreturn]] void missing(std::string_view key, const std::string& expected) const;
  /// A key that must not appear here: `why` says when it is allowed.
  void forbid(std::string_view key, const std::string& why) const;

  [[nodiscard]] double numberOf(const toml::node& n, std::string_view key, const Range& r) const;
  [[nodiscard]] std::optional<double> optNumber(std::string_view key, const Range& r) const;
  [[nodiscard]] double number(std::string_view key, const Range& r, double fallback) const;
  [[nodiscard]] double number(std::string_view key, const Range& r) const;

  [[nodiscard]] std::optional<std::int64_t> optInteger(std::string_view key, std::int64_t lo, std::int64_t hi) const;
  [[nodiscard]] std::int64_t integer(std::string_view key, std::int64_t lo, std::int64_t hi) const;
  [[nodiscard]] std::int64_t integer(std::string_view key, std::int64_t lo, std::int64_t hi,
                                     std::int64_t fallback) const;

  [[nodiscard]] std::optional<bool> optBoolean(std::string_view key) const;
  [[nodiscard]] bool boolean(std::string_view key, bool fallback) const { return optBoolean(key).value_or(fallback); }

  /// An array of exactly `n` numbers, each within `r`.
  [[nodiscard]] std::optional<std::vector<double>> optNumbers(std::string_view key, std::size_t n,
                                                              const Range& r = kAnyFinite) const;

  [[nodiscard]] std::optional<std::string> optString(std::string_view key) const;
  [[nodiscard]] std::string string(std::string_view key, const std::string& expected) const;
  /// A string that must be one of `choices`; `fallback` when absent.
  [[nodiscard]] std::string choice(std::string_view key, std::span<const std::string_view> choices,
                                   std::string_view fallback) const;
  /// An array of strings (each non-empty).
  [[nodiscard]] std::optional<std::vector<std::string>> optStrings(std::string_view key) const;

  /// A sub-table, or nullptr when absent; an error when the key holds something else.
  [[nodiscard]] const toml::table* optTable(std::string_view key) const;
  [[nodiscard]] const toml::table& requiredTable(std::string_view key) const;

  /// Calls f(table, label, ordinal from 1) for each table of the array of tables `key`
  /// ([[lamp]], [[channel]] …); nothing when the key is absent.
  template <class F>
  void forEachEntry(std::string_view key, F&& f) const {
    const toml::node* n = find(key);
    if (!n) return;
    const std::string expected = "expected an array of tables [[" + std::string(key) + "]], found ";
    const auto* a = n->as_array();
    if (!a) failAt(*n, key, expected + describeNode(*n));
    for (std::size_t i = 0; i < a->size(); ++i) {
      const toml::node& e = *a->get(i);
      const auto* t = e.as_table();
      if (!t) failAt(e, key, expected + "an array holding " + describeNode(e));
      f(*t, (label_.empty() ? "" : label_ + " ") + "[[" + std::string(key) + "]] #" + std::to_string(i + 1), i + 1);
    }
  }

 private:
  const std::string& file_;
  const toml::table& table_;
  std::string label_;
};

/// Runs `parse` on the TOML text and turns every failure (TOML syntax, ConfigError, allocation)
/// into an Error naming `name`: the entry point of each file format.
template <class T, class F>
Result<T> parseTomlFile(std::string_view text, const std::string& name, F&& parse) {
  try {
    const toml::table root = toml::parse(text, name);
    return parse(root);
  } catch (const toml::parse_error& e) {
    const toml::source_position& at = e.source().begin;
    return Error{name + ":" + std::to_string(at.line) + ":" + std::to_string(at.column) + ": " +
                 std::string(e.description())};
  } catch (const ConfigError& e) {
    return e.error;
  } catch (const std::exception& e) {  // allocation failure and the like: still no throw
    return Error{name + ": " + e.what()};
  }
}

}  // namespace fogbeam::config
