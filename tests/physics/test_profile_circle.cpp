// A profile along a great circle, the SIMD way a moving lamp's spokes sample it
// (Profile::intensitiesOnCircle, Profile::appendFeatureKinks; core/src/physics/profile_simd.cpp),
// against the scalar definitions: intensity() at each direction, and the crossings of the
// circle with every grid line (appendKinks, scalar), of which the feature lines are a subset.
// On measured files of each photometric type (A, B, C), on the SIMD target dispatch picks for
// the CPU (the arithmetic is the same on each; vector lengths 2 to 8, tails included).
#include <fogbeam/physics/photometry_io.hpp>
#include <fogbeam/physics/profile.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace fogbeam {
namespace {

std::shared_ptr<const Profile> load(const std::string& path) {
  Result<std::shared_ptr<const Profile>> p = loadProfileFile(path);
  EXPECT_TRUE(p.has_value()) << path << ": " << (p ? std::string() : p.error().message);
  return p ? *p : nullptr;
}

std::vector<std::string> files() {
  const std::string data = std::string(FOGBEAM_TEST_DATA_DIR) + "/photometry/";
  return {std::string(FOGBEAM_CONFIG_DIR) + "/lamps/low_beam.ies",  // type B, 181 × 199
          data + "lm63_2019_type_a_mirror.ies", data + "lm63_2002_type_c_full.ies", data + "isym0_full.ldt"};
}

// Random great circles: u uniform on the sphere, v a random unit vector ⟂ u; half of them start
// near the lamp's axis (+x), where headlamp data is densest.
struct Circle {
  Vec3 u, v;
};
std::vector<Circle> circles(int count, std::mt19937& rng) {
  std::normal_distribution<double> g;
  std::vector<Circle> out;
  for (int k = 0; k < count; ++k) {
    Vec3 u = glm::normalize(Vec3(g(rng), g(rng), g(rng)));
    if (k % 2 == 0) u = glm::normalize(Vec3(1.0, 0.05 * g(rng), 0.05 * g(rng)));
    const Vec3 r(g(rng), g(rng), g(rng));
    out.push_back({u, glm::normalize(r - glm::dot(r, u) * u)});
  }
  return out;
}

TEST(ProfileCircle, IntensitiesOnCircleAreThoseOfEachDirection) {
  std::mt19937 rng(7);
  for (const std::string& file : files()) {
    const auto p = load(file);
    ASSERT_TRUE(p);
    const double peak = p->peak().intensity_cd;
    std::vector<double> psi, got;
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (int i = 0; i < 203; ++i) psi.push_back(3.141592653589793 * unit(rng));  // not a multiple of any lane count
    psi.push_back(0.0);
    psi.push_back(3.141592653589793);
    got.resize(psi.size());
    double worst = 0.0;
    for (const Circle& c : circles(40, rng)) {
      p->intensitiesOnCircle(c.u, c.v, psi.data(), psi.size(), got.data());
      for (std::size_t i = 0; i < psi.size(); ++i) {
        const double want = p->intensity(std::cos(psi[i]) * c.u + std::sin(psi[i]) * c.v);
        worst = std::max(worst, std::abs(got[i] - want));
      }
    }
    // The angles differ in their last bits (Highway's atan and sin/cos against fastAtan2 and
    // libm): 1e-12 of the peak is ~1e4 times what that can move a bilinear value by.
    EXPECT_LE(worst, 1e-12 * peak) << file;
    std::printf("%s: worst |SIMD − scalar| %.2e cd (peak %.0f cd)\n", file.c_str(), worst, peak);
  }
}

TEST(ProfileCircle, FeatureKinksAreGridLineCrossings) {
  std::mt19937 rng(11);
  for (const std::string& file : files()) {
    const auto p = load(file);
    ASSERT_TRUE(p);
    std::size_t total = 0;
    for (const Circle& c : circles(60, rng)) {
      std::vector<double> feature, grid;
      p->appendFeatureKinks(c.u, c.v, 0.0, 3.141592653589793, feature);
      p->appendKinks(c.u, c.v, 0.0, 3.141592653589793, grid);
      std::sort(grid.begin(), grid.end());
      total += feature.size();
      for (double th : feature) {
        ASSERT_TRUE(th > 0.0 && th < 3.141592653589793);
        // The nearest crossing of a grid line (the scalar crossingsDot) is the same angle.
        const auto it = std::lower_bound(grid.begin(), grid.end(), th);
        double nearest = 1.0;
        if (it != grid.end()) nearest = std::min(nearest, *it - th);
        if (it != grid.begin()) nearest = std::min(nearest, th - *(it - 1));
        EXPECT_LE(nearest, 1e-12) << file << " θ " << th;
      }
    }
    // Headlamp data has feature lines (its cut-off), and circles near the axis cross them.
    if (file.find("low_beam") != std::string::npos) {
      EXPECT_GT(total, 60u) << file;
    }
    std::printf("%s: %zu feature crossings on 60 circles\n", file.c_str(), total);
  }
}

}  // namespace
}  // namespace fogbeam
