// Test writer for `fogbeam view` (tests/view/view_screenshot.py): publishes a known pattern into a
// shared-memory channel, like `fogbeam serve` would, without a renderer.
//
// The frame is 4 × 2 patches; patch p = 4·row + column (row 0 at the top) holds
//   luminance  L_p = (0.05 + 0.3·column, 0.05 + 0.8·row, 2.0 − 0.22·p) cd/m² (R, G, B)
//   transmittance T_p = (p + 0.5) / 8, or 1 − that with variant 1 (a restarted writer's frames
//   must look different).
// Formats: rgba8-srgb (L_p tone-mapped at EV 0 by packRgba8Srgb, as serve does), rgba16f-linear
// (L_p, A = 1), rgba16f-overlay (L_p, A = T_p). The metadata carries fixed stage times (total
// 12.5 ms, surface 2.5, airlight 8, composite 2, latency 20), lights low beam + position and 2
// traffic objects, so the stats overlay has something to show.
//
// usage: fogbeam_view_test_writer CHANNEL FORMAT WIDTH HEIGHT RATE_HZ FRAMES VARIANT
//        FRAMES 0 = until SIGTERM/SIGINT; exits 0 after a clean close of the channel.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/render/pixel_pack.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

namespace {

std::atomic<bool> gStop{false};
extern "C" void onSignal(int) { gStop.store(true); }

}  // namespace

int main(int argc, char** argv) {
  if (argc != 8) {
    std::fprintf(stderr, "usage: %s CHANNEL rgba8-srgb|rgba16f-linear|rgba16f-overlay WIDTH HEIGHT RATE_HZ FRAMES VARIANT\n",
                 argv[0]);
    return 2;
  }
  const std::string channel = argv[1], fmt = argv[2];
  const auto W = static_cast<std::uint32_t>(std::stoul(argv[3])), H = static_cast<std::uint32_t>(std::stoul(argv[4]));
  const double rate_hz = std::stod(argv[5]);
  const auto frames = std::stoull(argv[6]);
  const int variant = std::stoi(argv[7]);
  std::uint32_t format = 0;
  if (fmt == "rgba8-srgb") format = FOGBEAM_FORMAT_RGBA8_SRGB;
  else if (fmt == "rgba16f-linear") format = FOGBEAM_FORMAT_RGBA16F_LINEAR;
  else if (fmt == "rgba16f-overlay") format = FOGBEAM_FORMAT_RGBA16F_OVERLAY;
  else {
    std::fprintf(stderr, "unknown format %s\n", fmt.c_str());
    return 2;
  }

  const std::size_t n = std::size_t{W} * H;
  std::vector<float> rgb(n * 3), alpha(n);
  for (std::uint32_t y = 0; y < H; ++y)
    for (std::uint32_t x = 0; x < W; ++x) {
      const std::uint32_t col = 4 * x / W, row = 2 * y / H, p = 4 * row + col;
      const std::size_t i = std::size_t{y} * W + x;
      rgb[3 * i + 0] = 0.05f + 0.3f * static_cast<float>(col);
      rgb[3 * i + 1] = 0.05f + 0.8f * static_cast<float>(row);
      rgb[3 * i + 2] = 2.0f - 0.22f * static_cast<float>(p);
      const float t = (static_cast<float>(p) + 0.5f) / 8.0f;
      alpha[i] = variant == 1 ? 1.0f - t : t;
    }
  std::vector<std::byte> packed(n * fogbeam::ipc::bytesPerPixel(format));
  if (format == FOGBEAM_FORMAT_RGBA8_SRGB)
    fogbeam::packRgba8Srgb(rgb.data(), n, 0.0, reinterpret_cast<std::uint8_t*>(packed.data()));
  else
    fogbeam::packRgba16F(rgb.data(), format == FOGBEAM_FORMAT_RGBA16F_OVERLAY ? alpha.data() : nullptr, 1.0f, n,
                         reinterpret_cast<std::uint16_t*>(packed.data()));

  fogbeam::ipc::ShmChannelOptions o;
  o.channel = channel;
  o.width = W;
  o.height = H;
  o.format = format;
  auto writer = fogbeam::ipc::ShmWriter::create(o);
  if (!writer) {
    std::fprintf(stderr, "view_test_writer: %s\n", writer.error().message.c_str());
    return 1;
  }
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(1.0 / rate_hz));
  auto next = std::chrono::steady_clock::now();
  for (std::uint64_t f = 1; !gStop.load() && (frames == 0 || f <= frames); ++f) {
    fogbeam::ipc::FrameMeta m;
    m.frame = f;
    m.total_ms = 12.5;
    m.surface_ms = 2.5;
    m.airlight_ms = 8.0;
    m.composite_ms = 2.0;
    m.latency_ms = 20.0;
    m.lights = fogbeam::ipc::light::kLowBeam | fogbeam::ipc::light::kPosition;
    m.traffic_count = 2;
    (*writer)->publish(m, packed);
    next += period;
    std::this_thread::sleep_until(next);
  }
  std::printf("view_test_writer: /fogbeam.%s closed\n", channel.c_str());
  return 0;
}
