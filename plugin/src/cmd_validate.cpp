// `fogbeam validate`: the three airlight methods against a reference, as a table.
#include "commands.hpp"
#include "lamp_models.hpp"

#include <fogbeam/physics/airlight_vectors.hpp>
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/physics/validation.hpp>

#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace fogbeam::cli {

namespace {

struct ValidateOptions {
  std::string vectors;
  std::string out;
  std::vector<std::string> methods{"seed", "accurate", "reference"};
  std::string headlamp;
  int rays = 24;
  int segments = AirlightOptions{}.accurate_segments;
};

std::string human(std::size_t bytes) {
  char b[32];
  if (bytes >= (1u << 20)) std::snprintf(b, sizeof b, "%.1f MiB", static_cast<double>(bytes) / (1 << 20));
  else std::snprintf(b, sizeof b, "%.1f KiB", static_cast<double>(bytes) / 1024.0);
  return b;
}

int run(const ValidateOptions& o) {
  std::vector<AirlightMethod> methods;
  for (const auto& m : o.methods) {
    auto pm = parseAirlightMethod(m);
    if (!pm) {
      std::fprintf(stderr, "fogbeam validate: %s\n", pm.error().message.c_str());
      return 2;
    }
    methods.push_back(*pm);
  }
  AirlightOptions options;
  options.accurate_segments = o.segments;

  std::vector<ValidationCase> cases;
  std::string source;
  if (!o.vectors.empty()) {
    auto rows = loadAirlightVectors(o.vectors);
    if (!rows) {
      std::fprintf(stderr, "fogbeam validate: %s\n", rows.error().message.c_str());
      return 2;
    }
    auto c = casesFromVectors(*rows);
    if (!c) {
      std::fprintf(stderr, "fogbeam validate: %s: %s\n", o.vectors.c_str(), c.error().message.c_str());
      return 2;
    }
    cases = std::move(c).value();
    source = o.vectors;
  } else {
    std::shared_ptr<const Profile> headlamp;
    if (!o.headlamp.empty()) {
      auto p = loadProfileFile(o.headlamp);
      if (!p) {
        std::fprintf(stderr, "fogbeam validate: %s\n", p.error().message.c_str());
        return 2;
      }
      headlamp = *p;
      source = "built-in sweep, headlamp " + o.headlamp;
    } else {
      headlamp = makeProfile(lamps::makeLowBeam()).value();
      source = "built-in sweep, headlamp = built-in low beam (config/lamps/low_beam.ies)";
    }
    std::printf("building the sweep (reference values for every case)...\n");
    cases = builtinSweep(headlamp, o.rays);
  }

  auto res = runValidation(cases, methods, options);
  if (!res) {
    std::fprintf(stderr, "fogbeam validate: %s\n", res.error().message.c_str());
    return 2;
  }
  std::size_t nonzero = 0;
  for (const auto& c : cases) nonzero += c.expected_cd_m2 > kZeroThreshold ? 1 : 0;
  std::printf("fogbeam validate: %zu cases from %s\n", cases.size(), source.c_str());
  std::printf("  relative error over the %zu cases with L > 1e-6 cd/m2; %zu zero cases must give |L| <= 1e-6\n\n",
              nonzero, cases.size() - nonzero);
  std::printf("  %-10s %10s %10s %10s  %-9s %11s %11s %9s\n", "method", "median", "p95", "max", "zero ok",
              "ns/eval", "tables", "build s");
  int exitCode = 0;
  for (const auto& s : res->summaries) {
    char zero[32];
    std::snprintf(zero, sizeof zero, "%zu/%zu", s.zeroRows - s.zeroViolations, s.zeroRows);
    std::printf("  %-10s %10.3g %10.3g %10.3g  %-9s %11.0f %11s %9.2f\n", std::string(toString(s.method)).c_str(),
                s.median, s.p95, s.max, zero, s.nsPerEval, human(s.tableBytes).c_str(), s.buildSeconds);
  }
  std::printf("\n");
  for (const auto& s : res->summaries) {
    std::printf("  worst %-9s case: %s\n", std::string(toString(s.method)).c_str(), s.worstLabel.c_str());
    if (s.method == AirlightMethod::Accurate) {
      const bool ok = accurateWithinBounds(s);
      std::printf("  accurate bounds (p95 <= %.1f %%, max <= %.1f %%, zero cases): %s\n", 100 * kAccurateP95Bound,
                  100 * kAccurateMaxBound, ok ? "PASS" : "FAIL");
      if (!ok) exitCode = 1;
    }
  }
  if (!o.out.empty()) {
    std::ofstream f(o.out);
    if (!f) {
      std::fprintf(stderr, "fogbeam validate: cannot write %s\n", o.out.c_str());
      return 2;
    }
    f << "method,row,value,expected,rel_error\n";
    f.precision(10);
    for (const auto& r : res->rows)
      f << toString(r.method) << ',' << (r.index + 1) << ',' << r.value << ',' << r.expected << ',' << r.relError << '\n';
    std::printf("  wrote %zu result rows to %s\n", res->rows.size(), o.out.c_str());
  }
  return exitCode;
}

}  // namespace

void addValidateCommand(CLI::App& app, int& exitCode) {
  auto opts = std::make_shared<ValidateOptions>();
  auto* sub = app.add_subcommand(
      "validate",
      "Evaluate the airlight methods (seed, accurate, reference) on test vectors or a built-in sweep and print "
      "median / 95th percentile / max relative error and cost per evaluation. Exits 1 when the accurate method "
      "misses its bounds (p95 <= 0.5 %, max <= 2 %), 2 on bad input.");
  sub->add_option("--vectors", opts->vectors,
                  "CSV of rays, lamps and fogs with expected airlight (cd/m2), columns as "
                  "shared/reference/airlight_vectors.csv; lengths in m, angles in degrees, extinction in 1/m. "
                  "Without it, a built-in sweep is evaluated against the reference method.")
      ->check(CLI::ExistingFile);
  sub->add_option("--out", opts->out, "write one row per case and method: method,row,value,expected,rel_error "
                                      "(value and expected in cd/m2; rel_error is |L| for zero cases)");
  sub->add_option("--methods", opts->methods, "methods to run (default: seed accurate reference)")->delimiter(',');
  sub->add_option("--headlamp", opts->headlamp,
                  "sweep only: headlamp profile file (.ies/.ldt/.csv) instead of the built-in low beam");
  sub->add_option("--rays", opts->rays, "sweep only: rays per situation (default 24; 7 fogs x 2 profiles x 4 situations)")
      ->check(CLI::Range(1, 10000));
  sub->add_option("--segments", opts->segments,
                  "accurate method: quadratic pieces per ray for tabulated profiles (default 48)")
      ->check(CLI::Range(1, 4096));
  sub->callback([opts, &exitCode] { exitCode = run(*opts); });
}

}  // namespace fogbeam::cli
