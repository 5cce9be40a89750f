// fogbeam — minimal PNG output for charts and debug images (8-bit RGB).
//
// Uses libpng's simplified API (png_image_*), which reports errors through the image's
// message instead of longjmp, so no C++ object is ever jumped over.
// Thread-safety: an RgbImage is a value; writePng may run concurrently on distinct images.
#pragma once

#include <fogbeam/util/result.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace fogbeam::png {

using Rgb = std::array<std::uint8_t, 3>;

/// A width × height image, rows top to bottom, 3 bytes per pixel (R, G, B).
class RgbImage {
 public:
  RgbImage(int width, int height, Rgb fill = {0, 0, 0});

  [[nodiscard]] int width() const noexcept { return width_; }
  [[nodiscard]] int height() const noexcept { return height_; }
  [[nodiscard]] bool contains(int x, int y) const noexcept { return x >= 0 && y >= 0 && x < width_ && y < height_; }
  /// Sets a pixel; coordinates outside the image are ignored (clipping for drawing code).
  void set(int x, int y, Rgb c) noexcept;
  [[nodiscard]] Rgb get(int x, int y) const noexcept;
  /// Mixes `c` into the pixel with weight alpha ∈ [0, 1].
  void blend(int x, int y, Rgb c, double alpha) noexcept;
  [[nodiscard]] const std::vector<std::uint8_t>& bytes() const noexcept { return pixels_; }

 private:
  [[nodiscard]] std::size_t index(int x, int y) const noexcept {
    return (static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(x)) * 3;
  }
  int width_;
  int height_;
  std::vector<std::uint8_t> pixels_;
};

/// Writes the image as an 8-bit RGB PNG. Error: "path: cannot write PNG (libpng's reason)".
[[nodiscard]] Status writePng(const RgbImage& image, const std::string& path);

}  // namespace fogbeam::png
