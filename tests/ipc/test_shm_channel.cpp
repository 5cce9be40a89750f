// Shared-memory channels: round trip, permissions, no torn frame under a fast writer, closed /
// stale / live segments, reader errors, and the C SDK's example host against a live writer.
#include <fogbeam/fogbeam_host.h>
#include <fogbeam/ipc/shm_channel.hpp>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>

namespace fogbeam::ipc {
namespace {

// A channel name unique to this process and test.
std::string channelName(const char* tag) { return std::string("test-") + tag + "-" + std::to_string(::getpid()); }

ShmChannelOptions opts(const std::string& ch, std::uint32_t w = 64, std::uint32_t h = 32) {
  ShmChannelOptions o;
  o.channel = ch;
  o.width = w;
  o.height = h;
  o.format = FOGBEAM_FORMAT_RGBA16F_OVERLAY;
  o.distance = true;
  return o;
}

TEST(ShmChannel, FrameAndMetadataRoundTrip) {
  const std::string ch = channelName("rt");
  auto w = ShmWriter::create(opts(ch));
  ASSERT_TRUE(w) << w.error().message;
  auto r = ShmReader::attach(ch);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ((*r)->width(), 64u);
  EXPECT_EQ((*r)->format(), FOGBEAM_FORMAT_RGBA16F_OVERLAY);
  EXPECT_TRUE((*r)->hasDistance());
  FrameMeta m;
  std::vector<std::byte> px;
  EXPECT_EQ((*r)->latest(m, px), ReadStatus::NoFrame);
  FrameMeta out;
  out.frame = 42;
  out.sim_time_s = 3.25;
  out.position_m = {1.0, 2.0, 1.2};
  out.yaw_deg = 90.0f;
  out.lights = 0x6;
  out.ego_sequence = 17;
  out.latency_ms = 4.5;
  std::vector<std::byte> pixels(64 * 32 * 8);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<std::byte>(i * 7);
  std::vector<float> dist(64 * 32, 12.5f);
  dist[5] = std::numeric_limits<float>::infinity();
  (*w)->publish(out, pixels, dist);
  std::vector<float> d;
  ASSERT_EQ((*r)->latest(m, px, &d), ReadStatus::Ok);
  EXPECT_EQ(m.frame, 42u);
  EXPECT_EQ(m.sim_time_s, 3.25);
  EXPECT_EQ(m.position_m[2], 1.2);
  EXPECT_EQ(m.yaw_deg, 90.0f);
  EXPECT_EQ(m.lights, 0x6u);
  EXPECT_EQ(m.ego_sequence, 17u);
  EXPECT_EQ(m.latency_ms, 4.5);
  EXPECT_GT(m.publish_ns, 0u);
  EXPECT_EQ(px, pixels);
  EXPECT_EQ(d, dist);
}

TEST(ShmChannel, SegmentsAreOwnerOnlyByDefault) {
  const std::string ch = channelName("perm");
  {
    auto w = ShmWriter::create(opts(ch));
    ASSERT_TRUE(w);
    struct stat st {};
    ASSERT_EQ(::stat(("/dev/shm/fogbeam." + ch).c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 0777, 0600u);
  }
  EXPECT_NE(::access(("/dev/shm/fogbeam." + ch).c_str(), F_OK), 0) << "not unlinked on destruction";
  auto o = opts(ch);
  o.group_access = true;
  auto w = ShmWriter::create(o);
  ASSERT_TRUE(w);
  struct stat st {};
  ASSERT_EQ(::stat(("/dev/shm/fogbeam." + ch).c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0660u);
}

// The writer publishes as fast as it can, each frame filled with one byte value derived from
// its number; the reader must never accept a frame whose bytes or metadata disagree.
TEST(ShmChannel, NoTornFrameUnderAFastWriter) {
  const std::string ch = channelName("torn");
  auto w = ShmWriter::create(opts(ch, 256, 128));
  ASSERT_TRUE(w);
  auto r = ShmReader::attach(ch);
  ASSERT_TRUE(r);
  std::atomic<bool> done{false};
  std::thread writer([&] {
    std::vector<std::byte> px(256 * 128 * 8);
    for (std::uint64_t f = 1; f <= 3000; ++f) {
      std::fill(px.begin(), px.end(), static_cast<std::byte>(f & 0xFF));
      FrameMeta m;
      m.frame = f;
      m.sim_time_s = static_cast<double>(f);
      (*w)->publish(m, px);
    }
    done = true;
  });
  std::size_t ok = 0, bad = 0, busy = 0;
  FrameMeta m;
  std::vector<std::byte> px;
  while (!done.load()) {
    const ReadStatus s = (*r)->latest(m, px);
    if (s == ReadStatus::Busy) ++busy;
    if (s != ReadStatus::Ok) continue;
    ++ok;
    const auto v = static_cast<std::byte>(m.frame & 0xFF);
    if (m.sim_time_s != static_cast<double>(m.frame) ||
        std::any_of(px.begin(), px.end(), [&](std::byte b) { return b != v; }))
      ++bad;
  }
  writer.join();
  std::printf("  %zu whole frames read, %zu busy, %llu retries, %zu torn accepted\n", ok, busy,
              static_cast<unsigned long long>((*r)->retries()), bad);
  EXPECT_EQ(bad, 0u);
  EXPECT_GT(ok, 0u);
}

// The seqlock itself, deterministically: a slot caught mid-write (odd counter) is never
// returned, and a frame whose counter changed during the copy is retried.
TEST(ShmChannel, ASlotBeingWrittenIsNeverReturned) {
  const std::string ch = channelName("seq");
  auto w = ShmWriter::create(opts(ch));
  ASSERT_TRUE(w);
  auto r = ShmReader::attach(ch);
  ASSERT_TRUE(r);
  std::vector<std::byte> px(64 * 32 * 8, std::byte{1});
  (*w)->publish(FrameMeta{1}, px);  // slot 0
  // A second, writable mapping plays a writer stopped in the middle of slot 0.
  const int fd = ::shm_open(("/fogbeam." + ch).c_str(), O_RDWR, 0);
  ASSERT_GE(fd, 0);
  struct stat st {};
  ASSERT_EQ(::fstat(fd, &st), 0);
  void* map = ::mmap(nullptr, static_cast<std::size_t>(st.st_size), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  ::close(fd);
  ASSERT_NE(map, MAP_FAILED);
  auto* seq = reinterpret_cast<std::uint64_t*>(static_cast<std::byte*>(map) + FOGBEAM_SHM_HEADER_SIZE + FOGBEAM_SLOT_SEQ);
  const std::uint64_t even = *seq;
  EXPECT_EQ(even % 2, 0u);
  *seq = even + 1;  // odd: being written
  FrameMeta m;
  std::vector<std::byte> out;
  EXPECT_EQ((*r)->latest(m, out), ReadStatus::Busy);
  EXPECT_GE((*r)->retries(), 8u);
  *seq = even;
  EXPECT_EQ((*r)->latest(m, out), ReadStatus::Ok);
  ::munmap(map, static_cast<std::size_t>(st.st_size));
}

TEST(ShmChannel, ReaderSeesAClosedWriterAndAttachErrorsSayWhy) {
  const std::string ch = channelName("gone");
  auto w = ShmWriter::create(opts(ch));
  ASSERT_TRUE(w);
  auto r = ShmReader::attach(ch);
  ASSERT_TRUE(r);
  std::vector<std::byte> px(64 * 32 * 8);
  (*w)->publish(FrameMeta{1}, px);
  FrameMeta m;
  ASSERT_EQ((*r)->latest(m, px), ReadStatus::Ok);
  w->reset();  // clean exit: state closed, unlinked
  EXPECT_EQ((*r)->latest(m, px), ReadStatus::WriterGone);
  auto again = ShmReader::attach(ch);
  ASSERT_FALSE(again);
  EXPECT_NE(again.error().message.find("is the fogbeam service running"), std::string::npos);
  auto badName = ShmReader::attach("../etc");
  ASSERT_FALSE(badName);
  EXPECT_NE(badName.error().message.find("expected 1–48 characters"), std::string::npos);
}

// A writer that vanished without cleaning up (here: leaked, so its mapping stays and no
// destructor runs) blocks a new writer while its heartbeat is fresh, and is replaced once the
// heartbeat is older than 2 s. A reader of the old segment sees the writer gone.
TEST(ShmChannel, LiveSegmentsAreRefusedStaleOnesReplaced) {
  const std::string ch = channelName("stale");
  auto first = ShmWriter::create(opts(ch));
  ASSERT_TRUE(first);
  ShmWriter* crashed = std::move(first).value().release();  // never destroyed: like a crash
  (void)crashed;
  auto r = ShmReader::attach(ch);
  ASSERT_TRUE(r);
  const std::uint64_t oldGeneration = (*r)->generation();
  auto refused = ShmWriter::create(opts(ch));
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("in use by a running writer (pid " + std::to_string(::getpid())),
            std::string::npos)
      << refused.error().message;
  std::this_thread::sleep_for(std::chrono::milliseconds(2100));
  FrameMeta m;
  std::vector<std::byte> px;
  EXPECT_EQ((*r)->latest(m, px), ReadStatus::WriterGone);  // heartbeat silent for > 2 s
  auto replacement = ShmWriter::create(opts(ch));
  ASSERT_TRUE(replacement) << replacement.error().message;
  EXPECT_TRUE((*replacement)->replacedStale());
  auto r2 = ShmReader::attach(ch);
  ASSERT_TRUE(r2);
  EXPECT_NE((*r2)->generation(), oldGeneration);
}

// The C SDK end to end: the example host (plain C) reads 5 frames from a live writer.
TEST(ShmChannel, CHostExampleReadsFramesFromALiveWriter) {
  const std::string ch = channelName("sdk");
  auto o = opts(ch);
  o.format = FOGBEAM_FORMAT_RGBA8_SRGB;
  o.distance = false;
  auto w = ShmWriter::create(o);
  ASSERT_TRUE(w);
  std::atomic<bool> stop{false};
  std::thread writer([&] {
    std::vector<std::byte> px(64 * 32 * 4, std::byte{200});
    for (std::uint64_t f = 1; !stop.load(); ++f) {
      FrameMeta m;
      m.frame = f;
      m.total_ms = 1.0;
      (*w)->publish(m, px);
      std::this_thread::sleep_for(std::chrono::milliseconds(16));
    }
  });
  const std::string cmd = std::string(FOGBEAM_HOST_EXAMPLE) + " " + ch + " 5 5 > /dev/null";
  const int rc = std::system(cmd.c_str());
  stop = true;
  writer.join();
  EXPECT_EQ(rc, 0) << cmd;
}

}  // namespace
}  // namespace fogbeam::ipc
