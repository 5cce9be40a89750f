// fogbeam — the text form shared by the shipped tables (multiple scattering, *.msc; the ground's
// factor, *.gnd): a line reader whose errors name the source and the line, the phase function
// written as its identity and rebuilt from it, and "<key> <count> <values…>" lists. Private to
// the physics library. Hand-written: a dozen lines of a fixed, line-oriented format that TOML or
// JSON would make several times larger (the tables hold ~10⁴ numbers).
#pragma once

#include <fogbeam/physics/medium.hpp>
#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <ostream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::detail {

class TableText {
 public:
  TableText(std::string_view text, std::string source) : in_{std::string(text)}, source_(std::move(source)) {}

  /// Reads the next line; false at the end of the text (failMissing() then names the line that
  /// is missing).
  bool nextLine() {
    if (!std::getline(in_, line_)) return false;
    ++lineNo_;
    words_.clear();
    words_.str(line_);
    return true;
  }
  /// The next line, true when its first word is `key`; its other words are then in words().
  bool next(const char* key) {
    if (!nextLine()) return false;
    std::string k;
    return static_cast<bool>(words_ >> k) && k == key;
  }
  [[nodiscard]] const std::string& line() const noexcept { return line_; }
  std::istringstream& words() noexcept { return words_; }
  /// "source:line: what".
  [[nodiscard]] Error fail(const std::string& what) const {
    return Error{source_ + ":" + std::to_string(lineNo_) + ": " + what};
  }
  /// The same for the line after the last one read (the text ended before it).
  [[nodiscard]] Error failMissing(const std::string& what) const {
    return Error{source_ + ":" + std::to_string(lineNo_ + 1) + ": " + what};
  }

  /// The first line, "<magic> 1" (the format's version), then the phase (phase()).
  Result<Phase> headerAndPhase(const char* magic) {
    int version = 0;
    if (!next(magic) || !(words_ >> version) || version != 1)
      return fail(std::string("expected the header '") + magic + " 1'");
    return phase();
  }
  /// The lines "phase <name>" (informational) and "phase_identity <kind> <a> <b> <c>": the phase
  /// rebuilt from its identity, which must match what phaseIdentity() gives it back.
  Result<Phase> phase() {
    if (!next("phase")) return fail("expected 'phase <name>'");
    std::size_t kind = 0;
    double a = 0, b = 0, c = 0;
    if (!next("phase_identity") || !(words_ >> kind >> a >> b >> c))
      return fail("expected 'phase_identity <kind> <a> <b> <c>'");
    Result<Phase> p = fail("unknown phase kind " + std::to_string(kind));
    if (kind == 0) p = Phase{IsotropicPhase{}};
    if (kind == 1) p = makeHenyeyGreenstein(a);
    if (kind == 2) p = makeFogMie(a);
    if (!p) return fail(p.error().message);
    if (phaseIdentity(*p) != PhaseIdentity{kind, a, b, c})
      return fail("phase_identity does not match the phase rebuilt from it (written by another version?)");
    return p;
  }

  /// The line "<key> <count> <values…>", each value times `scale`; at most 100 000 values.
  Status list(const char* key, std::vector<double>& v, double scale, bool mayBeEmpty = false) {
    std::size_t n = 0;
    if (!next(key) || !(words_ >> n) || (n == 0 && !mayBeEmpty) || n > 100000)
      return fail(std::string("expected '") + key + " <count> <values…>'");
    v.resize(n);
    for (auto& x : v) {
      if (!(words_ >> x)) return fail(std::string(key) + ": expected " + std::to_string(n) + " numbers");
      x *= scale;
    }
    return Ok{};
  }

 private:
  std::istringstream in_;
  std::istringstream words_;
  std::string source_, line_;
  int lineNo_ = 0;
};

/// "phase <describe>" and "phase_identity <kind> <a> <b> <c>" lines (TableText::phase reads them).
inline void writePhase(std::ostream& f, const Phase& phase) {
  const auto id = phaseIdentity(phase);
  f << "phase " << describe(phase) << "\n";
  f << "phase_identity " << std::get<0>(id) << ' ' << std::get<1>(id) << ' ' << std::get<2>(id) << ' '
    << std::get<3>(id) << "\n";
}

/// "<name> <count> <values…>", each value times `scale` (TableText::list reads it).
inline void writeList(std::ostream& f, const char* name, const std::vector<double>& v, double scale) {
  f << name << ' ' << v.size();
  for (double x : v) f << ' ' << x * scale;
  f << "\n";
}

/// The whole file, or an error naming it (`what`: the kind of file, for the message).
inline Result<std::string> readTextFile(const std::filesystem::path& path, const std::string& what) {
  std::ifstream in(path);
  if (!in) return Error{"cannot open " + what + " " + path.string()};
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

/// The shipped HG tables' g nodes, and where g falls among them: the lower node i and the weight
/// w of the next (g ≈ (1 − w) g_i + w g_{i+1}); false outside [0.75, 0.90].
inline constexpr double kShippedHgG[4] = {0.75, 0.80, 0.85, 0.90};
inline bool shippedHgNeighbours(double g, std::size_t& i, double& w) {
  constexpr std::size_t n = 4;
  if (!(g >= kShippedHgG[0] - 1e-9 && g <= kShippedHgG[n - 1] + 1e-9)) return false;
  i = 0;
  while (i + 2 < n && g > kShippedHgG[i + 1]) ++i;
  w = (g - kShippedHgG[i]) / (kShippedHgG[i + 1] - kShippedHgG[i]);
  w = w < 0.0 ? 0.0 : w > 1.0 ? 1.0 : w;
  return true;
}

/// A text file embedded in the library (cmake/embed_text_files.cmake defines the same struct in
/// its generated sources).
struct EmbeddedTable {
  const char* name;
  const char* text;
};

/// The shipped table of type T (T::parse(text, source)) for a phase function: for HG between two
/// of kShippedHgG, the two blended by T::blend(a, b, w, phase) (cached per g, at most 64 kept);
/// fog-mie the one of its name whose phase identity matches; nullptr otherwise. Each embedded
/// file is parsed on first use and kept. `ext` names the source in errors
/// ("config/multiple_scattering/<name><ext>"). Thread-safe.
template <class T>
std::shared_ptr<const T> shippedTable(const Phase& phase, const EmbeddedTable* files, std::size_t count, const char* ext,
                                      std::string (*nameOf)(const Phase&)) {
  auto embedded = [&](const std::string& name) {
    static std::mutex mutex;
    static std::map<std::string, std::shared_ptr<const T>> parsed;
    std::lock_guard lock(mutex);
    if (auto it = parsed.find(name); it != parsed.end()) return it->second;
    std::shared_ptr<const T> sp;
    for (std::size_t i = 0; i < count; ++i) {
      if (name != files[i].name) continue;
      auto t = T::parse(files[i].text, std::string("config/multiple_scattering/") + files[i].name + ext);
      if (t) sp = std::make_shared<const T>(std::move(*t));
    }
    parsed[name] = sp;
    return sp;
  };
  if (const auto* hg = std::get_if<HenyeyGreensteinPhase>(&phase)) {
    const double g = hg->g;
    std::size_t i = 0;
    double w = 0.0;
    if (!shippedHgNeighbours(g, i, w)) return nullptr;
    auto a = embedded(nameOf(HenyeyGreensteinPhase{kShippedHgG[i]}));
    auto b = embedded(nameOf(HenyeyGreensteinPhase{kShippedHgG[i + 1]}));
    if (w < 1e-9) return a;
    if (w > 1.0 - 1e-9) return b;
    if (!a || !b) return nullptr;
    static std::mutex mutex;
    static std::map<double, std::shared_ptr<const T>> blended;
    std::lock_guard lock(mutex);
    if (auto it = blended.find(g); it != blended.end()) return it->second;
    auto t = T::blend(*a, *b, w, phase);
    auto sp = t ? std::make_shared<const T>(std::move(*t)) : nullptr;
    if (blended.size() > 64) blended.clear();  // a g that changes every frame must not grow it
    blended[g] = sp;
    return sp;
  }
  if (std::holds_alternative<FogMiePhase>(phase)) {
    auto t = embedded(nameOf(phase));
    return t && phaseIdentity(t->phase()) == phaseIdentity(phase) ? t : nullptr;
  }
  return nullptr;
}

}  // namespace fogbeam::detail
