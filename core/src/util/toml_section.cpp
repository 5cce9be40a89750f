// fogbeam — typed TOML access shared by every configuration parser (toml_section.hpp).
#include <fogbeam/util/toml_section.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <system_error>
#include <utility>

namespace fogbeam::config {

// ---- Messages -------------------------------------------------------------------------------

std::string formatNumber(double x) {
  std::array<char, 32> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), x);
  if (ec != std::errc()) return "?";
  return std::string(buf.data(), end);
}

std::string inQuotes(std::string_view s) { return "\"" + std::string(s) + "\""; }

// What a node holds, for "found …": a value as written, or its kind.
std::string describeNode(const toml::node& n) {
  if (const auto* v = n.as_integer()) return std::to_string(v->get());
  if (const auto* v = n.as_floating_point()) {
    // As a float: "found 320.0" where an integer is expected, not "found 320".
    std::string t = formatNumber(v->get());
    if (t.find_first_of(".eEin") == std::string::npos) t += ".0";
    return t;
  }
  if (const auto* v = n.as_string()) return "the string " + inQuotes(v->get());
  if (const auto* v = n.as_boolean()) return std::string("the boolean ") + (v->get() ? "true" : "false");
  if (const auto* v = n.as_array()) return "an array of " + std::to_string(v->size()) + " elements";
  if (n.is_table()) return "a table";
  if (n.is_date()) return "a date";
  if (n.is_time()) return "a time";
  if (n.is_date_time()) return "a date-time";
  return "an unknown value";
}

namespace {

std::size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0u : 1u)});
      diag = up;
    }
  }
  return row[b.size()];
}

}  // namespace

// ---- Range -----------------------------------------------------------------------------------

bool Range::contains(double x) const {
  if (!std::isfinite(x)) return false;
  return (loOpen ? x > lo : x >= lo) && (hiOpen ? x < hi : x <= hi);
}

std::string Range::expectation() const {
  const bool hasLo = std::isfinite(lo), hasHi = std::isfinite(hi);
  if (!hasLo && !hasHi) return "a finite number";
  if (!hasHi) return std::string("a number ") + (loOpen ? "> " : ">= ") + formatNumber(lo);
  if (!hasLo) return std::string("a number ") + (hiOpen ? "< " : "<= ") + formatNumber(hi);
  return std::string("a number in ") + (loOpen ? "(" : "[") + formatNumber(lo) + ", " + formatNumber(hi) +
         (hiOpen ? ")" : "]");
}

// ---- Section -------------------------------------------------------------------------------

void Section::fail(std::size_t line, std::string_view key, const std::string& what) const {
  std::string where = label_;
  if (!key.empty()) where += (where.empty() ? "" : " ") + std::string(key);
  throw ConfigError{fileError(file_, line, where.empty() ? what : where + ": " + what)};
}

void Section::failAt(const toml::node& n, std::string_view key, const std::string& what) const {
  fail(lineOf(n.source()), key, what);
}

void Section::checkKeys(std::span<const KeySpec> allowed, std::span<const KeySpec> alsoAllowed) const {
  auto known = [&](std::string_view k) {
    auto is = [&](const KeySpec& s) { return s.name == k; };
    return std::any_of(allowed.begin(), allowed.end(), is) || std::any_of(alsoAllowed.begin(), alsoAllowed.end(), is);
  };
  for (const auto& [key, node] : table_) {
    const std::string_view k = key.str();
    if (known(k)) continue;
    std::string what = (label_.empty() ? "unknown top-level key '" : "unknown key '") + std::string(k) + "'";
    std::string_view best;
    std::size_t bestDistance = 3;  // suggest only near misses (at most 2 edits)
    for (std::span<const KeySpec> list : {allowed, alsoAllowed}) {
      for (const KeySpec& s : list) {
        if (const std::size_t d = editDistance(k, s.name); d < bestDistance) {
          bestDistance = d;
          best = s.name;
        }
      }
    }
    if (!best.empty()) what += " (did you mean '" + std::string(best) + "'?)";
    fail(lineOf(key.source()), "", what);
  }
}

void Section::missing(std::string_view key, const std::string& expected) const {
  fail(line(), key, "missing (expected " + expected + ")");
}

void Section::forbid(std::string_view key, const std::string& why) const {
  if (const toml::node* n = find(key)) failAt(*n, key, why);
}

double Section::numberOf(const toml::node& n, std::string_view key, const Range& r) const {
  double x = 0.0;
  if (const auto* f = n.as_floating_point()) {
    x = f->get();
  } else if (const auto* i = n.as_integer()) {
    x = static_cast<double>(i->get());
  } else {
    failAt(n, key, "expected " + r.expectation() + ", found " + describeNode(n));
  }
  if (!r.contains(x)) failAt(n, key, "expected " + r.expectation() + ", found " + describeNode(n));
  return x;
}

std::optional<double> Section::optNumber(std::string_view key, const Range& r) const {
  const toml::node* n = find(key);
  if (!n) return std::nullopt;
  return numberOf(*n, key, r);
}

double Section::number(std::string_view key, const Range& r, double fallback) const {
  return optNumber(key, r).value_or(fallback);
}

double Section::number(std::string_view key, const Range& r) const {
  if (auto x = optNumber(key, r)) return *x;
  missing(key, r.expectation());
}

std::optional<std::int64_t> Section::optInteger(std::string_view key, std::int64_t lo, std::int64_t hi) const {
  const toml::node* n = find(key);
  if (!n) return std::nullopt;
  const auto* i = n->as_integer();
  if (!i || i->get() < lo || i->get() > hi) {
    failAt(*n, key,
           "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], found " + describeNode(*n));
  }
  return i->get();
}

std::int64_t Section::integer(std::string_view key, std::int64_t lo, std::int64_t hi) const {
  if (auto v = optInteger(key, lo, hi)) return *v;
  missing(key, "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
}

std::int64_t Section::integer(std::string_view key, std::int64_t lo, std::int64_t hi, std::int64_t fallback) const {
  return optInteger(key, lo, hi).value_or(fallback);
}

std::optional<bool> Section::optBoolean(std::string_view key) const {
  const toml::node* n = find(key);
  if (!n) return std::nullopt;
  const auto* b = n->as_boolean();
  if (!b) failAt(*n, key, "expected true or false, found " + describeNode(*n));
  return b->get();
}

std::optional<std::vector<double>> Section::optNumbers(std::string_view key, std::size_t count, const Range& r) const {
  const toml::node* n = find(key);
  if (!n) return std::nullopt;
  const auto* a = n->as_array();
  if (!a || a->size() != count) {
    failAt(*n, key, "expected an array of " + std::to_string(count) + " numbers, found " + describeNode(*n));
  }
  std::vector<double> v(count);
  for (std::size_t c = 0; c < count; ++c) {
    v[c] = numberOf(*a->get(c), std::string(key) + "[" + std::to_string(c) + "]", r);
  }
  return v;
}

std::optional<std::string> Section::optString(std::string_view key) const {
  const toml::node* n = find(key);
  if (!n) return std::nullopt;
  const auto* s = n->as_string();
  if (!s) failAt(*n, key, "expected a string, found " + describeNode(*n));
  return s->get();
}

std::string Section::string(std::string_view key, const std::string& expected) const {
  if (auto s = optString(key)) return *s;
  missing(key, expected);
}

std::string Section::choice(std::string_view key, std::span<const std::string_view> choices,
                            std::string_view fallback) const {
  const auto s = optString(key);
  if (!s) return std::string(fallback);
  if (std::find(choices.begin(), choices.end(), *s) != choices.end()) return *s;
  std::string expected;
  for (std::size_t i = 0; i < choices.size(); ++i) {
    expected += (i == 0 ? "" : i + 1 == choices.size() ? " or " : ", ") + inQuotes(choices[i]);
  }
  failAt(*find(key), key, "expected " + expected + ", found " + inQuotes(*s));
}

std::optional<std::vector<std::string>> Section::optStrings(std::string_view key) const {
  const toml::node* n = find(key);
  if (!n) return std::nullopt;
  const auto* a = n->as_array();
  if (!a) failAt(*n, key, "expected an array of strings, found " + describeNode(*n));
  std::vector<std::string> out;
  for (std::size_t i = 0; i < a->size(); ++i) {
    const auto* s = a->get(i)->as_string();
    if (!s || s->get().empty()) {
      failAt(*a->get(i), std::string(key) + "[" + std::to_string(i) + "]",
             "expected a non-empty string, found " + describeNode(*a->get(i)));
    }
    out.push_back(s->get());
  }
  return out;
}

const toml::table* Section::optTable(std::string_view key) const {
  const toml::node* n = find(key);
  if (!n) return nullptr;
  const auto* t = n->as_table();
  if (!t) failAt(*n, key, "expected a table [" + std::string(key) + "], found " + describeNode(*n));
  return t;
}

const toml::table& Section::requiredTable(std::string_view key) const {
  if (const toml::table* t = optTable(key)) return *t;
  // A missing top-level table has no line of its own: the message names the file only.
  fail(label_.empty() ? 0 : line(), "", "missing table [" + std::string(key) + "]");
}

}  // namespace fogbeam::config
