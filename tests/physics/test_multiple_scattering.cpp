// Multiple-scattering tables (fogbeam/physics/multiple_scattering.hpp; docs/physics.md,
// "Multiple scattering tables"): the table's estimator against the all-orders path tracer (two
// independent Monte Carlo estimates of the same radiance must agree within their errors), the
// shipped tables between their nodes against the path tracer, the albedo weights, determinism,
// the text form and its errors.
#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/physics/path_tracer.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace fogbeam {
namespace {

constexpr double kDeg = kPi / 180.0;

// The path tracer's orders ≥ 2 for an isotropic lamp of `cd` at distance R (m) and angle θ from a
// sky ray from the origin along +z, in fog of K_t, albedo Ω, phase p.
RadianceEstimate pathTracerMultiple(const Phase& phase, double kt, double albedo, double R, double theta, double cd,
                                    std::uint64_t samples, std::uint64_t seed, ThreadPool& pool) {
  Lamp lamp;
  lamp.position_m = R * Vec3(std::sin(theta), 0.0, std::cos(theta));
  lamp.worldFromLamp = worldFromAxis(Vec3(1, 0, 0));
  auto prof = makeProfile(IsotropicProfile{cd});
  EXPECT_TRUE(prof.has_value());
  lamp.profile = *prof;
  Medium m;
  m.extinction_per_m = kt;
  m.albedo = albedo;
  m.phase = phase;
  auto pt = PathTracer::build({lamp}, m);
  EXPECT_TRUE(pt.has_value());
  const Ray ray{Vec3(0.0), Vec3(0.0, 0.0, 1.0), std::numeric_limits<double>::infinity()};
  return pt->radiance(std::span<const Ray>(&ray, 1), samples, seed, &pool)[0];
}

// The table's estimator and the path tracer estimate the same radiance (orders 2 … 1000) by
// different paths (the tracer: one lamp, paths through its one camera ray; the table: every node's
// lamp from the same paths, the segments' lamp integrals from the G moments): they must agree
// within 3.5 combined standard errors plus 2 % (the G-moment integrals' own error is < 0.1 %).
TEST(MultipleScattering, TableNodesAgreeWithThePathTracer) {
  ThreadPool pool(2);
  MultipleScatteringOptions o;
  o.optical_distances = {0.5, 2.0, 5.0};
  o.albedos = {0.9, 1.0};
  o.paths = 6000;
  const Phase phase = HenyeyGreensteinPhase{0.85};
  o.angles_rad = {6.0 * kDeg, 16.0 * kDeg};
  auto t = MultipleScatteringTable::build(phase, o, &pool);
  ASSERT_TRUE(t.has_value()) << t.error().message;
  const double kt = 0.05, cd = 1000.0;
  struct Node {
    std::size_t i, j, a;
  };
  int checked = 0;
  // Nodes where the path tracer (one camera ray, 30 000 paths) gets within a few percent; next
  // to the lamp's image its σ is 20 % and more at this count (the table's far less: every path
  // feeds every node, its segments' integrals are exact).
  for (const Node n : {Node{0, 0, 1}, Node{1, 0, 1}, Node{1, 1, 1}, Node{2, 0, 1}, Node{1, 0, 0}}) {
    const double T = o.optical_distances[n.i], th = o.angles_rad[n.j], om = o.albedos[n.a];
    const double table = cd * kt * kt * t->nodeMean(n.a, n.i, n.j);
    const double tableSe = cd * kt * kt * t->nodeStdError(n.a, n.i, n.j);
    const auto pt = pathTracerMultiple(phase, kt, om, T / kt, th, cd, 30000, static_cast<std::uint64_t>(40 + checked), pool);
    const double se = std::hypot(tableSe, pt.multiple.std_error);
    std::printf("  T = %.1f, theta = %5.1f deg, albedo %.2f: table %.5g +- %.2g, path tracer %.5g +- %.2g (%.1f sigma)\n", T,
                th / kDeg, om, table, tableSe, pt.multiple.mean, pt.multiple.std_error,
                std::abs(table - pt.multiple.mean) / se);
    EXPECT_LT(std::abs(table - pt.multiple.mean), 3.5 * se + 0.02 * pt.multiple.mean) << T << " " << th;
    // So that the bound has teeth: both within 10 %.
    EXPECT_LT(se, 0.1 * pt.multiple.mean) << T << " " << th;
    ++checked;
  }
  // The albedo nodes come from the same paths weighted Ω^n (n ≥ 2): Ω = 0.9 keeps between 0.9^{max
  // order} and 0.81 of the Ω = 1 value, and more of it close to the lamp (low orders).
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 2; ++j) {
      const double r = t->nodeMean(0, i, j) / t->nodeMean(1, i, j);
      EXPECT_LT(r, 0.81 + 1e-12);
      EXPECT_GT(r, 0.0);
    }
  EXPECT_GT(t->nodeMean(0, 0, 0) / t->nodeMean(1, 0, 0), t->nodeMean(0, 2, 1) / t->nodeMean(1, 2, 1));
}

// The shipped tables between their nodes (T, θ off the grid; interpolation in log f over log T,
// log θ): against the path tracer within 3σ + 8 %, the tables' own node noise (1–7 % at T ≤ 8)
// and the interpolation's error together. Also an HG g between two shipped ones (blended).
TEST(MultipleScattering, ShippedTablesBetweenTheirNodesAgreeWithThePathTracer) {
  ThreadPool pool(2);
  const auto names = shippedMultipleScatteringTableNames();
  std::printf("  shipped tables:");
  for (const auto& n : names) std::printf(" %s", n.c_str());
  std::printf("\n");
  struct Case {
    double g, T, thetaDeg;
  };
  const double kt = 0.04, cd = 1000.0;
  int seed = 70;
  for (const Case c : {Case{0.85, 1.2, 0.6}, Case{0.85, 3.0, 3.0}, Case{0.85, 6.0, 12.0}, Case{0.85, 2.4, 70.0},
                       Case{0.75, 4.5, 1.5}, Case{0.875, 2.0, 5.0}}) {
    const Phase phase = HenyeyGreensteinPhase{c.g};
    auto t = shippedMultipleScatteringTable(phase);
    ASSERT_NE(t, nullptr) << "no shipped table for g = " << c.g;
    const double th = c.thetaDeg * kDeg;
    const double table = t->radiance(cd, kt, c.T / kt, th, 1.0);
    const auto pt = pathTracerMultiple(phase, kt, 1.0, c.T / kt, th, cd, 30000, static_cast<std::uint64_t>(seed++), pool);
    std::printf("  g = %.3f, T = %.1f, theta = %5.1f deg: table %.5g, path tracer %.5g +- %.2g (ratio %.3f)\n", c.g, c.T,
                c.thetaDeg, table, pt.multiple.mean, pt.multiple.std_error, table / pt.multiple.mean);
    EXPECT_LT(std::abs(table - pt.multiple.mean), 3.0 * pt.multiple.std_error + 0.08 * pt.multiple.mean)
        << c.g << " " << c.T << " " << c.thetaDeg;
  }
  // No table for phases outside the shipped range (the glow then uses the APSF).
  EXPECT_EQ(shippedMultipleScatteringTable(HenyeyGreensteinPhase{0.5}), nullptr);
  EXPECT_EQ(shippedMultipleScatteringTable(IsotropicPhase{}), nullptr);
}

TEST(MultipleScattering, DeterministicForAnyPoolAndSeedDependent) {
  MultipleScatteringOptions o;
  o.optical_distances = {1.0, 3.0};
  o.angles_rad = {2.0 * kDeg, 30.0 * kDeg};
  o.albedos = {1.0};
  o.paths = 150;
  o.batch_size = 16;
  const Phase phase = HenyeyGreensteinPhase{0.8};
  auto none = MultipleScatteringTable::build(phase, o, nullptr);
  ThreadPool one(1), two(2);
  auto a = MultipleScatteringTable::build(phase, o, &one);
  auto b = MultipleScatteringTable::build(phase, o, &two);
  o.seed = 2;
  auto c = MultipleScatteringTable::build(phase, o, &two);
  ASSERT_TRUE(none && a && b && c);
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < 2; ++j) {
      EXPECT_EQ(none->nodeMean(0, i, j), a->nodeMean(0, i, j));
      EXPECT_EQ(a->nodeMean(0, i, j), b->nodeMean(0, i, j));
      EXPECT_EQ(a->nodeStdError(0, i, j), b->nodeStdError(0, i, j));
      EXPECT_NE(a->nodeMean(0, i, j), c->nodeMean(0, i, j));
    }
}

TEST(MultipleScattering, TextRoundTripAndInterpolation) {
  MultipleScatteringOptions o;
  o.optical_distances = {1.0, 2.0, 4.0};
  o.angles_rad = {1.0 * kDeg, 4.0 * kDeg, 90.0 * kDeg};
  o.albedos = {0.9, 1.0};
  o.paths = 100;
  auto fm = makeFogMie(10.0);
  ASSERT_TRUE(fm.has_value());
  auto t = MultipleScatteringTable::build(*fm, o, nullptr);
  ASSERT_TRUE(t.has_value()) << t.error().message;
  const auto path = std::filesystem::temp_directory_path() / "fogbeam_ms_roundtrip.msc";
  ASSERT_TRUE(t->save(path).has_value());
  auto u = MultipleScatteringTable::load(path);
  ASSERT_TRUE(u.has_value()) << u.error().message;
  EXPECT_EQ(phaseIdentity(u->phase()), phaseIdentity(*fm));
  EXPECT_EQ(u->opticalDistances(), t->opticalDistances());
  for (std::size_t a = 0; a < 2; ++a)
    for (std::size_t i = 0; i < 3; ++i)
      for (std::size_t j = 0; j < 3; ++j) EXPECT_NEAR(u->nodeMean(a, i, j), t->nodeMean(a, i, j), 1e-7 * t->nodeMean(a, i, j));
  // At the nodes the value is the node's; between them it lies between its neighbours; θ below
  // the first node takes the first node's value; T below the first scales as T².
  EXPECT_NEAR(u->value(2.0, 4.0 * kDeg, 1.0), u->nodeMean(1, 1, 1), 1e-9 * u->nodeMean(1, 1, 1));
  const double mid = u->value(2.0, 2.0 * kDeg, 1.0);
  EXPECT_LE(mid, std::max(u->nodeMean(1, 1, 0), u->nodeMean(1, 1, 1)));
  EXPECT_GE(mid, std::min(u->nodeMean(1, 1, 0), u->nodeMean(1, 1, 1)));
  EXPECT_EQ(u->value(2.0, 0.1 * kDeg, 1.0), u->value(2.0, 1.0 * kDeg, 1.0));
  EXPECT_NEAR(u->value(0.5, 1.0 * kDeg, 1.0), 0.25 * u->nodeMean(1, 0, 0), 1e-9);
  const double om = u->value(2.0, 4.0 * kDeg, 0.95);
  EXPECT_GT(om, u->nodeMean(0, 1, 1));
  EXPECT_LT(om, u->nodeMean(1, 1, 1));

  // Errors name the file and line.
  auto writeBad = [&](const std::string& text) {
    std::ofstream f(path);
    f << text;
  };
  std::ifstream in(path);
  std::string good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  writeBad("not a table\n");
  auto e1 = MultipleScatteringTable::load(path);
  ASSERT_FALSE(e1.has_value());
  EXPECT_NE(e1.error().message.find(path.string() + ":1:"), std::string::npos) << e1.error().message;
  writeBad(good.substr(0, good.rfind('\n', good.size() / 2) + 1));
  auto e2 = MultipleScatteringTable::load(path);
  ASSERT_FALSE(e2.has_value());
  EXPECT_NE(e2.error().message.find("node lines"), std::string::npos) << e2.error().message;
  std::string bad = good;
  bad.replace(bad.find("albedos 2 "), 10, "albedos 2 x");
  writeBad(bad);
  auto e3 = MultipleScatteringTable::load(path);
  ASSERT_FALSE(e3.has_value());
  EXPECT_NE(e3.error().message.find(":7: albedos"), std::string::npos) << e3.error().message;
  std::filesystem::remove(path);

  EXPECT_FALSE(MultipleScatteringTable::build(*fm, MultipleScatteringOptions{{2.0, 1.0}, {}, {}, 10}, nullptr).has_value());
  EXPECT_FALSE(MultipleScatteringTable::build(*fm, MultipleScatteringOptions{{}, {0.0}, {}, 10}, nullptr).has_value());
  EXPECT_FALSE(MultipleScatteringTable::build(*fm, MultipleScatteringOptions{{}, {}, {1.5}, 10}, nullptr).has_value());
}

}  // namespace
}  // namespace fogbeam
