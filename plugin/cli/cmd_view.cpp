// `fogbeam view` (issue 5): a GLFW window on one or more shared-memory channels (docs/shm.md),
// tiled side by side, each frame drawn as a texture through a small shader that decodes the
// channel's format: RGBA8 sRGB is shown as published (already tone-mapped and sRGB-encoded by the
// writer), RGBA16F layers are linear cd/m² and go through the display mapping of
// fogbeam::toneMapSrgb8 (x = L·2^EV, Reinhard x/(1 + x), sRGB transfer), the transmittance (A of
// the overlay format) is shown as grey = T. The exposure of linear layers is automatic by default
// (fogbeam/render/exposure.hpp: the night exposure of the linear pixels shown, metered on the CPU
// from each new frame, every visible tone-mapped channel in one histogram so that tiles match,
// adapted like the eye over wall-clock time); key A toggles it, +/- set it by hand. A stats overlay per channel comes from the slot
// metadata (stage times, latency, lights) and from the reader (fps shown, retries).
//
// Channels are attached with ipc::ShmReader and attached again when their writer goes or restarts
// (new generation); until then the tile says "waiting for /fogbeam.<name>". --screenshot saves
// the back buffer as PNG once every channel has shown --after-frames new frames, so the viewer
// can be tested under Xvfb (tests/view/view_screenshot.py).
//
// GL 3.3 core through libepoxy (as core/src/gl does), windows and input through GLFW (GLX under
// X11 and Xvfb), text through stb_easy_font (quads, no texture).
#include "cmd_view.hpp"
#include "png_writer.hpp"

#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/render/exposure.hpp>
#include <fogbeam/render/pixel_pack.hpp>

#include <epoxy/gl.h>
#include <fmt/format.h>
// epoxy provides the GL declarations; GLFW must not include a GL header of its own.
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <stb/stb_easy_font.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstddef>
#include <cstdio>
#include <deque>
#include <memory>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace fogbeam::cli {

namespace {

using Clock = std::chrono::steady_clock;

std::atomic<bool> gStop{false};
extern "C" void onViewSignal(int) { gStop.store(true); }

enum class Layer { Composite = 0, Airlight = 1, Transmittance = 2 };
const char* layerName(Layer l) {
  switch (l) {
    case Layer::Composite: return "composite";
    case Layer::Airlight: return "airlight";
    case Layer::Transmittance: return "transmittance";
  }
  return "?";
}

/// How the shader shows a texel (uniform `mode` of kFrameFragment).
enum class Decode : int { AsIs = 0, ToneMap = 1, AlphaGrey = 2 };

/// What a channel of `format` can show for the wanted layer: the layer shown, how it is decoded,
/// and a note for the overlay when it is not the one wanted.
struct Shown {
  Layer layer;
  Decode decode;
  const char* note;
};
Shown shownFor(std::uint32_t format, Layer wanted) {
  switch (format) {
    case FOGBEAM_FORMAT_RGBA8_SRGB:
      return {Layer::Composite, Decode::AsIs, wanted == Layer::Composite ? "" : "RGBA8 sRGB has only the composite"};
    case FOGBEAM_FORMAT_RGBA16F_LINEAR:
      return {Layer::Composite, Decode::ToneMap,
              wanted == Layer::Composite ? "" : "RGBA16F linear has only the composite"};
    case FOGBEAM_FORMAT_RGBA16F_OVERLAY:
      if (wanted == Layer::Transmittance) return {Layer::Transmittance, Decode::AlphaGrey, ""};
      return {Layer::Airlight, Decode::ToneMap,
              wanted == Layer::Airlight ? "" : "overlay format has no composite (host*T + A): showing the airlight"};
    default: return {Layer::Composite, Decode::AsIs, "unknown pixel format"};
  }
}

const char* formatName(std::uint32_t format) {
  switch (format) {
    case FOGBEAM_FORMAT_RGBA8_SRGB: return "RGBA8 sRGB";
    case FOGBEAM_FORMAT_RGBA16F_LINEAR: return "RGBA16F linear";
    case FOGBEAM_FORMAT_RGBA16F_OVERLAY: return "RGBA16F overlay";
    case FOGBEAM_FORMAT_DISTANCE_F32: return "f32 distance";
    default: return "unknown";
  }
}

std::string lightNames(std::uint32_t bits) {
  static constexpr std::pair<std::uint32_t, const char*> kNames[] = {
      {ipc::light::kPosition, "pos"},      {ipc::light::kLowBeam, "low"},       {ipc::light::kHighBeam, "high"},
      {ipc::light::kBrake, "brake"},       {ipc::light::kIndicatorLeft, "ind-L"}, {ipc::light::kIndicatorRight, "ind-R"},
      {ipc::light::kFrontFog, "front-fog"}, {ipc::light::kRearFog, "rear-fog"},  {ipc::light::kDrl, "drl"}};
  std::string s;
  for (const auto& [bit, name] : kNames)
    if ((bits & bit) != 0) s += (s.empty() ? "" : "+") + std::string(name);
  return s.empty() ? "none" : s;
}

// ---- channels -------------------------------------------------------------------------------

struct Channel {
  std::string name;
  std::unique_ptr<ipc::ShmReader> reader;
  std::string waiting = "not attached yet";  ///< why there is no frame to show now ("" = live)
  Clock::time_point nextAttach{};
  Clock::time_point nextLivenessCheck{};
  std::uint64_t lastTag = 0;                 ///< reader->latestTag() at the last copy
  ipc::FrameMeta meta;                       ///< of the frame shown
  std::vector<std::byte> pixels;
  std::uint64_t shownFrame = 0, shownPublishNs = 0;
  GLuint texture = 0;
  std::uint32_t texWidth = 0, texHeight = 0, texFormat = 0;  ///< 0 = nothing uploaded yet
  std::uint64_t newFrames = 0;               ///< new frames shown since start, over all attaches
  std::uint64_t attaches = 0;                ///< successful attaches (1 + writer restarts seen)
  std::uint64_t goneGeneration = 0;          ///< generation of the writer last found gone (0 = none)
  std::uint64_t oldRetries = 0;              ///< retries of the readers before the current one
  std::deque<Clock::time_point> arrivals;    ///< of the last 2 s, for the fps shown
  Clock::time_point lastNew{};               ///< start or the last new frame (--timeout)

  [[nodiscard]] std::uint64_t retries() const { return oldRetries + (reader ? reader->retries() : 0); }
  /// New frames per second over the last 2 s (0 when fewer than two arrived in them).
  [[nodiscard]] double fps(Clock::time_point now) const {
    if (arrivals.size() < 2 || now - arrivals.back() > std::chrono::seconds(2)) return 0.0;
    const double s = std::chrono::duration<double>(arrivals.back() - arrivals.front()).count();
    return s > 0.0 ? static_cast<double>(arrivals.size() - 1) / s : 0.0;
  }
  void detach(const std::string& why) {
    if (reader) oldRetries += reader->retries();
    reader.reset();
    waiting = why;
  }
};

/// Uploads the frame in c.pixels as c.texture (RGBA16F from the packed binary16 data, or RGBA8
/// without sRGB decoding: the bytes are display values and are drawn as they are).
void upload(Channel& c, std::uint32_t width, std::uint32_t height, std::uint32_t fmt) {
  if (c.texture == 0) {
    glGenTextures(1, &c.texture);
    glBindTexture(GL_TEXTURE_2D, c.texture);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    // Nearest when magnified: enlarged pixels keep their published values.
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  }
  glBindTexture(GL_TEXTURE_2D, c.texture);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  const auto w = static_cast<GLsizei>(width), h = static_cast<GLsizei>(height);
  const bool half = fmt != FOGBEAM_FORMAT_RGBA8_SRGB;
  if (width != c.texWidth || height != c.texHeight || fmt != c.texFormat) {
    glTexImage2D(GL_TEXTURE_2D, 0, half ? GL_RGBA16F : GL_RGBA8, w, h, 0, GL_RGBA,
                 half ? GL_HALF_FLOAT : GL_UNSIGNED_BYTE, c.pixels.data());
    c.texWidth = width;
    c.texHeight = height;
    c.texFormat = fmt;
  } else {
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGBA, half ? GL_HALF_FLOAT : GL_UNSIGNED_BYTE, c.pixels.data());
  }
}

/// Attaches when due, and uploads the newest frame when there is a new one. True when it did.
bool poll(Channel& c, Clock::time_point now) {
  if (!c.reader) {
    if (now < c.nextAttach) return false;
    c.nextAttach = now + std::chrono::milliseconds(250);
    auto r = ipc::ShmReader::attach(c.name);
    if (!r) {
      c.waiting = r.error().message;
      return false;
    }
    if ((*r)->format() == FOGBEAM_FORMAT_DISTANCE_F32) {
      c.waiting = "a host depth input (f32 distance), not a frame channel";
      return false;
    }
    // The segment of the writer found gone is still there until it unlinks it (clean exit) or a
    // new writer replaces it (after a crash): not a new writer, keep waiting.
    if ((*r)->generation() == c.goneGeneration) return false;
    c.reader = std::move(r).value();
    c.lastTag = 0;
    c.waiting = "attached, no frame yet";
    ++c.attaches;
    std::fprintf(stderr, "fogbeam view: attached /fogbeam.%s: %ux%u %s, writer generation %016llx\n", c.name.c_str(),
                 c.reader->width(), c.reader->height(), formatName(c.reader->format()),
                 static_cast<unsigned long long>(c.reader->generation()));
  }
  // Copy only when the writer published since the last copy; ask latest() now and then anyway,
  // since it is what notices a closed, dead or silent writer.
  const std::uint64_t tag = c.reader->latestTag();
  if (tag == c.lastTag && now < c.nextLivenessCheck) return false;
  c.nextLivenessCheck = now + std::chrono::milliseconds(250);
  ipc::FrameMeta meta;
  switch (c.reader->latest(meta, c.pixels)) {
    case ipc::ReadStatus::Ok: break;
    case ipc::ReadStatus::NoFrame:
    case ipc::ReadStatus::Busy: return false;
    case ipc::ReadStatus::WriterGone:
      std::fprintf(stderr, "fogbeam view: /fogbeam.%s: writer gone; waiting for a new one\n", c.name.c_str());
      c.goneGeneration = c.reader->generation();
      c.detach("writer gone");
      return false;
  }
  c.lastTag = tag;
  c.waiting.clear();
  if (meta.frame == c.shownFrame && meta.publish_ns == c.shownPublishNs) return false;  // seen already
  c.meta = meta;
  c.shownFrame = meta.frame;
  c.shownPublishNs = meta.publish_ns;
  upload(c, c.reader->width(), c.reader->height(), c.reader->format());
  ++c.newFrames;
  c.lastNew = now;
  c.arrivals.push_back(now);
  while (c.arrivals.size() > 2 && now - c.arrivals.front() > std::chrono::seconds(2)) c.arrivals.pop_front();
  return true;
}

// ---- GL programs ----------------------------------------------------------------------------

// One quad from gl_VertexID (no vertex buffer); row 0 of the frame is its top, so v is flipped.
constexpr const char* kFrameVertex = R"(#version 330 core
out vec2 uv;
void main() {
  vec2 p = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
  uv = vec2(p.x, 1.0 - p.y);
  gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
)";

// Display mapping, the same as fogbeam::toneMapSrgb8 (core/src/render/frame.cpp): x = L·2^EV
// with L in cd/m² (1 cd/m² at EV 0 → 0.5 before the sRGB curve), Reinhard x/(1 + x), sRGB
// transfer. The default framebuffer is not sRGB (GL_FRAMEBUFFER_SRGB stays off), so values
// written here are the display values; RGBA8 sRGB texels already are and pass unchanged.
constexpr const char* kFrameFragment = R"(#version 330 core
uniform sampler2D frame;
uniform int mode;             // 0 as published (display values), 1 tone-map linear RGB, 2 grey = alpha
uniform float exposureScale;  // 2^EV
in vec2 uv;
out vec4 color;
vec3 srgbEncode(vec3 l) {
  return mix(12.92 * l, 1.055 * pow(l, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), l));
}
void main() {
  vec4 t = texture(frame, uv);
  if (mode == 0) {
    color = vec4(t.rgb, 1.0);
  } else if (mode == 1) {
    vec3 x = clamp(t.rgb * exposureScale, 0.0, 1e30);  // +inf from binary16 overflow → white
    color = vec4(srgbEncode(x / (1.0 + x)), 1.0);
  } else {
    color = vec4(vec3(clamp(t.a, 0.0, 1.0)), 1.0);  // transmittance T ∈ [0, 1], shown as data
  }
}
)";

// stb_easy_font's vertices (x, y, z floats and RGBA bytes) in window pixels, y down.
constexpr const char* kTextVertex = R"(#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec4 colorIn;
uniform vec2 viewport;  // framebuffer size, pixels
out vec4 colorV;
void main() {
  colorV = colorIn;
  gl_Position = vec4(position.x / viewport.x * 2.0 - 1.0, 1.0 - position.y / viewport.y * 2.0, 0.0, 1.0);
}
)";
constexpr const char* kTextFragment = R"(#version 330 core
in vec4 colorV;
out vec4 color;
void main() { color = colorV; }
)";

GLuint compile(GLenum type, const char* source, std::string& error) {
  const GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &source, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[1024] = {};
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    error = log;
  }
  return s;
}

/// Links a program; "" in `error` when it worked.
GLuint link(const char* vertex, const char* fragment, std::string& error) {
  const GLuint v = compile(GL_VERTEX_SHADER, vertex, error);
  const GLuint f = compile(GL_FRAGMENT_SHADER, fragment, error);
  const GLuint p = glCreateProgram();
  glAttachShader(p, v);
  glAttachShader(p, f);
  glLinkProgram(p);
  glDeleteShader(v);
  glDeleteShader(f);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok && error.empty()) {
    char log[1024] = {};
    glGetProgramInfoLog(p, sizeof log, nullptr, log);
    error = log;
  }
  return p;
}

/// Text and translucent boxes as stb_easy_font quads, drawn as indexed triangles (core profile
/// has no GL_QUADS).
class TextBatch {
 public:
  struct Vertex {
    float x, y, z;
    std::uint8_t rgba[4];
  };
  static_assert(sizeof(Vertex) == 16, "stb_easy_font's vertex layout");

  void clear() { vertices_.clear(); }
  /// A filled rectangle, window pixels.
  void box(float x0, float y0, float x1, float y1, std::array<std::uint8_t, 4> c) {
    for (const auto& [x, y] : {std::pair{x0, y0}, std::pair{x1, y0}, std::pair{x1, y1}, std::pair{x0, y1}})
      vertices_.push_back({x, y, 0.0f, {c[0], c[1], c[2], c[3]}});
  }
  /// `text` (may hold '\n') with its top-left at (x, y), glyphs scaled by `scale`.
  void text(float x, float y, std::string text, float scale, std::array<std::uint8_t, 4> c) {
    std::vector<Vertex> quads(text.size() * 60 + 64);  // stb: ~270 bytes per character on average
    unsigned char color[4] = {c[0], c[1], c[2], c[3]};
    const int n = stb_easy_font_print(0.0f, 0.0f, text.data(), color, quads.data(),
                                      static_cast<int>(quads.size() * sizeof(Vertex)));
    for (std::size_t k = 0; k < static_cast<std::size_t>(n) * 4; ++k) {
      Vertex v = quads[k];
      v.x = x + v.x * scale;
      v.y = y + v.y * scale;
      vertices_.push_back(v);
    }
  }
  /// Size in pixels of `text` at `scale`.
  static std::pair<float, float> extent(std::string text, float scale) {
    return {static_cast<float>(stb_easy_font_width(text.data())) * scale,
            static_cast<float>(stb_easy_font_height(text.data())) * scale};
  }

  void init() {
    glGenVertexArrays(1, &vao_);
    glGenBuffers(1, &vbo_);
    glGenBuffers(1, &ibo_);
    glBindVertexArray(vao_);
    glBindBuffer(GL_ARRAY_BUFFER, vbo_);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ibo_);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(Vertex), nullptr);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 4, GL_UNSIGNED_BYTE, GL_TRUE, sizeof(Vertex),
                          reinterpret_cast<const void*>(offsetof(Vertex, rgba)));
    glBindVertexArray(0);
  }
  void draw() {
    if (vertices_.empty()) return;
    const std::size_t quads = vertices_.size() / 4;
    while (indices_.size() / 6 < quads) {
      const auto b = static_cast<GLuint>(indices_.size() / 6 * 4);
      for (GLuint i : {0u, 1u, 2u, 0u, 2u, 3u}) indices_.push_back(b + i);
      indexCountUploaded_ = 0;
    }
    glBindVertexArray(vao_);
    glBindBuffer(GL_ARRAY_BUFFER, vbo_);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertices_.size() * sizeof(Vertex)), vertices_.data(),
                 GL_STREAM_DRAW);
    if (indexCountUploaded_ != indices_.size()) {
      glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(indices_.size() * sizeof(GLuint)), indices_.data(),
                   GL_STATIC_DRAW);
      indexCountUploaded_ = indices_.size();
    }
    glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(quads * 6), GL_UNSIGNED_INT, nullptr);
    glBindVertexArray(0);
  }

 private:
  std::vector<Vertex> vertices_;
  std::vector<GLuint> indices_;
  std::size_t indexCountUploaded_ = 0;
  GLuint vao_ = 0, vbo_ = 0, ibo_ = 0;
};

// ---- window state and keys ------------------------------------------------------------------

struct ViewState {
  Layer layer = Layer::Composite;
  double exposureEv = 0.0;   ///< of linear layers: set by hand, or the automatic one
  bool autoExposure = true;  ///< key A; --exposure EV starts with it off
  ExposureAdaptation adaptation;
  bool metered = false;      ///< a frame was metered (the automatic EV is the frames')
  Clock::time_point lastMetered{};
  bool stats = true;
  int focus = -1;  ///< -1: every channel tiled; else the one shown alone
  int channelCount = 1;
  bool quit = false;
  bool dirty = true;  ///< redraw on the next turn
};

void onKey(GLFWwindow* w, int key, int, int action, int) {
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  auto* s = static_cast<ViewState*>(glfwGetWindowUserPointer(w));
  switch (key) {
    case GLFW_KEY_1: case GLFW_KEY_KP_1: s->layer = Layer::Composite; break;
    case GLFW_KEY_2: case GLFW_KEY_KP_2: s->layer = Layer::Airlight; break;
    case GLFW_KEY_3: case GLFW_KEY_KP_3: s->layer = Layer::Transmittance; break;
    case GLFW_KEY_S: s->stats = !s->stats; break;
    case GLFW_KEY_A:
      // On: adapts from the EV shown (no jump), or takes the next frame's EV when none was
      // metered yet. Off: keeps the EV shown.
      s->autoExposure = !s->autoExposure;
      if (s->autoExposure && s->metered) s->adaptation.startFrom(s->exposureEv);
      else s->adaptation.reset();
      break;
    case GLFW_KEY_TAB:  // all tiled → channel 0 alone → channel 1 alone → … → all tiled
      s->focus = s->focus + 1 >= s->channelCount ? -1 : s->focus + 1;
      break;
    case GLFW_KEY_ESCAPE: case GLFW_KEY_Q: s->quit = true; break;
    default: return;
  }
  s->dirty = true;
}

// '+' and '-' as characters, so that they work whatever the keyboard layout ('=' for an
// unshifted '+' on US keyboards).
void onChar(GLFWwindow* w, unsigned int codepoint) {
  auto* s = static_cast<ViewState*>(glfwGetWindowUserPointer(w));
  if (codepoint == '+' || codepoint == '=') s->exposureEv += 0.5;
  else if (codepoint == '-') s->exposureEv -= 0.5;
  else return;
  s->autoExposure = false;  // by hand from the EV shown
  s->dirty = true;
}

void onDirty(GLFWwindow* w) { static_cast<ViewState*>(glfwGetWindowUserPointer(w))->dirty = true; }
void onFramebufferSize(GLFWwindow* w, int, int) { onDirty(w); }

std::string gGlfwError;
extern "C" void onGlfwError(int code, const char* description) {
  gGlfwError = fmt::format("{} (GLFW error {:#x})", description, code);
}

// ---- drawing --------------------------------------------------------------------------------

struct Programs {
  GLuint frame = 0, text = 0, emptyVao = 0;
  GLint mode = -1, exposureScale = -1, viewport = -1;
  TextBatch batch;
};

constexpr std::array<std::uint8_t, 4> kWhite{255, 255, 255, 255}, kAmber{255, 200, 80, 255},
    kShade{0, 0, 0, 170};

/// The stats lines of one channel (what `shown` is, the writer's metadata, the reader's counts).
std::string statsText(const Channel& c, const ViewState& s, const Shown& shown, Clock::time_point now) {
  std::string t = fmt::format("/fogbeam.{}  {}x{}  {}\n", c.name, c.texWidth, c.texHeight, formatName(c.texFormat));
  t += fmt::format("frame {}  {:.1f} fps shown  {}", c.meta.frame, c.fps(now),
              layerName(shown.layer));
  if (shown.decode == Decode::ToneMap) t += fmt::format("  {:+.1f} EV{}", s.exposureEv, s.autoExposure ? " auto" : "");
  else if (shown.decode == Decode::AsIs) t += "  (tone-mapped by the writer)";
  t += fmt::format("\nwriter: total {:.1f} ms  surface {:.1f}  airlight {:.1f}  composite {:.1f}\n", c.meta.total_ms,
              c.meta.surface_ms, c.meta.airlight_ms, c.meta.composite_ms);
  t += fmt::format("latency {:.1f} ms  lights {:#05x} {}\ntraffic {}  reader retries {}  attaches {}", c.meta.latency_ms,
                   c.meta.lights, lightNames(c.meta.lights), c.meta.traffic_count, c.retries(), c.attaches);
  if (*shown.note) t += std::string("\n") + shown.note;
  return t;
}

void drawText(Programs& p, int fbW, int fbH) {
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glUseProgram(p.text);
  glUniform2f(p.viewport, static_cast<float>(fbW), static_cast<float>(fbH));
  p.batch.draw();
  p.batch.clear();
  glDisable(GL_BLEND);
}

void draw(std::vector<Channel>& channels, const ViewState& s, Programs& p, int fbW, int fbH) {
  glDisable(GL_SCISSOR_TEST);
  glViewport(0, 0, fbW, fbH);
  glClearColor(0.05f, 0.05f, 0.05f, 1.0f);
  glClear(GL_COLOR_BUFFER_BIT);
  std::vector<std::size_t> visible;
  for (std::size_t i = 0; i < channels.size(); ++i)
    if (s.focus < 0 || static_cast<std::size_t>(s.focus) == i) visible.push_back(i);
  // Column widths in proportion to the frames' widths (640 for a channel without a frame yet), so
  // that the default window holds every frame at its native size.
  const std::size_t n = visible.size();
  std::vector<double> share(n);
  for (std::size_t k = 0; k < n; ++k) share[k] = channels[visible[k]].texWidth > 0 ? channels[visible[k]].texWidth : 640.0;
  const double shareSum = std::accumulate(share.begin(), share.end(), 0.0);
  p.batch.clear();
  double edge = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    Channel& c = channels[visible[k]];
    const int tx = static_cast<int>(std::lround(edge / shareSum * fbW));
    edge += share[k];
    const int tw = static_cast<int>(std::lround(edge / shareSum * fbW)) - tx;
    Shown shown{s.layer, Decode::AsIs, ""};
    if (c.texFormat != 0) {
      shown = shownFor(c.texFormat, s.layer);
      // Fit the frame in its column, aspect kept, centred (exactly the column at native size).
      const double scale = std::min(static_cast<double>(tw) / c.texWidth, static_cast<double>(fbH) / c.texHeight);
      const int dw = static_cast<int>(std::lround(c.texWidth * scale)), dh = static_cast<int>(std::lround(c.texHeight * scale));
      const int dx = tx + (tw - dw) / 2, dy = (fbH - dh) / 2;
      glViewport(dx, fbH - dy - dh, dw, dh);  // GL's origin is the bottom-left
      glUseProgram(p.frame);
      glUniform1i(p.mode, static_cast<int>(shown.decode));
      glUniform1f(p.exposureScale, static_cast<float>(std::exp2(s.exposureEv)));
      glActiveTexture(GL_TEXTURE0);
      glBindTexture(GL_TEXTURE_2D, c.texture);
      glBindVertexArray(p.emptyVao);
      glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
      glViewport(0, 0, fbW, fbH);
    }
    // Text at twice stb_easy_font's size where the stats fit in the tile at that size.
    const std::string t = s.stats && c.texFormat != 0 ? statsText(c, s, shown, Clock::now()) : std::string();
    const float textScale = 2.0f * TextBatch::extent(t, 1.0f).first + 16.0f <= static_cast<float>(tw) ? 2.0f : 1.0f;
    const float x0 = static_cast<float>(tx) + 4.0f * textScale;
    if (!t.empty()) {
      const auto [w, h] = TextBatch::extent(t, textScale);
      p.batch.box(static_cast<float>(tx), 0.0f, x0 + w + 4.0f * textScale, h + 6.0f * textScale, kShade);
      p.batch.text(x0, 4.0f * textScale, t, textScale, kWhite);
    }
    if (!c.waiting.empty()) {
      // Shown with or without the stats: the tile is stale or empty.
      const std::string m = fmt::format("waiting for /fogbeam.{}\n({})", c.name, c.waiting);
      const float ms = 2.0f * TextBatch::extent(m, 1.0f).first + 16.0f <= static_cast<float>(tw) ? 2.0f : 1.0f;
      const float mx = static_cast<float>(tx) + 4.0f * ms;
      const auto [w, h] = TextBatch::extent(m, ms);
      const float y = static_cast<float>(fbH) / 2.0f - h / 2.0f;
      p.batch.box(static_cast<float>(tx), y - 4.0f * ms, mx + w + 4.0f * ms, y + h + 2.0f * ms, kShade);
      p.batch.text(mx, y, m, ms, kAmber);
    }
    // Each tile's text stays in its tile.
    glEnable(GL_SCISSOR_TEST);
    glScissor(tx, 0, tw, fbH);
    drawText(p, fbW, fbH);
    glDisable(GL_SCISSOR_TEST);
  }
  if (s.stats) {
    const std::string help = "1/2/3 layer  A auto EV  +/- EV  S stats  Tab focus  Q quit";
    const float scale = fbW >= 1280 ? 2.0f : 1.0f;
    const auto [w, h] = TextBatch::extent(help, scale);
    const float y = static_cast<float>(fbH) - h - 4.0f * scale;
    p.batch.box(0.0f, y - 4.0f * scale, w + 8.0f * scale, static_cast<float>(fbH), kShade);
    p.batch.text(4.0f * scale, y, help, scale, kWhite);
    drawText(p, fbW, fbH);
  }
}

/// Reads the back buffer (what the next swap shows) and writes it as an 8-bit RGB PNG.
Status screenshot(int fbW, int fbH, const std::string& path) {
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(fbW) * static_cast<std::size_t>(fbH) * 3);
  glReadBuffer(GL_BACK);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, fbW, fbH, GL_RGB, GL_UNSIGNED_BYTE, rgb.data());
  png::RgbImage img(fbW, fbH);
  for (int y = 0; y < fbH; ++y)  // GL rows start at the bottom, PNG rows at the top
    for (int x = 0; x < fbW; ++x) {
      const std::size_t i = (static_cast<std::size_t>(fbH - 1 - y) * static_cast<std::size_t>(fbW) +
                             static_cast<std::size_t>(x)) * 3;
      img.set(x, y, {rgb[i], rgb[i + 1], rgb[i + 2]});
    }
  return png::writePng(img, path);
}

/// The automatic exposure: every visible channel whose layer is tone-mapped (linear RGB, the
/// binary16 pixels of its newest frame) metered into one histogram, the EV adapted over the
/// wall-clock time since the last metering.
void meterExposure(const std::vector<Channel>& channels, ViewState& s, Clock::time_point now) {
  ExposureMeter meter;
  for (std::size_t i = 0; i < channels.size(); ++i) {
    const Channel& c = channels[i];
    if (c.texFormat == 0 || (s.focus >= 0 && static_cast<std::size_t>(s.focus) != i)) continue;
    if (shownFor(c.texFormat, s.layer).decode != Decode::ToneMap) continue;
    const int w = static_cast<int>(c.texWidth), h = static_cast<int>(c.texHeight);
    if (c.pixels.size() < std::size_t{8} * c.texWidth * c.texHeight) continue;
    const auto* half = reinterpret_cast<const std::uint16_t*>(c.pixels.data());
    const int step = meteringStep(w, h);
    int k = 0;
    for (int y = step / 2; y < h; y += step, ++k)
      for (int x = k % step; x < w; x += step) {
        const std::uint16_t* p = half + 4 * (static_cast<std::size_t>(y) * c.texWidth + static_cast<std::size_t>(x));
        meter.add(luminanceOf(halfToFloat(p[0]), halfToFloat(p[1]), halfToFloat(p[2])));
      }
  }
  if (meter.count() == 0) return;
  const double dt = s.metered ? std::chrono::duration<double>(now - s.lastMetered).count() : 0.0;
  s.exposureEv = s.adaptation.update(meter.ev(), dt);
  s.metered = true;
  s.lastMetered = now;
}

}  // namespace

// ---- the loop -------------------------------------------------------------------------------

int runView(const ViewOptions& o) {
  if ((o.width > 0) != (o.height > 0)) {
    std::fprintf(stderr, "fogbeam view: give both --width and --height, or neither\n");
    return 2;
  }
  std::vector<Channel> channels;
  for (const std::string& name : o.channels) {
    if (name.empty()) continue;
    channels.emplace_back();
    channels.back().name = name;
  }
  if (channels.empty()) {
    std::fprintf(stderr, "fogbeam view: no channel given (--channel NAME)\n");
    return 2;
  }
  ViewState state;
  state.layer = o.layer == "airlight" ? Layer::Airlight : o.layer == "transmittance" ? Layer::Transmittance : Layer::Composite;
  state.autoExposure = !o.exposure.has_value();
  state.exposureEv = o.exposure.value_or(0.0);
  state.stats = !o.noStats;
  state.channelCount = static_cast<int>(channels.size());

  glfwSetErrorCallback(onGlfwError);
  if (!glfwInit()) {
    std::fprintf(stderr, "fogbeam view: no display (set DISPLAY or run under xvfb-run): %s\n", gGlfwError.c_str());
    return 2;
  }
  struct Terminate {
    ~Terminate() { glfwTerminate(); }
  } terminate;
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_SRGB_CAPABLE, GLFW_FALSE);  // the shader writes display values itself
  glfwWindowHint(GLFW_DOUBLEBUFFER, GLFW_TRUE);
  // Until the frames' sizes are known: 640×360 per channel; then the native size, tiled.
  const bool sizeGiven = o.width > 0 && o.height > 0;
  const int n = static_cast<int>(channels.size());
  std::string title = "fogbeam view:";
  for (const Channel& c : channels) title += " " + c.name;
  GLFWwindow* win = glfwCreateWindow(sizeGiven ? o.width : 640 * n, sizeGiven ? o.height : 360, title.c_str(), nullptr,
                                     nullptr);
  if (!win) {
    std::fprintf(stderr, "fogbeam view: cannot open a window with an OpenGL 3.3 core context: %s\n", gGlfwError.c_str());
    return 2;
  }
  struct Destroy {
    GLFWwindow* w;
    ~Destroy() { glfwDestroyWindow(w); }
  } destroy{win};
  glfwMakeContextCurrent(win);
  glfwSwapInterval(1);
  glfwSetWindowUserPointer(win, &state);
  glfwSetKeyCallback(win, onKey);
  glfwSetCharCallback(win, onChar);
  glfwSetFramebufferSizeCallback(win, onFramebufferSize);
  glfwSetWindowRefreshCallback(win, onDirty);

  Programs prog;
  std::string error;
  prog.frame = link(kFrameVertex, kFrameFragment, error);
  if (error.empty()) prog.text = link(kTextVertex, kTextFragment, error);
  if (!error.empty()) {
    std::fprintf(stderr, "fogbeam view: shader: %s\n", error.c_str());
    return 2;
  }
  glUseProgram(prog.frame);
  glUniform1i(glGetUniformLocation(prog.frame, "frame"), 0);
  prog.mode = glGetUniformLocation(prog.frame, "mode");
  prog.exposureScale = glGetUniformLocation(prog.frame, "exposureScale");
  prog.viewport = glGetUniformLocation(prog.text, "viewport");
  glGenVertexArrays(1, &prog.emptyVao);  // core profile draws need a vertex array, even an empty one
  prog.batch.init();

  std::signal(SIGINT, onViewSignal);
  std::signal(SIGTERM, onViewSignal);
  const auto start = Clock::now();
  for (Channel& c : channels) c.lastNew = start;
  bool sized = sizeGiven;
  auto nextRefresh = start;
  int exitCode = 0;
  while (!glfwWindowShouldClose(win) && !state.quit && !gStop.load()) {
    // Wake at least every 5 ms to poll the channels (a latest-word load each when idle).
    glfwWaitEventsTimeout(0.005);
    const auto now = Clock::now();
    bool fresh = false;
    for (Channel& c : channels)
      if (poll(c, now)) fresh = true;
    if (fresh) {
      state.dirty = true;
      if (state.autoExposure) meterExposure(channels, state, now);
    }
    if (!sized && std::all_of(channels.begin(), channels.end(), [](const Channel& c) { return c.texWidth > 0; })) {
      int w = 0, h = 0;
      for (const Channel& c : channels) {
        w += static_cast<int>(c.texWidth);
        h = std::max(h, static_cast<int>(c.texHeight));
      }
      glfwSetWindowSize(win, w, h);
      sized = true;
    }
    if (o.timeout_s > 0.0) {
      for (const Channel& c : channels) {
        if (std::chrono::duration<double>(now - c.lastNew).count() <= o.timeout_s) continue;
        std::fprintf(stderr, "fogbeam view: no new frame from /fogbeam.%s within %.1f s (%s)\n", c.name.c_str(),
                     o.timeout_s, c.waiting.empty() ? "the writer is alive but published nothing" : c.waiting.c_str());
        exitCode = 1;
      }
      if (exitCode != 0) break;
    }
    // Stats (fps) and waiting messages change without new frames: refresh them twice a second.
    if (now >= nextRefresh) {
      nextRefresh = now + std::chrono::milliseconds(500);
      if (state.stats || std::any_of(channels.begin(), channels.end(), [](const Channel& c) { return !c.waiting.empty(); }))
        state.dirty = true;
    }
    if (!state.dirty) continue;
    state.dirty = false;
    int fbW = 0, fbH = 0;
    glfwGetFramebufferSize(win, &fbW, &fbH);
    if (fbW <= 0 || fbH <= 0) continue;  // minimised
    draw(channels, state, prog, fbW, fbH);
    if (!o.screenshot.empty() && sized &&
        std::all_of(channels.begin(), channels.end(), [&o](const Channel& c) { return c.newFrames >= o.afterFrames; })) {
      if (auto st = screenshot(fbW, fbH, o.screenshot); !st) {
        std::fprintf(stderr, "fogbeam view: %s\n", st.error().message.c_str());
        return 1;
      }
      std::printf("fogbeam view: wrote %s (%dx%d), exposure %+.4f EV (%s)\n", o.screenshot.c_str(), fbW, fbH,
                  state.exposureEv, state.autoExposure ? "auto" : "fixed");
      for (const Channel& c : channels)
        std::printf("fogbeam view: /fogbeam.%s: %llu new frames shown, %.1f fps over the last 2 s, %llu reader retries\n",
                    c.name.c_str(), static_cast<unsigned long long>(c.newFrames), c.fps(Clock::now()),
                    static_cast<unsigned long long>(c.retries()));
      return 0;
    }
    glfwSwapBuffers(win);
  }
  for (Channel& c : channels)
    if (c.texture != 0) glDeleteTextures(1, &c.texture);
  return exitCode;
}

}  // namespace fogbeam::cli
