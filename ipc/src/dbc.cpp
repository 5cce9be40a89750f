// fogbeam — DBC reader, signal decoder and encoder (format summary and choices in dbc.hpp).
//
// Sources: Vector, "DBC File Format Documentation" v01/2007 (§8.1 message definitions, §8.2
// signal definitions, §11 SIG_VALTYPE_); the byte-order conventions were checked against
// cantools (cantools/database/utils.py, start_bit) and opendbc's generated DBCs, which agree
// that a Motorola signal's start bit is its most significant bit.
//
// The parser works line by line: BO_, SG_ and SIG_VALTYPE_ are read field by field, every
// other statement is skipped (a string in a skipped statement may span lines, e.g. CM_
// comments). Nothing is returned until the whole file has been read and checked.
#include <fogbeam/ipc/dbc.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/text_scan.hpp>


#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <map>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace fogbeam::ipc {

namespace {

constexpr std::uint32_t kDbcExtendedBit = 0x8000'0000u;
// Vector's pseudo-message that collects signals not assigned to any frame.
constexpr std::uint32_t kIndependentSignalsId = 0xC000'0000u;
constexpr std::string_view kIndependentSignalsName = "VECTOR__INDEPENDENT_SIG_MSG";
constexpr std::size_t kMaxBits = kDbcMaxMessageSize * 8;

using text::isBlank;  // blanks, tabs, line ends (fogbeam/util/text_scan.hpp)
using text::Line;
using text::splitLines;
using text::trim;
bool isIdentStart(char c) noexcept { return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || c == '_'; }
bool isIdentChar(char c) noexcept { return isIdentStart(c) || (c >= '0' && c <= '9'); }
bool isPunct(char c) noexcept {
  return c == ':' || c == '|' || c == '@' || c == '(' || c == ')' || c == ',' || c == '[' || c == ']' ||
         c == '"' || c == ';';
}

// A token as shown in messages: quoted, cut to 40 characters.
std::string quote(std::string_view token) {
  constexpr std::size_t kMax = 40;
  std::string out;
  out.push_back('\'');
  out.append(token.substr(0, kMax));
  if (token.size() > kMax) out.append("...");
  out.push_back('\'');
  return out;
}

// "A, B, C", at most 40 names, then how many more.
std::string listNames(const std::vector<std::string_view>& names) {
  constexpr std::size_t kMax = 40;
  if (names.empty()) return "(none)";
  std::string out;
  for (std::size_t i = 0; i < names.size() && i < kMax; ++i) {
    if (i > 0) out.append(", ");
    out.append(names[i]);
  }
  if (names.size() > kMax) out.append(", … (" + std::to_string(names.size() - kMax) + " more)");
  return out;
}


// Reads the fields of one statement and words errors as "file:line: expected …, found …".
class Cursor {
 public:
  Cursor(std::string_view text, const std::string& file, std::size_t line) noexcept
      : text_(text), file_(file), line_(line) {}

  bool atEnd() noexcept {
    skipBlanks();
    return pos_ == text_.size();
  }

  bool peek(char c) noexcept { return !atEnd() && text_[pos_] == c; }

  bool consume(char c) noexcept {
    if (!peek(c)) return false;
    ++pos_;
    return true;
  }

  Status expect(char c, const std::string& what) {
    if (consume(c)) return Ok{};
    return error(what);
  }

  // An identifier, or an empty view when the next token is none.
  std::string_view identifier() noexcept {
    skipBlanks();
    if (pos_ == text_.size() || !isIdentStart(text_[pos_])) return {};
    const std::size_t start = pos_;
    while (pos_ < text_.size() && isIdentChar(text_[pos_])) ++pos_;
    return text_.substr(start, pos_ - start);
  }

  Result<std::string> name(const std::string& what) {
    const std::string_view id = identifier();
    if (id.empty()) return error(what);
    return std::string(id);
  }

  // A decimal integer in [0, max].
  Result<std::uint64_t> unsignedInt(const std::string& what, std::uint64_t max) {
    skipBlanks();
    const std::size_t start = pos_;
    while (pos_ < text_.size() && text_[pos_] >= '0' && text_[pos_] <= '9') ++pos_;
    std::uint64_t value = 0;
    const char* first = text_.data() + start;
    const char* last = text_.data() + pos_;
    const auto [ptr, ec] = std::from_chars(first, last, value);
    if (start == pos_ || ptr != last || ec != std::errc() || value > max ||
        (pos_ < text_.size() && isIdentChar(text_[pos_]))) {
      pos_ = start;
      return error(what + " (an integer from 0 to " + std::to_string(max) + ")");
    }
    return value;
  }

  // A finite decimal number ("0.01", "-40", "1E-005", "+3").
  Result<double> number(const std::string& what) {
    skipBlanks();
    const std::size_t start = pos_;
    while (pos_ < text_.size() && !isBlank(text_[pos_]) && !isPunct(text_[pos_])) ++pos_;
    std::string_view token = text_.substr(start, pos_ - start);
    if (token.size() > 1 && token.front() == '+' && token[1] != '-') token.remove_prefix(1);
    double value = 0.0;
    const char* first = token.data();
    const char* last = token.data() + token.size();
    const auto [ptr, ec] = std::from_chars(first, last, value);
    if (token.empty() || ptr != last || ec != std::errc() || !std::isfinite(value)) {
      pos_ = start;
      return error(what + " (a finite number)");
    }
    return value;
  }

  // A "quoted string"; backslash escapes the next character.
  Result<std::string> quoted(const std::string& what) {
    if (!consume('"')) return error(what + " (a quoted string)");
    std::string out;
    while (pos_ < text_.size() && text_[pos_] != '"') {
      if (text_[pos_] == '\\' && pos_ + 1 < text_.size()) ++pos_;
      out.push_back(text_[pos_++]);
    }
    if (pos_ == text_.size()) return error("the closing '\"' of " + what);
    ++pos_;
    return out;
  }

  // "file:line: expected <expected>, found <the next token>".
  Error error(const std::string& expected) {
    skipBlanks();
    std::string found;
    if (pos_ == text_.size()) {
      found = "the end of the line";
    } else {
      std::size_t end = pos_;
      while (end < text_.size() && !isBlank(text_[end]) && !isPunct(text_[end])) ++end;
      if (end == pos_) end = pos_ + 1;
      found = quote(text_.substr(pos_, end - pos_));
    }
    return fileError(file_, line_, "expected " + expected + ", found " + found);
  }

  Error errorHere(const std::string& what) const { return fileError(file_, line_, what); }

 private:
  void skipBlanks() noexcept {
    while (pos_ < text_.size() && isBlank(text_[pos_])) ++pos_;
  }

  std::string_view text_;
  const std::string& file_;
  std::size_t line_;
  std::size_t pos_ = 0;
};

// The first token of a line: up to a blank or ':' ("BS_:" → "BS_").
std::string_view keywordOf(std::string_view trimmed) noexcept {
  std::size_t end = 0;
  while (end < trimmed.size() && !isBlank(trimmed[end]) && trimmed[end] != ':') ++end;
  return trimmed.substr(0, end);
}

// Whether a line leaves a string open: counts quotes outside/inside strings, honouring
// backslash escapes inside strings. `inString` carries the state across lines.
void scanQuotes(std::string_view text, bool& inString) noexcept {
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (inString && text[i] == '\\') {
      ++i;
    } else if (text[i] == '"') {
      inString = !inString;
    }
  }
}

// Linear bit index (byte·8 + 7 − bit, "big-endian order") of a Motorola signal's MSB.
std::size_t motorolaMsbLinear(std::uint16_t startBit) noexcept {
  return std::size_t{startBit} / 8 * 8 + (7 - std::size_t{startBit} % 8);
}

// Bytes a bit field needs: one past the last byte it touches.
std::size_t bytesNeeded(const DbcBitField& bits) noexcept {
  if (bits.order == DbcByteOrder::Intel) return (std::size_t{bits.start_bit} + bits.length - 1) / 8 + 1;
  return (motorolaMsbLinear(bits.start_bit) + bits.length - 1) / 8 + 1;
}

struct PendingValueType {
  std::uint32_t dbcId = 0;
  std::string signal;
  DbcValueType type = DbcValueType::Integer;
  std::size_t line = 0;
};

struct MessageBuild {
  DbcMessage message;
  std::uint32_t dbcId = 0;  // as written (with bit 31 for extended ids)
  std::size_t line = 0;
  bool skipped = false;                  // VECTOR__INDEPENDENT_SIG_MSG
  std::vector<std::size_t> signalLines;  // per signal, for messages after the message is complete
  std::optional<std::size_t> multiplexor;
};

class DbcParser {
 public:
  DbcParser(std::string_view text, const std::string& file) : text_(text), file_(file) {}

  Result<DbcDatabase> parse() {
    const std::vector<Line> lines = splitLines(text_);
    bool inNamespaceList = false;
    for (std::size_t i = 0; i < lines.size(); ++i) {
      const Line& line = lines[i];
      const std::string_view t = trim(line.text);
      if (t.empty()) continue;
      const std::string_view keyword = keywordOf(t);
      if (inNamespaceList) {
        // NS_ lists one keyword per line (SG_MUL_VAL_, BA_DEF_, …), usually indented; it
        // ends at the first line that is neither indented nor a single token.
        const bool singleToken = keyword.size() == t.size() || trim(t.substr(keyword.size())) == ":";
        if (isBlank(line.text.front()) || singleToken) continue;
        inNamespaceList = false;
      }
      if (keyword == "BO_") {
        if (Status s = finishMessage(); !s) return s.error();
        if (Status s = parseMessage(t, line.number); !s) return s.error();
      } else if (keyword == "SG_") {
        if (!current_) {
          return fileError(file_, line.number,
                           "expected SG_ to follow a BO_ line or another SG_ line of its message, found "
                           "it after other statements");
        }
        if (Status s = parseSignal(t, line.number); !s) return s.error();
      } else {
        if (Status s = finishMessage(); !s) return s.error();
        if (keyword == "NS_") {
          inNamespaceList = true;
        } else if (keyword == "SG_MUL_VAL_") {
          return fileError(file_, line.number,
                           "extended multiplexing (SG_MUL_VAL_) is not supported; expected at most one "
                           "multiplexor (M) per message with signals selected by m<N>");
        } else if (keyword == "SIG_VALTYPE_") {
          if (Status s = parseValueType(t, line.number); !s) return s.error();
        }
        // Any other statement is skipped; a string in it may continue on the next lines.
        bool inString = false;
        scanQuotes(t, inString);
        const std::size_t opened = line.number;
        while (inString) {
          if (++i == lines.size()) {
            return fileError(file_, opened,
                             "expected the closing '\"' of the string opened on this line, found the end "
                             "of the file");
          }
          scanQuotes(lines[i].text, inString);
        }
      }
    }
    if (Status s = finishMessage(); !s) return s.error();
    if (Status s = applyValueTypes(); !s) return s.error();

    DbcDatabase db;
    db.file_name = file_;
    db.messages.reserve(messages_.size());
    for (MessageBuild& m : messages_) db.messages.push_back(std::move(m.message));
    std::sort(db.messages.begin(), db.messages.end(), [](const DbcMessage& a, const DbcMessage& b) {
      return std::pair(a.extended, a.id) < std::pair(b.extended, b.id);
    });
    return db;
  }

 private:
  // BO_ <id> <name>: <size> <transmitter>
  Status parseMessage(std::string_view t, std::size_t lineNo) {
    Cursor c(t, file_, lineNo);
    (void)c.identifier();  // "BO_"
    MessageBuild b;
    b.line = lineNo;
    const Result<std::uint64_t> id = c.unsignedInt("a message id", 0xFFFF'FFFFu);
    if (!id) return id.error();
    b.dbcId = static_cast<std::uint32_t>(*id);
    const Result<std::string> name = c.name("a message name");
    if (!name) return name.error();
    b.message.name = *name;
    if (Status s = c.expect(':', "':' after the message name"); !s) return s;
    const Result<std::uint64_t> size = c.unsignedInt("the message size in bytes", kDbcMaxMessageSize);
    if (!size) return size.error();
    b.message.size = static_cast<std::uint8_t>(*size);
    const Result<std::string> transmitter = c.name("the transmitting node (Vector__XXX for none)");
    if (!transmitter) return transmitter.error();
    b.message.transmitter = *transmitter;
    if (!c.atEnd()) return c.error("the end of the BO_ line");

    if (b.dbcId == kIndependentSignalsId && b.message.name == kIndependentSignalsName) {
      b.skipped = true;
    } else if ((b.dbcId & kDbcExtendedBit) != 0) {
      b.message.extended = true;
      b.message.id = b.dbcId & ~kDbcExtendedBit;
      if (b.message.id > kCanMaxExtendedId) {
        return c.errorHere("expected an extended id (bit 31 set) of at most 29 bits (≤ 2147483648 + " +
                           std::to_string(kCanMaxExtendedId) + "), found " + std::to_string(b.dbcId));
      }
    } else {
      b.message.id = b.dbcId;
      if (b.message.id > kCanMaxStandardId) {
        return c.errorHere("expected a standard id ≤ 2047 (an extended id is written with bit 31 set, i.e. "
                           "2147483648 + id), found " + std::to_string(b.dbcId));
      }
    }
    if (!b.skipped) {
      if (const auto it = lineByName_.find(b.message.name); it != lineByName_.end()) {
        return c.errorHere("expected a unique message name, found " + quote(b.message.name) +
                           " again (first defined on line " + std::to_string(it->second) + ")");
      }
      const auto key = std::pair(b.message.extended, b.message.id);
      if (const auto it = byId_.find(key); it != byId_.end()) {
        return c.errorHere("expected a unique message id, found " + std::to_string(b.dbcId) +
                           " again (first defined on line " + std::to_string(it->second.first) + " as " +
                           quote(it->second.second) + ")");
      }
      lineByName_.emplace(b.message.name, lineNo);
      byId_.emplace(key, std::pair(lineNo, b.message.name));
    }
    current_ = std::move(b);
    return Ok{};
  }

  // SG_ <name> [M|m<N>] : <start>|<length>@<order><sign> (<factor>,<offset>) [<min>|<max>]
  //     "<unit>" <receivers>
  Status parseSignal(std::string_view t, std::size_t lineNo) {
    Cursor c(t, file_, lineNo);
    (void)c.identifier();  // "SG_"
    MessageBuild& m = *current_;
    DbcSignal s;
    const Result<std::string> name = c.name("a signal name");
    if (!name) return name.error();
    s.name = *name;

    // Multiplexer indicator: "M", "m<N>", or (extended multiplexing) "m<N>M".
    if (!c.peek(':')) {
      const std::string_view mux = c.identifier();
      if (mux == "M") {
        s.mux_role = DbcMuxRole::Multiplexor;
      } else if (mux.size() >= 2 && mux.front() == 'm' && mux[1] >= '0' && mux[1] <= '9') {
        std::string_view digits = mux.substr(1);
        if (digits.back() == 'M') {
          return c.errorHere("extended multiplexing (signal " + quote(s.name) + " is multiplexed and a " +
                             "multiplexor, " + quote(mux) + ") is not supported; expected 'M' or 'm<N>'");
        }
        std::uint64_t value = 0;
        const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
        if (ec != std::errc() || ptr != digits.data() + digits.size()) {
          return c.errorHere("expected a multiplexer indicator 'M' or 'm<N>' (N a decimal integer), found " +
                             quote(mux));
        }
        s.mux_role = DbcMuxRole::Multiplexed;
        s.mux_value = value;
      } else if (!mux.empty()) {
        return c.errorHere("expected ':' or a multiplexer indicator 'M' or 'm<N>' after the signal name, found " +
                           quote(mux));
      }
    }
    if (Status st = c.expect(':', "':' after the signal name"); !st) return st;
    const Result<std::uint64_t> start = c.unsignedInt("the start bit", kMaxBits - 1);
    if (!start) return start.error();
    if (Status st = c.expect('|', "'|' between start bit and length"); !st) return st;
    const Result<std::uint64_t> length = c.unsignedInt("the signal length in bits", 64);
    if (!length) return length.error();
    if (*length == 0) return c.errorHere("expected a signal length from 1 to 64 bits, found 0");
    if (Status st = c.expect('@', "'@' before the byte order"); !st) return st;
    if (c.consume('1')) {
      s.bits.order = DbcByteOrder::Intel;
    } else if (c.consume('0')) {
      s.bits.order = DbcByteOrder::Motorola;
    } else {
      return c.error("the byte order '1' (Intel, little-endian) or '0' (Motorola, big-endian)");
    }
    if (c.consume('-')) {
      s.bits.is_signed = true;
    } else if (!c.consume('+')) {
      return c.error("the value type '+' (unsigned) or '-' (signed)");
    }
    s.bits.start_bit = static_cast<std::uint16_t>(*start);
    s.bits.length = static_cast<std::uint8_t>(*length);

    if (Status st = c.expect('(', "'(' before the factor"); !st) return st;
    const Result<double> factor = c.number("the factor");
    if (!factor) return factor.error();
    if (Status st = c.expect(',', "',' between factor and offset"); !st) return st;
    const Result<double> offset = c.number("the offset");
    if (!offset) return offset.error();
    if (Status st = c.expect(')', "')' after the offset"); !st) return st;
    if (Status st = c.expect('[', "'[' before the minimum"); !st) return st;
    const Result<double> minimum = c.number("the minimum");
    if (!minimum) return minimum.error();
    if (Status st = c.expect('|', "'|' between minimum and maximum"); !st) return st;
    const Result<double> maximum = c.number("the maximum");
    if (!maximum) return maximum.error();
    if (Status st = c.expect(']', "']' after the maximum"); !st) return st;
    const Result<std::string> unit = c.quoted("the unit");
    if (!unit) return unit.error();
    s.factor = *factor;
    s.offset = *offset;
    s.minimum = *minimum;
    s.maximum = *maximum;
    s.unit = *unit;
    // Receivers: node names separated by ',' (some writers add blanks); may be absent.
    while (!c.atEnd()) {
      const Result<std::string> rx = c.name("a receiving node name");
      if (!rx) return rx.error();
      s.receivers.push_back(*rx);
      (void)c.consume(',');
    }

    // The field must lie inside the message (and so inside 64 bytes).
    if (s.bits.order == DbcByteOrder::Intel && *start + *length > kMaxBits) {
      return c.errorHere("expected start bit + length ≤ " + std::to_string(kMaxBits) + " (64 bytes), found " +
                         std::to_string(*start) + " + " + std::to_string(*length));
    }
    if (s.bits.order == DbcByteOrder::Motorola && motorolaMsbLinear(s.bits.start_bit) + *length > kMaxBits) {
      return c.errorHere("expected a Motorola signal that ends within 64 bytes, found start bit " +
                         std::to_string(*start) + " (MSB) with length " + std::to_string(*length));
    }
    if (!m.skipped && bytesNeeded(s.bits) > m.message.size) {
      return c.errorHere("expected signal " + quote(s.name) + " (" + std::to_string(*start) + "|" +
                         std::to_string(*length) + "@" + (s.bits.order == DbcByteOrder::Intel ? "1" : "0") +
                         ") to fit in message " + quote(m.message.name) + " of " +
                         std::to_string(m.message.size) + " bytes, found it needs " +
                         std::to_string(bytesNeeded(s.bits)) + " bytes");
    }
    for (std::size_t k = 0; k < m.message.signals.size(); ++k) {
      if (m.message.signals[k].name == s.name) {
        return c.errorHere("expected a unique signal name in message " + quote(m.message.name) + ", found " +
                           quote(s.name) + " again (first defined on line " + std::to_string(m.signalLines[k]) +
                           ")");
      }
    }
    if (s.mux_role == DbcMuxRole::Multiplexor) {
      if (m.multiplexor) {
        return c.errorHere("expected at most one multiplexor (M) in message " + quote(m.message.name) +
                           ", found " + quote(s.name) + " after " +
                           quote(m.message.signals[*m.multiplexor].name) + " (line " +
                           std::to_string(m.signalLines[*m.multiplexor]) +
                           "); several multiplexors (extended multiplexing) are not supported");
      }
      m.multiplexor = m.message.signals.size();
    }
    m.message.signals.push_back(std::move(s));
    m.signalLines.push_back(lineNo);
    return Ok{};
  }

  // SIG_VALTYPE_ <id> <signal> : <0|1|2> ;
  Status parseValueType(std::string_view t, std::size_t lineNo) {
    Cursor c(t, file_, lineNo);
    (void)c.identifier();  // "SIG_VALTYPE_"
    PendingValueType p;
    p.line = lineNo;
    const Result<std::uint64_t> id = c.unsignedInt("a message id", 0xFFFF'FFFFu);
    if (!id) return id.error();
    p.dbcId = static_cast<std::uint32_t>(*id);
    const Result<std::string> name = c.name("a signal name");
    if (!name) return name.error();
    p.signal = *name;
    if (Status s = c.expect(':', "':' after the signal name"); !s) return s;
    const Result<std::uint64_t> type = c.unsignedInt("the value type 0 (integer), 1 (float) or 2 (double)", 2);
    if (!type) return type.error();
    p.type = *type == 1 ? DbcValueType::Float32 : *type == 2 ? DbcValueType::Float64 : DbcValueType::Integer;
    if (Status s = c.expect(';', "';' after the value type"); !s) return s;
    valueTypes_.push_back(std::move(p));
    return Ok{};
  }

  // Checks the multiplexing of the message being read and stores it.
  Status finishMessage() {
    if (!current_) return Ok{};
    MessageBuild m = std::move(*current_);
    current_.reset();
    if (m.skipped) {
      skipped_.push_back(std::move(m));
      return Ok{};
    }
    for (std::size_t k = 0; k < m.message.signals.size(); ++k) {
      DbcSignal& s = m.message.signals[k];
      if (s.mux_role != DbcMuxRole::Multiplexed) continue;
      if (!m.multiplexor) {
        return fileError(file_, m.signalLines[k],
                         "expected a multiplexor signal (M) in message " + quote(m.message.name) +
                             " for the multiplexed signal " + quote(s.name) + ", found none");
      }
      s.multiplexor = m.message.signals[*m.multiplexor].bits;
    }
    messages_.push_back(std::move(m));
    return Ok{};
  }

  Status applyValueTypes() {
    for (const PendingValueType& p : valueTypes_) {
      DbcSignal* target = nullptr;
      bool inSkipped = false;
      for (MessageBuild& m : messages_) {
        if (m.dbcId != p.dbcId) continue;
        for (DbcSignal& s : m.message.signals)
          if (s.name == p.signal) target = &s;
      }
      for (const MessageBuild& m : skipped_)
        if (m.dbcId == p.dbcId) inSkipped = true;
      if (inSkipped) continue;
      if (!target) {
        return fileError(file_, p.line,
                         "expected SIG_VALTYPE_ to name a signal defined by BO_/SG_, found message id " +
                             std::to_string(p.dbcId) + " signal " + quote(p.signal));
      }
      const std::uint8_t need = p.type == DbcValueType::Float32 ? 32 : p.type == DbcValueType::Float64 ? 64 : 0;
      if (need != 0 && target->bits.length != need) {
        return fileError(file_, p.line,
                         "expected signal " + quote(p.signal) + " to be " + std::to_string(need) +
                             " bits long for SIG_VALTYPE_ " + (need == 32 ? "1 (float)" : "2 (double)") +
                             ", found " + std::to_string(target->bits.length) + " bits");
      }
      target->value_type = p.type;
    }
    return Ok{};
  }

  std::string_view text_;
  const std::string& file_;
  std::vector<MessageBuild> messages_;
  std::vector<MessageBuild> skipped_;
  std::optional<MessageBuild> current_;
  std::vector<PendingValueType> valueTypes_;
  // For duplicate checks: where each message name and id was defined.
  std::map<std::string, std::size_t, std::less<>> lineByName_;
  std::map<std::pair<bool, std::uint32_t>, std::pair<std::size_t, std::string>> byId_;
};

}  // namespace

// ---------------------------------------------------------------------------------------
// Database look-ups.

const DbcMessage* DbcDatabase::findMessage(std::uint32_t id, bool extended) const noexcept {
  const auto key = std::pair(extended, id);
  const auto it = std::lower_bound(messages.begin(), messages.end(), key, [](const DbcMessage& m, const auto& k) {
    return std::pair(m.extended, m.id) < k;
  });
  if (it == messages.end() || it->extended != extended || it->id != id) return nullptr;
  return &*it;
}

Result<const DbcMessage*> DbcDatabase::message(std::string_view name) const {
  std::vector<std::string_view> names;
  for (const DbcMessage& m : messages) {
    if (m.name == name) return &m;
    names.push_back(m.name);
  }
  std::sort(names.begin(), names.end());
  return fileError(file_name, 0, "no message " + quote(name) + "; messages: " + listNames(names));
}

Result<const DbcSignal*> DbcDatabase::signal(std::string_view messageName, std::string_view signalName) const {
  const Result<const DbcMessage*> m = message(messageName);
  if (!m) return m.error();
  std::vector<std::string_view> names;
  for (const DbcSignal& s : (*m)->signals) {
    if (s.name == signalName) return &s;
    names.push_back(s.name);
  }
  return fileError(file_name, 0,
                   "no signal " + quote(signalName) + " in message " + quote(messageName) +
                       "; its signals: " + listNames(names));
}

Result<DbcDatabase> parseDbc(std::string_view text, const std::string& fileName) {
  return DbcParser(text, fileName).parse();
}

Result<DbcDatabase> loadDbc(const std::string& path) {
  const Result<std::string> text = readTextFile(path);
  if (!text) return text.error();
  return parseDbc(*text, path);
}

// ---------------------------------------------------------------------------------------
// Decoding.

std::optional<std::uint64_t> extractRaw(const DbcBitField& bits, const CanFrame& frame) noexcept {
  if (bits.length == 0 || bits.length > 64) return std::nullopt;
  const std::size_t len = std::min<std::size_t>(frame.len, kCanFdMaxLen);
  if (bytesNeeded(bits) > len) return std::nullopt;
  std::uint64_t raw = 0;
  if (bits.order == DbcByteOrder::Intel) {
    // Bit i of the value is bit (start + i) in byte·8 + bit numbering, LSB first.
    for (std::size_t i = 0; i < bits.length; ++i) {
      const std::size_t b = std::size_t{bits.start_bit} + i;
      const unsigned bit = (unsigned{frame.data[b / 8]} >> (b % 8)) & 1u;
      raw |= std::uint64_t{bit} << i;
    }
  } else {
    // Walk from the MSB in big-endian linear order (byte 0 bit 7, …, byte 0 bit 0, byte 1 bit 7, …).
    const std::size_t msb = motorolaMsbLinear(bits.start_bit);
    for (std::size_t i = 0; i < bits.length; ++i) {
      const std::size_t l = msb + i;
      const unsigned bit = (unsigned{frame.data[l / 8]} >> (7 - l % 8)) & 1u;
      raw = (raw << 1) | bit;
    }
  }
  return raw;
}

bool isOutOfRange(const DbcSignal& signal, double physical) noexcept {
  if (!signal.hasRange()) return false;
  // Ranges are written in decimal and physical = raw·factor + offset is rounded, so a value
  // on the boundary may land a few ulps outside it: allow a millionth of one raw count.
  const double tolerance =
      std::max(1e-6 * std::abs(signal.factor), 1e-12 * std::max(std::abs(signal.minimum), std::abs(signal.maximum)));
  return physical < signal.minimum - tolerance || physical > signal.maximum + tolerance;
}

std::optional<DbcValue> decodeSignalValue(const DbcSignal& signal, const CanFrame& frame) noexcept {
  if (signal.mux_role == DbcMuxRole::Multiplexed) {
    const std::optional<std::uint64_t> selector = extractRaw(signal.multiplexor, frame);
    if (!selector || *selector != signal.mux_value) return std::nullopt;
  }
  const std::optional<std::uint64_t> raw = extractRaw(signal.bits, frame);
  if (!raw) return std::nullopt;
  double value = 0.0;
  switch (signal.value_type) {
    case DbcValueType::Float32:
      value = static_cast<double>(std::bit_cast<float>(static_cast<std::uint32_t>(*raw)));
      break;
    case DbcValueType::Float64:
      value = std::bit_cast<double>(*raw);
      break;
    case DbcValueType::Integer:
      if (signal.bits.is_signed) {
        // Two's complement: set every bit above the field when its top bit is set.
        std::uint64_t extended = *raw;
        if (signal.bits.length < 64 && ((*raw >> (signal.bits.length - 1)) & 1u) != 0)
          extended |= ~std::uint64_t{0} << signal.bits.length;
        value = static_cast<double>(static_cast<std::int64_t>(extended));
      } else {
        value = static_cast<double>(*raw);
      }
      break;
  }
  DbcValue out;
  out.raw = *raw;
  out.physical = value * signal.factor + signal.offset;
  out.out_of_range = isOutOfRange(signal, out.physical);
  return out;
}

std::optional<double> decodeSignal(const DbcSignal& signal, const CanFrame& frame) noexcept {
  const std::optional<DbcValue> v = decodeSignalValue(signal, frame);
  if (!v) return std::nullopt;
  return v->physical;
}

// ---------------------------------------------------------------------------------------
// Encoding.

namespace {

// Shortest text that reads back as the same double ("72", "0.01", "1e+300"), for messages.
std::string numberText(double v) {
  std::array<char, 32> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  if (ec != std::errc{}) return "?";
  return std::string(buf.data(), end);
}

std::string valueText(const DbcSignal& signal, double physical) {
  return numberText(physical) + (signal.unit.empty() ? std::string() : " " + signal.unit);
}

std::uint64_t fieldMask(std::uint8_t length) noexcept {
  return length >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << length) - 1;
}

}  // namespace

bool insertRaw(const DbcBitField& bits, std::uint64_t raw, CanFrame& frame) noexcept {
  // Mirrors extractRaw bit for bit; the same checks, so that a field extractRaw cannot read is
  // never half-written.
  if (bits.length == 0 || bits.length > 64) return false;
  const std::size_t len = std::min<std::size_t>(frame.len, kCanFdMaxLen);
  if (bytesNeeded(bits) > len) return false;
  auto put = [&frame](std::size_t byte, unsigned bitInByte, std::uint64_t bit) {
    const auto m = static_cast<std::uint8_t>(1u << bitInByte);
    if (bit != 0)
      frame.data[byte] = static_cast<std::uint8_t>(frame.data[byte] | m);
    else
      frame.data[byte] = static_cast<std::uint8_t>(frame.data[byte] & static_cast<std::uint8_t>(~m));
  };
  if (bits.order == DbcByteOrder::Intel) {
    // Bit i of the value goes to bit (start + i), byte·8 + bit numbering, LSB first.
    for (std::size_t i = 0; i < bits.length; ++i) {
      const std::size_t b = std::size_t{bits.start_bit} + i;
      put(b / 8, static_cast<unsigned>(b % 8), (raw >> i) & 1u);
    }
  } else {
    // extractRaw reads linear index msb + i as value bit (length − 1 − i): MSB first.
    const std::size_t msb = motorolaMsbLinear(bits.start_bit);
    for (std::size_t i = 0; i < bits.length; ++i) {
      const std::size_t l = msb + i;
      put(l / 8, static_cast<unsigned>(7 - l % 8), (raw >> (bits.length - 1 - i)) & 1u);
    }
  }
  return true;
}

Result<std::uint64_t> encodeSignalValue(const DbcSignal& signal, double physical) {
  const std::string what = "signal '" + signal.name + "': cannot encode " + valueText(signal, physical);
  if (!std::isfinite(physical)) return Error{what + " (not a finite number)"};
  if (signal.factor == 0.0 || !std::isfinite(signal.factor))
    return Error{what + " (the factor is " + numberText(signal.factor) + ", so no raw value maps to it)"};
  const double scaled = (physical - signal.offset) / signal.factor;
  if (!std::isfinite(scaled)) return Error{what + " (overflows (value − offset) / factor)"};
  switch (signal.value_type) {
    case DbcValueType::Float32: {
      if (signal.bits.length != 32) return Error{what + " (a float signal must be 32 bits long)"};
      if (std::abs(scaled) > static_cast<double>(std::numeric_limits<float>::max()))
        return Error{what + " (outside the range of a 32-bit float)"};
      return std::uint64_t{std::bit_cast<std::uint32_t>(static_cast<float>(scaled))};
    }
    case DbcValueType::Float64:
      if (signal.bits.length != 64) return Error{what + " (a double signal must be 64 bits long)"};
      return std::bit_cast<std::uint64_t>(scaled);
    case DbcValueType::Integer:
      break;
  }
  const std::uint8_t length = signal.bits.length;
  if (length == 0 || length > 64) return Error{what + " (field length " + std::to_string(length) + " is not 1-64)"};
  double counts = std::round(scaled);
  // Representable raw counts, as doubles: [lo, hiExclusive). Powers of two are exact, so the
  // comparisons are exact even for 64-bit fields where 2^64 − 1 itself is not a double.
  const double lo = signal.bits.is_signed ? -std::ldexp(1.0, length - 1) : 0.0;
  const double hiExclusive = std::ldexp(1.0, signal.bits.is_signed ? length - 1 : length);
  // Above 53 bits the field's largest value 2^n − 1 is not a double: it decodes to exactly
  // 2^n, the nearest double. Take that back as the largest value, so that every decoded value
  // encodes again; nothing else lies within rounding distance of the field.
  const std::uint64_t mask = fieldMask(length);
  if (length > 53 && counts == hiExclusive) return signal.bits.is_signed ? mask >> 1 : mask;
  if (counts < lo || counts >= hiExclusive) {
    // The physical range the field holds, for the message (factor may be negative).
    const double a = lo * signal.factor + signal.offset;
    const double b = (hiExclusive - 1.0) * signal.factor + signal.offset;
    return Error{what + " (the " + std::to_string(length) + "-bit " + (signal.bits.is_signed ? "signed" : "unsigned") +
                 " field holds " + numberText(std::min(a, b)) + " to " + numberText(std::max(a, b)) +
                 (signal.unit.empty() ? std::string() : " " + signal.unit) + ")"};
  }
  std::uint64_t raw = 0;
  if (signal.bits.is_signed)
    raw = static_cast<std::uint64_t>(static_cast<std::int64_t>(counts));  // two's complement
  else
    raw = static_cast<std::uint64_t>(counts);
  return raw & mask;
}

Status encodeSignal(const DbcSignal& signal, double physical, CanFrame& frame) {
  const Result<std::uint64_t> raw = encodeSignalValue(signal, physical);
  if (!raw) return raw.error();
  const std::size_t need = std::max(bytesNeeded(signal.bits), signal.mux_role == DbcMuxRole::Multiplexed
                                                                   ? bytesNeeded(signal.multiplexor)
                                                                   : std::size_t{0});
  if (need > std::min<std::size_t>(frame.len, kCanFdMaxLen))
    return Error{"signal '" + signal.name + "' needs a frame of at least " + std::to_string(need) + " bytes, found " +
                 std::to_string(frame.len)};
  // Both writes succeed: the lengths were checked above.
  if (signal.mux_role == DbcMuxRole::Multiplexed && !insertRaw(signal.multiplexor, signal.mux_value, frame))
    return Error{"signal '" + signal.name + "': the multiplexor field does not fit the frame"};
  if (!insertRaw(signal.bits, *raw, frame))
    return Error{"signal '" + signal.name + "': the field does not fit the frame"};
  return Ok{};
}

}  // namespace fogbeam::ipc
