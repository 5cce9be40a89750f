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
  std::uint32_t colourFormat = 0;  ///< 0: distances only (format 4); else the pixels' format
};

namespace {
thread_local std::string lastError;
}

namespace {

int createDepthWriter(const char* fn, const char* name, uint32_t width, uint32_t height, uint32_t colourFormat,
                      fogbeam_depth_writer** out) {
  if (!name || !out) {
    lastError = std::string(fn) + ": null argument";
    return FOGBEAM_ERROR;
  }
  fogbeam::ipc::ShmChannelOptions o;
  o.channel = name;
  o.width = width;
  o.height = height;
  if (colourFormat == 0) {
    o.format = FOGBEAM_FORMAT_DISTANCE_F32;
  } else if (colourFormat == FOGBEAM_FORMAT_RGBA16F_LINEAR || colourFormat == FOGBEAM_FORMAT_RGBA8_SRGB) {
    o.format = colourFormat;
    o.distance = true;  // the distances in the distance plane, the colour as the pixels
  } else {
    lastError = std::string(fn) + ": colour format " + std::to_string(colourFormat) +
                ": expected FOGBEAM_FORMAT_RGBA16F_LINEAR (2) or FOGBEAM_FORMAT_RGBA8_SRGB (1)";
    return FOGBEAM_ERROR;
  }
  auto w = fogbeam::ipc::ShmWriter::create(o);
  if (!w) {
    lastError = w.error().message;
    return FOGBEAM_ERROR;
  }
  *out = new fogbeam_depth_writer{std::move(w).value(), std::size_t{width} * height, colourFormat};
  return FOGBEAM_OK;
}

fogbeam::ipc::FrameMeta cameraMeta(const fogbeam_camera* camera) {
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
  return m;
}

int checkPublish(const char* fn, fogbeam_depth_writer* w, const float* distance_m, const fogbeam_camera* camera) {
  if (!w || !distance_m || !camera) {
    lastError = std::string(fn) + ": null argument";
    return FOGBEAM_ERROR;
  }
  if (camera->frame == 0) {
    // The header's `latest` word is (frame << 8) | slot and 0 means "nothing yet" (docs/shm.md).
    lastError = std::string(fn) + ": frame 0: host frame numbers start at 1";
    return FOGBEAM_ERROR;
  }
  return FOGBEAM_OK;
}

}  // namespace

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
  return createDepthWriter("fogbeam_depth_create", name, width, height, 0, out);
}

int fogbeam_depth_create_colour(const char* name, uint32_t width, uint32_t height, uint32_t colour_format,
                                fogbeam_depth_writer** out) {
  return createDepthWriter("fogbeam_depth_create_colour", name, width, height, colour_format, out);
}

int fogbeam_depth_publish(fogbeam_depth_writer* w, const float* distance_m, const fogbeam_camera* camera) {
  if (checkPublish("fogbeam_depth_publish", w, distance_m, camera) != FOGBEAM_OK) return FOGBEAM_ERROR;
  if (w->colourFormat != 0) {
    lastError = "fogbeam_depth_publish: a colour channel: use fogbeam_depth_publish_colour";
    return FOGBEAM_ERROR;
  }
  w->writer->publish(cameraMeta(camera), std::as_bytes(std::span<const float>(distance_m, w->pixels)));
  return FOGBEAM_OK;
}

int fogbeam_depth_publish_colour(fogbeam_depth_writer* w, const float* distance_m, const void* colour,
                                 const fogbeam_camera* camera) {
  if (checkPublish("fogbeam_depth_publish_colour", w, distance_m, camera) != FOGBEAM_OK) return FOGBEAM_ERROR;
  if (!colour) {
    lastError = "fogbeam_depth_publish_colour: null argument";
    return FOGBEAM_ERROR;
  }
  if (w->colourFormat == 0) {
    lastError = "fogbeam_depth_publish_colour: a depth-only channel (fogbeam_depth_create): use fogbeam_depth_publish";
    return FOGBEAM_ERROR;
  }
  const std::size_t bytes = w->pixels * fogbeam::ipc::bytesPerPixel(w->colourFormat);
  w->writer->publish(cameraMeta(camera), std::span<const std::byte>(static_cast<const std::byte*>(colour), bytes),
                     std::span<const float>(distance_m, w->pixels));
  return FOGBEAM_OK;
}

void fogbeam_depth_destroy(fogbeam_depth_writer* w) { delete w; }

const char* fogbeam_last_error(void) { return lastError.c_str(); }

}  // extern "C"
