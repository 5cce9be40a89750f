// fogbeam — EULUMDAT (.ldt) reader.
//
// One field per line (field names after the EULUMDAT description, Stockmar 1990):
//    1 company identification         2 Ityp, type indicator (0–3)   3 Isym, symmetry (0–4)
//    4 Mc, number of C planes         5 Dc, distance between C planes
//    6 Ng, intensities per C plane    7 Dg, distance between them
//    8 measurement report number      9 luminaire name   10 luminaire number
//   11 file name                     12 date/user
//   13–15 luminaire length/diameter, width, height (mm)
//   16–17 luminous area length/diameter, width (mm)
//   18–21 luminous area height in the C0, C90, C180, C270 planes (mm)
//   22 DFF, downward flux fraction (%)   23 LORL, light output ratio (%)
//   24 CFLI, conversion factor for luminous intensities   25 tilt during measurement (°)
//   26 n, number of standard sets of lamps; then for each set, one line each: number of
//      lamps, type of lamps, total luminous flux (lm), colour appearance, colour rendering
//      group, wattage including ballast (W)
//   then 10 direct ratios (room indices k = 0.6 … 5), the Mc C angles, the Ng γ angles, and
//   the luminous intensities in cd/klm, Ng values per stored C plane.
// Stored planes by Isym: 0 all Mc; 1 one plane (rotational); 2 Mc/2+1, C0–C180; 3 Mc/2+1,
// C90–C270; 4 Mc/4+1, C0–C90. The C angle list always covers the full circle; only the
// planes stored are kept, with the matching PlaneSymmetry.
//
// Behaviour choices:
//  * cd = cd/klm × |number of lamps| × total luminous flux of lamp set 1 / 1000. Some tools
//    write a negative number of lamps for absolute photometry (the flux is then the
//    luminaire's own); with |n| both conventions give the same candela.
//  * CFLI is reported as a keyword, not applied: cd/klm × lamp flux is already candela,
//    and writers disagree on what the factor would correct.
//  * Numeric fields may use a decimal comma ("12,5"), as European writers do. Text fields
//    may be empty. Lines may end in "\r\n". Trailing blank lines are fine; anything else
//    after the intensities means the counts were wrong and is an error.

#include <fogbeam/physics/eulumdat.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/text_scan.hpp>

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <iterator>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace fogbeam {

namespace {

using text::quote;

constexpr int kMaxPlanes = 3600;       // Mc: 0.1° steps over the circle
constexpr int kMaxGammaAngles = 3601;  // Ng: 0.05° steps over 180°
constexpr int kMaxLampSets = 20;
constexpr int kMaxLamps = 10000;

// Walks the file one field (line) at a time; errors name the field and its line, or the
// last line of the file when the data end early.
class LineCursor {
 public:
  LineCursor(const std::vector<text::Line>& lines, std::string name) : lines_(lines), name_(std::move(name)) {}

  const std::string& name() const noexcept { return name_; }
  // Line number of the field read last.
  std::size_t line() const noexcept { return i_ == 0 ? 1 : lines_[i_ - 1].number; }

  // A text field (may be empty), trimmed.
  Result<std::string_view> text(const std::string& field) {
    if (i_ >= lines_.size()) return endOfFile("expected " + field + ", found the end of the file");
    return text::trim(lines_[i_++].text);
  }

  Result<double> number(const std::string& field) {
    Result<std::string_view> t = text(field);
    if (!t) return t.error();
    return text::finiteNumber(*t, name_, line(), field, /*decimalComma=*/true);
  }

  Result<int> integer(const std::string& field, int lo, int hi) {
    Result<std::string_view> t = text(field);
    if (!t) return t.error();
    return text::integerInRange(*t, name_, line(), field, lo, hi, /*decimalComma=*/true);
  }

  // Element i of a block of n numbers; running out says how many were expected and found.
  Result<double> listItem(std::size_t i, std::size_t n, const std::string& what, const std::string& itemWhat) {
    if (i_ >= lines_.size()) {
      return endOfFile("expected " + std::to_string(n) + " " + what + ", found only " + std::to_string(i) +
                       " before the end of the file");
    }
    return number(itemWhat);
  }

  // An error about the field read last: "expected <expected>, found '<its text>'".
  Error atLast(const std::string& expected) const {
    return fileError(name_, line(), "expected " + expected + ", found " + quote(text::trim(lines_[i_ - 1].text)));
  }

  Status expectEnd(const std::string& after) {
    for (; i_ < lines_.size(); ++i_) {
      const std::string_view rest = text::trim(lines_[i_].text);
      if (!rest.empty())
        return fileError(name_, lines_[i_].number,
                         "expected the end of the file after " + after + ", found " + quote(rest));
    }
    return Ok{};
  }

 private:
  Error endOfFile(const std::string& message) const {
    return fileError(name_, lines_.empty() ? 1 : lines_.back().number, message);
  }

  const std::vector<text::Line>& lines_;
  std::string name_;
  std::size_t i_ = 0;
};

using Keywords = std::vector<std::pair<std::string, std::string>>;

Status keepText(LineCursor& in, const std::string& field, const char* keyword, Keywords& out) {
  Result<std::string_view> t = in.text(field);
  if (!t) return t.error();
  out.emplace_back(keyword, std::string(*t));
  return Ok{};
}

struct Header {
  int isym = 0;
  int mc = 0, ng = 0;
  std::size_t mcLine = 0;
  Keywords keywords;
};

// Lines 1–12: identification, indicators, counts and descriptive text.
Result<Header> readHeader(LineCursor& in) {
  Header h;
  if (Status s = keepText(in, "the company identification (line 1)", "COMPANY", h.keywords); !s) return s.error();
  if (Result<int> ityp = in.integer("Ityp, the type indicator", 0, 3); !ityp) return ityp.error();
  Result<int> isym = in.integer("Isym, the symmetry indicator", 0, 4);
  if (!isym) return isym.error();
  Result<int> mc = in.integer("Mc, the number of C planes", 1, kMaxPlanes);
  if (!mc) return mc.error();
  h.mcLine = in.line();
  if (Result<double> dc = in.number("Dc, the distance between C planes"); !dc) return dc.error();
  Result<int> ng = in.integer("Ng, the number of luminous intensities per C plane", 2, kMaxGammaAngles);
  if (!ng) return ng.error();
  if (Result<double> dg = in.number("Dg, the distance between luminous intensities"); !dg) return dg.error();
  h.isym = *isym;
  h.mc = *mc;
  h.ng = *ng;
  const std::pair<const char*, const char*> texts[] = {
      {"the measurement report number (line 8)", "REPORT_NUMBER"}, {"the luminaire name (line 9)", "LUMINAIRE_NAME"},
      {"the luminaire number (line 10)", "LUMINAIRE_NUMBER"},      {"the file name (line 11)", "FILE_NAME"},
      {"the date/user (line 12)", "DATE_USER"},
  };
  for (const auto& [field, keyword] : texts)
    if (Status s = keepText(in, field, keyword, h.keywords); !s) return s.error();
  return h;
}

// Lines 13–25: dimensions (mm), DFF, LORL, CFLI, tilt. Only CFLI is kept, for reports.
Status readDimensions(LineCursor& in, Keywords& keywords) {
  static constexpr const char* kFields[] = {
      "the luminaire length or diameter (line 13)", "the luminaire width (line 14)",
      "the luminaire height (line 15)",             "the luminous area length or diameter (line 16)",
      "the luminous area width (line 17)",          "the luminous area height in the C0 plane (line 18)",
      "the luminous area height in the C90 plane (line 19)", "the luminous area height in the C180 plane (line 20)",
      "the luminous area height in the C270 plane (line 21)", "DFF, the downward flux fraction (line 22)",
      "LORL, the light output ratio (line 23)",     "CFLI, the conversion factor for luminous intensities (line 24)",
      "the tilt of the luminaire during measurement (line 25)",
  };
  for (const char* field : kFields) {
    Result<double> v = in.number(field);
    if (!v) return v.error();
    if (std::string_view(field).substr(0, 4) == "CFLI") keywords.emplace_back("CFLI", text::formatNumber(*v));
  }
  return Ok{};
}

// Line 26 and the lamp sets; returns the cd/klm → cd factor of lamp set 1.
Result<double> readLampSets(LineCursor& in, Keywords& keywords) {
  Result<int> sets = in.integer("n, the number of standard sets of lamps (line 26)", 1, kMaxLampSets);
  if (!sets) return sets.error();
  double scale = 0.0;
  for (int s = 1; s <= *sets; ++s) {
    const std::string set = " of lamp set " + std::to_string(s);
    Result<int> lamps = in.integer("the number of lamps" + set, -kMaxLamps, kMaxLamps);
    if (!lamps) return lamps.error();
    if (s == 1 && *lamps == 0) return in.atLast("a non-zero number of lamps" + set);
    Result<std::string_view> type = in.text("the type of lamps" + set);
    if (!type) return type.error();
    Result<double> flux = in.number("the total luminous flux" + set);
    if (!flux) return flux.error();
    if (s == 1 && !(*flux > 0.0)) return in.atLast("a total luminous flux > 0 lm" + set);
    Result<std::string_view> colour = in.text("the colour appearance" + set);
    if (!colour) return colour.error();
    Result<std::string_view> rendering = in.text("the colour rendering group" + set);
    if (!rendering) return rendering.error();
    if (Result<double> watts = in.number("the wattage including ballast" + set); !watts) return watts.error();
    if (s == 1) {
      scale = std::abs(*lamps) * *flux / 1000.0;
      keywords.emplace_back("LAMP_COUNT", std::to_string(*lamps));
      keywords.emplace_back("LAMP_TYPE", std::string(*type));
      keywords.emplace_back("LAMP_FLUX", text::formatNumber(*flux));
      keywords.emplace_back("COLOUR_APPEARANCE", std::string(*colour));
      keywords.emplace_back("COLOUR_RENDERING", std::string(*rendering));
    }
  }
  return scale;
}

// `n` angles in degrees within [0, hi], strictly ascending; also their first line.
struct AngleList {
  std::vector<double> deg;
  std::size_t firstLine = 0;
};

Result<AngleList> readAngles(LineCursor& in, std::size_t n, const std::string& plural, const std::string& one,
                             double hi) {
  AngleList list;
  list.deg.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    Result<double> a = in.listItem(i, n, plural, one);
    if (!a) return a.error();
    if (*a < 0.0 || *a > hi) return in.atLast(plural + " from 0 to " + text::formatNumber(hi) + " degrees");
    if (i > 0 && !(*a > list.deg.back()))
      return in.atLast(plural + " in ascending order after " + text::formatNumber(list.deg.back()));
    if (i == 0) list.firstLine = in.line();
    list.deg.push_back(*a);
  }
  return list;
}

// Which of the Mc planes carry intensities, by Isym.
struct StoredPlanes {
  std::size_t first = 0, count = 0;
  PlaneSymmetry symmetry = PlaneSymmetry::None;
  double firstDeg = -1.0, lastDeg = -1.0;  // the C angles they must span (< 0: any)
  const char* meaning = "";
};

Result<StoredPlanes> storedPlanes(const Header& h, const std::string& name) {
  const auto mc = static_cast<std::size_t>(h.mc);
  auto needDivisor = [&](int d, const char* meaning) -> Error {
    return fileError(name, h.mcLine,
                     "expected Mc, the number of C planes, divisible by " + std::to_string(d) + " for Isym " +
                         std::to_string(h.isym) + " (" + meaning + "), found " + std::to_string(h.mc));
  };
  switch (h.isym) {
    case 0: return StoredPlanes{0, mc, PlaneSymmetry::None, -1.0, -1.0, "no symmetry"};
    case 1: return StoredPlanes{0, 1, PlaneSymmetry::Rotational, -1.0, -1.0, "rotational symmetry"};
    case 2:
      if (mc % 2 != 0) return needDivisor(2, "symmetry about the C0-C180 plane");
      return StoredPlanes{0, mc / 2 + 1, PlaneSymmetry::Half0To180, 0.0, 180.0, "symmetry about the C0-C180 plane"};
    case 3:
      if (mc % 4 != 0) return needDivisor(4, "symmetry about the C90-C270 plane");
      return StoredPlanes{mc / 4, mc / 2 + 1, PlaneSymmetry::Half90To270, 90.0, 270.0,
                          "symmetry about the C90-C270 plane"};
    default:
      if (mc % 4 != 0) return needDivisor(4, "symmetry about the C0-C180 and C90-C270 planes");
      return StoredPlanes{0, mc / 4 + 1, PlaneSymmetry::Quadrant, 0.0, 90.0,
                          "symmetry about the C0-C180 and C90-C270 planes"};
  }
}

// The stored planes must start and end where Isym says (e.g. C90 and C270 for Isym 3).
Status checkStoredRange(const StoredPlanes& p, const AngleList& c, int isym, const std::string& name) {
  if (p.firstDeg < 0.0) return Ok{};
  const std::size_t ends[] = {p.first, p.first + p.count - 1};
  const double want[] = {p.firstDeg, p.lastDeg};
  for (int k = 0; k < 2; ++k) {
    const std::size_t i = ends[k];
    if (!text::sameAngle(c.deg[i], want[k]))
      return fileError(name, c.firstLine + i,
                       "expected C angle " + text::formatNumber(want[k]) + " for plane " + std::to_string(i + 1) +
                           " with Isym " + std::to_string(isym) + " (" + p.meaning + "), found " +
                           text::formatNumber(c.deg[i]));
  }
  return Ok{};
}

Result<std::vector<double>> readIntensities(LineCursor& in, std::size_t planes, std::size_t ng, double scale) {
  const std::size_t n = planes * ng;
  const std::string what = "luminous intensities (" + std::to_string(planes) + " C planes x " + std::to_string(ng) +
                           " gamma angles)";
  std::vector<double> cd;
  cd.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    Result<double> v = in.listItem(i, n, what, "a luminous intensity in cd/klm");
    if (!v) return v.error();
    if (*v < 0.0) return in.atLast("a luminous intensity >= 0 cd/klm");
    cd.push_back(*v * scale);
  }
  return cd;
}

std::vector<double> toRadians(std::vector<double>::const_iterator first, std::vector<double>::const_iterator last) {
  std::vector<double> rad;
  std::transform(first, last, std::back_inserter(rad), [](double d) { return radians(d); });
  return rad;
}

// Lines 27 onwards: direct ratios, angles, intensities → the profile's grid.
Status readGrid(LineCursor& in, const Header& h, double scale, TabulatedProfile& p) {
  for (std::size_t i = 0; i < 10; ++i)
    if (Result<double> dr = in.listItem(i, 10, "direct ratios", "a direct ratio"); !dr) return dr.error();
  Result<StoredPlanes> planes = storedPlanes(h, in.name());
  if (!planes) return planes.error();
  Result<AngleList> c = readAngles(in, static_cast<std::size_t>(h.mc), "C angles", "a C angle in degrees", 360.0);
  if (!c) return c.error();
  if (Status s = checkStoredRange(*planes, *c, h.isym, in.name()); !s) return s.error();
  const auto ng = static_cast<std::size_t>(h.ng);
  Result<AngleList> g = readAngles(in, ng, "gamma angles", "a gamma angle in degrees", 180.0);
  if (!g) return g.error();
  Result<std::vector<double>> cd = readIntensities(in, planes->count, ng, scale);
  if (!cd) return cd.error();
  if (Status end = in.expectEnd(std::to_string(cd->size()) + " luminous intensities"); !end) return end.error();

  const auto first = c->deg.begin() + static_cast<std::ptrdiff_t>(planes->first);
  p.horizontal = planes->symmetry == PlaneSymmetry::Rotational
                     ? std::vector<double>{0.0}
                     : toRadians(first, first + static_cast<std::ptrdiff_t>(planes->count));
  p.vertical = toRadians(g->deg.begin(), g->deg.end());
  p.candela = std::move(*cd);
  p.symmetry = planes->symmetry;
  return Ok{};
}

}  // namespace

Result<TabulatedProfile> parseEulumdat(std::string_view text, const std::string& name) {
  const std::vector<text::Line> lines = text::splitLines(text);
  if (std::all_of(lines.begin(), lines.end(), [](const text::Line& l) { return text::trim(l.text).empty(); }))
    return fileError(name, 1, "expected an EULUMDAT file (company line, Ityp, Isym, Mc, ...), found an empty file");
  LineCursor in(lines, name);
  Result<Header> header = readHeader(in);
  if (!header) return header.error();
  TabulatedProfile p;
  p.keywords = std::move(header->keywords);
  if (Status s = readDimensions(in, p.keywords); !s) return s.error();
  Result<double> scale = readLampSets(in, p.keywords);
  if (!scale) return scale.error();
  if (Status s = readGrid(in, *header, *scale, p); !s) return s.error();
  p.type = PhotometricType::C;
  p.format = "EULUMDAT";
  p.source = name;
  if (Status s = p.validate(); !s) return s.error();
  return p;
}

Result<TabulatedProfile> parseEulumdatFile(const std::string& path) {
  Result<std::string> text = readTextFile(path);
  if (!text) return text.error();
  return parseEulumdat(*text, path);
}

}  // namespace fogbeam
