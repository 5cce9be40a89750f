// fogbeam — the C host SDK (fogbeam/fogbeam_host.h) over ShmReader.
#include <fogbeam/fogbeam_host.h>
#include <fogbeam/ipc/shm_channel.hpp>

#include <cstring>
#include <string>
#include <vector>

struct fogbeam_reader {
  std::unique_ptr<fogbeam::ipc::ShmReader> reader;
  std::vector<std::byte> pixels;
};

struct fogbeam_depth_writer {
  std::unique_ptr<fogbeam::ipc::ShmWriter> writer;
  std::size_t pixels = 0;
};

namespace {
thread_local std::string lastError;
}

extern "C" {

int fogbeam_attach(const char* name, fogbeam_reader** out) {
  if (!name || !out) {
    lastError = "fogbeam_attach: null argument";
    return FOGBEAM_ERROR;
  }
  auto r = fogbeam::ipc::ShmReader::attach(name);
  if (!r) {
    lastError = r.error().message;
    return FOGBEAM_ERROR;
  }
  *out = new fogbeam_reader{std::move(r).value(), {}};
  return FOGBEAM_OK;
}

size_t fogbeam_frame_bytes(const fogbeam_reader* r) {
  if (!r) return 0;
  return std::size_t{r->reader->width()} * r->reader->height() * fogbeam::ipc::bytesPerPixel(r->reader->format());
}

int fogbeam_latest(fogbeam_reader* r, void* dst, size_t dst_size, fogbeam_frame_info* info) {
  if (!r || !dst || !info) {
    lastError = "fogbeam_latest: null argument";
    return FOGBEAM_ERROR;
  }
  if (dst_size < fogbeam_frame_bytes(r)) {
    lastError = "fogbeam_latest: buffer of " + std::to_string(dst_size) + " bytes, a frame needs " +
                std::to_string(fogbeam_frame_bytes(r));
    return FOGBEAM_ERROR;
  }
  fogbeam::ipc::FrameMeta m;
  switch (r->reader->latest(m, r->pixels)) {
    case fogbeam::ipc::ReadStatus::Ok: break;
    case fogbeam::ipc::ReadStatus::NoFrame: return FOGBEAM_NO_FRAME;
    case fogbeam::ipc::ReadStatus::Busy: return FOGBEAM_BUSY;
    case fogbeam::ipc::ReadStatus::WriterGone: return FOGBEAM_WRITER_GONE;
  }
  std::memcpy(dst, r->pixels.data(), r->pixels.size());
  info->frame = m.frame;
  info->sim_time_s = m.sim_time_s;
  for (int k = 0; k < 3; ++k) info->position_m[k] = m.position_m[static_cast<std::size_t>(k)];
  info->yaw_deg = m.yaw_deg;
  info->pitch_deg = m.pitch_deg;
  info->roll_deg = m.roll_deg;
  info->lights = m.lights;
  info->ego_sequence = m.ego_sequence;
  info->lamp_sequence = m.lamp_sequence;
  info->environment_sequence = m.environment_sequence;
  info->traffic_count = m.traffic_count;
  info->surface_ms = m.surface_ms;
  info->airlight_ms = m.airlight_ms;
  info->composite_ms = m.composite_ms;
  info->total_ms = m.total_ms;
  info->latency_ms = m.latency_ms;
  info->frame_request = m.frame_request;
  info->publish_ns = m.publish_ns;
  info->width = r->reader->width();
  info->height = r->reader->height();
  info->format = r->reader->format();
  info->fov_x_deg = m.fov_x_deg;
  info->fov_y_deg = m.fov_y_deg;
  for (std::size_t k = 0; k < 4; ++k) info->frustum_deg[k] = m.frustum_deg[k];
  info->host_frame = m.host_frame;
  return FOGBEAM_OK;
}

void fogbeam_detach(fogbeam_reader* r) { delete r; }

int fogbeam_depth_create(const char* name, uint32_t width, uint32_t height, fogbeam_depth_writer** out) {
  if (!name || !out) {
    lastError = "fogbeam_depth_create: null argument";
    return FOGBEAM_ERROR;
  }
  fogbeam::ipc::ShmChannelOptions o;
  o.channel = name;
  o.width = width;
  o.height = height;
  o.format = FOGBEAM_FORMAT_DISTANCE_F32;
  auto w = fogbeam::ipc::ShmWriter::create(o);
  if (!w) {
    lastError = w.error().message;
    return FOGBEAM_ERROR;
  }
  *out = new fogbeam_depth_writer{std::move(w).value(), std::size_t{width} * height};
  return FOGBEAM_OK;
}

int fogbeam_depth_publish(fogbeam_depth_writer* w, const float* distance_m, const fogbeam_camera* camera) {
  if (!w || !distance_m || !camera) {
    lastError = "fogbeam_depth_publish: null argument";
    return FOGBEAM_ERROR;
  }
  if (camera->frame == 0) {
    // The header's `latest` word is (frame << 8) | slot and 0 means "nothing yet" (docs/shm.md).
    lastError = "fogbeam_depth_publish: frame 0: host frame numbers start at 1";
    return FOGBEAM_ERROR;
  }
  fogbeam::ipc::FrameMeta m;
  m.frame = camera->frame;
  m.sim_time_s = camera->sim_time_s;
  for (std::size_t k = 0; k < 3; ++k) m.position_m[k] = camera->position_m[k];
  m.yaw_deg = camera->yaw_deg;
  m.pitch_deg = camera->pitch_deg;
  m.roll_deg = camera->roll_deg;
  m.fov_x_deg = camera->fov_x_deg;
  m.fov_y_deg = camera->fov_y_deg;
  for (std::size_t k = 0; k < 4; ++k) m.frustum_deg[k] = camera->frustum_deg[k];
  w->writer->publish(m, std::as_bytes(std::span<const float>(distance_m, w->pixels)));
  return FOGBEAM_OK;
}

void fogbeam_depth_destroy(fogbeam_depth_writer* w) { delete w; }

const char* fogbeam_last_error(void) { return lastError.c_str(); }

}  // extern "C"
