// fogbeam — the GL surface pass's frames in flight (readback_ring.hpp).
#include "readback_ring.hpp"

#include "gl_errors.hpp"

#include <chrono>
#include <cstring>

namespace fogbeam::gl {

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// The GPU gets this long to finish a frame before collect() reports it instead of waiting on.
constexpr double kFenceTimeout_ms = 30'000.0;

// Copies a bottom-up RGBA float image (GL rows) into a top-down RGB one.
void flipRgbaToRgb(const float* rgba, std::size_t w, std::size_t h, float* rgb) {
  for (std::size_t j = 0; j < h; ++j) {
    const float* src = rgba + 4 * w * (h - 1 - j);
    float* dst = rgb + 3 * w * j;
    for (std::size_t i = 0; i < w; ++i) {
      dst[3 * i] = src[4 * i];
      dst[3 * i + 1] = src[4 * i + 1];
      dst[3 * i + 2] = src[4 * i + 2];
    }
  }
}

// Maps the first `bytes` of `buffer` for reading (bound to GL_PIXEL_PACK_BUFFER); null on failure.
const float* mapForRead(const Buffer& buffer, std::size_t bytes) {
  glBindBuffer(GL_PIXEL_PACK_BUFFER, buffer.get());
  return static_cast<const float*>(
      glMapBufferRange(GL_PIXEL_PACK_BUFFER, 0, static_cast<GLsizeiptr>(bytes), GL_MAP_READ_BIT));
}

}  // namespace

ReadbackRing::ReadbackRing(bool timerQueries) {
  for (Slot& s : slots_) {
    s.color.buffer = genBuffer();
    s.distance.buffer = genBuffer();
    s.airlight.buffer = genBuffer();
    s.rho.buffer = genBuffer();
    if (timerQueries) {
      s.surfaceTimer = genQuery();
      s.airlightTimer = genQuery();
    }
  }
}

ReadbackRing::Timers ReadbackRing::beginFrame() {
  const Slot& s = slots_[next_];
  return {s.surfaceTimer.get(), s.airlightTimer.get()};
}

void ReadbackRing::readInto(PackBuffer& pb, GLenum attachment, GLenum format, int width, int height, std::size_t bytes) {
  glBindBuffer(GL_PIXEL_PACK_BUFFER, pb.buffer.get());
  if (pb.bytes != bytes) {
    glBufferData(GL_PIXEL_PACK_BUFFER, static_cast<GLsizeiptr>(bytes), nullptr, GL_STREAM_READ);
    pb.bytes = bytes;
  }
  glReadBuffer(attachment);
  glReadPixels(0, 0, width, height, format, GL_FLOAT, nullptr);
}

void ReadbackRing::endFrame(const Reads& reads) {
  const std::size_t si = next_;
  next_ = (next_ + 1) % slots_.size();
  Slot& slot = slots_[si];
  const std::size_t n = static_cast<std::size_t>(reads.width) * static_cast<std::size_t>(reads.height);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  slot.hasAirlight = reads.airlightFbo != 0;
  if (slot.hasAirlight) {
    glBindFramebuffer(GL_READ_FRAMEBUFFER, reads.airlightFbo);
    readInto(slot.airlight, GL_COLOR_ATTACHMENT0, GL_RGBA, reads.width, reads.height, 4 * n * sizeof(float));
  }
  slot.gbuffer = reads.gbuffer;
  slot.empty = reads.gbuffer && reads.empty;
  if (!slot.empty) {
    glBindFramebuffer(GL_READ_FRAMEBUFFER, reads.surfaceFbo);
    readInto(slot.color, GL_COLOR_ATTACHMENT0, GL_RGBA, reads.width, reads.height, 4 * n * sizeof(float));
    readInto(slot.distance, GL_COLOR_ATTACHMENT1, GL_RED, reads.width, reads.height, n * sizeof(float));
    if (slot.gbuffer) readInto(slot.rho, GL_COLOR_ATTACHMENT2, GL_RG, reads.width, reads.height, 2 * n * sizeof(float));
  }
  glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
  slot.width = reads.width;
  slot.height = reads.height;
  slot.triangles = reads.triangles;
  // The fence tells collect() when the copies are done; the flush makes sure it is reached even
  // when nothing else is submitted before collect() waits on it.
  slot.fence = fenceSync();
  glFlush();
  pending_.push_back(si);
}

void ReadbackRing::setSubmitMs(double ms) noexcept {
  if (!pending_.empty()) slots_[pending_.back()].submitMs = ms;
}

Status ReadbackRing::collect(SurfaceBuffers& out, std::vector<float>* airlight, GlSurfaceStats& stats,
                             const Shade& shade) {
  const auto t0 = Clock::now();
  Slot& slot = slots_[pending_.front()];
  pending_.pop_front();
  for (;;) {  // wait in 1 s steps; a GPU that never signals is reported, not waited on forever
    const GLenum r = glClientWaitSync(slot.fence.get(), GL_SYNC_FLUSH_COMMANDS_BIT, 1'000'000'000);
    if (r == GL_ALREADY_SIGNALED || r == GL_CONDITION_SATISFIED) break;
    if (r == GL_WAIT_FAILED) {
      slot.fence.reset();
      return Error{"glClientWaitSync failed: " + glErrorName(glGetError())};
    }
    if (msSince(t0) > kFenceTimeout_ms) return Error{"GL surface pass: the GPU did not finish within 30 s"};
  }
  slot.fence.reset();

  const auto w = static_cast<std::size_t>(slot.width), h = static_cast<std::size_t>(slot.height);
  const std::size_t n = w * h;
  out.width = slot.width;
  out.height = slot.height;
  out.rgb.resize(3 * n);
  out.distance.resize(n);
  if (slot.empty) {
    if (!shade) return Error{"GlSurfacePass: a geometry-buffer frame needs a shader to collect it"};
    shade(SurfaceGBufferView{slot.width, slot.height, nullptr, nullptr, nullptr, true}, out);
  } else if (slot.gbuffer) {
    // The three buffers mapped at once (GL allows several mapped buffers), shaded straight from
    // the mapping: no copy of the 28 bytes a pixel.
    if (!shade) return Error{"GlSurfacePass: a geometry-buffer frame needs a shader to collect it"};
    const float* mapped[3] = {nullptr, nullptr, nullptr};
    const PackBuffer* buffers[3] = {&slot.color, &slot.distance, &slot.rho};
    const std::size_t floats[3] = {4 * n, n, 2 * n};
    GLenum err = GL_NO_ERROR;
    for (int b = 0; b < 3 && err == GL_NO_ERROR; ++b) {
      mapped[b] = mapForRead(buffers[b]->buffer, floats[b] * sizeof(float));
      if (mapped[b] == nullptr) err = glGetError();
    }
    if (err == GL_NO_ERROR) shade(SurfaceGBufferView{slot.width, slot.height, mapped[0], mapped[2], mapped[1], true}, out);
    for (int b = 0; b < 3; ++b)
      if (mapped[b] != nullptr) {
        glBindBuffer(GL_PIXEL_PACK_BUFFER, buffers[b]->buffer.get());
        glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
      }
    if (err != GL_NO_ERROR) return Error{"glMapBufferRange (geometry-buffer PBOs) failed: " + glErrorName(err)};
  } else {
    const float* rgba = mapForRead(slot.color.buffer, 4 * n * sizeof(float));
    if (rgba == nullptr) return Error{"glMapBufferRange (colour PBO) failed: " + glErrorName(glGetError())};
    flipRgbaToRgb(rgba, w, h, out.rgb.data());
    glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
    const float* dist = mapForRead(slot.distance.buffer, n * sizeof(float));
    if (dist == nullptr) return Error{"glMapBufferRange (distance PBO) failed: " + glErrorName(glGetError())};
    for (std::size_t j = 0; j < h; ++j)
      std::memcpy(out.distance.data() + w * j, dist + w * (h - 1 - j), w * sizeof(float));
    glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
  }
  if (airlight) {
    if (!slot.hasAirlight) return Error{"GlSurfacePass: the frame was submitted without the GPU airlight stage"};
    airlight->resize(3 * n);
    const float* air = mapForRead(slot.airlight.buffer, 4 * n * sizeof(float));
    if (air == nullptr) return Error{"glMapBufferRange (airlight PBO) failed: " + glErrorName(glGetError())};
    flipRgbaToRgb(air, w, h, airlight->data());
    glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
  }
  glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);

  stats.readback_ms = msSince(t0);
  stats.submit_ms = slot.submitMs;
  stats.triangles = slot.triangles;
  if (slot.surfaceTimer) {
    GLuint64 ns = 0;
    glGetQueryObjectui64v(slot.surfaceTimer.get(), GL_QUERY_RESULT, &ns);
    stats.surface_ms = static_cast<double>(ns) * 1e-6;
    stats.airlight_ms = 0.0;
    if (slot.hasAirlight) {
      glGetQueryObjectui64v(slot.airlightTimer.get(), GL_QUERY_RESULT, &ns);
      stats.airlight_ms = static_cast<double>(ns) * 1e-6;
    }
  }
  if (std::string e = glErrors("surface pass readback"); !e.empty()) return Error{e};
  return Ok{};
}

}  // namespace fogbeam::gl
