// fogbeam — ShmWriter / ShmReader (fogbeam/ipc/shm_channel.hpp, fogbeam/ipc/shm_layout.h).
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/util/unique_fd.hpp>

#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <random>
#include <utility>

namespace fogbeam::ipc {

namespace {

constexpr std::uint32_t kAttempts = 8;  // reader retries before reporting Busy
// Slots per channel (docs/shm.md: slot count 3–16). The header's `latest` word keeps the slot
// index in its low 8 bits, beside the frame number.
constexpr std::uint32_t kMinSlots = 3, kMaxSlots = 16;
static_assert(kMaxSlots <= 0xFF + 1, "the slot index must fit in the low 8 bits of `latest`");

std::string sysError(const std::string& what) { return what + ": " + std::strerror(errno); }


// Plain (non-atomic) fields: written by the writer before the slot's seq is made even, or
// once at creation before anyone can read them.
template <class T>
void put(std::byte* base, std::size_t off, T v) {
  std::memcpy(base + off, &v, sizeof v);
}
template <class T>
T get(const std::byte* base, std::size_t off) {
  T v;
  std::memcpy(&v, base + off, sizeof v);
  return v;
}

// Atomic 64/32-bit words inside the mapping (8-/4-byte aligned by the layout).
std::atomic_ref<std::uint64_t> word64(std::byte* base, std::size_t off) {
  return std::atomic_ref<std::uint64_t>(*reinterpret_cast<std::uint64_t*>(base + off));
}
std::atomic_ref<std::uint32_t> word32(std::byte* base, std::size_t off) {
  return std::atomic_ref<std::uint32_t>(*reinterpret_cast<std::uint32_t*>(base + off));
}
// Readers map the segment read-only; atomic_ref needs a non-const object, and a load does not
// write, so casting away const here is sound.
std::uint64_t load64(const std::byte* base, std::size_t off, std::memory_order mo) {
  return word64(const_cast<std::byte*>(base), off).load(mo);
}
std::uint32_t load32(const std::byte* base, std::size_t off, std::memory_order mo) {
  return word32(const_cast<std::byte*>(base), off).load(mo);
}

void writeMeta(std::byte* slot, const FrameMeta& m) {
  put(slot, FOGBEAM_SLOT_FRAME, m.frame);
  put(slot, FOGBEAM_SLOT_SIM_TIME, m.sim_time_s);
  for (std::size_t k = 0; k < 3; ++k) put(slot, FOGBEAM_SLOT_POSE + 8 * k, m.position_m[k]);
  put(slot, FOGBEAM_SLOT_ORIENTATION, m.yaw_deg);
  put(slot, FOGBEAM_SLOT_ORIENTATION + 4, m.pitch_deg);
  put(slot, FOGBEAM_SLOT_ORIENTATION + 8, m.roll_deg);
  put(slot, FOGBEAM_SLOT_LIGHTS, m.lights);
  put(slot, FOGBEAM_SLOT_EGO_SEQ, m.ego_sequence);
  put(slot, FOGBEAM_SLOT_LAMP_SEQ, m.lamp_sequence);
  put(slot, FOGBEAM_SLOT_ENV_SEQ, m.environment_sequence);
  put(slot, FOGBEAM_SLOT_TRAFFIC_COUNT, m.traffic_count);
  put(slot, FOGBEAM_SLOT_SURFACE_MS, m.surface_ms);
  put(slot, FOGBEAM_SLOT_AIRLIGHT_MS, m.airlight_ms);
  put(slot, FOGBEAM_SLOT_COMPOSITE_MS, m.composite_ms);
  put(slot, FOGBEAM_SLOT_TOTAL_MS, m.total_ms);
  put(slot, FOGBEAM_SLOT_LATENCY_MS, m.latency_ms);
  put(slot, FOGBEAM_SLOT_PUBLISH_NS, m.publish_ns);
  put(slot, FOGBEAM_SLOT_FRAME_REQUEST, m.frame_request);
  put(slot, FOGBEAM_SLOT_FOV_X, m.fov_x_deg);
  put(slot, FOGBEAM_SLOT_FOV_Y, m.fov_y_deg);
  for (std::size_t k = 0; k < 4; ++k) put(slot, FOGBEAM_SLOT_FRUSTUM + 4 * k, m.frustum_deg[k]);
  put(slot, FOGBEAM_SLOT_HOST_FRAME, m.host_frame);
}

FrameMeta readMeta(const std::byte* slot) {
  FrameMeta m;
  m.frame = get<std::uint64_t>(slot, FOGBEAM_SLOT_FRAME);
  m.sim_time_s = get<double>(slot, FOGBEAM_SLOT_SIM_TIME);
  for (std::size_t k = 0; k < 3; ++k) m.position_m[k] = get<double>(slot, FOGBEAM_SLOT_POSE + 8 * k);
  m.yaw_deg = get<float>(slot, FOGBEAM_SLOT_ORIENTATION);
  m.pitch_deg = get<float>(slot, FOGBEAM_SLOT_ORIENTATION + 4);
  m.roll_deg = get<float>(slot, FOGBEAM_SLOT_ORIENTATION + 8);
  m.lights = get<std::uint32_t>(slot, FOGBEAM_SLOT_LIGHTS);
  m.ego_sequence = get<std::uint32_t>(slot, FOGBEAM_SLOT_EGO_SEQ);
  m.lamp_sequence = get<std::uint32_t>(slot, FOGBEAM_SLOT_LAMP_SEQ);
  m.environment_sequence = get<std::uint32_t>(slot, FOGBEAM_SLOT_ENV_SEQ);
  m.traffic_count = get<std::uint32_t>(slot, FOGBEAM_SLOT_TRAFFIC_COUNT);
  m.surface_ms = get<double>(slot, FOGBEAM_SLOT_SURFACE_MS);
  m.airlight_ms = get<double>(slot, FOGBEAM_SLOT_AIRLIGHT_MS);
  m.composite_ms = get<double>(slot, FOGBEAM_SLOT_COMPOSITE_MS);
  m.total_ms = get<double>(slot, FOGBEAM_SLOT_TOTAL_MS);
  m.latency_ms = get<double>(slot, FOGBEAM_SLOT_LATENCY_MS);
  m.publish_ns = get<std::uint64_t>(slot, FOGBEAM_SLOT_PUBLISH_NS);
  m.frame_request = get<std::uint64_t>(slot, FOGBEAM_SLOT_FRAME_REQUEST);
  m.fov_x_deg = get<float>(slot, FOGBEAM_SLOT_FOV_X);
  m.fov_y_deg = get<float>(slot, FOGBEAM_SLOT_FOV_Y);
  for (std::size_t k = 0; k < 4; ++k) m.frustum_deg[k] = get<float>(slot, FOGBEAM_SLOT_FRUSTUM + 4 * k);
  m.host_frame = get<std::uint64_t>(slot, FOGBEAM_SLOT_HOST_FRAME);
  return m;
}

bool processAlive(std::uint32_t pid) {
  if (pid == 0) return false;
  return ::kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM;
}

}  // namespace

bool validChannelName(const std::string& c) noexcept {
  if (c.empty() || c.size() > kMaxChannelName) return false;
  for (char ch : c)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '.' || ch == '-')) return false;
  return true;
}

std::uint32_t bytesPerPixel(std::uint32_t format) noexcept {
  switch (format) {
    case FOGBEAM_FORMAT_RGBA8_SRGB:
    case FOGBEAM_FORMAT_DISTANCE_F32: return 4;
    case FOGBEAM_FORMAT_RGBA16F_LINEAR:
    case FOGBEAM_FORMAT_RGBA16F_OVERLAY: return 8;
    default: return 0;
  }
}

std::uint64_t monotonicNs() noexcept {
  timespec ts{};
  // CLOCK_MONOTONIC always exists on Linux and `ts` is valid, so a failure is a bug (EINVAL,
  // EFAULT), not a condition: abort (fogbeam/util/result.hpp) rather than publish heartbeats of 0,
  // which every reader would take for a dead writer.
  if (::clock_gettime(CLOCK_MONOTONIC, &ts) != 0) {
    std::fprintf(stderr, "fogbeam: clock_gettime(CLOCK_MONOTONIC): %s\n", std::strerror(errno));
    std::abort();
  }
  return static_cast<std::uint64_t>(ts.tv_sec) * 1000000000ull + static_cast<std::uint64_t>(ts.tv_nsec);
}

// ---------------------------------------------------------------------------------------------
namespace {

// What the header of an existing segment says about its writer (docs/shm.md, "Segment"): alive
// when its state is running, its heartbeat younger than 2 s and its pid exists; anything else
// (no magic, too small to hold a header, or vanished since) is stale.
struct ExistingWriter {
  bool alive = false;
  std::uint32_t pid = 0;
};

Result<ExistingWriter> inspectExisting(const std::string& name) {
  ExistingWriter e;
  const UniqueFd old(::shm_open(name.c_str(), O_RDONLY | O_CLOEXEC, 0));
  if (!old) {
    if (errno == ENOENT) return e;  // removed since our O_EXCL attempt: nothing left to replace
    return Error{sysError("shm_open " + name + " (an existing segment, to check its writer)")};
  }
  struct stat st {};
  if (::fstat(old.get(), &st) != 0) return Error{sysError("fstat " + name)};
  if (static_cast<std::uint64_t>(st.st_size) < FOGBEAM_SHM_HEADER_SIZE) return e;
  auto header = ShmMapping::map(old.get(), FOGBEAM_SHM_HEADER_SIZE, false, name + " (header of an existing segment)");
  if (!header) return header.error();
  const std::byte* b = header->data();
  if (get<std::uint32_t>(b, FOGBEAM_HDR_MAGIC) == FOGBEAM_SHM_MAGIC) {
    e.pid = get<std::uint32_t>(b, FOGBEAM_HDR_WRITER_PID);
    const bool running = load32(b, FOGBEAM_HDR_WRITER_STATE, std::memory_order_acquire) == FOGBEAM_WRITER_RUNNING;
    const std::uint64_t beat = load64(b, FOGBEAM_HDR_HEARTBEAT_NS, std::memory_order_acquire);
    const bool recent = monotonicNs() - beat < 2'000'000'000ull;
    e.alive = running && recent && processAlive(e.pid);
  }
  return e;
}

// The writer's generation: random, so that a restarted writer differs from the one before.
std::uint64_t newGeneration() {
  try {
    std::random_device rd;
    return (std::uint64_t{rd()} << 32) ^ rd() ^ monotonicNs();
  } catch (const std::exception& e) {
    // No entropy source: the start time and pid still tell two writer starts apart.
    spdlog::warn("shm: std::random_device unavailable ({}): generation from the clock and pid", e.what());
    return monotonicNs() ^ (std::uint64_t{static_cast<std::uint32_t>(::getpid())} << 32);
  }
}

}  // namespace

Result<std::unique_ptr<ShmWriter>> ShmWriter::create(const ShmChannelOptions& o) {
  if (!validChannelName(o.channel))
    return Error{"shm channel '" + o.channel + "': expected 1–48 characters from [A-Za-z0-9_.-]"};
  const std::uint32_t bpp = bytesPerPixel(o.format);
  if (bpp == 0) return Error{"shm channel '" + o.channel + "': unknown format " + std::to_string(o.format)};
  if (o.width == 0 || o.height == 0 || o.width > 16384 || o.height > 16384)
    return Error{"shm channel '" + o.channel + "': image size must be 1–16384 pixels per side"};
  if (o.slots < kMinSlots || o.slots > kMaxSlots)
    return Error{"shm channel '" + o.channel + "': slots must be " + std::to_string(kMinSlots) + "–" +
                 std::to_string(kMaxSlots)};
  // Every error return below destroys `w`: its members unmap, close and unlink what was made so
  // far, the segment's name once (ShmName).
  std::unique_ptr<ShmWriter> w(new ShmWriter());
  w->name_ = "/fogbeam." + o.channel;
  const std::string& name = w->name_;
  const std::uint64_t pixels = std::uint64_t{o.width} * o.height * bpp;
  const std::uint64_t dist = o.distance ? std::uint64_t{o.width} * o.height * 4 : 0;
  auto align = [](std::uint64_t v) { return (v + 63) / 64 * 64; };  // cache lines
  const std::uint64_t stride = align(FOGBEAM_SHM_SLOT_META_SIZE + align(pixels) + dist);
  const std::uint64_t size = FOGBEAM_SHM_HEADER_SIZE + stride * o.slots;
  const mode_t mode = o.group_access ? 0660 : 0600;

  int openErrno = 0;
  for (int attempt = 0; attempt < 2; ++attempt) {
    w->fd_.reset(::shm_open(name.c_str(), O_CREAT | O_EXCL | O_RDWR | O_CLOEXEC, mode));
    if (w->fd_) {
      w->segment_ = ShmName(name, w->fd_.get());  // created here: ours to unlink, once
      break;
    }
    openErrno = errno;
    if (openErrno != EEXIST) return Error{sysError("shm_open " + name)};
    // A segment exists: refuse it if its writer is alive, replace it if it is stale.
    const auto existing = inspectExisting(name);
    if (!existing) return existing.error();
    if (existing->alive)
      return Error{"shm channel " + name + " is in use by a running writer (pid " + std::to_string(existing->pid) + ")"};
    spdlog::warn("shm: replacing stale segment {} (writer pid {} gone)", name, existing->pid);
    // Not ours: a plain unlink. ENOENT: it went away by itself, which is as good.
    if (::shm_unlink(name.c_str()) != 0 && errno != ENOENT)
      return Error{sysError("shm channel " + name + ": cannot remove the stale segment: shm_unlink")};
    w->replacedStale_ = true;
  }
  if (!w->fd_) return Error{"shm_open " + name + ": " + std::strerror(openErrno)};
  // The umask may have cleared the group bits of shm_open's mode (docs/shm.md: 0600 or 0660).
  if (::fchmod(w->fd_.get(), mode) != 0)
    return Error{sysError("fchmod " + name + " to mode " + (o.group_access ? "0660" : "0600"))};
  if (::ftruncate(w->fd_.get(), static_cast<off_t>(size)) != 0)
    return Error{sysError("ftruncate " + name + " to " + std::to_string(size) + " bytes")};
  auto mapping = ShmMapping::map(w->fd_.get(), size, true, name);
  if (!mapping) return mapping.error();
  w->mapping_ = std::move(mapping).value();
  w->slots_ = o.slots;
  w->generation_ = newGeneration();
  std::byte* b = w->mapping_.data();
  put(b, FOGBEAM_HDR_VERSION, static_cast<std::uint16_t>(FOGBEAM_SHM_VERSION));
  put(b, FOGBEAM_HDR_HEADER_SIZE, static_cast<std::uint16_t>(FOGBEAM_SHM_HEADER_SIZE));
  put(b, FOGBEAM_HDR_SLOT_COUNT, o.slots);
  put(b, FOGBEAM_HDR_FORMAT, o.format);
  put(b, FOGBEAM_HDR_WIDTH, o.width);
  put(b, FOGBEAM_HDR_HEIGHT, o.height);
  put(b, FOGBEAM_HDR_BYTES_PER_PIXEL, bpp);
  put(b, FOGBEAM_HDR_HAS_DISTANCE, static_cast<std::uint32_t>(o.distance ? 1 : 0));
  put(b, FOGBEAM_HDR_FIRST_SLOT, std::uint64_t{FOGBEAM_SHM_HEADER_SIZE});
  put(b, FOGBEAM_HDR_SLOT_STRIDE, stride);
  put(b, FOGBEAM_HDR_PIXELS_OFFSET, std::uint64_t{FOGBEAM_SHM_SLOT_META_SIZE});
  put(b, FOGBEAM_HDR_PIXELS_BYTES, pixels);
  put(b, FOGBEAM_HDR_DISTANCE_OFFSET, o.distance ? FOGBEAM_SHM_SLOT_META_SIZE + align(pixels) : std::uint64_t{0});
  put(b, FOGBEAM_HDR_SEGMENT_BYTES, size);
  put(b, FOGBEAM_HDR_GENERATION, w->generation_);
  put(b, FOGBEAM_HDR_WRITER_PID, static_cast<std::uint32_t>(::getpid()));
  std::strncpy(reinterpret_cast<char*>(b + FOGBEAM_HDR_CHANNEL_NAME), o.channel.c_str(), 63);
  word32(b, FOGBEAM_HDR_WRITER_STATE).store(FOGBEAM_WRITER_RUNNING, std::memory_order_relaxed);
  word64(b, FOGBEAM_HDR_HEARTBEAT_NS).store(monotonicNs(), std::memory_order_relaxed);
  // The magic last (release): a reader that sees it sees a complete header.
  word32(b, FOGBEAM_HDR_MAGIC).store(FOGBEAM_SHM_MAGIC, std::memory_order_release);
  spdlog::info("shm: created {} ({}x{}, format {}, {} slots, {} bytes, mode {:o})", name, o.width, o.height,
               o.format, o.slots, size, mode);
  return w;
}

ShmWriter::~ShmWriter() {
  // Readers see "closed" first; then the members unmap, close and unlink, in that order
  // (reverse declaration order, shm_channel.hpp).
  if (mapping_) word32(mapping_.data(), FOGBEAM_HDR_WRITER_STATE).store(FOGBEAM_WRITER_CLOSED, std::memory_order_release);
}

void ShmWriter::heartbeat() noexcept {
  word64(mapping_.data(), FOGBEAM_HDR_HEARTBEAT_NS).store(monotonicNs(), std::memory_order_release);
}

std::uint32_t ShmWriter::publish(FrameMeta meta, std::span<const std::byte> pixels, std::span<const float> distance) {
  std::byte* const base = mapping_.data();
  const std::uint32_t slot = next_;
  next_ = (next_ + 1) % slots_;
  std::byte* s = base + get<std::uint64_t>(base, FOGBEAM_HDR_FIRST_SLOT) +
                 static_cast<std::uint64_t>(slot) * get<std::uint64_t>(base, FOGBEAM_HDR_SLOT_STRIDE);
  auto seq = word64(s, FOGBEAM_SLOT_SEQ);
  const std::uint64_t begin = seq.load(std::memory_order_relaxed) + 1;  // odd: being written
  seq.store(begin, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);  // seq odd before any data store
  meta.publish_ns = monotonicNs();
  writeMeta(s, meta);
  const std::uint64_t nPix = get<std::uint64_t>(base, FOGBEAM_HDR_PIXELS_BYTES);
  std::memcpy(s + FOGBEAM_SHM_SLOT_META_SIZE, pixels.data(), std::min<std::uint64_t>(nPix, pixels.size()));
  const std::uint64_t dOff = get<std::uint64_t>(base, FOGBEAM_HDR_DISTANCE_OFFSET);
  if (dOff != 0 && !distance.empty()) {
    const std::uint64_t nDist = std::uint64_t{get<std::uint32_t>(base, FOGBEAM_HDR_WIDTH)} *
                                get<std::uint32_t>(base, FOGBEAM_HDR_HEIGHT);
    std::memcpy(s + dOff, distance.data(), 4 * std::min<std::uint64_t>(nDist, distance.size()));
  }
  seq.store(begin + 1, std::memory_order_release);  // even: complete
  word64(base, FOGBEAM_HDR_LATEST).store((meta.frame << 8) | slot, std::memory_order_release);
  word64(base, FOGBEAM_HDR_HEARTBEAT_NS).store(meta.publish_ns, std::memory_order_release);
  return slot;
}

// ---------------------------------------------------------------------------------------------
Result<std::unique_ptr<ShmReader>> ShmReader::attach(const std::string& channel) {
  if (!validChannelName(channel))
    return Error{"shm channel '" + channel + "': expected 1–48 characters from [A-Za-z0-9_.-]"};
  std::unique_ptr<ShmReader> r(new ShmReader());
  r->name_ = "/fogbeam." + channel;
  UniqueFd fd(::shm_open(r->name_.c_str(), O_RDONLY | O_CLOEXEC, 0));
  if (!fd) return Error{sysError("shm_open " + r->name_ + " (is the fogbeam service running?)")};
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0) return Error{sysError("fstat " + r->name_)};
  const auto size = static_cast<std::size_t>(st.st_size);
  if (size < FOGBEAM_SHM_HEADER_SIZE)
    return Error{r->name_ + ": " + std::to_string(size) + " bytes, smaller than the header"};
  auto mapping = ShmMapping::map(fd.get(), size, false, r->name_);
  fd.reset();  // the mapping keeps the segment; the descriptor is of no further use
  if (!mapping) return mapping.error();
  r->mapping_ = std::move(mapping).value();
  const std::byte* b = r->mapping_.data();
  if (load32(b, FOGBEAM_HDR_MAGIC, std::memory_order_acquire) != FOGBEAM_SHM_MAGIC)
    return Error{r->name_ + ": not a fogbeam channel (magic)"};
  if (get<std::uint16_t>(b, FOGBEAM_HDR_VERSION) != FOGBEAM_SHM_VERSION)
    return Error{r->name_ + ": layout version " + std::to_string(get<std::uint16_t>(b, FOGBEAM_HDR_VERSION)) +
                 ", this reader knows " + std::to_string(FOGBEAM_SHM_VERSION)};
  r->width_ = get<std::uint32_t>(b, FOGBEAM_HDR_WIDTH);
  r->height_ = get<std::uint32_t>(b, FOGBEAM_HDR_HEIGHT);
  r->format_ = get<std::uint32_t>(b, FOGBEAM_HDR_FORMAT);
  r->slots_ = get<std::uint32_t>(b, FOGBEAM_HDR_SLOT_COUNT);
  r->firstSlot_ = get<std::uint64_t>(b, FOGBEAM_HDR_FIRST_SLOT);
  r->stride_ = get<std::uint64_t>(b, FOGBEAM_HDR_SLOT_STRIDE);
  r->pixelsOffset_ = get<std::uint64_t>(b, FOGBEAM_HDR_PIXELS_OFFSET);
  r->pixelsBytes_ = get<std::uint64_t>(b, FOGBEAM_HDR_PIXELS_BYTES);
  r->distanceOffset_ = get<std::uint64_t>(b, FOGBEAM_HDR_DISTANCE_OFFSET);
  r->generation_ = get<std::uint64_t>(b, FOGBEAM_HDR_GENERATION);
  // Every offset the reader will use must lie inside the mapping.
  const std::uint64_t declared = get<std::uint64_t>(b, FOGBEAM_HDR_SEGMENT_BYTES);
  const std::uint64_t need = r->firstSlot_ + r->stride_ * r->slots_;
  const std::uint64_t slotNeed =
      std::max(r->pixelsOffset_ + r->pixelsBytes_,
               r->distanceOffset_ ? r->distanceOffset_ + std::uint64_t{r->width_} * r->height_ * 4 : 0);
  if (r->slots_ < 1 || r->slots_ > 255 || declared != size || need > size || slotNeed > r->stride_ ||
      r->pixelsBytes_ != std::uint64_t{r->width_} * r->height_ * bytesPerPixel(r->format_))
    return Error{r->name_ + ": inconsistent header (sizes do not match the " + std::to_string(size) + "-byte segment)"};
  return r;
}

ShmReader::~ShmReader() = default;

std::uint64_t ShmReader::latestTag() const noexcept {
  return load64(mapping_.data(), FOGBEAM_HDR_LATEST, std::memory_order_acquire);
}

ReadStatus ShmReader::latest(FrameMeta& meta, std::vector<std::byte>& pixels, std::vector<float>* distance,
                             double heartbeat_timeout_s) {
  const std::byte* b = mapping_.data();
  const bool closed = load32(b, FOGBEAM_HDR_WRITER_STATE, std::memory_order_acquire) == FOGBEAM_WRITER_CLOSED;
  const std::uint64_t beat = load64(b, FOGBEAM_HDR_HEARTBEAT_NS, std::memory_order_acquire);
  const double silent_s = static_cast<double>(monotonicNs() - beat) * 1e-9;
  if (closed || silent_s > heartbeat_timeout_s) return ReadStatus::WriterGone;
  // A writer killed outright is gone at once, not only when its heartbeat ages.
  if (!processAlive(get<std::uint32_t>(b, FOGBEAM_HDR_WRITER_PID))) return ReadStatus::WriterGone;
  for (std::uint32_t attempt = 0; attempt < kAttempts; ++attempt) {
    const std::uint64_t latest = load64(b, FOGBEAM_HDR_LATEST, std::memory_order_acquire);
    if (latest == 0) return ReadStatus::NoFrame;
    const std::uint64_t slot = latest & 0xFF;
    if (slot >= slots_) return ReadStatus::WriterGone;  // cannot happen with a sane writer
    const std::byte* s = b + firstSlot_ + slot * stride_;
    const std::uint64_t s1 = load64(s, FOGBEAM_SLOT_SEQ, std::memory_order_acquire);
    if (s1 % 2 == 1) {
      ++retries_;
      continue;
    }
    meta = readMeta(s);
    pixels.resize(pixelsBytes_);
    std::memcpy(pixels.data(), s + pixelsOffset_, pixelsBytes_);
    if (distance && distanceOffset_) {
      distance->resize(std::size_t{width_} * height_);
      std::memcpy(distance->data(), s + distanceOffset_, distance->size() * 4);
    }
    std::atomic_thread_fence(std::memory_order_acquire);  // the copies happen before the re-check
    const std::uint64_t s2 = load64(s, FOGBEAM_SLOT_SEQ, std::memory_order_relaxed);
    if (s1 == s2) return ReadStatus::Ok;
    ++retries_;
  }
  return ReadStatus::Busy;
}

}  // namespace fogbeam::ipc
