#include <fogbeam/plugin/host_depth.hpp>
#include <fogbeam/ipc/shm_layout.h>

#include <cmath>
#include <cstring>

namespace fogbeam::plugin {

Result<std::unique_ptr<HostDepthInput>> HostDepthInput::attach(const std::string& channel) {
  auto r = ipc::ShmReader::attach(channel);
  if (!r) return r.error();
  if ((*r)->format() != FOGBEAM_FORMAT_DISTANCE_F32)
    return Error{"shm channel '" + channel + "' is not a host depth channel (format " +
                 std::to_string((*r)->format()) + ", expected " + std::to_string(FOGBEAM_FORMAT_DISTANCE_F32) + ")"};
  std::unique_ptr<HostDepthInput> in(new HostDepthInput());
  in->reader_ = std::move(r).value();
  return in;
}

ipc::ReadStatus HostDepthInput::latest(HostView& view, SurfaceBuffers& surface) {
  ipc::FrameMeta m;
  const ipc::ReadStatus s = reader_->latest(m, bytes_);
  if (s != ipc::ReadStatus::Ok) return s;
  const int w = static_cast<int>(reader_->width()), h = static_cast<int>(reader_->height());
  if (!(m.fov_x_deg > 0.0f && m.fov_x_deg < 180.0f)) {
    lastError_ = "host depth: fov_x_deg " + std::to_string(m.fov_x_deg) + " outside (0, 180)";
    return ipc::ReadStatus::WriterGone;
  }
  Camera cam;
  cam.width = w;
  cam.height = h;
  cam.fov_x = radians(static_cast<double>(m.fov_x_deg));
  if (m.fov_y_deg != 0.0f) {
    const double implied = cam.fovY();
    if (std::abs(radians(static_cast<double>(m.fov_y_deg)) - implied) > 1e-3 * implied) {
      lastError_ = "host depth: fov_y_deg " + std::to_string(m.fov_y_deg) + " does not match square pixels (" +
                   std::to_string(implied * 180.0 / kPi) + " deg for " + std::to_string(w) + "x" + std::to_string(h) +
                   "); asymmetric or non-square frusta are not supported yet";
      return ipc::ReadStatus::WriterGone;
    }
  }
  cam.position_m = Vec3(m.position_m[0], m.position_m[1], m.position_m[2]);
  cam.worldFromCamera = worldFromYawPitchRoll(radians(static_cast<double>(m.yaw_deg)),
                                              radians(static_cast<double>(m.pitch_deg)),
                                              radians(static_cast<double>(m.roll_deg)));
  view.camera = cam;
  view.frame = m.frame;
  view.sim_time_s = m.sim_time_s;
  surface.resize(w, h);
  std::fill(surface.rgb.begin(), surface.rgb.end(), 0.0f);
  std::memcpy(surface.distance.data(), bytes_.data(), surface.distance.size() * sizeof(float));
  lastError_.clear();
  return ipc::ReadStatus::Ok;
}

}  // namespace fogbeam::plugin
