// fogbeam profile FILE [--png OUT.png] [--size PX] [--h-range DEG] [--v-range DEG]
//
// Describes a lamp intensity file (.ies, .ldt, .csv) for a newcomer and optionally charts it
// as a false-colour H–V diagram, the view headlamp engineers use (an ECE "screen chart").
#include "cmd_profile.hpp"
#include "png_writer.hpp"

#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/physics/profile.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iomanip>
#include <locale>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace fogbeam::cli {

namespace {

// ------------------------------------------------------------------------------ report

const char* typeText(PhotometricType t) {
  switch (t) {
    case PhotometricType::A: return "A (IES type 3: polar axis vertical; H turns about z, V = elevation)";
    case PhotometricType::B: return "B (IES type 2, headlamp goniometer: V tilts the plane, H inside it)";
    case PhotometricType::C: return "C (IES type 1 / EULUMDAT: gamma from the axis, C planes about it)";
  }
  return "?";
}

const char* symmetryText(PlaneSymmetry s) {
  switch (s) {
    case PlaneSymmetry::None: return "none (data cover the full horizontal range)";
    case PlaneSymmetry::Rotational: return "rotational (one plane, the same about the axis)";
    case PlaneSymmetry::Quadrant: return "quadrant (C 0-90 deg, mirrored into the other three)";
    case PlaneSymmetry::Half0To180: return "half, C 0-180 deg (mirrored about the C0-C180 plane)";
    case PlaneSymmetry::Half90To270: return "half, C 90-270 deg (mirrored about the C90-C270 plane)";
    case PlaneSymmetry::MirrorH: return "mirrored about H = 0 (data for H >= 0: I(-H, V) = I(H, V))";
  }
  return "?";
}

// One number as text: `fixed` digits after the point (like %.Nf) or `significant` digits
// (like %.Ng), optionally with a sign.
enum class Notation { Fixed, Significant };
std::string number(double x, int digits, Notation n, bool sign = false) {
  std::ostringstream os;
  os.imbue(std::locale::classic());
  if (sign) os << std::showpos;
  if (n == Notation::Fixed) os << std::fixed;
  os << std::setprecision(digits) << x;
  return os.str();
}
std::string fixed0(double x) { return number(x, 0, Notation::Fixed); }
std::string signedFixed1(double x) { return number(x, 1, Notation::Fixed, true); }
std::string general3(double x) { return number(x, 3, Notation::Significant); }
std::string general6(double x) { return number(x, 6, Notation::Significant); }
std::string signedGeneral6(double x) { return number(x, 6, Notation::Significant, true); }

// Candela with sensible precision for both a 60 000 cd high beam and an 8 cd tail lamp.
std::string fmtCd(double cd) { return cd >= 100.0 ? fixed0(cd) : general3(cd); }

void printAxis(const char* name, const std::vector<double>& a) {
  double minStep = 0.0, maxStep = 0.0;
  for (std::size_t i = 1; i < a.size(); ++i) {
    const double d = degrees(a[i] - a[i - 1]);
    minStep = i == 1 ? d : std::min(minStep, d);
    maxStep = i == 1 ? d : std::max(maxStep, d);
  }
  std::printf("  %-8s %4zu angles from %s to %s deg", name, a.size(), signedGeneral6(degrees(a.front())).c_str(),
              signedGeneral6(degrees(a.back())).c_str());
  if (a.size() > 1) {
    if (maxStep - minStep < 1e-9)
      std::printf(", step %s deg", general6(minStep).c_str());
    else
      std::printf(", steps %s to %s deg (non-uniform)", general6(minStep).c_str(), general6(maxStep).c_str());
  }
  std::printf("\n");
}

// ECE R112 passing-beam test points (right-hand traffic) as positions on the measuring
// screen 25 m in front of the lamp: x to the right, y up, metres (R112 Annex 3).
struct EcePoint {
  const char* name;
  double x_m;
  double y_m;
  const char* kind;
};
constexpr std::array<EcePoint, 9> kEcePoints{{
    {"HV", 0.0, 0.0, "max (above the left cut-off)"},
    {"B50L", -1.50, +0.25, "max (glare to an oncoming driver at 50 m)"},
    {"75R", +0.50, -0.25, "min (own lane at 75 m)"},
    {"75L", -1.50, -0.25, "max (oncoming lane at 75 m)"},
    {"50L", -1.50, -0.375, "max (oncoming lane at 50 m)"},
    {"50R", +0.75, -0.375, "min (own lane at 50 m)"},
    {"50V", 0.0, -0.375, "min (road ahead at 50 m)"},
    {"25L", -3.96, -0.75, "min (left road edge at 25 m)"},
    {"25R", +3.96, -0.75, "min (right road edge at 25 m)"},
}};
constexpr double kScreenDistance_m = 25.0;

void printEcePoints(const Profile& profile) {
  std::printf(
      "ECE R112 passing-beam test points (right-hand traffic). Defined on a screen %.0f m ahead\n"
      "(x right, y up) and converted to type B angles: V = atan(y/25 m), H = atan(x/sqrt(25^2 + y^2)).\n"
      "The regulation's limit at each point is a minimum or a maximum as noted:\n",
      kScreenDistance_m);
  std::printf("  %-5s %7s %7s %8s %8s %10s  %s\n", "point", "x (m)", "y (m)", "H (deg)", "V (deg)", "I (cd)", "limit");
  for (const EcePoint& p : kEcePoints) {
    const Vec3 w = glm::normalize(Vec3(kScreenDistance_m, -p.x_m, p.y_m));
    const FileAngles a = anglesFromDirection(PhotometricType::B, w);
    std::printf("  %-5s %+7.2f %+7.3f %+8.2f %+8.2f %10s  %s\n", p.name, p.x_m, p.y_m, degrees(a.h), degrees(a.v),
                fmtCd(profile.intensity(w)).c_str(), p.kind);
  }
}

void printReport(const std::string& file, const Profile& profile) {
  std::printf("File:        %s\n", file.c_str());
  const auto* tab = std::get_if<TabulatedProfile>(&profile.model());
  if (tab == nullptr) {  // loadProfileFile always gives tabulated data; kept for completeness
    std::printf("Model:       analytic (not tabulated)\n");
  } else {
    std::printf("Format:      %s\n", tab->format.empty() ? "(not given)" : tab->format.c_str());
    std::printf("Type:        %s\n", typeText(tab->type));
    std::printf("Symmetry:    %s\n", symmetryText(tab->symmetry));
    std::printf("Angles (lamp frame: axis +x; H positive to the lamp's right, V positive up):\n");
    if (tab->type == PhotometricType::C) {
      printAxis("C planes", tab->horizontal);
      printAxis("gamma", tab->vertical);
    } else {
      printAxis("H", tab->horizontal);
      printAxis("V", tab->vertical);
    }
  }
  const Profile::Peak peak = profile.peak();
  const PhotometricType type = tab != nullptr ? tab->type : PhotometricType::B;
  const FileAngles at = anglesFromDirection(type, peak.direction);
  if (type == PhotometricType::C)
    std::printf("Peak:        %s cd at C = %.2f deg, gamma = %.2f deg\n", fmtCd(peak.intensity_cd).c_str(),
                degrees(at.h), degrees(at.v));
  else
    std::printf("Peak:        %s cd at H = %+.2f deg, V = %+.2f deg\n", fmtCd(peak.intensity_cd).c_str(),
                degrees(at.h), degrees(at.v));
  const double flux = profile.totalFlux();
  std::printf("Total flux:  %s lm (intensity integrated over the sphere)\n",
              flux >= 100.0 ? fixed0(flux).c_str() : general3(flux).c_str());
  // The passing-beam points mean something for headlamps only: type B files (the headlamp
  // goniometer) whose peak reaches 1 000 cd; signal lamps (a tail lamp's 8 cd) are skipped.
  if (tab != nullptr && tab->type == PhotometricType::B && peak.intensity_cd >= 1000.0) printEcePoints(profile);
  if (tab != nullptr) {
    std::printf("Keywords:%s\n", tab->keywords.empty() ? " (none)" : "");
    for (const auto& [key, value] : tab->keywords) std::printf("  [%s] %s\n", key.c_str(), value.c_str());
  }
}

// ------------------------------------------------------------------------------ chart

using png::Rgb;
using png::RgbImage;

// Viridis (perceptually uniform, readable in grey and by colour-blind readers): its nine
// anchor colours at t = 0, 1/8, …, 1 (matplotlib's table), linearly interpolated.
Rgb viridis(double t) {
  static constexpr std::array<Rgb, 9> kAnchors{{{0x44, 0x01, 0x54},
                                               {0x47, 0x2D, 0x7B},
                                               {0x3B, 0x52, 0x8B},
                                               {0x2C, 0x72, 0x8E},
                                               {0x21, 0x90, 0x8C},
                                               {0x27, 0xAD, 0x81},
                                               {0x5D, 0xC8, 0x63},
                                               {0xAA, 0xDC, 0x32},
                                               {0xFD, 0xE7, 0x25}}};
  const double x = std::clamp(t, 0.0, 1.0) * 8.0;
  const std::size_t i = std::min<std::size_t>(static_cast<std::size_t>(x), 7);
  const double f = x - static_cast<double>(i);
  Rgb c{};
  for (std::size_t k = 0; k < 3; ++k) {
    const double v = (1.0 - f) * kAnchors[i][k] + f * kAnchors[i + 1][k];
    c[k] = static_cast<std::uint8_t>(std::lround(v));
  }
  return c;
}

double luminance(Rgb c) { return (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]) / 255.0; }

// A 5×7 pixel font for the few characters a chart needs (digits, signs, axis letters).
// Built in so that labelling a chart does not pull a font library into the tool; each
// glyph is 7 rows of 5 bits, most significant bit on the left.
struct Glyph {
  char ch;
  std::array<std::uint8_t, 7> rows;
};
constexpr std::array<Glyph, 20> kFont{{
    {'0', {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}}, {'1', {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'2', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}}, {'3', {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}},
    {'4', {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}}, {'5', {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}},
    {'6', {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}}, {'7', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}}, {'9', {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}},
    {'-', {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00}}, {'+', {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00}},
    {'.', {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}}, {'H', {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}},
    {'V', {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}}, {'c', {0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E}},
    {'d', {0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F}}, {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}},
    {'R', {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}}, {' ', {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},
}};

int textWidth(const std::string& s, int scale) { return s.empty() ? 0 : static_cast<int>(s.size()) * 6 * scale - scale; }

// Draws `s` with its top-left corner at (x, y); unknown characters are left blank.
void drawText(RgbImage& img, int x, int y, const std::string& s, int scale, Rgb colour) {
  for (char ch : s) {
    const auto it = std::find_if(kFont.begin(), kFont.end(), [ch](const Glyph& g) { return g.ch == ch; });
    if (it != kFont.end()) {
      for (int row = 0; row < 7; ++row)
        for (int col = 0; col < 5; ++col)
          if ((static_cast<unsigned>(it->rows[static_cast<std::size_t>(row)]) >> static_cast<unsigned>(4 - col)) & 1U)
            for (int dy = 0; dy < scale; ++dy)
              for (int dx = 0; dx < scale; ++dx) img.set(x + col * scale + dx, y + row * scale + dy, colour);
    }
    x += 6 * scale;
  }
}

std::string angleLabel(double deg) {
  const long r = std::lround(deg);
  if (std::abs(deg - static_cast<double>(r)) < 1e-9) return (r > 0 ? "+" : "") + std::to_string(r);
  return signedFixed1(deg);
}

// "0.001", "0.01", …, "1", "10", "100000": plain decimals, no exponent glyphs needed.
std::string decadeLabel(int e) {
  if (e >= 0) return "1" + std::string(static_cast<std::size_t>(e), '0');
  return "0." + std::string(static_cast<std::size_t>(-e - 1), '0') + "1";
}

// Tick spacing (deg) with at least minPx pixels between ticks at scale pxPerDeg.
double tickStep(double pxPerDeg, double minPx) {
  for (double s : {0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 15.0, 30.0})
    if (s * pxPerDeg >= minPx) return s;
  return 45.0;
}

struct ChartRange {
  double h0, h1, v0, v1;  // degrees
};

Status writeChart(const Profile& profile, const ChartRange& r, int imageWidth, const std::string& path) {
  // Layout: the plot at equal angular scale in both axes, a colour bar on the right.
  constexpr int kScale = 2;  // font scale: 10×14 pixel glyphs
  constexpr int left = 70, right = 150, top = 40, bottom = 64;
  const int plotW = imageWidth - left - right;
  if (plotW < 100) return Error{path + ": --size too small for a chart"};
  const double pxPerDeg = plotW / (r.h1 - r.h0);
  const int plotH = std::max(40, static_cast<int>(std::lround((r.v1 - r.v0) * pxPerDeg)));
  const int imageHeight = plotH + top + bottom;
  if (static_cast<long>(plotW) * plotH > 40'000'000L) return Error{path + ": chart would be too large; lower --size"};

  const Profile::Peak peak = profile.peak();
  if (!(peak.intensity_cd > 0.0)) return Error{path + ": the profile is dark everywhere; nothing to chart"};
  const int maxDecade = static_cast<int>(std::ceil(std::log10(peak.intensity_cd) - 1e-9));
  const int minDecade = maxDecade - 4;  // four decades of dynamic range
  auto toT = [&](double cd) { return (std::log10(cd) - minDecade) / (maxDecade - minDecade); };

  // Intensity at every plot pixel centre; chart axes are type B angles whatever the file type.
  const auto nx = static_cast<std::size_t>(plotW), ny = static_cast<std::size_t>(plotH);
  std::vector<double> cd(nx * ny);
  for (std::size_t iy = 0; iy < ny; ++iy) {
    const double v = r.v1 - (static_cast<double>(iy) + 0.5) / pxPerDeg;
    for (std::size_t ix = 0; ix < nx; ++ix) {
      const double h = r.h0 + (static_cast<double>(ix) + 0.5) / pxPerDeg;
      cd[iy * nx + ix] = profile.intensity(directionFromAngles(PhotometricType::B, radians(h), radians(v)));
    }
  }

  const Rgb background{24, 24, 28}, ink{230, 230, 230}, white{255, 255, 255}, black{0, 0, 0};
  RgbImage img(imageWidth, imageHeight, background);
  auto px = [&](std::size_t ix) { return left + static_cast<int>(ix); };
  auto py = [&](std::size_t iy) { return top + static_cast<int>(iy); };
  for (std::size_t iy = 0; iy < ny; ++iy)
    for (std::size_t ix = 0; ix < nx; ++ix) {
      const double c = cd[iy * nx + ix];
      img.set(px(ix), py(iy), c > 0.0 ? viridis(toT(c)) : black);
    }

  // Grid lines under the contours: minor faint, major stronger, the H = 0 and V = 0 axes strongest.
  const double minor = tickStep(pxPerDeg, 25.0), major = 2.0 * minor;
  auto isMultiple = [](double x, double step) { return std::abs(x / step - std::round(x / step)) < 1e-6; };
  auto xOf = [&](double h) { return left + static_cast<int>(std::lround((h - r.h0) * pxPerDeg)); };
  auto yOf = [&](double v) { return top + static_cast<int>(std::lround((r.v1 - v) * pxPerDeg)); };
  auto gridAlpha = [&](double a) { return std::abs(a) < 1e-9 ? 0.6 : isMultiple(a, major) ? 0.3 : 0.15; };
  for (double h = std::ceil(r.h0 / minor) * minor; h <= r.h1 + 1e-9; h += minor) {
    const int x = xOf(h);
    for (int y = top; y < top + plotH; ++y) img.blend(x, y, white, gridAlpha(h));
    const int len = isMultiple(h, major) ? 8 : 4;
    for (int y = top + plotH; y < top + plotH + len; ++y) img.set(x, y, ink);
    if (isMultiple(h, major)) {
      const std::string s = angleLabel(h);
      drawText(img, x - textWidth(s, kScale) / 2, top + plotH + 12, s, kScale, ink);
    }
  }
  for (double v = std::ceil(r.v0 / minor) * minor; v <= r.v1 + 1e-9; v += minor) {
    const int y = yOf(v);
    for (int x = left; x < left + plotW; ++x) img.blend(x, y, white, gridAlpha(v));
    const int len = isMultiple(v, major) ? 8 : 4;
    for (int x = left - len; x < left; ++x) img.set(x, y, ink);
    if (isMultiple(v, major)) {
      const std::string s = angleLabel(v);
      drawText(img, left - 12 - textWidth(s, kScale), y - 7, s, kScale, ink);
    }
  }
  // Axis names: H along the bottom with the lamp's left (L) and right (R), V at the top left.
  drawText(img, left + plotW / 2 - textWidth("H", kScale) / 2, top + plotH + 36, "H", kScale, ink);
  drawText(img, left, top + plotH + 36, "L", kScale, ink);
  drawText(img, left + plotW - textWidth("R", kScale), top + plotH + 36, "R", kScale, ink);
  drawText(img, left - 12 - textWidth("V", kScale), 6, "V", kScale, ink);

  // Isocandela lines at 1 and 3 × 10^k cd: a pixel belongs to the line when the level lies
  // between its value and its right or lower neighbour's. Dark ink on bright colours.
  std::vector<double> levels;
  for (int e = minDecade + 1; e <= maxDecade; ++e)
    for (double m : {1.0, 3.0})
      if (m * std::pow(10.0, e) <= peak.intensity_cd) levels.push_back(m * std::pow(10.0, e));
  for (double level : levels) {
    const Rgb lineColour = luminance(viridis(toT(level))) > 0.45 ? black : white;
    for (std::size_t iy = 0; iy < ny; ++iy)
      for (std::size_t ix = 0; ix < nx; ++ix) {
        const bool here = cd[iy * nx + ix] >= level;
        const bool crossRight = ix + 1 < nx && (cd[iy * nx + ix + 1] >= level) != here;
        const bool crossDown = iy + 1 < ny && (cd[(iy + 1) * nx + ix] >= level) != here;
        if (crossRight || crossDown) img.set(px(ix), py(iy), lineColour);
      }
  }

  // Frame.
  for (int x = left - 1; x <= left + plotW; ++x) {
    img.set(x, top - 1, ink);
    img.set(x, top + plotH, ink);
  }
  for (int y = top - 1; y <= top + plotH; ++y) {
    img.set(left - 1, y, ink);
    img.set(left + plotW, y, ink);
  }

  // Colour bar: log10(cd) from 10^minDecade (bottom) to 10^maxDecade (top), decade labels,
  // and short marks at the isocandela levels.
  const int barX = left + plotW + 20, barW = 22, barTop = top, barH = plotH;
  for (int y = 0; y < barH; ++y) {
    const double t = 1.0 - (y + 0.5) / barH;
    for (int x = 0; x < barW; ++x) img.set(barX + x, barTop + y, viridis(t));
  }
  const int labelScale = barH >= 150 ? kScale : 1;
  for (int e = minDecade; e <= maxDecade; ++e) {
    const double t = static_cast<double>(e - minDecade) / (maxDecade - minDecade);
    const int y = barTop + static_cast<int>(std::lround((1.0 - t) * (barH - 1)));
    for (int x = barX + barW; x < barX + barW + 6; ++x) img.set(x, y, ink);
    drawText(img, barX + barW + 9, y - 7 * labelScale / 2, decadeLabel(e), labelScale, ink);
  }
  for (double level : levels) {
    const int y = barTop + static_cast<int>(std::lround((1.0 - toT(level)) * (barH - 1)));
    const Rgb lineColour = luminance(viridis(toT(level))) > 0.45 ? black : white;
    for (int x = barX; x < barX + barW; ++x) img.set(x, y, lineColour);
  }
  drawText(img, barX, top + plotH + 36, "cd", kScale, ink);

  return png::writePng(img, path);
}

Result<ChartRange> chartRange(const ProfileOptions& o) {
  auto span = [](const std::vector<double>& v, const char* name, double limit) -> Result<std::pair<double, double>> {
    const double lo = v.size() == 1 ? -std::abs(v[0]) : v[0];
    const double hi = v.size() == 1 ? std::abs(v[0]) : v[1];
    if (!(lo < hi) || lo < -limit || hi > limit)
      return Error{std::string(name) + ": need LO < HI within [-" + fixed0(limit) + ", " + fixed0(limit) +
                   "] deg (or one value D for -D..D)"};
    return std::make_pair(lo, hi);
  };
  const auto h = span(o.hRange, "--h-range", 90.0);
  if (!h) return h.error();
  const auto v = span(o.vRange, "--v-range", 90.0);
  if (!v) return v.error();
  return ChartRange{h->first, h->second, v->first, v->second};
}

}  // namespace

int runProfile(const ProfileOptions& o) {
  const auto range = chartRange(o);
  if (!range) {
    std::fprintf(stderr, "fogbeam profile: %s\n", range.error().message.c_str());
    return 1;
  }
  const auto profile = loadProfileFile(o.file);
  if (!profile) {
    std::fprintf(stderr, "fogbeam profile: %s\n", profile.error().message.c_str());
    return 1;
  }
  printReport(o.file, **profile);
  if (!o.png.empty()) {
    if (Status s = writeChart(**profile, *range, o.size, o.png); !s) {
      std::fprintf(stderr, "fogbeam profile: %s\n", s.error().message.c_str());
      return 1;
    }
    std::printf("Chart:       %s (H %s..%s deg, V %s..%s deg, log10 cd colour scale)\n", o.png.c_str(),
                angleLabel(range->h0).c_str(), angleLabel(range->h1).c_str(), angleLabel(range->v0).c_str(),
                angleLabel(range->v1).c_str());
  }
  std::fflush(stdout);
  return 0;
}

}  // namespace fogbeam::cli
