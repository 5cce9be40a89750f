/* fogbeam — the shared-memory frame channel, byte by byte (docs/shm.md). Plain C so that the
 * host SDK (fogbeam_host.h) and any image generator can include it. Offsets are from the start
 * of the segment; the segment holds no pointers, only offsets. Little-endian (x86-64, AArch64).
 *
 *   [header 256 B] [slot 0] [slot 1] … [slot n−1]
 *   slot = [slot metadata 256 B] [pixels: width·height·bytes_per_pixel] [distance: width·height·4, optional]
 *
 * Synchronisation: a seqlock per slot. The writer makes the slot's `seq` odd (release), writes
 * metadata and pixels, makes `seq` even (release), then stores the slot index and frame number
 * in the header's `latest` word (release). A reader loads `latest` (acquire), loads the slot's
 * `seq` (acquire), copies, issues an acquire fence and loads `seq` again: equal and even means
 * the copy is a whole frame. The writer never waits for readers; with ≥ 3 slots a reader that
 * copies within two frame periods always succeeds.
 */
#ifndef FOGBEAM_SHM_LAYOUT_H
#define FOGBEAM_SHM_LAYOUT_H

#include <stdint.h>

#define FOGBEAM_SHM_MAGIC 0x53424746u /* bytes "FGBS" */
/* Version 2 (fogbeam 0.x, issue 16): the slot metadata gained the off-axis frustum (144) and the
 * host frame (160). A version-1 reader refuses a version-2 segment by this number, and back. */
#define FOGBEAM_SHM_VERSION 2u
#define FOGBEAM_SHM_HEADER_SIZE 256u
#define FOGBEAM_SHM_SLOT_META_SIZE 256u

/* Pixel formats (header.format). */
#define FOGBEAM_FORMAT_RGBA8_SRGB 1u          /* composite, tone-mapped, 8-bit sRGB, A = 255 */
#define FOGBEAM_FORMAT_RGBA16F_LINEAR 2u      /* composite, linear cd/m², A = 1 */
#define FOGBEAM_FORMAT_RGBA16F_OVERLAY 3u     /* RGB in-scattered luminance (cd/m²), A transmittance: host·A + RGB */
#define FOGBEAM_FORMAT_DISTANCE_F32 4u        /* host depth input: f32 distance along each pixel's ray (m, +inf sky) */

/* Writer states (header.writer_state). */
#define FOGBEAM_WRITER_RUNNING 1u
#define FOGBEAM_WRITER_CLOSED 2u /* clean exit: no more frames */

/* Header: offsets in bytes. */
#define FOGBEAM_HDR_MAGIC 0             /* u32 */
#define FOGBEAM_HDR_VERSION 4           /* u16 */
#define FOGBEAM_HDR_HEADER_SIZE 6       /* u16, = 256 */
#define FOGBEAM_HDR_SLOT_COUNT 8        /* u32, ≥ 3 */
#define FOGBEAM_HDR_FORMAT 12           /* u32, FOGBEAM_FORMAT_* */
#define FOGBEAM_HDR_WIDTH 16            /* u32, pixels */
#define FOGBEAM_HDR_HEIGHT 20           /* u32, pixels; row 0 is the top */
#define FOGBEAM_HDR_BYTES_PER_PIXEL 24  /* u32: 4 (RGBA8) or 8 (RGBA16F) */
#define FOGBEAM_HDR_HAS_DISTANCE 28     /* u32: 1 = each slot has an f32 distance plane (m, +inf = sky) */
#define FOGBEAM_HDR_FIRST_SLOT 32       /* u64: offset of slot 0 */
#define FOGBEAM_HDR_SLOT_STRIDE 40      /* u64: bytes from one slot to the next */
#define FOGBEAM_HDR_PIXELS_OFFSET 48    /* u64: offset of the pixels inside a slot */
#define FOGBEAM_HDR_PIXELS_BYTES 56     /* u64 */
#define FOGBEAM_HDR_DISTANCE_OFFSET 64  /* u64: offset of the distance plane inside a slot (0 = none) */
#define FOGBEAM_HDR_SEGMENT_BYTES 72    /* u64: total size; readers check it against the mapping */
#define FOGBEAM_HDR_GENERATION 80       /* u64: random per writer start; changes when a writer restarts */
#define FOGBEAM_HDR_WRITER_PID 88       /* u32 */
#define FOGBEAM_HDR_WRITER_STATE 92     /* u32 atomic: FOGBEAM_WRITER_* */
#define FOGBEAM_HDR_HEARTBEAT_NS 96     /* u64 atomic: CLOCK_MONOTONIC of the writer's last sign of life */
#define FOGBEAM_HDR_LATEST 104          /* u64 atomic: (frame number << 8) | slot index; 0 = no frame yet */
#define FOGBEAM_HDR_CHANNEL_NAME 128    /* char[64], NUL-terminated */

/* Slot metadata: offsets from the start of the slot. */
#define FOGBEAM_SLOT_SEQ 0              /* u64 atomic seqlock counter: odd while being written */
#define FOGBEAM_SLOT_FRAME 8            /* u64 frame number (from 1) */
#define FOGBEAM_SLOT_SIM_TIME 16        /* f64 s: the input state's simulation time */
#define FOGBEAM_SLOT_POSE 24            /* f64 ×3 x, y, z (m) then f32 ×3 yaw, pitch, roll (deg): the eye used */
#define FOGBEAM_SLOT_ORIENTATION 48     /* f32 ×3 yaw, pitch, roll (deg): the second half of the pose */
#define FOGBEAM_SLOT_LIGHTS 60          /* u32: ego light bits used (docs/protocol.md) */
#define FOGBEAM_SLOT_EGO_SEQ 64         /* u32: sequence number of the ego-state message used */
#define FOGBEAM_SLOT_LAMP_SEQ 68        /* u32: of the lamp-state message used */
#define FOGBEAM_SLOT_ENV_SEQ 72         /* u32: of the environment message used */
#define FOGBEAM_SLOT_TRAFFIC_COUNT 76   /* u32: traffic objects drawn */
#define FOGBEAM_SLOT_SURFACE_MS 80      /* f64: render timings (ms) */
#define FOGBEAM_SLOT_AIRLIGHT_MS 88     /* f64 */
#define FOGBEAM_SLOT_COMPOSITE_MS 96    /* f64 */
#define FOGBEAM_SLOT_TOTAL_MS 104       /* f64 */
#define FOGBEAM_SLOT_LATENCY_MS 112     /* f64: input receive → publish */
#define FOGBEAM_SLOT_PUBLISH_NS 120     /* u64: CLOCK_MONOTONIC at publish */
#define FOGBEAM_SLOT_FRAME_REQUEST 128  /* u64: lock-step frame request answered (0 = free-running) */
#define FOGBEAM_SLOT_FOV_X 136          /* f32 deg: horizontal field of view of the centred pinhole */
#define FOGBEAM_SLOT_FOV_Y 140          /* f32 deg: vertical field of view; 0 = from width/height (square pixels) */
#define FOGBEAM_SLOT_FRUSTUM 144        /* f32 ×4 deg: left, right, up, down half-angles of an off-axis view; all 0 = centred (fov) */
#define FOGBEAM_SLOT_HOST_FRAME 160     /* u64: the host depth frame this frame was rendered on (0 = fogbeam's own view) */

#endif /* FOGBEAM_SHM_LAYOUT_H */
