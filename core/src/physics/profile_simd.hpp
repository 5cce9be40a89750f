// fogbeam — SIMD trigonometry along a great circle (private; profile_simd.cpp).
#pragma once

#include <cstddef>

namespace fogbeam::detail {

// PhotometricType as an int (the SIMD source does not include profile.hpp's GLM types).
inline constexpr int kTypeA = 0, kTypeB = 1, kTypeC = 2;

/// For each ψ[i], the file angles (h[i], v[i]) in radians (anglesFromDirection's conventions for
/// `type`) of the lamp-frame direction cos ψ u + sin ψ v; u, v: 3 doubles each, orthonormal.
/// Thread-safe; dispatched to the best SIMD target of the CPU.
void circleAngles(int type, const double* u, const double* v, const double* psi, std::size_t n, double* h,
                  double* vOut);

/// For each line i (axis (ax[i], ay[i], az[i]), unit; cosine c[i]), the two angles θ of the
/// circle w(θ) = cos θ n + sin θ t where w·axis = c (thA = centre − half, thB = centre + half,
/// unwrapped: any real), NaN where the circle does not meet the line. Thread-safe; dispatched.
void lineCrossings(const double* n, const double* t, const double* ax, const double* ay, const double* az,
                   const double* c, std::size_t count, double* thA, double* thB);

/// out[i] = cos ψ_i a + sin ψ_i b. Thread-safe; dispatched.
void circleComponent(double a, double b, const double* psi, std::size_t n, double* out);

}  // namespace fogbeam::detail
