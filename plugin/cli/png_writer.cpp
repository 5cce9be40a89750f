#include "png_writer.hpp"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace fogbeam::png {

namespace {

// Owns a png_image's internal state (png_image_free releases it on every path).
class PngImageOwner {
 public:
  PngImageOwner() {
    std::memset(&image_, 0, sizeof image_);
    image_.version = PNG_IMAGE_VERSION;
  }
  ~PngImageOwner() { png_image_free(&image_); }
  PngImageOwner(const PngImageOwner&) = delete;
  PngImageOwner& operator=(const PngImageOwner&) = delete;
  PngImageOwner(PngImageOwner&&) = delete;
  PngImageOwner& operator=(PngImageOwner&&) = delete;

  png_image& get() noexcept { return image_; }

 private:
  png_image image_;
};

}  // namespace

RgbImage::RgbImage(int width, int height, Rgb fill)
    : width_(std::max(width, 0)),
      height_(std::max(height, 0)),
      pixels_(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 3) {
  for (std::size_t i = 0; i < pixels_.size(); i += 3) std::copy(fill.begin(), fill.end(), pixels_.begin() + static_cast<std::ptrdiff_t>(i));
}

void RgbImage::set(int x, int y, Rgb c) noexcept {
  if (!contains(x, y)) return;
  const std::size_t i = index(x, y);
  pixels_[i] = c[0];
  pixels_[i + 1] = c[1];
  pixels_[i + 2] = c[2];
}

Rgb RgbImage::get(int x, int y) const noexcept {
  if (!contains(x, y)) return {0, 0, 0};
  const std::size_t i = index(x, y);
  return {pixels_[i], pixels_[i + 1], pixels_[i + 2]};
}

void RgbImage::blend(int x, int y, Rgb c, double alpha) noexcept {
  if (!contains(x, y)) return;
  const double a = std::clamp(alpha, 0.0, 1.0);
  const std::size_t i = index(x, y);
  for (std::size_t k = 0; k < 3; ++k) {
    const double mixed = (1.0 - a) * pixels_[i + k] + a * c[k];
    pixels_[i + k] = static_cast<std::uint8_t>(std::lround(std::clamp(mixed, 0.0, 255.0)));
  }
}

Status writePng(const RgbImage& image, const std::string& path) {
  if (image.width() <= 0 || image.height() <= 0) return Error{path + ": cannot write PNG (empty image)"};
  PngImageOwner owner;
  png_image& img = owner.get();
  img.width = static_cast<png_uint_32>(image.width());
  img.height = static_cast<png_uint_32>(image.height());
  img.format = PNG_FORMAT_RGB;
  const png_int_32 rowStride = image.width() * 3;
  if (png_image_write_to_file(&img, path.c_str(), 0, image.bytes().data(), rowStride, nullptr) == 0) {
    return Error{path + ": cannot write PNG (" + std::string(img.message) + ")"};
  }
  return Ok{};
}

}  // namespace fogbeam::png
