// fogbeam — IES LM-63 reader (LM-63-1986, -1991, -1995, -2002, -2019).
//
// Layout, the same order in every version (field names as in LM-63-2002):
//   header line        "IESNA91", "IESNA:LM-63-1995", "IESNA:LM-63-2002", "IES:LM-63-2019";
//                      absent in LM-63-1986 files, whose first lines are free text labels
//   keyword lines      "[KEYWORD] value"; "[MORE] text" continues the previous keyword
//   TILT=NONE | TILT=INCLUDE | TILT=<filename>
//   tilt data          (INCLUDE, or the named file) lamp-to-luminaire geometry, number of
//                      angles, the angles, the multiplying factors
//   10 numbers         number of lamps, lumens per lamp (−1 = absolute photometry),
//                      candela multiplier, number of vertical angles, number of horizontal
//                      angles, photometric type (1 = C, 2 = B, 3 = A), units type (1 = feet,
//                      2 = metres), width, length, height
//   3 numbers          ballast factor, future use (LM-63-1986/1991: ballast-lamp
//                      photometric factor), input watts
//   vertical angles, horizontal angles, then one block of #vertical candela values per
//   horizontal angle.
// From the tilt data on, numbers may wrap across lines freely; blanks and commas (written
// by some tools) separate them.
//
// Behaviour choices:
//  * Intensity = candela × candela multiplier × ballast factor, × ballast-lamp photometric
//    factor for 1986/1991 files (1995 and later define that field as "future use" and it is
//    ignored). Relative photometry (lumens per lamp > 0) is used as given: LM-63 values are
//    already candela for the rated lamp lumens, so no rescaling by lumens happens.
//  * TILT: with lamp-to-luminaire geometry 1 (vertical lamp, base up or down) the tilt
//    factors depend on the luminaire tilt alone, and fogbeam applies the factor for the
//    luminaire as photometered (tilt 0°, linear interpolation, the end value outside the
//    tabulated angles) to every candela value. Geometries 2 and 3 (horizontal lamp) make
//    the factor depend on the plane the luminaire is tilted in, which a lamp description
//    does not state, so they are rejected with an error naming the geometry.
//    TILT=<filename> reads the same tilt data from a file through the IesTiltLoader;
//    parseIesFile resolves it relative to the IES file's directory.
//  * Angles must use the ranges LM-63 allows, which fix the symmetry:
//      type C horizontal {0} rotational, 0–90 quadrant, 0–180 half (C0–C180 plane),
//      90–270 half (C90–C270 plane), 0 to more than 180 (usually 360) full circle;
//      type C vertical 0–90, 90–180 or 0–180;
//      types A/B horizontal 0–90 (mirrored, I(−H) = I(H)) or −90–90; vertical −90–90 or
//      0–90 (the lower half is then not covered and reads 0 cd).
//  * Anything left after the last candela value is an error (the counts were wrong), except
//    blanks and the DOS end-of-file mark Ctrl-Z.

#include <fogbeam/physics/ies.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/text_scan.hpp>

#include <algorithm>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace fogbeam {

namespace {

using text::quote;

enum class IesVersion { Lm63_1986, Lm63_1991, Lm63_1995, Lm63_2002, Lm63_2019 };

const char* formatName(IesVersion v) {
  switch (v) {
    case IesVersion::Lm63_1986: return "IES LM-63-1986";
    case IesVersion::Lm63_1991: return "IES LM-63-1991";
    case IesVersion::Lm63_1995: return "IES LM-63-1995";
    case IesVersion::Lm63_2002: return "IES LM-63-2002";
    case IesVersion::Lm63_2019: return "IES LM-63-2019";
  }
  return "IES LM-63";
}

// Only LM-63-1986 and -1991 define the second number of the ballast line as the
// "ballast-lamp photometric factor"; later versions reserve it for future use.
bool hasBallastLampFactor(IesVersion v) { return v == IesVersion::Lm63_1986 || v == IesVersion::Lm63_1991; }

// Guards against absurd counts before anything is allocated: 0.05° steps over a full
// circle, and 32 MB of candela values.
constexpr int kMaxAngles = 7201;
constexpr std::size_t kMaxValues = 4'000'000;
constexpr int kMaxTiltAngles = 3601;

const char* typeName(PhotometricType t) {
  switch (t) {
    case PhotometricType::A: return "type A";
    case PhotometricType::B: return "type B";
    case PhotometricType::C: return "type C";
  }
  return "type ?";
}

// ---------------------------------------------------------------------------------------
// Numeric data: a tokenizer that tracks line numbers, and a reader that words errors.

struct Token {
  std::string_view text;
  std::size_t line = 0;
};

// Splits the numeric part of an LM-63 file into tokens. Numbers may wrap across lines
// freely and some writers separate them with commas, so blanks and ',' both separate.
class Tokenizer {
 public:
  Tokenizer(std::string_view text, std::size_t firstLine) noexcept : text_(text), line_(firstLine) {}

  std::optional<Token> next() noexcept {
    while (pos_ < text_.size() && isSeparator(text_[pos_])) {
      if (text_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ == text_.size()) return std::nullopt;
    const std::size_t start = pos_;
    while (pos_ < text_.size() && !isSeparator(text_[pos_])) ++pos_;
    return Token{text_.substr(start, pos_ - start), line_};
  }

 private:
  static constexpr bool isSeparator(char c) noexcept { return c == ',' || text::isBlank(c); }

  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_;
};

// Reads numbers from a Tokenizer and reports problems as "file:line: expected …, found …".
// At the end of the data the error names the line where the data ended.
class NumberReader {
 public:
  // `firstLine` is the line number of text[0]; before any token is read, "where the data
  // ended" is the line before it (the TILT= line of an IES file).
  NumberReader(std::string_view text, std::size_t firstLine, std::string file)
      : tokens_(text, firstLine), file_(std::move(file)), endLine_(std::max<std::size_t>(1, firstLine - 1)) {}

  const std::string& file() const noexcept { return file_; }

  std::optional<Token> next() {
    std::optional<Token> t = tokens_.next();
    if (t) endLine_ = t->line;
    return t;
  }

  // A single field: a finite number, or an error naming `what`.
  Result<double> number(const std::string& what) {
    const std::optional<Token> t = next();
    if (!t) return endOfData(what);
    last_ = *t;
    return text::finiteNumber(t->text, file_, t->line, what);
  }

  Result<int> integer(const std::string& what, int lo, int hi) {
    const std::optional<Token> t = next();
    if (!t) return endOfData(what);
    last_ = *t;
    return text::integerInRange(t->text, file_, t->line, what, lo, hi);
  }

  // Element `i` of a list of `n` values: at the end of the data the error says how many
  // were expected and how many were found.
  Result<double> listItem(std::size_t i, std::size_t n, const std::string& what, const std::string& itemWhat) {
    const std::optional<Token> t = next();
    if (!t) {
      return fileError(file_, endLine_,
                       "expected " + std::to_string(n) + " " + what + ", found only " + std::to_string(i) +
                           " before the end of the file");
    }
    last_ = *t;
    return text::finiteNumber(t->text, file_, t->line, itemWhat);
  }

  // The token read last, for errors about its value ("expected … >= 0, found '-3'").
  Error atLast(const std::string& expected) const {
    return fileError(file_, last_.line, "expected " + expected + ", found " + quote(last_.text));
  }
  std::size_t lastLine() const noexcept { return last_.line; }

  // Fails when anything but blanks follows the data.
  Status expectEnd(const std::string& after, const std::string& hint) {
    const std::optional<Token> t = next();
    if (!t) return Ok{};
    return fileError(file_, t->line,
                     "expected the end of the file after " + after + ", found " + quote(t->text) + hint);
  }

 private:
  Error endOfData(const std::string& what) const {
    return fileError(file_, endLine_, "expected " + what + ", found the end of the file");
  }

  Tokenizer tokens_;
  std::string file_;
  std::size_t endLine_;
  Token last_;
};

// ---------------------------------------------------------------------------------------
// Header: version line, keyword lines, TILT= line.

struct IesHeader {
  IesVersion version = IesVersion::Lm63_1986;
  std::vector<std::pair<std::string, std::string>> keywords;
  std::string tilt;            // the text after "TILT="
  std::size_t tiltLine = 0;    // its line number
  std::size_t dataOffset = 0;  // where the line after it starts in the text
};

std::string expectedTilt(const std::string& found) {
  return "expected a TILT= line (TILT=NONE, TILT=INCLUDE or TILT=<file>)" + found;
}

// LM-63-1991 and later open with a header line; LM-63-1986 files start with label text.
bool looksLikeVersionLine(std::string_view line) {
  return line.substr(0, 5) == "IESNA" || line.substr(0, 4) == "IES:";
}

Result<IesVersion> versionFromHeader(std::string_view line, std::size_t number, const std::string& name) {
  struct Known {
    std::string_view text;
    IesVersion version;
  };
  static constexpr Known kKnown[] = {
      {"IESNA91", IesVersion::Lm63_1991},          {"IESNA:LM-63-1991", IesVersion::Lm63_1991},
      {"IESNA:LM-63-1995", IesVersion::Lm63_1995}, {"IESNA:LM-63-2002", IesVersion::Lm63_2002},
      {"IES:LM-63-2019", IesVersion::Lm63_2019},   {"IESNA:LM-63-2019", IesVersion::Lm63_2019},
  };
  for (const Known& k : kKnown)
    if (line == k.text) return k.version;
  return fileError(name, number,
                   "expected an LM-63 header line (IESNA91, IESNA:LM-63-1995, IESNA:LM-63-2002 or IES:LM-63-2019), "
                   "found " + quote(line));
}

// The value of a "TILT=…" line, or nullopt when the line is something else.
std::optional<std::string_view> tiltValue(std::string_view line) {
  if (line.size() < 4) return std::nullopt;
  for (std::size_t i = 0; i < 4; ++i)
    if ((line[i] & ~0x20) != "TILT"[i]) return std::nullopt;
  std::string_view rest = text::trim(line.substr(4));
  if (rest.empty() || rest.front() != '=') return std::nullopt;
  return text::trim(rest.substr(1));
}

// A line of numbers before TILT= means the TILT line is missing: the photometric data
// line (10 numbers) has begun. Labels of 1986 files are text, not lists of numbers.
bool looksLikeNumbers(std::string_view line) {
  Tokenizer t(line, 1);
  int count = 0;
  while (const std::optional<Token> tok = t.next()) {
    if (!text::parseNumber(tok->text)) return false;
    ++count;
  }
  return count >= 2;
}

// "[KEYWORD] value" → (KEYWORD, value); "[MORE] text" is appended to the previous
// keyword's value after a space. Lines without brackets (the labels of LM-63-1986, stray
// text in later files) are kept under the name "TEXT".
Status addKeywordLine(std::string_view line, std::size_t number, const std::string& name,
                      std::vector<std::pair<std::string, std::string>>& keywords) {
  if (line.front() != '[') {
    keywords.emplace_back("TEXT", std::string(line));
    return Ok{};
  }
  const std::size_t close = line.find(']');
  if (close == std::string_view::npos)
    return fileError(name, number, "expected a keyword line '[KEYWORD] value', found " + quote(line));
  std::string key(text::trim(line.substr(1, close - 1)));
  std::string value(text::trim(line.substr(close + 1)));
  if (key == "MORE" && !keywords.empty()) {
    std::string& previous = keywords.back().second;
    if (!previous.empty() && !value.empty()) previous += ' ';
    previous += value;
    return Ok{};
  }
  keywords.emplace_back(std::move(key), std::move(value));
  return Ok{};
}

Result<IesHeader> readHeader(const std::vector<text::Line>& lines, const std::string& name) {
  IesHeader header;
  // The header line is the first non-blank line (the caller made sure there is one).
  std::size_t i = 0;
  while (text::trim(lines[i].text).empty()) ++i;
  if (const std::string_view first = text::trim(lines[i].text); looksLikeVersionLine(first)) {
    Result<IesVersion> version = versionFromHeader(first, lines[i].number, name);
    if (!version) return version.error();
    header.version = *version;
    ++i;
  }
  for (; i < lines.size(); ++i) {
    const std::string_view line = text::trim(lines[i].text);
    if (const std::optional<std::string_view> tilt = tiltValue(line)) {
      if (tilt->empty()) return fileError(name, lines[i].number, expectedTilt(", found " + quote(line)));
      header.tilt = std::string(*tilt);
      header.tiltLine = lines[i].number;
      header.dataOffset = lines[i].next;
      return header;
    }
    if (line.empty()) continue;
    if (looksLikeNumbers(line))
      return fileError(name, lines[i].number, expectedTilt(" before the photometric data, found " + quote(line)));
    if (Status s = addKeywordLine(line, lines[i].number, name, header.keywords); !s) return s.error();
  }
  return fileError(name, lines.back().number, expectedTilt(", found the end of the file"));
}

// ---------------------------------------------------------------------------------------
// Tilt data.

bool equalsIgnoringCase(std::string_view a, std::string_view b) {
  return a.size() == b.size() &&
         std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) { return (x & ~0x20) == (y & ~0x20); });
}

// Linear interpolation of the factors at a luminaire tilt of 0°; outside the tabulated
// angles the nearest end value holds.
double factorAtZeroTilt(const std::vector<double>& angles, const std::vector<double>& factors) {
  if (angles.front() >= 0.0) return factors.front();
  if (angles.back() <= 0.0) return factors.back();
  std::size_t hi = 1;
  while (angles[hi] < 0.0) ++hi;
  const double t = (0.0 - angles[hi - 1]) / (angles[hi] - angles[hi - 1]);
  return (1.0 - t) * factors[hi - 1] + t * factors[hi];
}

// LM-63 tilt data: "lamp-to-luminaire geometry", "number of pairs of angles and
// multiplying factors", the angles (degrees, ascending), the multiplying factors.
// Returns the factor for the luminaire as photometered (see the file comment).
Result<double> readTiltData(NumberReader& in) {
  Result<int> geometry = in.integer("the TILT lamp-to-luminaire geometry", 1, 3);
  if (!geometry) return geometry.error();
  if (*geometry != 1)
    return in.atLast("TILT lamp-to-luminaire geometry 1 (vertical lamp; geometries 2 and 3, horizontal lamps, are "
                     "not supported)");
  Result<int> count = in.integer("the number of TILT angles", 1, kMaxTiltAngles);
  if (!count) return count.error();
  const auto n = static_cast<std::size_t>(*count);
  std::vector<double> angles, factors;
  for (std::size_t i = 0; i < n; ++i) {
    Result<double> a = in.listItem(i, n, "TILT angles", "a TILT angle in degrees");
    if (!a) return a.error();
    if (*a < -180.0 || *a > 180.0) return in.atLast("TILT angles from -180 to 180 degrees");
    if (i > 0 && !(*a > angles.back()))
      return in.atLast("TILT angles in ascending order after " + text::formatNumber(angles.back()));
    angles.push_back(*a);
  }
  for (std::size_t i = 0; i < n; ++i) {
    Result<double> f = in.listItem(i, n, "TILT multiplying factors", "a TILT multiplying factor");
    if (!f) return f.error();
    if (*f < 0.0) return in.atLast("a TILT multiplying factor >= 0");
    factors.push_back(*f);
  }
  return factorAtZeroTilt(angles, factors);
}

Result<double> tiltFactor(const IesHeader& header, NumberReader& data, const std::string& name,
                          const IesTiltLoader& loader) {
  if (equalsIgnoringCase(header.tilt, "NONE")) return 1.0;
  if (equalsIgnoringCase(header.tilt, "INCLUDE")) return readTiltData(data);
  if (!loader)
    return fileError(name, header.tiltLine,
                     "TILT=" + header.tilt + " names a tilt file, but no tilt file loader was given (use parseIesFile)");
  Result<std::string> tiltText = loader(header.tilt);
  if (!tiltText)
    return fileError(name, header.tiltLine,
                     "cannot read TILT file " + quote(header.tilt) + ": " + tiltText.error().message);
  NumberReader tiltData(*tiltText, 1, header.tilt);
  Result<double> factor = readTiltData(tiltData);
  if (!factor) return factor;
  if (Status end = tiltData.expectEnd("the TILT multiplying factors", ""); !end) return end.error();
  return factor;
}

// ---------------------------------------------------------------------------------------
// Photometric data.

struct PhotometricLine {
  std::size_t nv = 0, nh = 0;
  PhotometricType type = PhotometricType::C;
  double scale = 1.0;  // candela multiplier × ballast factor (× ballast-lamp factor)
};

Result<PhotometricType> readPhotometricType(NumberReader& in) {
  Result<int> t = in.integer("the photometric type, 1 (C), 2 (B) or 3 (A)", 1, 3);
  if (!t) return t.error();
  if (*t == 1) return PhotometricType::C;
  return *t == 2 ? PhotometricType::B : PhotometricType::A;
}

// The 10 numbers after the tilt data: lamps, lumens, multiplier, counts, type, units, size.
Result<PhotometricLine> readPhotometricLine(NumberReader& in) {
  PhotometricLine p;
  if (Result<int> lamps = in.integer("the number of lamps", 1, 1'000'000); !lamps) return lamps.error();
  Result<double> lumens = in.number("the lumens per lamp");
  if (!lumens) return lumens.error();
  if (!(*lumens > 0.0 || *lumens == -1.0)) return in.atLast("the lumens per lamp > 0, or -1 for absolute photometry");
  Result<double> multiplier = in.number("the candela multiplier");
  if (!multiplier) return multiplier.error();
  if (!(*multiplier > 0.0)) return in.atLast("a candela multiplier > 0");
  Result<int> nv = in.integer("the number of vertical angles", 2, kMaxAngles);
  if (!nv) return nv.error();
  Result<int> nh = in.integer("the number of horizontal angles", 1, kMaxAngles);
  if (!nh) return nh.error();
  p.nv = static_cast<std::size_t>(*nv);
  p.nh = static_cast<std::size_t>(*nh);
  if (p.nv * p.nh > kMaxValues)
    return in.atLast("at most " + std::to_string(kMaxValues) + " candela values (vertical x horizontal angles)");
  Result<PhotometricType> type = readPhotometricType(in);
  if (!type) return type.error();
  p.type = *type;
  if (Result<int> units = in.integer("the units type, 1 (feet) or 2 (metres)", 1, 2); !units) return units.error();
  for (const char* what : {"the luminaire width", "the luminaire length", "the luminaire height"})
    if (Result<double> size = in.number(what); !size) return size.error();
  p.scale = *multiplier;
  return p;
}

// The 3 numbers of the ballast line: ballast factor, future use (1986/1991: ballast-lamp
// photometric factor), input watts. Returns the factor they contribute to every value.
Result<double> readBallastLine(NumberReader& in, IesVersion version) {
  Result<double> ballast = in.number("the ballast factor");
  if (!ballast) return ballast.error();
  if (!(*ballast > 0.0)) return in.atLast("a ballast factor > 0");
  double factor = *ballast;
  if (hasBallastLampFactor(version)) {
    Result<double> lampFactor = in.number("the ballast-lamp photometric factor");
    if (!lampFactor) return lampFactor.error();
    if (!(*lampFactor > 0.0)) return in.atLast("a ballast-lamp photometric factor > 0");
    factor *= *lampFactor;
  } else if (Result<double> future = in.number("the 'future use' field"); !future) {
    return future.error();
  }
  if (Result<double> watts = in.number("the input watts"); !watts) return watts.error();
  return factor;
}

struct AngleList {
  std::vector<double> deg;
  std::size_t firstLine = 0, lastLine = 0;
};

// `n` angles in degrees, each within [lo, hi] and strictly ascending. A descending step
// usually means the declared count is wrong, so the message points at it.
Result<AngleList> readAngles(NumberReader& in, std::size_t n, const std::string& axis, PhotometricType type,
                             double lo, double hi) {
  AngleList list;
  list.deg.reserve(n);
  const std::string plural = axis + " angles";
  for (std::size_t i = 0; i < n; ++i) {
    Result<double> a = in.listItem(i, n, plural, "a " + axis + " angle in degrees");
    if (!a) return a.error();
    if (*a < lo || *a > hi)
      return in.atLast(plural + " from " + text::formatNumber(lo) + " to " + text::formatNumber(hi) +
                       " degrees for photometric " + typeName(type));
    if (i > 0 && !(*a > list.deg.back()))
      return in.atLast(plural + " in ascending order after " + text::formatNumber(list.deg.back()) +
                       " (is the number of " + plural + ", " + std::to_string(n) + ", right?)");
    if (i == 0) list.firstLine = in.lastLine();
    list.lastLine = in.lastLine();
    list.deg.push_back(*a);
  }
  return list;
}

std::string rangeText(const AngleList& a) {
  return text::formatNumber(a.deg.front()) + " to " + text::formatNumber(a.deg.back());
}

// LM-63 allows vertical angles 0–90, 90–180 or 0–180 (type C) and −90–90 or 0–90 (A/B).
Status checkVerticalRange(const AngleList& v, PhotometricType type, const std::string& name) {
  const double first = v.deg.front(), last = v.deg.back();
  using text::sameAngle;
  if (type == PhotometricType::C) {
    if ((sameAngle(first, 0.0) || sameAngle(first, 90.0)) && (sameAngle(last, 90.0) || sameAngle(last, 180.0)))
      return Ok{};
    return fileError(name, v.lastLine,
                     "expected type C vertical angles from 0 or 90 to 90 or 180 degrees, found " + rangeText(v));
  }
  if ((sameAngle(first, -90.0) || sameAngle(first, 0.0)) && sameAngle(last, 90.0)) return Ok{};
  return fileError(name, v.lastLine,
                   std::string("expected ") + typeName(type) + " vertical angles from -90 or 0 to 90 degrees, found " +
                       rangeText(v));
}

// The horizontal range fixes the symmetry (the layouts LM-63 allows; see the file comment).
Result<PlaneSymmetry> horizontalSymmetry(const AngleList& h, PhotometricType type, const std::string& name) {
  const double first = h.deg.front(), last = h.deg.back();
  using text::sameAngle;
  if (type == PhotometricType::C) {
    if (h.deg.size() == 1 && sameAngle(first, 0.0)) return PlaneSymmetry::Rotational;
    if (h.deg.size() > 1 && sameAngle(first, 0.0)) {
      if (sameAngle(last, 90.0)) return PlaneSymmetry::Quadrant;
      if (sameAngle(last, 180.0)) return PlaneSymmetry::Half0To180;
      if (last > 180.0) return PlaneSymmetry::None;
    }
    if (sameAngle(first, 90.0) && sameAngle(last, 270.0)) return PlaneSymmetry::Half90To270;
    return fileError(name, h.lastLine,
                     "expected type C horizontal angles 0 (rotational), 0 to 90, 0 to 180, 90 to 270 or 0 to 360 "
                     "degrees, found " + rangeText(h));
  }
  if (h.deg.size() > 1 && sameAngle(last, 90.0)) {
    if (sameAngle(first, 0.0)) return PlaneSymmetry::MirrorH;
    if (sameAngle(first, -90.0)) return PlaneSymmetry::None;
  }
  return fileError(name, h.lastLine,
                   std::string("expected ") + typeName(type) +
                       " horizontal angles from 0 to 90 (mirrored) or -90 to 90 degrees, found " + rangeText(h));
}

std::string gridText(std::size_t nv, std::size_t nh) {
  return std::to_string(nh) + " horizontal x " + std::to_string(nv) + " vertical angles";
}

// One block of nv values per horizontal angle, in the order of TabulatedProfile::candela.
Result<std::vector<double>> readCandela(NumberReader& in, std::size_t nv, std::size_t nh, double scale) {
  const std::size_t n = nv * nh;
  const std::string what = "candela values (" + gridText(nv, nh) + ")";
  std::vector<double> cd;
  cd.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    Result<double> v = in.listItem(i, n, what, "a candela value");
    if (!v) return v.error();
    if (*v < 0.0) return in.atLast("a candela value >= 0");
    cd.push_back(*v * scale);
  }
  return cd;
}

struct Grid {
  PhotometricType type = PhotometricType::C;
  PlaneSymmetry symmetry = PlaneSymmetry::None;
  std::vector<double> horizontal, vertical, candela;  // degrees, degrees, cd
};

// Everything after the tilt data: photometric line, ballast line, angles, candela values.
Result<Grid> readGrid(NumberReader& in, IesVersion version, double tilt) {
  Result<PhotometricLine> p = readPhotometricLine(in);
  if (!p) return p.error();
  Result<double> ballast = readBallastLine(in, version);
  if (!ballast) return ballast.error();
  const bool typeC = p->type == PhotometricType::C;
  Result<AngleList> v = readAngles(in, p->nv, "vertical", p->type, typeC ? 0.0 : -90.0, typeC ? 180.0 : 90.0);
  if (!v) return v.error();
  Result<AngleList> h = readAngles(in, p->nh, "horizontal", p->type, typeC ? 0.0 : -90.0, typeC ? 360.0 : 90.0);
  if (!h) return h.error();
  if (Status s = checkVerticalRange(*v, p->type, in.file()); !s) return s.error();
  Result<PlaneSymmetry> symmetry = horizontalSymmetry(*h, p->type, in.file());
  if (!symmetry) return symmetry.error();
  Result<std::vector<double>> cd = readCandela(in, p->nv, p->nh, p->scale * *ballast * tilt);
  if (!cd) return cd.error();
  const std::string after = std::to_string(p->nv * p->nh) + " candela values";
  if (Status end = in.expectEnd(after, " (more values than " + gridText(p->nv, p->nh) + ")"); !end) return end.error();
  return Grid{p->type, *symmetry, std::move(h->deg), std::move(v->deg), std::move(*cd)};
}

std::vector<double> toRadians(const std::vector<double>& deg) {
  std::vector<double> rad(deg.size());
  std::transform(deg.begin(), deg.end(), rad.begin(), [](double d) { return radians(d); });
  return rad;
}

bool isBlankText(const std::vector<text::Line>& lines) {
  return std::all_of(lines.begin(), lines.end(), [](const text::Line& l) { return text::trim(l.text).empty(); });
}

}  // namespace

Result<TabulatedProfile> parseIes(std::string_view text, const std::string& name, const IesTiltLoader& tiltLoader) {
  const std::vector<text::Line> lines = text::splitLines(text);
  if (isBlankText(lines))
    return fileError(name, 1,
                     "expected an IES LM-63 file (header, keywords, TILT=, photometric data), found an empty file");
  Result<IesHeader> header = readHeader(lines, name);
  if (!header) return header.error();
  NumberReader data(text.substr(header->dataOffset), header->tiltLine + 1, name);
  Result<double> tilt = tiltFactor(*header, data, name, tiltLoader);
  if (!tilt) return tilt.error();
  Result<Grid> grid = readGrid(data, header->version, *tilt);
  if (!grid) return grid.error();

  TabulatedProfile p;
  p.type = grid->type;
  p.symmetry = grid->symmetry;
  p.horizontal = toRadians(grid->horizontal);
  p.vertical = toRadians(grid->vertical);
  p.candela = std::move(grid->candela);
  p.format = formatName(header->version);
  p.source = name;
  p.keywords = std::move(header->keywords);
  if (Status s = p.validate(); !s) return s.error();
  return p;
}

Result<TabulatedProfile> parseIesFile(const std::string& path) {
  Result<std::string> text = readTextFile(path);
  if (!text) return text.error();
  // TILT=<filename> is relative to the IES file's directory (an absolute name stays as is).
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  const IesTiltLoader loader = [dir](const std::string& tiltName) { return readTextFile((dir / tiltName).string()); };
  return parseIes(*text, path, loader);
}

}  // namespace fogbeam
