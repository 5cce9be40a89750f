// FOGBEAM_TEST_SCALE: how much of the accuracy tests' sampling to run (docs/reliability.md).
//
// A number in (0, 1]; unset or empty means 1, the full size, which is what the plain build runs:
// every ray, pixel and size the tests were written with, the same figures printed. The sanitizer
// pass (scripts/asan.sh) sets 0.25: there the suite is run to find memory errors, leaks and
// undefined behaviour on every code path, so the heavy accuracy tests keep every kind of case
// (every method, lamp, branch, surface and sky ray, off-axis case) and thin only the repetitions
// of it. Bounds stay as they are; a statistic (a p95) keeps enough samples to mean something.
//
// Header-only: every test binary has tests/ on its include path (tests/CMakeLists.txt).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace fogbeam::test {

/// FOGBEAM_TEST_SCALE, read once: 1 when unset or empty. Anything but a number in (0, 1] throws
/// (the test that asks fails with the reason: a mistyped knob must not silently run full size,
/// nor a scale above 1 silently run more than the plain build).
inline double scale() {
  static const double value = [] {
    const char* text = std::getenv("FOGBEAM_TEST_SCALE");
    if (text == nullptr || *text == '\0') return 1.0;
    char* end = nullptr;
    const double x = std::strtod(text, &end);
    if (end == text || *end != '\0' || !(x > 0.0 && x <= 1.0))
      throw std::invalid_argument(std::string("FOGBEAM_TEST_SCALE=\"") + text + "\": expected a number in (0, 1]");
    return x;
  }();
  return value;
}

/// True when the tests run reduced (scale() < 1): for the few choices that are not a count.
inline bool reduced() { return scale() < 1.0; }

/// `n` scaled by `fraction` (default scale()), rounded up, never below `minimum` (nor above `n`):
/// scaled(n) is n itself at full size.
inline std::size_t scaled(std::size_t n, std::size_t minimum = 1, double fraction = scale()) {
  // The 1e-9 keeps exact products (0.25 × 8) from rounding up on a last bit.
  const auto k = static_cast<std::size_t>(std::ceil(static_cast<double>(n) * fraction - 1e-9));
  return std::min(n, std::max(k, minimum));
}

/// scaled(v.size(), minimum, fraction) elements of `v`, in order and evenly spread over it, the
/// first and the last always among them (only the first when one is kept): a list of cases
/// ordered by a parameter keeps both ends of its range. `v` itself at full size. For a grid,
/// thin each of its d axes by scale()^(1/d).
template <class T>
std::vector<T> thinned(const std::vector<T>& v, std::size_t minimum = 2, double fraction = scale()) {
  const std::size_t k = scaled(v.size(), minimum, fraction);
  if (k >= v.size()) return v;
  std::vector<T> out;
  out.reserve(k);
  for (std::size_t i = 0; i < k; ++i)
    out.push_back(v[k == 1 ? 0 : (i * (v.size() - 1) + (k - 1) / 2) / (k - 1)]);  // round(i (n-1) / (k-1))
  return out;
}

/// A binary subdivision depth (at most 2^depth pieces) whose budget of pieces is scaled:
/// depth + floor(log2(fraction)), never below `minimum`. `depth` itself at full size.
inline unsigned scaledDepth(unsigned depth, unsigned minimum, double fraction = scale()) {
  const auto drop = static_cast<unsigned>(std::floor(-std::log2(fraction) + 1e-9));
  return drop >= depth ? minimum : std::max(minimum, depth - drop);
}

}  // namespace fogbeam::test
