/* fogbeam host SDK: read fogbeam's frames from shared memory in any image generator.
 * Plain C (C99), no C++ in the interface; link with libfogbeam_host (fogbeam_ipc).
 *
 * Usage:
 *   fogbeam_reader* r;
 *   if (fogbeam_attach("main", &r) != FOGBEAM_OK) { ... fogbeam_last_error() ... }
 *   fogbeam_frame_info info;
 *   size_t size = fogbeam_frame_bytes(r);   // width · height · bytes per pixel
 *   void* pixels = malloc(size);
 *   int rc = fogbeam_latest(r, pixels, size, &info);   // FOGBEAM_OK: a whole, newest frame
 *   ...
 *   fogbeam_detach(r);
 *
 * Layout of the pixels: row 0 at the top, `info.format` one of FOGBEAM_FORMAT_* (shm_layout.h):
 * RGBA8 sRGB composite, RGBA16F linear composite (cd/m²), or RGBA16F overlay (RGB = in-scattered
 * luminance in cd/m², A = transmittance: display = host·A + RGB).
 * Thread-safety: one fogbeam_reader per thread; any number of readers per channel.
 */
#ifndef FOGBEAM_HOST_H
#define FOGBEAM_HOST_H

#include <stddef.h>
#include <stdint.h>

#include <fogbeam/ipc/shm_layout.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fogbeam_reader fogbeam_reader;

enum {
  FOGBEAM_OK = 0,
  FOGBEAM_NO_FRAME = 1,     /* nothing published yet */
  FOGBEAM_BUSY = 2,         /* every attempt overlapped a write: call again */
  FOGBEAM_WRITER_GONE = 3,  /* closed, dead or restarted writer: detach and attach again */
  FOGBEAM_ERROR = -1        /* see fogbeam_last_error() */
};

typedef struct fogbeam_frame_info {
  uint64_t frame;            /* frame number, from 1 */
  double sim_time_s;         /* simulation time of the state rendered */
  double position_m[3];      /* eye position used (world, m) */
  float yaw_deg, pitch_deg, roll_deg;
  uint32_t lights;           /* ego light bits (docs/protocol.md) */
  uint32_t ego_sequence, lamp_sequence, environment_sequence, traffic_count;
  double surface_ms, airlight_ms, composite_ms, total_ms, latency_ms;
  uint64_t frame_request;    /* lock-step request answered, 0 = free-running */
  uint64_t publish_ns;       /* CLOCK_MONOTONIC at publish */
  uint32_t width, height, format;
  float fov_x_deg, fov_y_deg;  /* the view's whole horizontal and vertical extent (deg) */
  float frustum_deg[4];        /* off-axis view: left, right, up, down half-angles (deg); all 0 = centred */
  uint64_t host_frame;         /* the host depth frame (fogbeam_camera.frame) this overlay is for; 0 = none */
} fogbeam_frame_info;

/* ---- Host depth input: the host publishes its own distance buffer and camera, which fogbeam
 * uses instead of its surface pass (overlay mode on top of the host's rendering). ---- */
typedef struct fogbeam_depth_writer fogbeam_depth_writer;

typedef struct fogbeam_camera {
  uint64_t frame;          /* the host's frame number, from 1 (0 is refused: 0 means "no frame yet") */
  double sim_time_s;       /* simulation time of this view */
  double position_m[3];    /* eye (world, docs/physics.md axes: x forward, y left, z up) */
  float yaw_deg, pitch_deg, roll_deg;  /* positive pitch = nose down */
  float fov_x_deg;         /* horizontal field of view of a centred pinhole (ignored when frustum_deg is set) */
  float fov_y_deg;         /* 0 = from width/height (square pixels) */
  /* Off-axis (multi-channel cabs): left, right, up, down half-angles from the view axis in deg,
   * positive outwards, each in (-89, 89), left + right > 0, up + down > 0, square pixels
   * (height = width (tan up + tan down) / (tan left + tan right) within half a pixel). All 0 = the
   * centred pinhole of fov_x_deg. */
  float frustum_deg[4];
} fogbeam_camera;

/* Creates channel `name` (mode 0600) for width × height distances. FOGBEAM_OK or FOGBEAM_ERROR. */
int fogbeam_depth_create(const char* name, uint32_t width, uint32_t height, fogbeam_depth_writer** out);
/* Publishes one view: width·height floats, the distance along each pixel's ray in metres
 * (+inf for sky), row 0 at the top. Never waits for fogbeam. FOGBEAM_ERROR for frame 0. fogbeam
 * answers with an overlay whose fogbeam_frame_info.host_frame is camera->frame
 * (docs/service.md, "Host depth"). */
int fogbeam_depth_publish(fogbeam_depth_writer* w, const float* distance_m, const fogbeam_camera* camera);
/* The same with the host's colour in the same frame, for a fogbeam channel that composites
 * host·T + A itself (docs/service.md, "Host depth"): `colour_format` FOGBEAM_FORMAT_RGBA16F_LINEAR
 * (linear luminance in cd/m², A ignored) or FOGBEAM_FORMAT_RGBA8_SRGB (the image as displayed,
 * A ignored; fogbeam decodes it through the inverse of its own tone curve at the channel's
 * exposure_ev). The segment holds the colour as its pixels and the distances as its distance
 * plane, so that both are one frame under one seqlock. */
int fogbeam_depth_create_colour(const char* name, uint32_t width, uint32_t height, uint32_t colour_format,
                                fogbeam_depth_writer** out);
/* Publishes distances and colour (width·height pixels of the channel's colour format, row 0 at
 * the top) of one view. FOGBEAM_ERROR on a depth-only writer or frame 0. */
int fogbeam_depth_publish_colour(fogbeam_depth_writer* w, const float* distance_m, const void* colour,
                                 const fogbeam_camera* camera);
void fogbeam_depth_destroy(fogbeam_depth_writer* w);

/* Attaches to channel `name` (the service config's channel name). FOGBEAM_OK or FOGBEAM_ERROR. */
int fogbeam_attach(const char* name, fogbeam_reader** out);
/* Bytes a frame's pixels take (width · height · bytes per pixel). */
size_t fogbeam_frame_bytes(const fogbeam_reader* r);
/* Copies the newest whole frame into `dst` (at least fogbeam_frame_bytes) and fills `info`. */
int fogbeam_latest(fogbeam_reader* r, void* dst, size_t dst_size, fogbeam_frame_info* info);
void fogbeam_detach(fogbeam_reader* r);
/* The calling thread's last error message (valid until the next call on that thread). */
const char* fogbeam_last_error(void);

#ifdef __cplusplus
}
#endif

#endif /* FOGBEAM_HOST_H */
