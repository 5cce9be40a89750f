// `fogbeam tables` (cmd_tables.hpp).
#include "cmd_tables.hpp"

#include <fogbeam/physics/ground_correction.hpp>
#include <fogbeam/physics/multiple_scattering.hpp>
#include <fogbeam/util/thread_pool.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

namespace fogbeam::cli {

namespace {

// --ground: the factor against the shipped table of the same phase function (the glow layer's).
int runGroundTable(const Phase& phase, const TablesOptions& o) {
  const auto ms = shippedMultipleScatteringTable(phase);
  if (!ms) {
    std::fprintf(stderr, "fogbeam tables --ground: no shipped multiple-scattering table for %s\n", describe(phase).c_str());
    return 1;
  }
  GroundCorrectionOptions opt = GroundCorrectionOptions::defaults();
  opt.paths = o.paths;
  opt.seed = o.seed;
  ThreadPool pool(o.threads);
  const auto t0 = std::chrono::steady_clock::now();
  std::printf("%s: the ground's factor C(T, ring, rho) on the tables, %llu paths per node; rings (deg):", describe(phase).c_str(),
              static_cast<unsigned long long>(o.paths));
  for (std::size_t j = 0; j + 1 < opt.ring_edges_deg.size(); ++j)
    std::printf(" %g-%g", opt.ring_edges_deg[j], opt.ring_edges_deg[j + 1]);
  std::printf("\n");
  std::fflush(stdout);
  auto table = GroundCorrectionTable::build(phase, *ms, opt, &pool, [](const std::string& line) {
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  });
  if (!table) {
    std::fprintf(stderr, "fogbeam tables --ground: %s\n", table.error().message.c_str());
    return 1;
  }
  if (Status s = table->save(o.out); !s) {
    std::fprintf(stderr, "fogbeam tables --ground: %s\n", s.error().message.c_str());
    return 1;
  }
  std::printf("%.1f s on %u threads -> %s\n", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
              pool.size(), o.out.c_str());
  return 0;
}

}  // namespace

int runTables(const TablesOptions& o) {
  Result<Phase> phase = Error{"unknown phase '" + o.phase + "' (expected henyey-greenstein, fog-mie or isotropic)"};
  if (o.phase == "henyey-greenstein") phase = makeHenyeyGreenstein(o.g);
  if (o.phase == "fog-mie") phase = makeFogMie(o.dropletDiameter_um);
  if (o.phase == "isotropic") phase = Phase{IsotropicPhase{}};
  if (!phase) {
    std::fprintf(stderr, "fogbeam tables: %s\n", phase.error().message.c_str());
    return 1;
  }
  if (o.ground) return runGroundTable(*phase, o);
  MultipleScatteringOptions opt = MultipleScatteringOptions::defaults();
  opt.paths = o.paths;
  opt.seed = o.seed;
  ThreadPool pool(o.threads);
  auto table = MultipleScatteringTable::build(*phase, opt, &pool);
  if (!table) {
    std::fprintf(stderr, "fogbeam tables: %s\n", table.error().message.c_str());
    return 1;
  }
  if (Status s = table->save(o.out); !s) {
    std::fprintf(stderr, "fogbeam tables: %s\n", s.error().message.c_str());
    return 1;
  }
  // Relative standard errors of the Ω = 1 nodes, by optical distance: what the table is worth.
  const auto& T = table->opticalDistances();
  const std::size_t a = table->albedos().size() - 1;
  std::printf("%s: %llu paths, %.1f events a path, %.1f s on %u threads -> %s\n", describe(*phase).c_str(),
              static_cast<unsigned long long>(o.paths), table->meanEvents(), table->buildSeconds(), pool.size(),
              o.out.c_str());
  std::printf("relative standard error of the albedo-1 nodes (median / largest over the angles):\n");
  for (std::size_t i = 0; i < T.size(); ++i) {
    std::vector<double> rel;
    for (std::size_t j = 0; j < table->angles().size(); ++j) {
      const double m = table->nodeMean(a, i, j);
      rel.push_back(m > 0.0 ? table->nodeStdError(a, i, j) / m : 0.0);
    }
    std::sort(rel.begin(), rel.end());
    std::printf("  K_t R = %6.3f: %5.1f %% / %5.1f %%\n", T[i], 100.0 * rel[rel.size() / 2], 100.0 * rel.back());
  }
  return 0;
}

}  // namespace fogbeam::cli
