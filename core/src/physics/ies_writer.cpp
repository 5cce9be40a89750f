// fogbeam — IES LM-63-2002 writer.
//
// Layout written (docs/physics.md, "Headlamp photometry"):
//   IESNA:LM-63-2002
//   [KEYWORD] value            (profile.keywords; required ones added when missing)
//   TILT=NONE
//   1 -1 1 <#V> <#H> <type> 2 0 0 0     one lamp, absolute photometry, multiplier 1, metres
//   1 1 0                                ballast factor, future use, input watts
//   vertical angles, horizontal angles (degrees), then one block of #V candela values per
//   horizontal angle, every numeric line shorter than 80 characters (the format allows 256).
// Lines end with '\n' (LM-63 names CR LF; every reader we know accepts both, and a plain
// newline keeps files stable in git on every platform).

#include <fogbeam/physics/ies_writer.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

namespace {

constexpr std::size_t kMaxLine = 79;  // characters per line, excluding the newline

// Shortest of "%.<digits>g" that never uses exponent notation (some IES readers in the wild
// cannot parse exponents): large or tiny magnitudes fall back to fixed notation with the same
// number of significant digits.
std::string formatNumber(double x, int digits) {
  if (x == 0.0) return "0";  // also turns −0 into 0
  std::array<char, 64> buf{};
  std::snprintf(buf.data(), buf.size(), "%.*g", digits, x);
  std::string s(buf.data());
  if (s.find_first_of("eE") == std::string::npos) return s;
  const int exponent = static_cast<int>(std::floor(std::log10(std::abs(x))));
  const int decimals = std::clamp(digits - 1 - exponent, 0, 40);
  std::snprintf(buf.data(), buf.size(), "%.*f", decimals, x);
  s = buf.data();
  if (s.find('.') != std::string::npos) {  // drop trailing zeros of the fraction
    while (!s.empty() && s.back() == '0') s.pop_back();
    if (!s.empty() && s.back() == '.') s.pop_back();
  }
  return s;
}

// Appends numbers separated by one space, starting a new line before kMaxLine is reached.
void appendWrapped(std::string& out, const std::vector<std::string>& numbers) {
  std::size_t lineLength = 0;
  for (const std::string& n : numbers) {
    if (lineLength > 0 && lineLength + 1 + n.size() > kMaxLine) {
      out += '\n';
      lineLength = 0;
    }
    if (lineLength > 0) {
      out += ' ';
      ++lineLength;
    }
    out += n;
    lineLength += n.size();
  }
  out += '\n';
}

// "TEST" or "[TEST]" → "TEST" (upper case as LM-63 requires).
std::string keywordName(std::string_view raw) {
  std::string k(raw);
  if (!k.empty() && k.front() == '[') k.erase(0, 1);
  if (!k.empty() && k.back() == ']') k.pop_back();
  std::transform(k.begin(), k.end(), k.begin(), [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  return k;
}

// One keyword, continued with [MORE] lines when the value does not fit on one line.
void appendKeyword(std::string& out, const std::string& name, std::string value) {
  std::replace_if(value.begin(), value.end(), [](char c) { return c == '\n' || c == '\r' || c == '\t'; }, ' ');
  std::string tag = "[" + name + "]";
  if (value.empty()) {
    out += tag + '\n';
    return;
  }
  while (!value.empty()) {
    const std::size_t room = kMaxLine > tag.size() + 1 ? kMaxLine - tag.size() - 1 : 1;
    std::size_t take = value.size();
    if (take > room) {  // break at the last space that fits, else hard-break
      const std::size_t space = value.rfind(' ', room);
      take = (space != std::string::npos && space > 0) ? space : room;
    }
    out += tag + ' ' + value.substr(0, take) + '\n';
    value.erase(0, take);
    while (!value.empty() && value.front() == ' ') value.erase(0, 1);
    tag = "[MORE]";
  }
}

int iesPhotometricType(PhotometricType t) {
  switch (t) {
    case PhotometricType::C: return 1;
    case PhotometricType::B: return 2;
    case PhotometricType::A: return 3;
  }
  return 1;
}

}  // namespace

std::string writeIes(const TabulatedProfile& profile) {
  std::string out = "IESNA:LM-63-2002\n";

  // LM-63-2002 requires [TEST], [TESTLAB], [ISSUEDATE] and [MANUFAC]; [LUMCAT] and
  // [LUMINAIRE] are what every viewer shows. Missing ones get a neutral default first, then
  // the profile's own keywords follow in their order (so a written-then-parsed profile keeps it).
  struct Required {
    const char* name;
    std::string fallback;
  };
  const std::array<Required, 6> required{{
      {"TEST", profile.source.empty() ? std::string("none") : profile.source},
      {"TESTLAB", "none"},
      {"ISSUEDATE", "none"},
      {"MANUFAC", "unknown"},
      {"LUMCAT", "none"},
      {"LUMINAIRE", "unknown"},
  }};
  for (const Required& r : required) {
    const bool present = std::any_of(profile.keywords.begin(), profile.keywords.end(),
                                     [&](const auto& kv) { return keywordName(kv.first) == r.name; });
    if (!present) appendKeyword(out, r.name, r.fallback);
  }
  for (const auto& [key, value] : profile.keywords) appendKeyword(out, keywordName(key), value);

  out += "TILT=NONE\n";
  const std::size_t nv = profile.vertical.size();
  const std::size_t nh = profile.horizontal.size();
  out += "1 -1 1 " + std::to_string(nv) + ' ' + std::to_string(nh) + ' ' +
         std::to_string(iesPhotometricType(profile.type)) + " 2 0 0 0\n";
  out += "1 1 0\n";

  // Angles: 9 significant digits of degrees keep a radian grid to ~1e-9 relative and print
  // 0.1° as "0.1" (not 0.09999999999999999); candela: 7 significant digits (1e-7 relative).
  std::vector<std::string> numbers;
  numbers.reserve(std::max(nv, nh));
  for (double v : profile.vertical) numbers.push_back(formatNumber(degrees(v), 9));
  appendWrapped(out, numbers);
  numbers.clear();
  for (double h : profile.horizontal) numbers.push_back(formatNumber(degrees(h), 9));
  appendWrapped(out, numbers);
  for (std::size_t ih = 0; ih < nh; ++ih) {
    numbers.clear();
    for (std::size_t iv = 0; iv < nv; ++iv) {
      const std::size_t k = ih * nv + iv;
      numbers.push_back(formatNumber(k < profile.candela.size() ? profile.candela[k] : 0.0, 7));
    }
    appendWrapped(out, numbers);
  }
  return out;
}

}  // namespace fogbeam
