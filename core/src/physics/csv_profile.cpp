// fogbeam — CSV grid reader (H–V intensity tables exported from optics tools).
//
//   # lines starting with '#' are comments
//   # symmetry: mirror-h             optional directive, see below
//   V\H, -10, -5, 0, 5, 10           first row: a label cell, then H angles (degrees, ascending)
//   -5, 100, 200, 300, 200, 100      each row: a V angle (degrees, ascending), then one value
//   0, 400, 900, 1500, 900, 400      in cd per H angle
//
// Separators are ',' or ';': the header row decides, and with ';' a decimal comma is
// accepted ("12,5"). Cells may be wrapped in double quotes; empty cells at the end of a row
// (a trailing separator) are ignored.
//
// The grid is stored as photometric type B (the headlamp goniometer convention of
// profile.hpp). The table is row-major in V while TabulatedProfile holds one block per H
// angle, so it is transposed: candela[ih * nv + iv] = row iv, column ih.
//
// Symmetry: a grid that starts at H = 0 may be a genuinely one-sided measurement, so it is
// not mirrored by guesswork. Only the directive "# symmetry: mirror-h" mirrors
// (I(−H, V) = I(H, V); the first H angle must then be 0); "# symmetry: none" is the default.

#include <fogbeam/physics/csv_profile.hpp>
#include <fogbeam/util/files.hpp>
#include <fogbeam/util/text_scan.hpp>

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

namespace {

using text::quote;

constexpr std::size_t kMaxColumns = 100'000;
constexpr std::size_t kMaxValues = 4'000'000;

std::string lowercase(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

std::string_view unquote(std::string_view cell) {
  cell = text::trim(cell);
  if (cell.size() >= 2 && cell.front() == '"' && cell.back() == '"') cell = text::trim(cell.substr(1, cell.size() - 2));
  return cell;
}

std::vector<std::string_view> splitCells(std::string_view line, char sep) {
  std::vector<std::string_view> cells;
  std::size_t start = 0;
  for (;;) {
    const std::size_t end = line.find(sep, start);
    cells.push_back(unquote(line.substr(start, end == std::string_view::npos ? std::string_view::npos : end - start)));
    if (end == std::string_view::npos) break;
    start = end + 1;
  }
  while (!cells.empty() && cells.back().empty()) cells.pop_back();
  return cells;
}

class CsvReader {
 public:
  explicit CsvReader(const std::string& name) : name_(name) {}

  Status line(const text::Line& l) {
    const std::string_view t = text::trim(l.text);
    if (t.empty()) return Ok{};
    if (t.front() == '#') {
      sawComment_ = true;
      return comment(t.substr(1), l.number);
    }
    if (!haveHeader_) return header(t, l.number);
    return row(t, l.number);
  }

  Result<TabulatedProfile> finish(std::size_t lastLine) {
    if (!haveHeader_)
      return fileError(name_, lastLine,
                       std::string("expected a header row (a label cell, then H angles), found ") +
                           (sawComment_ ? "only comments" : "an empty file"));
    if (v_.size() < 2)
      return fileError(name_, lastLine,
                       "expected at least 2 rows (a V angle, then one value per H angle), found " +
                           std::to_string(v_.size()));
    if (mirror_ && !text::sameAngle(h_.front(), 0.0))
      return fileError(name_, headerLine_,
                       "expected the first H angle to be 0 for '# symmetry: mirror-h', found " +
                           text::formatNumber(h_.front()));
    TabulatedProfile p;
    p.type = PhotometricType::B;
    p.symmetry = mirror_ ? PlaneSymmetry::MirrorH : PlaneSymmetry::None;
    for (double h : h_) p.horizontal.push_back(radians(h));
    for (double v : v_) p.vertical.push_back(radians(v));
    const std::size_t nh = h_.size(), nv = v_.size();
    p.candela.resize(nh * nv);
    for (std::size_t iv = 0; iv < nv; ++iv)
      for (std::size_t ih = 0; ih < nh; ++ih) p.candela[ih * nv + iv] = rows_[iv * nh + ih];
    p.format = "CSV grid";
    p.source = name_;
    return p;
  }

 private:
  // "# symmetry: mirror-h" / "# symmetry: none"; other comments are ignored.
  Status comment(std::string_view body, std::size_t number) {
    const std::string c = lowercase(text::trim(body));
    if (c.rfind("symmetry", 0) != 0) return Ok{};
    const std::string_view rest = text::trim(std::string_view(c).substr(8));
    if (rest.empty() || rest.front() != ':') return Ok{};
    const std::string_view value = text::trim(rest.substr(1));
    if (value == "mirror-h") {
      mirror_ = true;
    } else if (value == "none") {
      mirror_ = false;
    } else {
      return fileError(name_, number, "expected 'mirror-h' or 'none' after '# symmetry:', found " + quote(value));
    }
    return Ok{};
  }

  // An angle cell within [-90, 90] degrees, ascending after `previous` (if any).
  Result<double> angle(std::string_view cell, std::size_t number, std::size_t column, const char* axis,
                       const std::vector<double>& previous) {
    const std::string where = "the " + std::string(axis) + " angle in column " + std::to_string(column);
    Result<double> a = text::finiteNumber(cell, name_, number, where, decimalComma_);
    if (!a) return a;
    if (*a < -90.0 || *a > 90.0)
      return fileError(name_, number, "expected " + where + " from -90 to 90 degrees, found " + quote(cell));
    if (!previous.empty() && !(*a > previous.back()))
      return fileError(name_, number,
                       "expected " + std::string(axis) + " angles in ascending order, found " + quote(cell) +
                           " after " + text::formatNumber(previous.back()));
    return a;
  }

  Status header(std::string_view t, std::size_t number) {
    haveHeader_ = true;
    headerLine_ = number;
    sep_ = t.find(';') != std::string_view::npos ? ';' : ',';
    decimalComma_ = sep_ == ';';
    const std::vector<std::string_view> cells = splitCells(t, sep_);
    if (cells.size() < 3)
      return fileError(name_, number,
                       "expected a header row with a label cell and at least 2 H angles, found " +
                           std::to_string(cells.size()) + " cells");
    if (cells.size() > kMaxColumns)
      return fileError(name_, number, "expected at most " + std::to_string(kMaxColumns) + " H angles");
    for (std::size_t i = 1; i < cells.size(); ++i) {
      Result<double> h = angle(cells[i], number, i + 1, "H", h_);
      if (!h) return h.error();
      h_.push_back(*h);
    }
    return Ok{};
  }

  Status row(std::string_view t, std::size_t number) {
    const std::vector<std::string_view> cells = splitCells(t, sep_);
    if (cells.size() != h_.size() + 1)
      return fileError(name_, number,
                       "expected " + std::to_string(h_.size() + 1) + " cells (a V angle and " +
                           std::to_string(h_.size()) + " values), found " + std::to_string(cells.size()));
    if (rows_.size() + h_.size() > kMaxValues)
      return fileError(name_, number, "expected at most " + std::to_string(kMaxValues) + " values in the grid");
    Result<double> v = angle(cells[0], number, 1, "V", v_);
    if (!v) return v.error();
    for (std::size_t i = 1; i < cells.size(); ++i) {
      const std::string what = "a candela value in column " + std::to_string(i + 1);
      Result<double> cd = text::finiteNumber(cells[i], name_, number, what, decimalComma_);
      if (!cd) return cd.error();
      if (*cd < 0.0) return fileError(name_, number, "expected " + what + " >= 0, found " + quote(cells[i]));
      rows_.push_back(*cd);
    }
    v_.push_back(*v);
    return Ok{};
  }

  const std::string& name_;
  bool haveHeader_ = false;
  bool mirror_ = false;
  bool sawComment_ = false;
  bool decimalComma_ = false;
  char sep_ = ',';
  std::size_t headerLine_ = 0;
  std::vector<double> h_, v_, rows_;  // degrees, degrees, cd row-major in V
};

}  // namespace

Result<TabulatedProfile> parseCsvProfile(std::string_view text, const std::string& name) {
  const std::vector<text::Line> lines = text::splitLines(text);
  CsvReader reader(name);
  for (const text::Line& l : lines)
    if (Status s = reader.line(l); !s) return s.error();
  Result<TabulatedProfile> p = reader.finish(lines.empty() ? 1 : lines.back().number);
  if (!p) return p;
  if (Status s = p->validate(); !s) return s.error();
  return p;
}

Result<TabulatedProfile> parseCsvProfileFile(const std::string& path) {
  Result<std::string> text = readTextFile(path);
  if (!text) return text.error();
  return parseCsvProfile(*text, path);
}

}  // namespace fogbeam
