// `fogbeam replay` (issue 5): renders a scenario (docs/scenario.md) headless, frame by frame at a
// fixed simulation rate, with the rigs and view of a service configuration (built-in default or
// --config), through the same per-frame step as `fogbeam serve` (plugin::FramePipeline,
// fogbeam/plugin/frame_pipeline.hpp): serve's sink publishes the frames in shared memory, replay's
// (FileSink below) writes frame_NNNNN.exr (the layers of `fogbeam render`) and/or
// frame_NNNNN.png, frames.csv (and effects_lamps.csv), then a contact sheet and timing.json.
//
// Deterministic: simulation time is k / fps, never the wall clock; tables are awaited (no
// background builds); so the same scenario and configuration give the same frames, byte for byte.
// Overlapped frames ([render] overlap_frames, --overlap; FramePipeline::submit): replay knows
// every state in advance, so the surface pass of frame k+1 always runs beside the rest of frame
// k; the frames are the same bytes.
#include "cmd_replay.hpp"
#include "exr_writer.hpp"
#include "png_writer.hpp"

#include <fogbeam/plugin/frame_pipeline.hpp>
#include <fogbeam/plugin/frame_renderer.hpp>
#include <fogbeam/plugin/scenario.hpp>
#include <fogbeam/plugin/service_config.hpp>
#include <fogbeam/render/exposure.hpp>
#include <fogbeam/render/frame.hpp>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace fogbeam::cli {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

png::RgbImage toImage(const FrameLayers& l, double exposure) {
  const auto bytes = toneMapSrgb8(l.composite, exposure);
  png::RgbImage img(l.width, l.height);
  for (int j = 0; j < l.height; ++j)
    for (int i = 0; i < l.width; ++i) {
      const std::size_t k = 3 * (static_cast<std::size_t>(j) * static_cast<std::size_t>(l.width) + static_cast<std::size_t>(i));
      img.set(i, j, {bytes[k], bytes[k + 1], bytes[k + 2]});
    }
  return img;
}

/// Box-filtered copy of `src` into the cell at (x0, y0) of size w × h of `sheet`.
void paste(const png::RgbImage& src, png::RgbImage& sheet, int x0, int y0, int w, int h) {
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int sx0 = x * src.width() / w, sx1 = std::max(sx0 + 1, (x + 1) * src.width() / w);
      const int sy0 = y * src.height() / h, sy1 = std::max(sy0 + 1, (y + 1) * src.height() / h);
      std::array<int, 3> sum{};
      int n = 0;
      for (int sy = sy0; sy < sy1; ++sy)
        for (int sx = sx0; sx < sx1; ++sx) {
          const png::Rgb c = src.get(sx, sy);
          for (int k = 0; k < 3; ++k) sum[static_cast<std::size_t>(k)] += c[static_cast<std::size_t>(k)];
          ++n;
        }
      png::Rgb c{};
      for (std::size_t k = 0; k < 3; ++k) c[k] = static_cast<std::uint8_t>(sum[k] / n);
      sheet.set(x0 + x, y0 + y, c);
    }
}

/// Replay's end of the frame pipeline: each frame into frame_NNNNN.exr / .png, a thumbnail for
/// the contact sheet, a frames.csv row (and, with glow or glare on, effects_lamps.csv rows), and
/// the figures of the summary and timing.json. One channel; the bookkeeping's frame number is
/// the frame index k, its simulation time start + k / fps.
/// How a frame's ego lamps were evaluated (frames.csv's `tables`): "pending" (per pixel while
/// their tables are built), "ladder" (from rungs of the fog ladder), "tables" (tables built for
/// the frame's fog and bending, or none needed: the GPU airlight).
const char* tablesOf(const plugin::RenderedFrame& f) { return f.pending ? "pending" : f.fog_rungs > 0 ? "ladder" : "tables"; }

class FileSink final : public plugin::FrameSink {
 public:
  FileSink(const ReplayOptions& o, bool effects) : o_(o), effects_(effects) {
    timeline_.open(fs::path(o.out) / "frames.csv");
    // Per visible lamp and frame (glow or glare on): what the frame's figures are made of.
    if (effects_) {
      lampRows_.open(fs::path(o.out) / "effects_lamps.csv");
      lampRows_ << "frame,t_s,lamp,distance_m,optical_distance,intensity_cd,eye_illuminance_lx,glow_source_cd,"
                   "glow_peak_cd_m2\n";
    }
    timeline_ << "frame,t_s,lights,traffic,total_ms,table_wait_ms,surface_ms,airlight_ms,evaluated_px,exposure_ev,tables"
              << (effects_ ? ",eye_illuminance_lx,veiling_luminance_cd_m2,glow_ms,glare_ms" : "") << "\n";
  }

  Status consume(std::size_t, const plugin::RenderedFrame& frame, const plugin::FrameBookkeeping& book) override {
    const auto b = Clock::now();
    // Frames arrive one submit late when they overlap: which one this is, from its bookkeeping.
    k_ = static_cast<std::size_t>(book.frame);
    t_ = o_.start_s + static_cast<double>(k_) / o_.fps;
    // The wall time between frames handed over: the replay's frame period (throughput), which
    // overlapping shortens while each frame's own stage times grow.
    if (lastHanded_) intervalMs.push_back(std::chrono::duration<double, std::milli>(b - *lastHanded_).count());
    lastHanded_ = b;
    char name[64];
    std::snprintf(name, sizeof name, "frame_%05zu", k_);
    const fs::path base = fs::path(o_.out) / name;
    if (o_.exr) {
      if (Status s = exr::writeFrameLayers(frame.layers, base.string() + ".exr"); !s) return s;
    }
    // The PNG's exposure: --exposure EV, or the frame's automatic night exposure adapted over
    // simulation time (the interval between frames, 1/fps: deterministic, like the frames).
    double ev = 0.0;
    if (o_.exposure) {
      ev = *o_.exposure;
    } else {
      const double target = autoExposureEv(frame.layers.composite, frame.layers.width, frame.layers.height);
      ev = adaptation_.update(target, adaptation_.started() ? t_ - previousT_ : 0.0);
      previousT_ = t_;
    }
    exposureEv.push_back(ev);
    png::RgbImage img = toImage(frame.layers, ev);
    if (o_.png) {
      if (Status s = png::writePng(img, base.string() + ".png"); !s) return s;
    }
    thumbs.push_back(std::move(img));
    const auto c = Clock::now();
    // The frame's time: the renderer's, from its first stage to the packed frame.
    const plugin::FrameTimings& tm = frame.timings;
    totalMs.push_back(tm.total_ms);
    waitMs.push_back(tm.table_wait_ms);
    surfaceMs.push_back(tm.surface_ms);
    airMs.push_back(tm.airlight_ms);
    ++tableFrames[tablesOf(frame)];
    writeMs.push_back(std::chrono::duration<double, std::milli>(c - b).count());
    timeline_ << k_ << "," << t_ << "," << plugin::lightNames(frame.inputs.lights) << "," << frame.inputs.traffic_count
              << "," << tm.total_ms << "," << tm.table_wait_ms << "," << tm.surface_ms << "," << tm.airlight_ms << ","
              << frame.airlight_evaluated << "," << ev << "," << tablesOf(frame);
    if (effects_) {
      const LampEffectsReport& fx = frame.effects;
      eyeLux.push_back(fx.eye_illuminance_lx);
      veiling.push_back(fx.veiling_luminance_cd_m2);
      glowMs.push_back(1e3 * fx.glow_seconds);
      glareMs.push_back(1e3 * fx.glare_seconds);
      timeline_ << "," << fx.eye_illuminance_lx << "," << fx.veiling_luminance_cd_m2 << "," << 1e3 * fx.glow_seconds
                << "," << 1e3 * fx.glare_seconds;
      for (const LampEffectsReport::Lamp& l : fx.lamps) {
        if (!l.visible) continue;
        // CSV: the name quoted (names may hold commas), quotes doubled.
        std::string quotedName = "\"";
        for (char letter : l.name) quotedName += letter == '"' ? std::string("\"\"") : std::string(1, letter);
        quotedName += "\"";
        lampRows_ << k_ << "," << t_ << "," << quotedName << "," << l.distance_m << "," << l.optical_distance << ","
                  << l.intensity_cd << "," << l.eye_illuminance_lx << "," << l.glow_source_cd << ","
                  << l.glow_peak_cd_m2 << "\n";
      }
    }
    timeline_ << "\n";
    return Ok{};
  }

  // Per frame, in order: ms (renderer's total, table wait, surface, airlight; file writing),
  // and with glow or glare on lx, cd/m², ms.
  std::vector<double> totalMs, surfaceMs, airMs, waitMs, writeMs, glowMs, glareMs, eyeLux, veiling;
  std::vector<double> intervalMs;  ///< ms between successive frames handed to the sink (frames − 1)
  std::map<std::string, std::size_t> tableFrames;  ///< frames by tablesOf()
  std::vector<png::RgbImage> thumbs;  ///< the PNG images, for the contact sheet
  std::vector<double> exposureEv;     ///< each PNG's exposure, EV

 private:
  const ReplayOptions& o_;
  bool effects_;
  std::ofstream timeline_, lampRows_;
  std::size_t k_ = 0;
  double t_ = 0.0;
  ExposureAdaptation adaptation_;
  double previousT_ = 0.0;
  std::optional<Clock::time_point> lastHanded_;
};

int fail(const std::string& what) {
  std::fprintf(stderr, "fogbeam replay: %s\n", what.c_str());
  return 2;
}

}  // namespace

int runReplay(const ReplayOptions& o) {
  auto scenario = plugin::loadScenario(o.scenario);
  if (!scenario) return fail(scenario.error().message);
  std::vector<std::string> settings = o.set;
  if (!o.method.empty()) settings.push_back("render.method=\"" + o.method + "\"");
  if (o.full) settings.push_back("render.subsampling=false");
  if (!o.surface.empty()) settings.push_back("render.surface=\"" + o.surface + "\"");
  if (!o.overlap.empty()) settings.push_back("render.overlap_frames=\"" + o.overlap + "\"");
  settings.push_back("world.scenario=\"\"");
  auto cfg = plugin::loadServiceConfig(o.config, settings);
  if (!cfg) return fail(cfg.error().message);
  std::size_t channel = 0;
  if (!o.channel.empty()) {
    const auto it = std::find_if(cfg->channels.begin(), cfg->channels.end(),
                                 [&](const plugin::ChannelConfig& c) { return c.name == o.channel; });
    if (it == cfg->channels.end()) return fail("--channel " + o.channel + ": no such channel in the service config");
    channel = static_cast<std::size_t>(it - cfg->channels.begin());
  }
  if (o.width > 0 || o.height > 0) {
    plugin::ChannelConfig& ch = cfg->channels[channel];
    if (ch.frustum_deg) return fail("--width/--height apply to centred (fov_x_deg) channels only");
    if (o.width > 0) ch.width = o.width;
    ch.height = o.height > 0 ? o.height : static_cast<int>(std::lround(ch.width * 9.0 / 16.0));
  }
  auto world = loadScene(scenario->scene_path);
  if (!world) return fail(world.error().message);
  std::error_code ec;
  fs::create_directories(o.out, ec);
  if (ec) return fail(o.out + ": " + ec.message());

  auto surface = plugin::openSurfacePass(*cfg);
  if (!surface) return fail(surface.error().message);
  if (!surface->fallback.empty())
    std::fprintf(stderr, "fogbeam replay: GL unavailable (%s); CPU planes only\n", surface->fallback.c_str());
  // The pipeline renders every channel of the configuration it is given: the chosen one only.
  // Frames await their tables, as lock-step serve's do.
  plugin::ServiceConfig one = *cfg;
  one.channels = {cfg->channels[channel]};
  auto pipeline = plugin::FramePipeline::create(std::move(one), *world, std::move(surface->gl), true);
  if (!pipeline) return fail(pipeline.error().message);

  const double end = o.end_s >= 0.0 ? std::min(o.end_s, scenario->duration_s) : scenario->duration_s;
  const auto count = static_cast<std::size_t>(std::floor((end - o.start_s) * o.fps + 1e-9)) + 1;
  const plugin::ChannelConfig& ch = cfg->channels[channel];
  const bool overlapped = (*pipeline)->overlapping();
  std::printf("fogbeam replay: %s (%s), %.2f s at %.3g fps = %zu frames, %dx%d, method %s (%s), glow %s, glare %s, "
              "frames %s, into %s\n",
              scenario->name.c_str(), o.scenario.c_str(), end - o.start_s, o.fps, count, ch.width, ch.height,
              cfg->method.c_str(), std::string(toString(cfg->effects.render.airlight)).c_str(),
              cfg->effects.glow.enabled ? "on" : "off", cfg->effects.glare.enabled ? "on" : "off",
              overlapped ? "overlapped" : "in sequence", o.out.c_str());
  std::fflush(stdout);

  ipc::StateStore store;
  std::uint32_t sequence = 1;
  // Glow and glare ([glow], [glare]): their figures per frame, as extra columns at the end.
  const bool effects = cfg->effects.glow.enabled || cfg->effects.glare.enabled;
  FileSink sink(o, effects);
  const bool tty = ::isatty(STDERR_FILENO) != 0;
  const auto t0 = Clock::now();
  for (std::size_t k = 0; k < count; ++k) {
    // The scenario's state at t, applied as if its messages had just arrived, then serve's step.
    const double t = o.start_s + static_cast<double>(k) / o.fps;
    const auto now = Clock::now();
    plugin::applyState(plugin::evaluate(*scenario, t), store, sequence, now);
    const auto snap = store.snapshot();
    plugin::FrameBookkeeping book;
    book.frame = k;
    // Overlapped: this state's surfaces beside the previous frame's rest, which is written.
    if (Status s = (*pipeline)->submit(*snap, now, book, sink); !s) return fail(s.error().message);
    if (k + 1 == count) {
      if (Status s = (*pipeline)->flush(sink); !s) return fail(s.error().message);
    }
    const double total = sink.totalMs.empty() ? 0.0 : sink.totalMs.back();
    // Progress: a bar redrawn in place on a terminal, a line per 10 % in logs.
    const double done = static_cast<double>(k + 1) / static_cast<double>(count);
    const double elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
    const double eta = elapsed / done - elapsed;
    if (tty) {
      const int bars = static_cast<int>(done * 30);
      std::fprintf(stderr, "\r  [%-30s] %zu/%zu  t = %6.2f s  %6.0f ms/frame  ETA %4.0f s ", std::string(static_cast<std::size_t>(bars), '#').c_str(),
                   k + 1, count, t, total, eta);
    } else if (k + 1 == count || (10 * (k + 1)) / count != (10 * k) / count) {
      std::fprintf(stderr, "  %3.0f %%  %zu/%zu frames, t = %.2f s, last frame %.0f ms, ETA %.0f s\n", 100 * done, k + 1,
                   count, t, total, eta);
    }
  }
  if (tty) std::fprintf(stderr, "\n");
  // Contact sheet: every frame, `sheetColumns` per row, box-filtered to the cell size.
  const int cols = std::max(1, std::min(o.sheetColumns, static_cast<int>(sink.thumbs.size())));
  const int rows = static_cast<int>((sink.thumbs.size() + static_cast<std::size_t>(cols) - 1) / static_cast<std::size_t>(cols));
  const int cellW = std::max(8, o.sheetWidth / cols - 4);
  const int cellH = std::max(4, cellW * ch.height / ch.width);
  png::RgbImage sheet(cols * (cellW + 4) + 4, rows * (cellH + 4) + 4, {40, 40, 40});
  for (std::size_t k = 0; k < sink.thumbs.size(); ++k) {
    const int col = static_cast<int>(k) % cols, row = static_cast<int>(k) / cols;
    paste(sink.thumbs[k], sheet, 4 + col * (cellW + 4), 4 + row * (cellH + 4), cellW, cellH);
  }
  const std::string sheetPath = (fs::path(o.out) / "contact_sheet.png").string();
  if (Status s = png::writePng(sheet, sheetPath); !s) return fail(s.error().message);

  const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
  std::printf("  frames          %zu in %.1f s (%.2f frames/s, writing included)\n", count, wall,
              static_cast<double>(count) / wall);
  std::printf("  frame time      median %.1f ms, p95 %.1f ms, max %.1f ms\n", percentile(sink.totalMs, 0.5),
              percentile(sink.totalMs, 0.95), percentile(sink.totalMs, 1.0));
  // The period: what a cab sees (frames/s = 1000 / it); with overlap shorter than the frame time.
  std::printf("  frame interval  median %.1f ms (%.2f frames/s), p95 %.1f ms; frames %s\n", percentile(sink.intervalMs, 0.5),
              sink.intervalMs.empty() ? 0.0 : 1e3 / percentile(sink.intervalMs, 0.5), percentile(sink.intervalMs, 0.95),
              overlapped ? "overlapped" : "in sequence");
  std::printf("  of which        table builds (fog/rig changes) median %.1f ms, max %.1f ms; surface median %.1f ms; "
              "airlight median %.1f ms\n",
              percentile(sink.waitMs, 0.5), percentile(sink.waitMs, 1.0), percentile(sink.surfaceMs, 0.5), percentile(sink.airMs, 0.5));
  // Which frames read tables (built for their fog, or the fog ladder's) and which went per pixel.
  std::printf("  ego lamps       %zu frames from tables, %zu from the fog ladder, %zu per pixel (tables pending)\n",
              sink.tableFrames["tables"], sink.tableFrames["ladder"], sink.tableFrames["pending"]);
  if (effects) {
    // Eye illuminance: Σ over the visible lamps of I e^{−K_t R} / R²; veiling luminance: the
    // CIE 146 stray light at the image centre (0 without [glare]).
    std::printf("  glow / glare    median %.2f / %.2f ms per frame; eye illuminance max %.3g lx, veiling luminance at "
                "the centre max %.3g cd/m2 (per frame: frames.csv)\n",
                percentile(sink.glowMs, 0.5), percentile(sink.glareMs, 0.5), percentile(sink.eyeLux, 1.0), percentile(sink.veiling, 1.0));
  }
  std::printf("  PNG exposure    %s %+.2f to %+.2f EV (per frame: frames.csv)\n", o.exposure ? "fixed" : "auto,",
              percentile(sink.exposureEv, 0.0), percentile(sink.exposureEv, 1.0));
  std::printf("  writing         median %.1f ms per frame\n", percentile(sink.writeMs, 0.5));
  std::printf("  wrote           %s/frame_*.%s, frames.csv%s, %s\n", o.out.c_str(),
              o.exr && o.png ? "{exr,png}" : o.exr ? "exr" : "png", effects ? ", effects_lamps.csv" : "",
              sheetPath.c_str());
  std::ofstream json(fs::path(o.out) / "timing.json");
  json << "{\"scenario\": \"" << scenario->name << "\", \"frames\": " << count << ", \"fps\": " << o.fps
       << ", \"width\": " << ch.width << ", \"height\": " << ch.height << ", \"method\": \"" << cfg->method
       << "\", \"wall_s\": " << wall << ", \"frame_ms_median\": " << percentile(sink.totalMs, 0.5)
       << ", \"frame_ms_p95\": " << percentile(sink.totalMs, 0.95) << ", \"table_ms_max\": " << percentile(sink.waitMs, 1.0)
       << ", \"interval_ms_median\": " << percentile(sink.intervalMs, 0.5)
       << ", \"frames_tables\": " << sink.tableFrames["tables"] << ", \"frames_ladder\": " << sink.tableFrames["ladder"]
       << ", \"frames_pending\": " << sink.tableFrames["pending"]
       << ", \"overlap_frames\": " << (overlapped ? "true" : "false");
  if (effects) {
    json << ", \"glow_ms_median\": " << percentile(sink.glowMs, 0.5) << ", \"glare_ms_median\": " << percentile(sink.glareMs, 0.5)
         << ", \"eye_illuminance_lx_max\": " << percentile(sink.eyeLux, 1.0)
         << ", \"veiling_luminance_cd_m2_max\": " << percentile(sink.veiling, 1.0);
  }
  json << ", \"airlight\": \"" << toString(cfg->effects.render.airlight) << "\"}\n";
  return 0;
}

}  // namespace fogbeam::cli
