// Test helpers: fogs the render and physics tests share.
#pragma once

#include <fogbeam/physics/medium.hpp>

namespace fogbeam::test {

/// Henyey–Greenstein fog of extinction `kt` (1/m), albedo and asymmetry g.
inline Medium hgFog(double kt, double albedo = 1.0, double g = 0.85) {
  Medium m;
  m.extinction_per_m = kt;
  m.albedo = albedo;
  m.phase = makeHenyeyGreenstein(g).value();
  return m;
}

}  // namespace fogbeam::test
