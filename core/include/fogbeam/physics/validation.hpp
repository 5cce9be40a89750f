// fogbeam — comparing the airlight methods against a reference, for `fogbeam validate`
// and the tests. Pure computation (no I/O).
//
// Error statistics follow the rules: relative errors over cases whose expected
// value exceeds 1e-6 cd/m²; cases with a smaller expected value must come out below
// 1e-6 cd/m² in absolute value ("zero rows").
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/physics/airlight_vectors.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace fogbeam {

/// One ray, lamp and medium, with the expected value (from a file, or from the reference).
struct ValidationCase {
  std::string label;  ///< e.g. "own-beam/headlamp/hg0.9"
  Lamp lamp;
  Medium medium;
  Ray ray;
  double expected_cd_m2 = 0.0;
};

/// Bounds of the accurate method (issue 2): 95th percentile and maximum relative error.
inline constexpr double kAccurateP95Bound = 0.005;
inline constexpr double kAccurateMaxBound = 0.02;
inline constexpr double kZeroThreshold = 1e-6;  ///< cd/m²

/// Cases from shared-format vectors (expected values from the file).
[[nodiscard]] Result<std::vector<ValidationCase>> casesFromVectors(const std::vector<AirlightVector>& rows);

/// A deterministic sweep of driving situations: HG g ∈ {0, 0.3, 0.6, 0.8, 0.85, 0.9} and
/// fog-mie 10 µm; visibility 30–300 m; a spot and `headlamp` (a type B low beam) profile;
/// the ego car's own beams seen from the driver's seat and oncoming lamps at 15–150 m, near
/// and far; rays across a 60°×30° view, some aimed within a few degrees of oncoming lamps;
/// sky or road depths. Expected values are computed with the reference method.
[[nodiscard]] std::vector<ValidationCase> builtinSweep(const std::shared_ptr<const Profile>& headlamp,
                                                       int raysPerSituation = 24, std::uint64_t seed = 20011);

struct MethodSummary {
  AirlightMethod method = AirlightMethod::Reference;
  std::size_t rows = 0;        ///< cases with expected > 1e-6 cd/m²
  double median = 0, p95 = 0, max = 0;  ///< relative errors over those rows
  std::size_t zeroRows = 0;    ///< cases with expected ≤ 1e-6
  std::size_t zeroViolations = 0;  ///< zero rows whose value exceeded 1e-6 in magnitude
  double nsPerEval = 0.0;      ///< mean wall time of evaluate() (tables already built)
  std::size_t tableBytes = 0;  ///< distinct table memory used by this method's evaluators
  double buildSeconds = 0.0;   ///< total table build time
  std::string worstLabel;      ///< label of the case with the largest relative error
};

struct ValidationResult {
  struct Row {
    AirlightMethod method;
    std::size_t index;
    double value, expected, relError;  ///< relError is |v − e|/e, or |v| for zero rows
  };
  std::vector<Row> rows;
  std::vector<MethodSummary> summaries;
};

/// Evaluates every case with every method in `methods` (tables built once per distinct
/// lamp/medium and reused) and summarises.
[[nodiscard]] Result<ValidationResult> runValidation(const std::vector<ValidationCase>& cases,
                                                     const std::vector<AirlightMethod>& methods,
                                                     const AirlightOptions& options = {});

/// True when the accurate method's summary is inside kAccurateP95Bound / kAccurateMaxBound
/// and it has no zero-row violation.
[[nodiscard]] bool accurateWithinBounds(const MethodSummary& s);

}  // namespace fogbeam
