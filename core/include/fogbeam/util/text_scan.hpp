// fogbeam — text-scanning helpers shared by the parsers of line-oriented text formats: the
// photometric files (ies.cpp, eulumdat.cpp, csv_profile.cpp) and the CAN codecs (ipc/src/dbc.cpp,
// candump.cpp). Thread-safety: pure functions.
//
// Numbers are read with std::from_chars (locale independent, no exceptions) and must
// fill the whole token, so "12abc" is an error rather than 12. Messages follow the
// "file:line: expected …, found …" form of fileError().
#pragma once

#include <fogbeam/util/result.hpp>

#include <charconv>
#include <cmath>
#include <cstddef>
#include <limits>
#include <optional>
#include <algorithm>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace fogbeam::text {

/// One line of a text without its line ending ("\n" or "\r\n"), numbered from 1.
/// `next` is the offset in the text where the following line starts.
struct Line {
  std::string_view text;
  std::size_t number = 0;
  std::size_t next = 0;
};

/// Splits text into lines. A final line without "\n" counts; a trailing "\n" does not
/// open an empty extra line. A leading UTF-8 byte order mark is skipped.
[[nodiscard]] inline std::vector<Line> splitLines(std::string_view text) {
  std::vector<Line> lines;
  std::size_t pos = 0;
  if (text.substr(0, 3) == "\xEF\xBB\xBF") pos = 3;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    const std::size_t next = end == std::string_view::npos ? text.size() : end + 1;
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    lines.push_back(Line{line, lines.size() + 1, next});
    pos = next;
  }
  return lines;
}

/// Separators that never belong to a value: blanks, tabs, line ends, and the DOS
/// end-of-file mark Ctrl-Z that old LM-63 files still carry.
[[nodiscard]] constexpr bool isBlank(char c) noexcept {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v' || c == '\x1a';
}

[[nodiscard]] inline std::string_view trim(std::string_view s) noexcept {
  while (!s.empty() && isBlank(s.front())) s.remove_prefix(1);
  while (!s.empty() && isBlank(s.back())) s.remove_suffix(1);
  return s;
}

/// A token as shown in messages: quoted and cut to 40 characters.
[[nodiscard]] inline std::string quote(std::string_view token) {
  // Built with append() rather than "'" + std::string(...): GCC 12 at -O3 reports a false
  // -Wrestrict in libstdc++'s operator+ for that pattern (GCC bug 105651).
  constexpr std::size_t kMax = 40;
  std::string out;
  out.reserve(std::min(token.size(), kMax) + 5);
  out.push_back('\'');
  out.append(token.substr(0, kMax));
  if (token.size() > kMax) out.append("...");
  out.push_back('\'');
  return out;
}

/// Parses a whole token as a decimal number. A leading '+' is accepted (from_chars does
/// not); with `decimalComma` a single ',' stands for the decimal point (European
/// EULUMDAT and CSV files). Returns nullopt when any character is left over. "inf",
/// "nan" and overflowing values come back as non-finite numbers for the caller to reject.
[[nodiscard]] inline std::optional<double> parseNumber(std::string_view token, bool decimalComma = false) {
  std::string buffer;
  if (decimalComma && token.find(',') != std::string_view::npos) {
    buffer.assign(token);
    const std::size_t comma = buffer.find(',');
    if (buffer.find(',', comma + 1) != std::string::npos || buffer.find('.') != std::string::npos)
      return std::nullopt;
    buffer[comma] = '.';
    token = buffer;
  }
  if (token.size() > 1 && token.front() == '+' && token[1] != '-' && token[1] != '+') token.remove_prefix(1);
  if (token.empty()) return std::nullopt;
  double value = 0.0;
  const char* first = token.data();
  const char* last = first + token.size();
  const auto [ptr, ec] = std::from_chars(first, last, value);
  if (ptr != last) return std::nullopt;
  if (ec == std::errc::result_out_of_range) {
    // from_chars reports under- and overflow alike; a negative exponent means underflow.
    const bool underflow = token.find("e-") != std::string_view::npos || token.find("E-") != std::string_view::npos;
    return underflow ? 0.0 : std::numeric_limits<double>::infinity();
  }
  if (ec != std::errc()) return std::nullopt;
  return value;
}

/// A finite number, or "file:line: expected <what>, found '<token>'".
[[nodiscard]] inline Result<double> finiteNumber(std::string_view token, const std::string& file, std::size_t line,
                                                 const std::string& what, bool decimalComma = false) {
  const std::optional<double> v = parseNumber(token, decimalComma);
  if (!v) return fileError(file, line, "expected " + what + " (a number), found " + quote(token));
  if (!std::isfinite(*v)) return fileError(file, line, "expected " + what + " (a finite number), found " + quote(token));
  return *v;
}

/// An integer in [lo, hi] (written as "12" or "12.0"), or an error naming the range.
[[nodiscard]] inline Result<int> integerInRange(std::string_view token, const std::string& file, std::size_t line,
                                                const std::string& what, int lo, int hi, bool decimalComma = false) {
  const std::optional<double> v = parseNumber(token, decimalComma);
  if (!v || !std::isfinite(*v) || std::floor(*v) != *v || *v < lo || *v > hi) {
    return fileError(file, line,
                     "expected " + what + " (an integer from " + std::to_string(lo) + " to " + std::to_string(hi) +
                         "), found " + quote(token));
  }
  return static_cast<int>(*v);
}

/// Degrees as shown in messages: "87.5", "-90", "1e+03".
[[nodiscard]] inline std::string formatNumber(double v) {
  char buf[32];
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  if (ec != std::errc()) return "?";
  return std::string(buf, ptr);
}

/// Whether two angles in degrees are the same within the precision files are written to.
[[nodiscard]] inline bool sameAngle(double a, double b) noexcept { return std::abs(a - b) <= 1e-6; }

}  // namespace fogbeam::text
