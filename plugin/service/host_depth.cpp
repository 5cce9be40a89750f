// fogbeam — host depth input (host_depth.hpp).
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/plugin/host_depth.hpp>
#include <fogbeam/render/pixel_pack.hpp>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace fogbeam::plugin {

namespace {

std::string deg(float v) { return std::to_string(static_cast<double>(v)); }

/// The camera a published view describes (position, orientation, intrinsics), or why not.
Result<Camera> cameraOf(const ipc::FrameMeta& m, int w, int h) {
  Camera cam;
  const auto& f = m.frustum_deg;
  if (f[0] != 0.0f || f[1] != 0.0f || f[2] != 0.0f || f[3] != 0.0f) {
    auto c = Camera::fromFrustum(FrustumAngles{radians(static_cast<double>(f[0])), radians(static_cast<double>(f[1])),
                                               radians(static_cast<double>(f[2])), radians(static_cast<double>(f[3]))},
                                 w, h);
    if (!c) return Error{"host depth: " + c.error().message};
    cam = *c;
  } else {
    if (!(m.fov_x_deg > 0.0f && m.fov_x_deg < 180.0f))
      return Error{"host depth: fov_x_deg " + deg(m.fov_x_deg) + " outside (0, 180) and no frustum_deg"};
    cam.width = w;
    cam.height = h;
    cam.fov_x = radians(static_cast<double>(m.fov_x_deg));
    if (m.fov_y_deg != 0.0f) {
      const double implied = cam.fovY();
      if (std::abs(radians(static_cast<double>(m.fov_y_deg)) - implied) > 1e-3 * implied)
        return Error{"host depth: fov_y_deg " + deg(m.fov_y_deg) + " does not match square pixels (" +
                     std::to_string(implied * 180.0 / kPi) + " deg for " + std::to_string(w) + "x" +
                     std::to_string(h) + "); an off-axis view sets frustum_deg instead"};
    }
  }
  cam.position_m = Vec3(m.position_m[0], m.position_m[1], m.position_m[2]);
  cam.worldFromCamera = worldFromYawPitchRoll(radians(static_cast<double>(m.yaw_deg)),
                                              radians(static_cast<double>(m.pitch_deg)),
                                              radians(static_cast<double>(m.roll_deg)));
  return cam;
}

}  // namespace

Result<std::unique_ptr<HostDepthInput>> HostDepthInput::attach(const std::string& channel, double exposureEv) {
  auto r = ipc::ShmReader::attach(channel);
  if (!r) return r.error();
  const std::uint32_t f = (*r)->format();
  const bool colour = f == FOGBEAM_FORMAT_RGBA16F_LINEAR || f == FOGBEAM_FORMAT_RGBA8_SRGB;
  if (!(f == FOGBEAM_FORMAT_DISTANCE_F32 || (colour && (*r)->hasDistance())))
    return Error{"shm channel '" + channel + "' is not a host depth channel (format " + std::to_string(f) +
                 ((*r)->hasDistance() ? "" : " without a distance plane") + ", expected " +
                 std::to_string(FOGBEAM_FORMAT_DISTANCE_F32) + ", or " + std::to_string(FOGBEAM_FORMAT_RGBA16F_LINEAR) +
                 " or " + std::to_string(FOGBEAM_FORMAT_RGBA8_SRGB) + " with a distance plane)"};
  std::unique_ptr<HostDepthInput> in(new HostDepthInput());
  in->reader_ = std::move(r).value();
  // The inverse of packRgba8Srgb's curve: code → display value y (the sRGB EOTF) → x = y/(1 − y)
  // → L = x / 2^EV. y is capped at 0.999 (code 255 would be infinite luminance).
  const double gain = std::exp2(-exposureEv);
  for (std::size_t c = 0; c < in->srgbToLinear_.size(); ++c) {
    const double s = static_cast<double>(c) / 255.0;
    const double y = std::min(0.999, s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4));
    in->srgbToLinear_[c] = static_cast<float>(y / (1.0 - y) * gain);
  }
  return in;
}

HostDepthStatus HostDepthInput::latest(HostView& view, SurfaceBuffers& surface) {
  ipc::FrameMeta m;
  // No heartbeat timeout: a host publishes depth frames when it renders, and one that pauses
  // (a stopped simulation, a lock-step host waiting) is stale, not gone. Gone is a closed
  // channel, a dead writer pid or a replaced segment (ShmReader::latest checks those).
  const bool colour = hasColour();
  switch (reader_->latest(m, bytes_, colour ? &distance_ : nullptr, std::numeric_limits<double>::infinity())) {
    case ipc::ReadStatus::Ok: break;
    case ipc::ReadStatus::NoFrame: return HostDepthStatus::NoFrame;
    case ipc::ReadStatus::Busy: return HostDepthStatus::Busy;
    case ipc::ReadStatus::WriterGone: return HostDepthStatus::WriterGone;
  }
  const int w = static_cast<int>(reader_->width()), h = static_cast<int>(reader_->height());
  auto cam = cameraOf(m, w, h);
  if (!cam) {
    lastError_ = "frame " + std::to_string(m.frame) + ": " + cam.error().message;
    return HostDepthStatus::Refused;
  }
  // The evaluator takes distances as they come: a NaN or a negative one would poison the
  // subsampling's interpolation. One pass over the buffer (≈ 0.3 ms at 1280×720).
  const auto* d = colour ? distance_.data() : reinterpret_cast<const float*>(bytes_.data());
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  for (std::size_t i = 0; i < n; ++i) {
    if (!(d[i] >= 0.0f)) {
      lastError_ = "frame " + std::to_string(m.frame) + ": host depth: pixel (" + std::to_string(i % static_cast<std::size_t>(w)) + ", " +
                   std::to_string(i / static_cast<std::size_t>(w)) + ") distance " + std::to_string(static_cast<double>(d[i])) +
                   ": expected metres ≥ 0 (+inf for sky)";
      return HostDepthStatus::Refused;
    }
  }
  view.camera = *cam;
  view.frame = m.frame;
  view.sim_time_s = m.sim_time_s;
  view.publish_ns = m.publish_ns;
  view.yaw_deg = m.yaw_deg;
  view.pitch_deg = m.pitch_deg;
  view.roll_deg = m.roll_deg;
  const FrustumAngles fa = view.camera.frustum();
  view.fov_x_deg = static_cast<float>((fa.left + fa.right) * 180.0 / kPi);
  view.fov_y_deg = static_cast<float>((fa.up + fa.down) * 180.0 / kPi);
  view.frustum_deg = m.frustum_deg;
  surface.resize(w, h);
  view.colour = colour;
  if (reader_->format() == FOGBEAM_FORMAT_RGBA16F_LINEAR) {
    const auto* px = reinterpret_cast<const std::uint16_t*>(bytes_.data());
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t c = 0; c < 3; ++c) {
        const float v = halfToFloat(px[4 * i + c]);
        if (!(v >= 0.0f && std::isfinite(v))) {
          lastError_ = "frame " + std::to_string(m.frame) + ": host colour: pixel (" +
                       std::to_string(i % static_cast<std::size_t>(w)) + ", " + std::to_string(i / static_cast<std::size_t>(w)) +
                       ") channel " + std::to_string(c) + " = " + std::to_string(static_cast<double>(v)) +
                       ": expected a finite luminance ≥ 0 cd/m²";
          return HostDepthStatus::Refused;
        }
        surface.rgb[3 * i + c] = v;
      }
    }
  } else if (reader_->format() == FOGBEAM_FORMAT_RGBA8_SRGB) {
    const auto* px = reinterpret_cast<const std::uint8_t*>(bytes_.data());
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t c = 0; c < 3; ++c) surface.rgb[3 * i + c] = srgbToLinear_[px[4 * i + c]];
  } else {
    std::fill(surface.rgb.begin(), surface.rgb.end(), 0.0f);
  }
  std::memcpy(surface.distance.data(), d, n * sizeof(float));
  lastError_.clear();
  return HostDepthStatus::Ok;
}

}  // namespace fogbeam::plugin

// ---- HostDepthLink ------------------------------------------------------------------------

namespace fogbeam::plugin {

namespace {
/// How often a missing host channel is looked for: a host that starts after the service is
/// attached within a quarter of a second, and a missing one costs 4 failed shm_open per second.
constexpr std::chrono::milliseconds kAttachRetry{250};
}  // namespace

HostDepthLink::HostDepthLink(std::string channel, int width, int height, std::string output, bool needsColour,
                             double exposureEv)
    : channel_(std::move(channel)),
      output_(std::move(output)),
      width_(width),
      height_(height),
      needsColour_(needsColour),
      exposureEv_(exposureEv) {}

void HostDepthLink::drop(const char* why) {
  spdlog::warn("serve: channel {}: host depth {} {}: overlays go on with host frame {}; attaching again when it is back",
               output_, channel_, why, counts_.last_frame);
  in_.reset();
  counts_.connected = false;
  ++counts_.lost;
}

void HostDepthLink::tryAttach(Clock::time_point now) {
  if (in_ || now < nextAttach_) return;
  nextAttach_ = now + kAttachRetry;
  auto in = HostDepthInput::attach(channel_, exposureEv_);
  if (!in) {
    if (!waitingLogged_) {
      spdlog::info("serve: channel {}: waiting for host depth channel {} ({})", output_, channel_, in.error().message);
      waitingLogged_ = true;
    }
    return;
  }
  const bool wrongSize = static_cast<int>((*in)->width()) != width_ || static_cast<int>((*in)->height()) != height_;
  if (wrongSize || (needsColour_ && !(*in)->hasColour())) {
    // Refused once per host generation: the same writer would be refused again every 250 ms.
    if ((*in)->generation() != sizeRefusedGeneration_) {
      sizeRefusedGeneration_ = (*in)->generation();
      ++counts_.refused;
      if (wrongSize)
        spdlog::error("serve: channel {}: host depth channel {} is {}x{}, the channel {}x{}: not used (make [[channel]] "
                      "width and height the host's)",
                      output_, channel_, (*in)->width(), (*in)->height(), width_, height_);
      else
        spdlog::error("serve: channel {}: host depth channel {} has no colour, and the channel composites: not used "
                      "(publish with fogbeam_depth_create_colour, or make the channel rgba16f-overlay)",
                      output_, channel_);
    }
    return;
  }
  in_ = std::move(in).value();
  waitingLogged_ = false;
  counts_.connected = true;
  ++counts_.attached;
  renderedTag_ = 0;
  spdlog::info("serve: channel {}: host depth channel {} attached ({}x{})", output_, channel_, width_, height_);
}

bool HostDepthLink::newFrameReady(Clock::time_point now) {
  tryAttach(now);
  if (!in_) return false;
  const std::uint64_t tag = in_->latestTag();
  return tag != 0 && tag != renderedTag_;
}

bool HostDepthLink::poll(Clock::time_point now) {
  tryAttach(now);
  bool fresh = false;
  if (in_) {
    const std::uint64_t tag = in_->latestTag();
    if (tag != 0 && tag != renderedTag_) {
      // Read into scratch buffers: a refused or torn read leaves the view in use untouched.
      switch (in_->latest(scratchView_, scratch_)) {
        case HostDepthStatus::Ok:
          std::swap(view_, scratchView_);
          std::swap(surface_, scratch_);
          renderedTag_ = tag;
          fresh = view_.frame != counts_.last_frame;
          counts_.last_frame = view_.frame;
          break;
        case HostDepthStatus::NoFrame:
        case HostDepthStatus::Busy: break;  // the next poll tries again
        case HostDepthStatus::WriterGone: drop("is gone (closed, dead or restarted)"); break;
        case HostDepthStatus::Refused:
          renderedTag_ = tag;  // the same frame is not read again
          ++counts_.refused;
          if (now - lastRefusedLog_ >= std::chrono::seconds(1)) {
            spdlog::warn("serve: channel {}: host depth {}: {} (refused: {} so far)", output_, channel_,
                         in_->lastError(), counts_.refused);
            lastRefusedLog_ = now;
          }
          break;
      }
    } else if (now - lastNew_ > std::chrono::duration<double>(kStaleS) && now >= nextLiveCheck_) {
      // The tag did not move for a while: is the writer still there? latest() checks its
      // state, heartbeat and pid (and copies a frame: hence at most every 250 ms).
      nextLiveCheck_ = now + kAttachRetry;
      HostDepthStatus st = in_->latest(scratchView_, scratch_);
      if (st == HostDepthStatus::WriterGone) drop("is gone (closed, dead or restarted)");
    }
  }
  if (fresh) {
    ++counts_.frames;
    lastNew_ = now;
    if (counts_.stale) {
      spdlog::info("serve: channel {}: host depth {} publishing again (frame {})", output_, channel_, counts_.last_frame);
      counts_.stale = false;
    }
  } else if (hasView()) {
    ++counts_.repeated;
    if (!counts_.stale && now - lastNew_ > std::chrono::duration<double>(kStaleS)) {
      spdlog::warn("serve: channel {}: no new host depth frame on {} for {:.1f} s: overlays go on with host frame {}",
                   output_, channel_, kStaleS, counts_.last_frame);
      counts_.stale = true;
    }
  }
  return hasView();
}

}  // namespace fogbeam::plugin
