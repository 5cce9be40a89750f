// fogbeam — the GL surface pass's frames in flight (docs/surface_pass.md, "Readback").
//
// Two slots, each with pixel-pack buffers for the frame's colour (RGBA32F), distance (R32F) and,
// when the GPU airlight stage ran, airlight (RGBA32F) attachments, GL_TIME_ELAPSED queries for
// the surface and airlight draws, and a fence. endFrame() issues glReadPixels into the slot's
// buffers, which returns at once, fences them and queues the slot; collect() waits on the
// oldest slot's fence, maps its buffers and copies them into SurfaceBuffers (GL rows bottom-up →
// row 0 at the top, RGBA → RGB). A caller that submits frame N+1 before collecting frame N never
// waits for the frame it has just submitted.
//
// Private to fogbeam_gl. Thread-safety: that of the owning GL context (one thread at a time).
#pragma once

#include "gl_object.hpp"

#include <fogbeam/gl/surface_pass.hpp>
#include <fogbeam/render/surface.hpp>
#include <fogbeam/util/result.hpp>

#include <fogbeam/render/surface_shading.hpp>

#include <array>
#include <cstddef>
#include <deque>
#include <functional>
#include <vector>

namespace fogbeam::gl {

class ReadbackRing {
 public:
  /// Creates the slots' buffers and, with `timerQueries` (GL 3.3 or ARB_timer_query), their
  /// timer queries. A GL context must be current; the objects belong to it.
  explicit ReadbackRing(bool timerQueries);

  [[nodiscard]] bool empty() const noexcept { return pending_.empty(); }
  /// Both slots hold frames not yet collected: collect() one before the next beginFrame().
  [[nodiscard]] bool full() const noexcept { return pending_.size() >= slots_.size(); }

  /// The timer queries of the frame being recorded (0: no timer queries), for the draws to
  /// bracket with glBeginQuery/glEndQuery(GL_TIME_ELAPSED).
  struct Timers {
    GLuint surface = 0;
    GLuint airlight = 0;
  };
  /// Starts recording a frame into the next slot. Precondition: !full().
  [[nodiscard]] Timers beginFrame();

  /// What endFrame() reads: the framebuffers with the frame's attachments, and its figures.
  struct Reads {
    GLuint surfaceFbo = 0;   ///< colour attachment 0 (RGBA32F), distance attachment 1 (R32F)
    bool gbuffer = false;    ///< attachment 0 holds (n, ρ red) and attachment 2 (RG32F) ρ green, blue
    /// With gbuffer: nothing was drawn (no mesh, no body or planes for GL to draw): nothing is
    /// read back, and collect() hands `shade` a view without buffers (planes only, cast on the CPU).
    bool empty = false;
    GLuint airlightFbo = 0;  ///< airlight attachment 0 (RGBA32F), or 0: the stage did not run
    int width = 0, height = 0;
    std::size_t triangles = 0;  ///< glTF triangles drawn (reported by collect())
  };
  /// Reads the frame's attachments into the slot's pixel-pack buffers (asynchronously), fences
  /// them and queues the slot. Leaves GL_PIXEL_PACK_BUFFER unbound.
  void endFrame(const Reads& reads);
  /// The CPU time the latest queued frame took to submit [ms] (reported by collect()).
  void setSubmitMs(double ms) noexcept;

  /// Lights a geometry buffer into `out` (SurfaceShader::shade with the frame's prepared lamps).
  using Shade = std::function<void(const SurfaceGBufferView&, SurfaceBuffers&)>;
  /// Waits for the oldest queued frame (at most 30 s), copies its colour and distance into
  /// `out` (a geometry-buffer frame: hands the mapped buffers to `shade`, which fills `out`)
  /// and, when `airlight` is given, its airlight (3 floats per pixel, cd/m²; an error when
  /// the frame was recorded without it); fills the readback, submit, triangle and timer figures
  /// of `stats`. Precondition: !empty().
  [[nodiscard]] Status collect(SurfaceBuffers& out, std::vector<float>* airlight, GlSurfaceStats& stats,
                               const Shade& shade = {});

 private:
  // A pixel-pack buffer and the bytes it holds (storage kept while the size stays the same).
  struct PackBuffer {
    Buffer buffer;
    std::size_t bytes = 0;
  };
  struct Slot {
    PackBuffer color, distance, airlight, rho;
    Query surfaceTimer, airlightTimer;
    Sync fence;
    bool hasAirlight = false;
    bool gbuffer = false, empty = false;
    int width = 0, height = 0;
    double submitMs = 0.0;
    std::size_t triangles = 0;
  };
  static void readInto(PackBuffer& pb, GLenum attachment, GLenum format, int width, int height, std::size_t bytes);

  std::array<Slot, 2> slots_;
  std::deque<std::size_t> pending_;  // slot indices in submission order
  std::size_t next_ = 0;
};

}  // namespace fogbeam::gl
