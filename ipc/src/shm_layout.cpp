// fogbeam — compile-time checks of the shared-memory layout (fogbeam/ipc/shm_layout.h) against
// what docs/shm.md promises every reader (the C SDK, the Python reader, a host's own code). Nothing
// here runs: a change of shm_layout.h that breaks the document fails to compile.
// tests/ipc/test_layout_docs.cpp checks the document's tables against the same macros at run time.
//
// Two kinds of check:
//   * each documented number: offset, size, magic, code (the document's tables, row by row);
//   * the layout as a whole: the structs below spell out the documented field types in table order,
//     with the document's gaps as reserved bytes; the compiler's natural layout of them must put
//     every field at its macro's offset. That catches a macro that overlaps its neighbour or
//     leaves an undocumented hole, and an atomic word that lost its alignment.
#include <fogbeam/ipc/shm_layout.h>

#include <atomic>
#include <cstddef>
#include <cstdint>

namespace fogbeam::ipc {
namespace {

// ---- Header (docs/shm.md, "Header (256 bytes)") --------------------------------------------
struct HeaderLayout {
  std::uint32_t magic;
  std::uint16_t version;
  std::uint16_t header_size;
  std::uint32_t slot_count;
  std::uint32_t format;
  std::uint32_t width;
  std::uint32_t height;
  std::uint32_t bytes_per_pixel;
  std::uint32_t has_distance;
  std::uint64_t first_slot;
  std::uint64_t slot_stride;
  std::uint64_t pixels_offset;
  std::uint64_t pixels_bytes;
  std::uint64_t distance_offset;
  std::uint64_t segment_bytes;
  std::uint64_t generation;
  std::uint32_t writer_pid;
  std::uint32_t writer_state;   // atomic
  std::uint64_t heartbeat_ns;   // atomic
  std::uint64_t latest;         // atomic
  std::uint8_t reserved[16];    // 112–127: not in the document's table
  char channel_name[64];
  std::uint8_t unused[64];      // 192–255
};

static_assert(FOGBEAM_SHM_HEADER_SIZE == 256 && sizeof(HeaderLayout) == FOGBEAM_SHM_HEADER_SIZE);
static_assert(FOGBEAM_SHM_MAGIC == 0x53424746u);  // the bytes "FGBS", little-endian:
static_assert(FOGBEAM_SHM_MAGIC == (std::uint32_t{'F'} | std::uint32_t{'G'} << 8 | std::uint32_t{'B'} << 16 |
                                    std::uint32_t{'S'} << 24));
static_assert(FOGBEAM_SHM_VERSION == 2);

static_assert(FOGBEAM_HDR_MAGIC == 0 && offsetof(HeaderLayout, magic) == FOGBEAM_HDR_MAGIC);
static_assert(FOGBEAM_HDR_VERSION == 4 && offsetof(HeaderLayout, version) == FOGBEAM_HDR_VERSION);
static_assert(FOGBEAM_HDR_HEADER_SIZE == 6 && offsetof(HeaderLayout, header_size) == FOGBEAM_HDR_HEADER_SIZE);
static_assert(FOGBEAM_HDR_SLOT_COUNT == 8 && offsetof(HeaderLayout, slot_count) == FOGBEAM_HDR_SLOT_COUNT);
static_assert(FOGBEAM_HDR_FORMAT == 12 && offsetof(HeaderLayout, format) == FOGBEAM_HDR_FORMAT);
static_assert(FOGBEAM_HDR_WIDTH == 16 && offsetof(HeaderLayout, width) == FOGBEAM_HDR_WIDTH);
static_assert(FOGBEAM_HDR_HEIGHT == 20 && offsetof(HeaderLayout, height) == FOGBEAM_HDR_HEIGHT);
static_assert(FOGBEAM_HDR_BYTES_PER_PIXEL == 24 && offsetof(HeaderLayout, bytes_per_pixel) == FOGBEAM_HDR_BYTES_PER_PIXEL);
static_assert(FOGBEAM_HDR_HAS_DISTANCE == 28 && offsetof(HeaderLayout, has_distance) == FOGBEAM_HDR_HAS_DISTANCE);
static_assert(FOGBEAM_HDR_FIRST_SLOT == 32 && offsetof(HeaderLayout, first_slot) == FOGBEAM_HDR_FIRST_SLOT);
static_assert(FOGBEAM_HDR_SLOT_STRIDE == 40 && offsetof(HeaderLayout, slot_stride) == FOGBEAM_HDR_SLOT_STRIDE);
static_assert(FOGBEAM_HDR_PIXELS_OFFSET == 48 && offsetof(HeaderLayout, pixels_offset) == FOGBEAM_HDR_PIXELS_OFFSET);
static_assert(FOGBEAM_HDR_PIXELS_BYTES == 56 && offsetof(HeaderLayout, pixels_bytes) == FOGBEAM_HDR_PIXELS_BYTES);
static_assert(FOGBEAM_HDR_DISTANCE_OFFSET == 64 && offsetof(HeaderLayout, distance_offset) == FOGBEAM_HDR_DISTANCE_OFFSET);
static_assert(FOGBEAM_HDR_SEGMENT_BYTES == 72 && offsetof(HeaderLayout, segment_bytes) == FOGBEAM_HDR_SEGMENT_BYTES);
static_assert(FOGBEAM_HDR_GENERATION == 80 && offsetof(HeaderLayout, generation) == FOGBEAM_HDR_GENERATION);
static_assert(FOGBEAM_HDR_WRITER_PID == 88 && offsetof(HeaderLayout, writer_pid) == FOGBEAM_HDR_WRITER_PID);
static_assert(FOGBEAM_HDR_WRITER_STATE == 92 && offsetof(HeaderLayout, writer_state) == FOGBEAM_HDR_WRITER_STATE);
static_assert(FOGBEAM_HDR_HEARTBEAT_NS == 96 && offsetof(HeaderLayout, heartbeat_ns) == FOGBEAM_HDR_HEARTBEAT_NS);
static_assert(FOGBEAM_HDR_LATEST == 104 && offsetof(HeaderLayout, latest) == FOGBEAM_HDR_LATEST);
static_assert(FOGBEAM_HDR_CHANNEL_NAME == 128 && offsetof(HeaderLayout, channel_name) == FOGBEAM_HDR_CHANNEL_NAME);
static_assert(sizeof(HeaderLayout::channel_name) == 64);  // char[64]; the writer copies at most 63 + NUL

// "offset of slot 0 (= 256)": the writer puts slot 0 right after the header.
// "offset of the pixels inside a slot (= 256)": right after the slot metadata.
// Both multiples of 64, so slots and pixel planes start on cache lines ("Segment").
static_assert(FOGBEAM_SHM_HEADER_SIZE % 64 == 0 && FOGBEAM_SHM_SLOT_META_SIZE % 64 == 0);

// Codes: formats 1–4 with 4 or 8 bytes per pixel (bytesPerPixel()); writer state 1 running, 2 closed.
static_assert(FOGBEAM_FORMAT_RGBA8_SRGB == 1 && FOGBEAM_FORMAT_RGBA16F_LINEAR == 2 &&
              FOGBEAM_FORMAT_RGBA16F_OVERLAY == 3 && FOGBEAM_FORMAT_DISTANCE_F32 == 4);
static_assert(FOGBEAM_WRITER_RUNNING == 1 && FOGBEAM_WRITER_CLOSED == 2);

// ---- Slot metadata (docs/shm.md, "Slot metadata (256 bytes at the start of each slot)") -----
struct SlotMetaLayout {
  std::uint64_t seq;  // atomic
  std::uint64_t frame;
  double sim_time_s;
  double position_m[3];
  float orientation_deg[3];  // yaw, pitch, roll
  std::uint32_t lights;
  std::uint32_t ego_seq;
  std::uint32_t lamp_seq;
  std::uint32_t env_seq;
  std::uint32_t traffic_count;
  double surface_ms;
  double airlight_ms;
  double composite_ms;
  double total_ms;
  double latency_ms;
  std::uint64_t publish_ns;
  std::uint64_t frame_request;
  float fov_x_deg;
  float fov_y_deg;
  float frustum_deg[4];
  std::uint64_t host_frame;
  std::uint8_t unused[88];  // 168–255
};

static_assert(FOGBEAM_SHM_SLOT_META_SIZE == 256 && sizeof(SlotMetaLayout) == FOGBEAM_SHM_SLOT_META_SIZE);
static_assert(FOGBEAM_SLOT_SEQ == 0 && offsetof(SlotMetaLayout, seq) == FOGBEAM_SLOT_SEQ);
static_assert(FOGBEAM_SLOT_FRAME == 8 && offsetof(SlotMetaLayout, frame) == FOGBEAM_SLOT_FRAME);
static_assert(FOGBEAM_SLOT_SIM_TIME == 16 && offsetof(SlotMetaLayout, sim_time_s) == FOGBEAM_SLOT_SIM_TIME);
static_assert(FOGBEAM_SLOT_POSE == 24 && offsetof(SlotMetaLayout, position_m) == FOGBEAM_SLOT_POSE);
static_assert(FOGBEAM_SLOT_ORIENTATION == 48 && offsetof(SlotMetaLayout, orientation_deg) == FOGBEAM_SLOT_ORIENTATION);
static_assert(FOGBEAM_SLOT_LIGHTS == 60 && offsetof(SlotMetaLayout, lights) == FOGBEAM_SLOT_LIGHTS);
static_assert(FOGBEAM_SLOT_EGO_SEQ == 64 && offsetof(SlotMetaLayout, ego_seq) == FOGBEAM_SLOT_EGO_SEQ);
static_assert(FOGBEAM_SLOT_LAMP_SEQ == 68 && offsetof(SlotMetaLayout, lamp_seq) == FOGBEAM_SLOT_LAMP_SEQ);
static_assert(FOGBEAM_SLOT_ENV_SEQ == 72 && offsetof(SlotMetaLayout, env_seq) == FOGBEAM_SLOT_ENV_SEQ);
static_assert(FOGBEAM_SLOT_TRAFFIC_COUNT == 76 && offsetof(SlotMetaLayout, traffic_count) == FOGBEAM_SLOT_TRAFFIC_COUNT);
static_assert(FOGBEAM_SLOT_SURFACE_MS == 80 && offsetof(SlotMetaLayout, surface_ms) == FOGBEAM_SLOT_SURFACE_MS);
static_assert(FOGBEAM_SLOT_AIRLIGHT_MS == 88 && offsetof(SlotMetaLayout, airlight_ms) == FOGBEAM_SLOT_AIRLIGHT_MS);
static_assert(FOGBEAM_SLOT_COMPOSITE_MS == 96 && offsetof(SlotMetaLayout, composite_ms) == FOGBEAM_SLOT_COMPOSITE_MS);
static_assert(FOGBEAM_SLOT_TOTAL_MS == 104 && offsetof(SlotMetaLayout, total_ms) == FOGBEAM_SLOT_TOTAL_MS);
static_assert(FOGBEAM_SLOT_LATENCY_MS == 112 && offsetof(SlotMetaLayout, latency_ms) == FOGBEAM_SLOT_LATENCY_MS);
static_assert(FOGBEAM_SLOT_PUBLISH_NS == 120 && offsetof(SlotMetaLayout, publish_ns) == FOGBEAM_SLOT_PUBLISH_NS);
static_assert(FOGBEAM_SLOT_FRAME_REQUEST == 128 && offsetof(SlotMetaLayout, frame_request) == FOGBEAM_SLOT_FRAME_REQUEST);
static_assert(FOGBEAM_SLOT_FOV_X == 136 && offsetof(SlotMetaLayout, fov_x_deg) == FOGBEAM_SLOT_FOV_X);
static_assert(FOGBEAM_SLOT_FOV_Y == 140 && offsetof(SlotMetaLayout, fov_y_deg) == FOGBEAM_SLOT_FOV_Y);
static_assert(FOGBEAM_SLOT_FRUSTUM == 144 && offsetof(SlotMetaLayout, frustum_deg) == FOGBEAM_SLOT_FRUSTUM);
static_assert(FOGBEAM_SLOT_HOST_FRAME == 160 && offsetof(SlotMetaLayout, host_frame) == FOGBEAM_SLOT_HOST_FRAME);

// ---- The atomic words (docs/shm.md, "Synchronisation") --------------------------------------
// shm_channel.cpp accesses them through std::atomic_ref, which needs this alignment relative to
// the mapping's start (page-aligned), and lock-free words, since the other side is another process.
static_assert(FOGBEAM_HDR_WRITER_STATE % std::atomic_ref<std::uint32_t>::required_alignment == 0);
static_assert(FOGBEAM_HDR_HEARTBEAT_NS % std::atomic_ref<std::uint64_t>::required_alignment == 0);
static_assert(FOGBEAM_HDR_LATEST % std::atomic_ref<std::uint64_t>::required_alignment == 0);
static_assert(FOGBEAM_HDR_MAGIC % std::atomic_ref<std::uint32_t>::required_alignment == 0);
static_assert(FOGBEAM_SLOT_SEQ % std::atomic_ref<std::uint64_t>::required_alignment == 0);
static_assert(FOGBEAM_SHM_SLOT_META_SIZE % std::atomic_ref<std::uint64_t>::required_alignment == 0);
static_assert(std::atomic_ref<std::uint32_t>::is_always_lock_free && std::atomic_ref<std::uint64_t>::is_always_lock_free);

}  // namespace
}  // namespace fogbeam::ipc
