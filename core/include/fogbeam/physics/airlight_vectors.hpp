// fogbeam — test vectors for the airlight evaluators, in the column layout of the reference
// vectors shipped in tests/data/airlight_vectors.csv (docs/physics.md, "Test oracles"):
//   eye_x,eye_y,eye_z,dir_x,dir_y,dir_z,depth_m,lamp_x,lamp_y,lamp_z,axis_x,axis_y,axis_z,
//   profile,intensity_cd,inner_deg,outer_deg,extinction_per_m,albedo,phase,g,
//   airlight_cd_m2,abs_err_estimate
// Columns are found by name (any order, extra columns ignored); depth "inf" is the sky.
// Thread-safety: pure functions.
#pragma once

#include <fogbeam/physics/airlight.hpp>
#include <fogbeam/util/result.hpp>

#include <string>
#include <string_view>
#include <vector>

namespace fogbeam {

struct AirlightVector {
  std::size_t line = 0;  ///< 1-based line in the file
  Ray ray;
  Vec3 lamp_m{0.0};
  Vec3 axis{1.0, 0.0, 0.0};
  std::string profile;  ///< "isotropic" | "spot"
  double intensity_cd = 0.0, inner_deg = 0.0, outer_deg = 0.0;
  double extinction_per_m = 0.0, albedo = 1.0;
  std::string phase;  ///< "isotropic" | "hg"
  double g = 0.0;
  double expected_cd_m2 = 0.0;

  /// The lamp and medium this row describes.
  [[nodiscard]] Result<Lamp> lamp() const;
  [[nodiscard]] Result<Medium> medium() const;
};

[[nodiscard]] Result<std::vector<AirlightVector>> parseAirlightVectors(std::string_view text, const std::string& name);
[[nodiscard]] Result<std::vector<AirlightVector>> loadAirlightVectors(const std::string& path);

}  // namespace fogbeam
