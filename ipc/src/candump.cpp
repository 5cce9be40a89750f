// fogbeam — candump log reader and replayer (format summary in candump.hpp).
//
// Source of the format: can-utils (github.com/linux-can/can-utils), candump.c (the "-L"
// log line "(%010lu.%06lu) %s %s") and lib.c (the frame notation written by
// snprint_canframe and read by parse_canframe: 3 hex digits for an 11-bit id, 8 for a 29-bit
// id, '#' data, "#R[len]" remote, "##<flags>" CAN FD, "_<dlc>" raw classic DLC, '.' byte
// separators).
#include <fogbeam/ipc/candump.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/text_scan.hpp>


#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

namespace fogbeam::ipc {

namespace {

constexpr std::uint32_t kCanErrFlag = 0x2000'0000u;  // SocketCAN CAN_ERR_FLAG
// Interface names are at most IFNAMSIZ − 1 = 15 characters on Linux; logs from elsewhere
// (renamed, converted) get some slack, but a line cannot carry an unbounded name.
constexpr std::size_t kMaxInterfaceName = 64;

using text::isBlank;  // fogbeam/util/text_scan.hpp
using text::trim;
bool isDigit(char c) noexcept { return c >= '0' && c <= '9'; }

std::optional<unsigned> hexValue(char c) noexcept {
  if (c >= '0' && c <= '9') return static_cast<unsigned>(c - '0');
  if (c >= 'A' && c <= 'F') return static_cast<unsigned>(c - 'A' + 10);
  if (c >= 'a' && c <= 'f') return static_cast<unsigned>(c - 'a' + 10);
  return std::nullopt;
}


// A token as shown in messages: quoted, cut to 40 characters, control bytes as '?'.
std::string quote(std::string_view token) {
  constexpr std::size_t kMax = 40;
  std::string out;
  out.push_back('\'');
  for (std::size_t i = 0; i < token.size() && i < kMax; ++i) {
    const char c = token[i];
    out.push_back(static_cast<unsigned char>(c) < 0x20 || c == '\x7f' ? '?' : c);
  }
  if (token.size() > kMax) out.append("...");
  out.push_back('\'');
  return out;
}

Error expected(const std::string& what, std::string_view found) {
  return Error{"expected " + what + ", found " + (found.empty() ? std::string("the end of the line") : quote(found))};
}

// "(seconds.fraction)": seconds and up to 9 fraction digits, read as integers so that
// microseconds survive; the double holds them to ~0.2 µs at today's epoch times.
Result<double> parseTimestamp(std::string_view token) {
  const std::string what = "a timestamp '(seconds.microseconds)'";
  if (token.size() < 3 || token.front() != '(' || token.back() != ')') return expected(what, token);
  const std::string_view body = token.substr(1, token.size() - 2);
  const std::size_t dot = body.find('.');
  const std::string_view whole = body.substr(0, dot);
  const std::string_view fraction = dot == std::string_view::npos ? std::string_view{} : body.substr(dot + 1);
  // 12 digits of seconds reach the year 33658; 9 fraction digits are nanoseconds.
  if (whole.empty() || whole.size() > 12 || fraction.size() > 9 || (dot != std::string_view::npos && fraction.empty()))
    return expected(what, token);
  std::uint64_t seconds = 0;
  for (const char c : whole) {
    if (!isDigit(c)) return expected(what, token);
    seconds = seconds * 10 + static_cast<std::uint64_t>(c - '0');
  }
  std::uint64_t frac = 0;
  double scale = 1.0;
  for (const char c : fraction) {
    if (!isDigit(c)) return expected(what, token);
    frac = frac * 10 + static_cast<std::uint64_t>(c - '0');
    scale *= 10.0;
  }
  return static_cast<double>(seconds) + static_cast<double>(frac) / scale;
}

// "<hex pairs>" with optional '.' between bytes, at most `maxBytes` bytes.
Status parseData(std::string_view text, std::size_t maxBytes, CanFrame& frame, std::string_view token,
                 const std::string& what) {
  std::size_t n = 0;
  std::size_t i = 0;
  bool afterByte = false;  // a '.' may separate two bytes, nothing else
  while (i < text.size()) {
    if (text[i] == '.' && afterByte && i + 1 < text.size()) {
      ++i;
      afterByte = false;
      continue;
    }
    if (i + 1 >= text.size()) return expected(what + " (two hex digits per byte)", token);
    const std::optional<unsigned> hi = hexValue(text[i]);
    const std::optional<unsigned> lo = hexValue(text[i + 1]);
    if (!hi || !lo) return expected(what + " (two hex digits per byte)", token);
    if (n == maxBytes) return expected(what + " of at most " + std::to_string(maxBytes) + " bytes", token);
    frame.data[n++] = static_cast<std::uint8_t>(*hi << 4 | *lo);
    i += 2;
    afterByte = true;
  }
  frame.len = static_cast<std::uint8_t>(n);
  return Ok{};
}

// The id: 3 hex digits (11-bit) or 8 (29-bit), into f.id and f.extended; `token` (the whole
// frame token) and `where` ("before '#'") for the messages.
Status parseId(std::string_view idText, CanFrame& f, std::string_view token, const std::string& where) {
  if (idText.size() != 3 && idText.size() != 8)
    return expected("a CAN id of 3 hex digits (11-bit) or 8 hex digits (29-bit) " + where, token);
  std::uint32_t id = 0;
  for (const char c : idText) {
    const std::optional<unsigned> v = hexValue(c);
    if (!v) return expected("a CAN id of 3 or 8 hex digits " + where, token);
    id = id << 4 | *v;
  }
  if (idText.size() == 3) {
    if (id > kCanMaxStandardId) return expected("an 11-bit id (3 hex digits, at most 7FF)", token);
  } else {
    if ((id & kCanErrFlag) != 0 && id <= (kCanErrFlag | kCanMaxExtendedId)) {
      return Error{"expected a data or remote frame, found the error frame " + quote(token) +
                   " (CAN_ERR_FLAG set; error frames, logged by candump -e, are not supported)"};
    }
    if (id > kCanMaxExtendedId) return expected("a 29-bit id (8 hex digits, at most 1FFFFFFF)", token);
    f.extended = true;
  }
  f.id = id;
  return Ok{};
}

// The frame token: "<id>#<data>", "<id>#R[len]", "<id>##<flags><data>".
Result<CanFrame> parseFrame(std::string_view token) {
  CanFrame f;
  const std::size_t hash = token.find('#');
  if (hash == std::string_view::npos) return expected("a frame '<id>#<data>'", token);
  if (Status s = parseId(token.substr(0, hash), f, token, "before '#'"); !s) return s.error();

  std::string_view rest = token.substr(hash + 1);
  if (rest.substr(0, 2) == "##") return Error{"expected a CAN or CAN FD frame, found the CAN XL frame " + quote(token) + " (not supported)"};
  if (!rest.empty() && rest.front() == '#') {
    // CAN FD: one hex digit of flags, then the data.
    rest.remove_prefix(1);
    f.fd = true;
    const std::optional<unsigned> flags = rest.empty() ? std::nullopt : hexValue(rest.front());
    if (!flags || *flags > 0x3)
      return expected("a CAN FD flags digit after '##' (0-3: 1 = BRS, 2 = ESI)", token);
    f.brs = (*flags & 0x1u) != 0;
    f.esi = (*flags & 0x2u) != 0;
    rest.remove_prefix(1);
    if (Status s = parseData(rest, kCanFdMaxLen, f, token, "CAN FD data"); !s) return s.error();
    if (!isValidCanFdLength(f.len)) {
      return expected("CAN FD data of a valid length (0-8, 12, 16, 20, 24, 32, 48 or 64 bytes)", token);
    }
    return f;
  }
  if (!rest.empty() && (rest.front() == 'R' || rest.front() == 'r')) {
    // Remote frame, optionally with the requested length (one digit 0-8).
    f.remote = true;
    rest.remove_prefix(1);
    if (!rest.empty()) {
      if (rest.size() != 1 || !isDigit(rest.front()) || rest.front() > '8')
        return expected("'R' alone or followed by one length digit 0-8 for a remote frame", token);
      f.len = static_cast<std::uint8_t>(rest.front() - '0');
    }
    return f;
  }
  // Classic data, optionally "_<raw dlc 9-F>" after 8 bytes (CAN_CTRLMODE_CC_LEN8_DLC).
  const std::size_t underscore = rest.find('_');
  std::string_view rawDlc;
  if (underscore != std::string_view::npos) {
    rawDlc = rest.substr(underscore + 1);
    rest = rest.substr(0, underscore);
  }
  if (Status s = parseData(rest, kCanMaxLen, f, token, "data"); !s) return s.error();
  if (underscore != std::string_view::npos) {
    const std::optional<unsigned> dlc = rawDlc.size() == 1 ? hexValue(rawDlc.front()) : std::nullopt;
    if (f.len != kCanMaxLen || !dlc || *dlc < 9)
      return expected("'_<raw DLC 9-F>' only after 8 data bytes", token);
  }
  return f;
}

// Splits off the next blank-separated token.
std::string_view nextToken(std::string_view& rest) noexcept {
  while (!rest.empty() && isBlank(rest.front())) rest.remove_prefix(1);
  std::size_t end = 0;
  while (end < rest.size() && !isBlank(rest[end])) ++end;
  const std::string_view token = rest.substr(0, end);
  rest.remove_prefix(end);
  return token;
}

// ---- candump's screen format -------------------------------------------------------------------
//
// What candump prints without -l/-L (can-utils candump.c, and lib.c snprintf_long_canframe):
//   " (1700000000.123456)  can0  123   [8]  11 22 33 44 55 66 77 88   '.\"3DUfw.'"
// an optional timestamp ("-t a|A|z|d"), the interface (right-aligned), with -x "RX|TX" and the
// CAN FD flags ("B"/"-" BRS, "E"/"-" ESI), the id, the length in brackets (one digit for a
// classic frame, two for CAN FD; "{X}", the raw DLC, with -8), the bytes as blank-separated hex
// pairs or "remote request", then optionally the bytes as ASCII between quotes (-a).

// "[n]" / "[nn]" or "{X}": the screen format's length token.
bool isLengthToken(std::string_view t) noexcept {
  if (t.size() == 3 && t.front() == '{' && t.back() == '}') return hexValue(t[1]).has_value();
  if (t.size() < 3 || t.size() > 4 || t.front() != '[' || t.back() != ']') return false;
  for (std::size_t i = 1; i + 1 < t.size(); ++i)
    if (!isDigit(t[i])) return false;
  return true;
}

// Whether the line is in the screen format: one of its tokens is a length token. (A -L line
// never has one: its frame is one token with '#'.)
bool isScreenLine(std::string_view line) noexcept {
  std::string_view rest = line;
  for (std::string_view t = nextToken(rest); !t.empty(); t = nextToken(rest))
    if (isLengthToken(t)) return true;
  return false;
}

// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's days_from_civil).
std::int64_t daysFromCivil(std::int64_t y, unsigned m, unsigned d) noexcept {
  y -= m <= 2 ? 1 : 0;
  const std::int64_t era = (y >= 0 ? y : y - 399) / 400;
  const auto yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? static_cast<unsigned>(-3) : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<std::int64_t>(doe) - 719468;
}

// "-t A": "(YYYY-MM-DD HH:MM:SS.ffffff)", candump's local time, taken as UTC: the replay uses
// only the gaps between lines (a log across a daylight-saving change would show its hour).
Result<double> parseDateTimestamp(std::string_view token) {
  const std::string what = "a timestamp '(YYYY-MM-DD HH:MM:SS.ffffff)'";
  const std::string_view body = token.substr(1, token.size() - 2);
  // Positions of the fixed fields: 0123-56-89 12:45:78
  if (body.size() < 19 || body[4] != '-' || body[7] != '-' || body[10] != ' ' || body[13] != ':' || body[16] != ':')
    return expected(what, token);
  auto number = [&](std::size_t at, std::size_t n, unsigned& v) {
    v = 0;
    for (std::size_t i = at; i < at + n; ++i) {
      if (!isDigit(body[i])) return false;
      v = v * 10 + static_cast<unsigned>(body[i] - '0');
    }
    return true;
  };
  unsigned y = 0, mo = 0, d = 0, h = 0, mi = 0, s = 0;
  if (!number(0, 4, y) || !number(5, 2, mo) || !number(8, 2, d) || !number(11, 2, h) || !number(14, 2, mi) ||
      !number(17, 2, s) || mo < 1 || mo > 12 || d < 1 || d > 31 || h > 23 || mi > 59 || s > 60)
    return expected(what, token);
  double fraction = 0.0;
  if (body.size() > 19) {
    // ".ffffff" (or nanoseconds with -N): the seconds' part through parseTimestamp's reader.
    const Result<double> f = parseTimestamp("(0" + std::string(body.substr(19)) + ")");
    if (!f || body[19] != '.') return expected(what, token);
    fraction = *f;
  }
  const std::int64_t days = daysFromCivil(static_cast<std::int64_t>(y), mo, d);
  return static_cast<double>(days * 86400 + static_cast<std::int64_t>(h * 3600 + mi * 60 + s)) + fraction;
}

Result<CandumpLine> parseScreenLine(std::string_view rest) {
  CandumpLine out;
  out.timed = false;
  while (!rest.empty() && isBlank(rest.front())) rest.remove_prefix(1);
  if (!rest.empty() && rest.front() == '(') {
    const std::size_t close = rest.find(')');
    if (close == std::string_view::npos)
      return expected("a timestamp '(seconds.microseconds)' closed by ')'", rest.substr(0, rest.find_first_of(" \t")));
    const std::string_view stamp = rest.substr(0, close + 1);
    rest.remove_prefix(close + 1);
    const Result<double> t = stamp.find('-') != std::string_view::npos ? parseDateTimestamp(stamp) : parseTimestamp(stamp);
    if (!t) return t.error();
    out.timestamp_s = *t;
    out.timed = true;
  }
  const std::string_view iface = nextToken(rest);
  if (iface.empty() || iface.size() > kMaxInterfaceName || isLengthToken(iface))
    return expected("an interface name (e.g. 'can0') of at most " + std::to_string(kMaxInterfaceName) + " characters",
                    iface);
  out.interface = std::string(iface);

  CanFrame& f = out.frame;
  std::string_view idText = nextToken(rest);
  bool brs = false, esi = false;
  if (idText == "RX" || idText == "TX") {  // candump -x: the direction and the CAN FD flags
    const std::string_view b = nextToken(rest), e = nextToken(rest);
    if ((b != "-" && b != "B") || (e != "-" && e != "E"))
      return expected("the CAN FD flags 'B'/'-' and 'E'/'-' after " + std::string(idText),
                      b != "-" && b != "B" ? b : e);
    brs = b == "B";
    esi = e == "E";
    idText = nextToken(rest);
  }
  if (Status s = parseId(idText, f, idText, "before the length '[n]'"); !s) return s.error();
  const std::string_view lenText = nextToken(rest);
  if (!isLengthToken(lenText)) return expected("a length '[n]' after the CAN id", lenText);
  std::size_t len = 0;
  if (lenText.front() == '{') {  // candump -8: the raw DLC of a classic frame (9-F: 8 bytes)
    len = std::min<std::size_t>(*hexValue(lenText[1]), kCanMaxLen);
  } else {
    for (std::size_t i = 1; i + 1 < lenText.size(); ++i) len = len * 10 + static_cast<std::size_t>(lenText[i] - '0');
    if (lenText.size() == 4) {  // two digits: CAN FD
      f.fd = true;
      f.brs = brs;
      f.esi = esi;
      if (!isValidCanFdLength(len))
        return expected("a CAN FD length (0-8, 12, 16, 20, 24, 32, 48 or 64)", lenText);
    } else if (len > kCanMaxLen) {
      return expected("a classic frame's length 0-8", lenText);
    }
  }
  while (!rest.empty() && isBlank(rest.front())) rest.remove_prefix(1);
  if (!f.fd && rest.substr(0, 14) == "remote request") {
    f.remote = true;
    f.len = static_cast<std::uint8_t>(len);
    rest.remove_prefix(14);
  } else {
    for (std::size_t n = 0; n < len; ++n) {
      const std::string_view byte = nextToken(rest);
      const std::optional<unsigned> hi = byte.size() == 2 ? hexValue(byte[0]) : std::nullopt;
      const std::optional<unsigned> lo = byte.size() == 2 ? hexValue(byte[1]) : std::nullopt;
      if (!hi || !lo)
        return expected(std::to_string(len) + " data byte(s) as hex pairs after " + quote(lenText) + " (byte " +
                            std::to_string(n + 1) + ")",
                        byte);
      f.data[n] = static_cast<std::uint8_t>(*hi << 4 | *lo);
    }
    f.len = static_cast<std::uint8_t>(len);
  }
  while (!rest.empty() && isBlank(rest.front())) rest.remove_prefix(1);
  while (!rest.empty() && isBlank(rest.back())) rest.remove_suffix(1);
  // candump -a: the bytes again as ASCII between quotes (which may hold blanks and quotes).
  if (!rest.empty() && rest.front() == '\'' && rest.size() >= 2 && rest.back() == '\'') rest = {};
  if (const std::string_view extra = nextToken(rest); !extra.empty())
    return expected("the end of the line after " + std::to_string(len) + " data byte(s)", extra);
  f.timestamp_s = out.timestamp_s;
  return out;
}

}  // namespace

Result<CandumpLine> parseCandumpLine(std::string_view line) {
  std::string_view rest = line;
  if (!rest.empty() && rest.back() == '\n') rest.remove_suffix(1);
  if (!rest.empty() && rest.back() == '\r') rest.remove_suffix(1);
  if (isScreenLine(rest)) return parseScreenLine(rest);
  CandumpLine out;
  const std::string_view stamp = nextToken(rest);
  const Result<double> t = parseTimestamp(stamp);
  if (!t) return t.error();
  out.timestamp_s = *t;

  const std::string_view iface = nextToken(rest);
  if (iface.empty() || iface.size() > kMaxInterfaceName || iface.find('#') != std::string_view::npos) {
    return expected("an interface name (e.g. 'can0') of at most " + std::to_string(kMaxInterfaceName) +
                        " characters after the timestamp",
                    iface);
  }
  out.interface = std::string(iface);

  const std::string_view frameToken = nextToken(rest);
  Result<CanFrame> frame = parseFrame(frameToken);
  if (!frame) return frame.error();
  out.frame = *frame;
  out.frame.timestamp_s = out.timestamp_s;

  // candump -x appends the direction: R (received) or T (transmitted).
  const std::string_view direction = nextToken(rest);
  if (!direction.empty() && direction != "R" && direction != "T")
    return expected("the end of the line (or a direction 'R'/'T')", direction);
  if (const std::string_view extra = nextToken(rest); !extra.empty()) return expected("the end of the line", extra);
  return out;
}

Result<std::vector<CandumpLine>> loadCandump(const std::string& path) {
  const Result<std::string> text = readTextFile(path);
  if (!text) return text.error();
  std::vector<CandumpLine> lines;
  const std::string_view all = *text;
  std::size_t pos = 0;
  std::size_t lineNo = 0;
  double lastTime = 0.0;  // a screen-format line without a timestamp takes the previous line's
  while (pos < all.size()) {
    ++lineNo;
    std::size_t end = all.find('\n', pos);
    if (end == std::string_view::npos) end = all.size();
    const std::string_view raw = all.substr(pos, end - pos);
    pos = end + 1;
    const std::string_view t = trim(raw);
    if (t.empty() || t.front() == '#') continue;
    Result<CandumpLine> parsed = parseCandumpLine(t);
    if (!parsed) return fileError(path, lineNo, parsed.error().message);
    if (!parsed->timed) parsed->timestamp_s = parsed->frame.timestamp_s = lastTime;
    lastTime = parsed->timestamp_s;
    lines.push_back(std::move(*parsed));
  }
  return lines;
}

void replayCandump(const std::vector<CandumpLine>& lines, double speed,
                   const std::function<bool(const CandumpLine&)>& sink) {
  if (lines.empty()) return;
  const bool paced = std::isfinite(speed) && speed > 0.0;
  using Clock = std::chrono::steady_clock;
  const Clock::time_point start = Clock::now();
  const double t0 = lines.front().timestamp_s;
  double latest = t0;  // a timestamp going backwards is sent at once, not waited for
  for (const CandumpLine& line : lines) {
    if (paced && line.timestamp_s > latest) {
      latest = line.timestamp_s;
      // Capped at a year so that a bogus timestamp cannot overflow the clock's duration.
      const std::chrono::duration<double> offset(std::min((latest - t0) / speed, 365.0 * 86400.0));
      std::this_thread::sleep_until(start + std::chrono::duration_cast<Clock::duration>(offset));
    }
    if (!sink(line)) return;
  }
}

}  // namespace fogbeam::ipc
