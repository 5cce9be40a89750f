// fogbeam — the single executable. Subcommands: validate, profile (issue 2), render, bench
// (issue 3), serve, replay, view, send (issue 5), tables (issue 18).
//
// The whole command line is here: every subcommand's options, help texts and checks, filled into
// the plain options struct of cmd_X.hpp and handed to runX() (cmd_X.cpp). This is the one
// translation unit of `fogbeam` that includes CLI11: CLI11 is header-only, and its non-template
// inline functions are compiled again, at -O2, by every translation unit that registers options
// (some 5 s of compile each, for each of the three builds of the test command).
#include "cmd_bench.hpp"
#include "cmd_profile.hpp"
#include "cmd_render.hpp"
#include "cmd_replay.hpp"
#include "cmd_send.hpp"
#include "cmd_serve.hpp"
#include "cmd_tables.hpp"
#include "cmd_validate.hpp"
#include "cmd_view.hpp"

#include <CLI/CLI.hpp>

#include <cstdint>
#include <exception>
#include <memory>
#include <optional>
#include <string>

namespace fogbeam::cli {

namespace {

// Each add*Command() adds one subcommand to the app and arranges for it to run when chosen; the
// command sets `exitCode` to its exit status.

/// --exposure auto|EV of render, replay and view: "auto" leaves `target` empty (the automatic
/// night exposure, fogbeam/render/exposure.hpp), a number in [-20, 20] fixes the EV.
CLI::Option* addExposureOption(CLI::App* sub, std::optional<double>& target, const std::string& help) {
  const CLI::Validator autoOrEv(
      [](std::string& v) -> std::string {
        if (v == "auto") return {};
        std::size_t used = 0;
        double ev = 0.0;
        try {
          ev = std::stod(v, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != v.size() || used == 0 || !(ev >= -20.0 && ev <= 20.0))
          return "expected auto or an EV in [-20, 20], found '" + v + "'";
        return {};
      },
      "auto|EV");
  return sub
      ->add_option_function<std::string>(
          "--exposure", [&target](const std::string& v) { target = v == "auto" ? std::nullopt : std::optional(std::stod(v)); },
          help)
      ->check(autoOrEv);
}

void addValidateCommand(CLI::App& app, int& exitCode) {
  auto opts = std::make_shared<ValidateOptions>();
  auto* sub = app.add_subcommand(
      "validate",
      "Evaluate the airlight methods (seed, accurate, reference) on test vectors or a built-in sweep and print "
      "median / 95th percentile / max relative error and cost per evaluation. Exits 1 when the accurate method "
      "misses its bounds (p95 <= 0.5 %, max <= 2 %), 2 on bad input.");
  sub->add_option("--vectors", opts->vectors,
                  "CSV of rays, lamps and fogs with expected airlight (cd/m2), columns as "
                  "tests/data/airlight_vectors.csv; lengths in m, angles in degrees, extinction in 1/m. "
                  "Without it, a built-in sweep is evaluated against the reference method.")
      ->check(CLI::ExistingFile);
  sub->add_option("--out", opts->out, "write one row per case and method: method,row,value,expected,rel_error "
                                      "(value and expected in cd/m2; rel_error is |L| for zero cases)");
  sub->add_option("--methods", opts->methods, "methods to run (default: seed accurate reference)")->delimiter(',');
  sub->add_option("--headlamp", opts->headlamp,
                  "sweep only: headlamp profile file (.ies/.ldt/.csv) instead of the built-in low beam");
  sub->add_flag("!--no-additions", opts->additions,
                "skip the checks of issue 7's additions (glow energy, glare, near-field lamps, GPU airlight)");
  sub->add_option("--rays", opts->rays, "sweep only: rays per situation (default 24; 7 fogs x 2 profiles x 4 situations)")
      ->check(CLI::Range(1, 10000));
  sub->add_option("--segments", opts->segments,
                  "accurate method: quadratic pieces per ray for tabulated profiles (default 48)")
      ->check(CLI::Range(1, 4096));
  sub->add_flag("--path-tracer", opts->path_tracer,
                "also compare fogbeam's single scattering and glow with the all-orders path tracer in rings 0.5-16 deg "
                "about a lamp in view (isotropic lamps in 6 fogs, a road, the low and high beams from 3 sides; a few minutes; exits 1 "
                "when the path tracer's single scattering misses fogbeam's by more than 3 sigma + 1 %)");
  sub->add_option("--pt-samples", opts->pt_samples,
                  "--path-tracer: paths per ring and case (default 20000; the error falls as 1/sqrt)")
      ->check(CLI::Range(100, 100000000));
  sub->add_flag("--pt-road-only", opts->pt_road_only,
                "--path-tracer: only the scattered light on the road (the fog light), not the rings");
  sub->add_option("--pt-cases", opts->pt_cases,
                  "--path-tracer: only the ring cases whose name contains this text (e.g. \"high beam\"), without the "
                  "road's scattered light");
  sub->add_option("--pt-out", opts->pt_out,
                  "--path-tracer: write the ring figures as CSV (one row per case and ring; luminances in cd/m2)");
  sub->add_option("--pt-pictures", opts->pt_pictures,
                  "write pictures of an isotropic lamp in fog into this folder: fogbeam single, single + glow and the "
                  "all-orders path tracer side by side (glow_vs_path_tracer.png) and their luminance and ratio along "
                  "the image's centre row (glow_rings.svg, .csv); --pt-samples paths per angle, 36 angles")
      ->check(CLI::ExistingDirectory);
  sub->callback([opts, &exitCode] { exitCode = runValidate(*opts); });
}

void addProfileCommand(CLI::App& app, int& exitCode) {
  auto opts = std::make_shared<ProfileOptions>();
  auto* sub = app.add_subcommand(
      "profile",
      "Describe a lamp intensity file (.ies IES LM-63, .ldt EULUMDAT, .csv H-V grid) and chart it as PNG.\n"
      "Prints format, photometric type and symmetry, angle ranges (deg), peak intensity (cd) and where,\n"
      "total flux (lm), for type B files the intensity at the ECE R112 passing-beam test points, and keywords.");
  sub->add_option("FILE", opts->file, "Lamp intensity file: .ies, .ldt or .csv")->required()->type_name("FILE");
  sub->add_option("--png", opts->png,
                  "Write a false-colour H-V chart to this PNG file: H across (lamp's left on the left), V up, "
                  "equal scale in degrees; colour = log10(cd) over four decades below the peak (viridis); "
                  "isocandela lines at 1 and 3 x 10^k cd; grid lines every 5/10 deg")
      ->type_name("OUT.png");
  sub->add_option("--size", opts->size, "Chart width in pixels (height follows from the ranges at equal scale)")
      ->type_name("PX")
      ->default_val(1200)
      ->check(CLI::Range(300, 8000));
  sub->add_option("--h-range", opts->hRange,
                  "Horizontal chart range in degrees: D for -D..+D, or LO HI (within -90..90; default 45 = -45..+45)")
      ->type_name("DEG")
      ->expected(1, 2);
  sub->add_option("--v-range", opts->vRange,
                  "Vertical chart range in degrees: D for -D..+D, or LO HI (within -90..90; default -15 10)")
      ->type_name("DEG")
      ->expected(1, 2);
  sub->callback([opts, &exitCode] { exitCode = runProfile(*opts); });
}

void addRenderCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<RenderOptions>();
  auto* sub = app.add_subcommand("render", "Render one frame of a scene file (TOML, docs/scene.md) to OpenEXR and PNG");
  sub->add_option("--scene", o->scene, "scene file (TOML); lengths in m, angles in deg, intensities in cd")
      ->required()
      ->check(CLI::ExistingFile);
  sub->add_option("--out", o->out,
                  "OpenEXR file, 32-bit float linear layers: R,G,B composite; airlight.R/G/B; surface.R/G/B; "
                  "overlay.R/G/B (A = airlight + glow + glare + ambient in-scatter); transmittance.Y; distance.Z (m, inf = "
                  "sky); glow.R/G/B and glare.R/G/B when on; luminance in cd/m2")
      ->required();
  sub->add_option("--png", o->png, "also write the composite tone-mapped to 8-bit sRGB PNG");
  sub->add_option("--method", o->method, "airlight method: seed | accurate | reference (default accurate)")
      ->each([o](const std::string&) { o->methodGiven = true; });
  sub->add_option("--glow", o->glow, "glow around lamps (multiple scattering): on | off (default: the scene's [glow])")
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--glare", o->glare,
                  "driver's disability glare (CIE 146 veiling luminance): on | off (default: the scene's [glare])")
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--fog-light", o->fogLight,
                  "the fog's scattered light on the surfaces (with the glow on): "
                  "on | off (default: the scene's [glow] surfaces)")
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--airlight", o->airlightDevice,
                  "where the airlight is computed: cpu (tables, SIMD, subsampling) | gpu (accurate method in GLSL in the "
                  "surface pass) (default: the scene's [render] airlight, else cpu)")
      ->check(CLI::IsMember({"cpu", "gpu"}));
  sub->add_flag("--full", o->full, "evaluate every pixel (no adaptive subsampling)");
  sub->add_option("--moving-lamps", o->movingLamps,
                  "measured and spot lamps fixed in the world (not mount = \"vehicle\"): pencil (default: the pencil "
                  "integrator per pixel) | map (each lamp's own adaptive sampling of the frame) | per-ray (the "
                  "accurate method per pixel)")
      ->check(CLI::IsMember({"pencil", "map", "per-ray"}));
  sub->add_option("--table-cache", o->tableCache,
                  "where the vehicle lamps' view tables (and the fog light's table and maps) are kept between runs: "
                  "auto (default: $XDG_CACHE_HOME/fogbeam or ~/.cache/fogbeam) | off | a directory");
  addExposureOption(sub, o->exposure,
                    "PNG exposure: auto (default: the frame's 99.5th percentile of luminance, lamp images left out, "
                    "shown at 0.8 of white; EV clamped to [-16, 6]; printed) | EV in [-20, 20]: x = L * 2^EV / (1 cd/m2), "
                    "Reinhard x/(1+x), sRGB (0: 1 cd/m2 = mid-grey)");
  sub->add_option("--coarse-step", o->coarseStep,
                  "subsampling: initial block size in pixels; 0 (default): 16 where 16 px span at most 0.8 deg, else 8")
      ->check(CLI::Range(0, 256));
  sub->add_option("--tolerance", o->tolerance,
                  "subsampling: relative error allowed between a block's centre and its bilinear prediction (default 0.005)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option("--threads", o->threads, "worker threads (default: all cores)");
  sub->add_option("--surface", o->surface,
                  "surface layer: auto (GL through EGL if available, else CPU), gl (fail without EGL), cpu (planes only)")
      ->check(CLI::IsMember({"auto", "gl", "cpu"}));
  sub->callback([o, &exitCode] { exitCode = runRender(*o); });
}

void addBenchCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<BenchOptions>();
  auto* sub = app.add_subcommand("bench", "Time every stage of a frame on the paper's headline scene and measure the "
                                          "error of each airlight method (and a ray marcher) against the reference");
  sub->add_option("--scene", o->scene, "scene file (default: the shipped config/scenes/bench.toml)")
      ->check(CLI::ExistingFile);
  sub->add_option("--sizes", o->sizes, "image sizes WIDTHxHEIGHT, comma-separated (default 1280x720,1920x1080)")
      ->delimiter(',');
  sub->add_option("--frames", o->frames, "repeated frames per stage (default 5)")->check(CLI::Range(1, 1000));
  sub->add_flag("--quick", o->quick, "CI mode: 320x180, 2 frames, view tables at 0.5 deg");
  sub->add_option("--view-table-step", o->viewTableStepDeg,
                  "view-table direction spacing, degrees (default 0.2, the renderer's default)")
      ->check(CLI::Range(0.01, 5.0));
  sub->add_option("--json", o->jsonPath, "also write every figure to this JSON file");
  sub->add_option("--gpu-size", o->gpuSize,
                  "size WIDTHxHEIGHT of the GPU airlight comparison (default 160x90: llvmpipe runs it on the CPU)");
  sub->add_option("--aperture-size", o->apertureSize,
                  "size WIDTHxHEIGHT of the near-field (aperture) lamps' comparison (default 320x180)");
  sub->add_option("--traffic-scene", o->trafficScene,
                  "scene of the moving-lamp section: measured lamps not fixed to the camera move every frame "
                  "(default: the shipped config/scenes/traffic.toml)");
  sub->add_option("--traffic-size", o->trafficSize,
                  "size WIDTHxHEIGHT of the moving-lamp section (default 1280x720)");
  sub->add_flag("--only-traffic", o->onlyTraffic, "run the moving-lamp section alone (its own scene; no other stage)");
  sub->add_flag("--only-pencil", o->onlyPencil,
                "with --only-traffic: its static and pencil frames alone (no maps, no changing-fog section): "
                "a quick measure of the moving-lamp path");
  sub->add_option("--threads", o->threads, "worker threads (default: all cores)");
  sub->add_option("--sample-pixels", o->samplePixels, "random pixels for the error figures (default 500)")
      ->check(CLI::Range(10, 1000000));
  sub->add_option("--stage-budget", o->stageBudgetSeconds,
                  "seconds allowed to each airlight stage per size: fewer frames (at least 1) when they do not fit "
                  "(default 30; --quick: 3)")
      ->check(CLI::Range(0.0, 3600.0));
  sub->add_option("--max-raymarch-steps", o->maxRayMarchSteps,
                  "largest ray-marcher step count tried (powers of two from 16; default 16384)")
      ->check(CLI::Range(16, 1 << 20));
  sub->callback([o, &exitCode] { exitCode = runBench(*o); });
}

void addTablesCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<TablesOptions>();
  auto* sub = app.add_subcommand("tables", "Estimate a multiple-scattering table for one phase function (the glow "
                                           "layer's; docs/physics.md, \"Multiple scattering tables\")");
  sub->add_option("--phase", o->phase, "phase function")->check(CLI::IsMember({"henyey-greenstein", "fog-mie", "isotropic"}));
  sub->add_option("--g", o->g, "HG asymmetry g (henyey-greenstein)")->check(CLI::Range(-0.99, 0.99));
  sub->add_option("--droplet-diameter", o->dropletDiameter_um, "droplet diameter in um (fog-mie)")->check(CLI::Range(5.0, 50.0));
  sub->add_option("--paths", o->paths, "Monte Carlo paths (default 80000)")->check(CLI::Range(2, 100000000));
  sub->add_option("--seed", o->seed, "random seed (default 1)");
  sub->add_option("--threads", o->threads, "threads (default: all)");
  sub->add_option("--out", o->out, "table file to write")->required();
  sub->add_flag("--ground", o->ground,
                "estimate the ground's factor on the shipped table of the phase function instead (a .gnd file; "
                "--paths per optical distance, reflectance and ring)");
  sub->callback([o, &exitCode] { exitCode = runTables(*o); });
}

void addServeCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<ServeOptions>();
  auto* sub = app.add_subcommand(
      "serve", "Run the cab service: UDP/CAN/scenario in, frames to shared-memory channels (docs/service.md)");
  sub->add_option("--config", o->config, "service config file, merged over the built-in default")
      ->check(CLI::ExistingFile);
  sub->add_option("--set", o->set, "override one key: section.key=value (TOML value), repeatable")
      ->take_all();
  sub->add_flag("--print-config", o->printConfig, "print the effective configuration (TOML) and exit");
  sub->add_option("--scenario", o->scenario, "play this scenario until a host sends (overrides world.scenario)")
      ->check(CLI::ExistingFile);
  sub->add_flag("--no-scenario", o->noScenario, "play no scenario: wait for a host");
  sub->add_option("--channel-prefix", o->channelPrefix, "prefix every channel name (several services on one machine)");
  sub->add_option("--duration", o->duration_s, "stop after this many seconds (default: until SIGINT/SIGTERM)")
      ->check(CLI::Range(0.0, 1e7));
  sub->add_option("--frames", o->frames, "stop after this many frames (default: no limit)");
  sub->add_flag("--lock-step", o->lockStep, "= --set timing.mode=\"lock-step\"");
  sub->add_option("--rate", o->rate_hz, "= --set timing.rate_hz=…")->check(CLI::Range(0.1, 1000.0));
  sub->add_option("--udp-port", o->udpPort, "= --set input.udp.port=… (0 = any free port)")->check(CLI::Range(0, 65535));
  sub->add_option("--status-port", o->statusPort, "= --set status.udp_port=… (0 = off)")->check(CLI::Range(0, 65535));
  sub->add_option("--surface", o->surface, "= --set render.surface=…")->check(CLI::IsMember({"auto", "gl", "cpu"}));
  sub->add_option("--overlap", o->overlap, "= --set render.overlap_frames=… (auto | on | off)")
      ->check(CLI::IsMember({"auto", "on", "off"}));
  sub->add_option("--view-table-step", o->viewTableStepDeg, "= --set render.view_table_step_deg=…")
      ->check(CLI::Range(0.05, 5.0));
  sub->add_option("--threads", o->threads, "= --set render.threads=…");
  sub->callback([o, &exitCode] { exitCode = runServe(*o); });
}

void addReplayCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<ReplayOptions>();
  auto* sub = app.add_subcommand("replay", "Render a scenario (docs/scenario.md) headless into frames, a contact sheet "
                                           "and a timing summary; deterministic");
  sub->add_option("--scenario", o->scenario, "scenario file (TOML)")->required()->check(CLI::ExistingFile);
  sub->add_option("--out", o->out, "output directory (created)")->required();
  sub->add_option("--fps", o->fps, "frames per second of simulation time (default 10)")->check(CLI::Range(0.01, 1000.0));
  sub->add_option("--method", o->method, "airlight method: accurate | seed | reference (default: the config's)")
      ->check(CLI::IsMember({"accurate", "seed", "reference"}));
  sub->add_option("--config", o->config, "service config for rigs and views (default: built-in)")->check(CLI::ExistingFile);
  sub->add_option("--set", o->set, "override a service config key: section.key=value, repeatable")->take_all();
  sub->add_option("--channel", o->channel, "which [[channel]] view to render (default: the first)");
  sub->add_flag("!--no-exr", o->exr, "do not write EXR frames");
  sub->add_flag("!--no-png", o->png, "do not write PNG frames (the contact sheet is still written)");
  sub->add_flag("--full", o->full, "evaluate every pixel (no adaptive subsampling)");
  addExposureOption(sub, o->exposure,
                    "PNG exposure: auto (default: each frame's automatic night exposure, as render's, adapted over "
                    "simulation time like the eye: time constant 0.5 s towards brighter, 1 s towards darker; in "
                    "frames.csv) | EV in [-20, 20] (0: 1 cd/m2 = mid-grey)");
  sub->add_option("--start", o->start_s, "first frame's time, s (default 0)")->check(CLI::Range(0.0, 1e6));
  sub->add_option("--end", o->end_s, "last frame's time, s (default: the scenario's duration)")->check(CLI::Range(0.0, 1e6));
  sub->add_option("--sheet-columns", o->sheetColumns, "contact sheet columns (default 6)")->check(CLI::Range(1, 64));
  sub->add_option("--sheet-width", o->sheetWidth, "contact sheet width, px (default 1536)")->check(CLI::Range(64, 16384));
  sub->add_option("--width", o->width, "image width, px (default: the channel's; same field of view)")
      ->check(CLI::Range(16, 16384));
  sub->add_option("--height", o->height, "image height, px (default: width · 9/16 when --width is given)")
      ->check(CLI::Range(9, 16384));
  sub->add_option("--surface", o->surface, "auto | gl | cpu (default: the config's)")->check(CLI::IsMember({"auto", "gl", "cpu"}));
  sub->add_option("--overlap", o->overlap,
                  "the surface pass of frame k+1 beside the rest of frame k: auto (where cores allow) | on | off "
                  "(default: the config's [render] overlap_frames); the frames are the same bytes")
      ->check(CLI::IsMember({"auto", "on", "off"}));
  sub->callback([o, &exitCode] { exitCode = runReplay(*o); });
}

void addSendCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<SendOptions>();
  auto* sub = app.add_subcommand("send", "Host stand-in: play a scenario (or keyboard driving) into a running "
                                         "`fogbeam serve` over UDP, optionally CAN");
  sub->add_option("--scenario", o->scenario, "scenario file to play in real time")->check(CLI::ExistingFile);
  sub->add_flag("--keyboard", o->keyboard, "drive with the keyboard instead (w/s/a/d, l/h/f/r lights, +/- fog, q)");
  sub->add_option("--to", o->to, "the service's UDP input, HOST:PORT (default 127.0.0.1:47800)");
  sub->add_option("--rate", o->rate_hz, "states per second (default 60)")->check(CLI::Range(0.1, 2000.0));
  sub->add_option("--speed", o->speed, "scenario time per wall-clock second (default 1)")->check(CLI::Range(0.01, 100.0));
  sub->add_option("--duration", o->duration_s, "stop after this many wall-clock seconds")->check(CLI::Range(0.0, 1e7));
  sub->add_flag("--loop", o->loop, "start the scenario again at its end");
  sub->add_flag("--lock-step", o->lockStep, "send a frame request (frame = state number, from 1) after each state");
  sub->add_option("--log", o->log, "write what was sent (ego sequence, time, pose, lights) to this CSV");
  sub->add_option("--can-config", o->canConfig, "CAN mapping file (docs/can.md): also send lamps and speed on CAN")
      ->check(CLI::ExistingFile);
  sub->add_option("--can-cannelloni", o->canCannelloni, "send the CAN frames as cannelloni to HOST:PORT");
  sub->add_option("--can-candump", o->canCandump, "write the CAN frames as a candump -L log");
  sub->add_option("--can-interface", o->canInterface, "interface name written in the candump log (default can0)");
  sub->callback([o, &exitCode] { exitCode = runSend(*o); });
}

void addViewCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<ViewOptions>();
  auto* sub = app.add_subcommand(
      "view", "Show shared-memory channels in a window (keys: 1/2/3 composite/airlight/transmittance, A automatic "
              "exposure on/off, +/- exposure by 0.5 EV (turns automatic off), S stats, Tab focus one channel, Esc/Q "
              "quit)");
  sub->add_option("--channel", o->channels, "channel name(s), repeatable or comma-separated: tiled side by side (default main)")
      ->delimiter(',');
  sub->add_option("--layer", o->layer, "initial layer: composite | airlight | transmittance (default composite)")
      ->check(CLI::IsMember({"composite", "airlight", "transmittance"}));
  addExposureOption(sub, o->exposure,
                    "initial exposure of linear formats: auto (default: the automatic night exposure of the frames "
                    "shown, adapted like the eye; key A toggles it) | EV: display = sRGB(Reinhard(2^EV * L)) with L in "
                    "cd/m2");
  sub->add_flag("--no-stats", o->noStats, "start without the stats overlay");
  sub->add_option("--width", o->width, "window width, pixels (default: the frames' native widths, tiled)")
      ->check(CLI::Range(16, 16384));
  sub->add_option("--height", o->height, "window height, pixels (default: the tallest frame's height)")
      ->check(CLI::Range(16, 16384));
  sub->add_option("--screenshot", o->screenshot, "save the window as this PNG after --after-frames new frames, then exit 0");
  sub->add_option("--after-frames", o->afterFrames, "new frames every channel shows before the screenshot (default 1)")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1000000}));
  sub->add_option("--timeout", o->timeout_s, "exit 1 when a channel shows no new frame for this many seconds "
                                             "(default 0: wait forever)")
      ->check(CLI::Range(0.0, 1e7));
  sub->callback([o, &exitCode] { exitCode = runView(*o); });
}

}  // namespace

}  // namespace fogbeam::cli

int main(int argc, char** argv) {
  CLI::App app{"fogbeam: real-time headlight beams in fog for driving simulators"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("fogbeam 0.1.0"));
  int exitCode = 0;
  fogbeam::cli::addValidateCommand(app, exitCode);
  fogbeam::cli::addProfileCommand(app, exitCode);
  fogbeam::cli::addRenderCommand(app, exitCode);
  fogbeam::cli::addBenchCommand(app, exitCode);
  fogbeam::cli::addServeCommand(app, exitCode);
  fogbeam::cli::addReplayCommand(app, exitCode);
  fogbeam::cli::addSendCommand(app, exitCode);
  fogbeam::cli::addViewCommand(app, exitCode);
  fogbeam::cli::addTablesCommand(app, exitCode);
  CLI11_PARSE(app, argc, argv);
  return exitCode;
}
