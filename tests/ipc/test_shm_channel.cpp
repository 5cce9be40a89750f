// Shared-memory channels: round trip, permissions, no torn frame under a fast writer, closed /
// stale / live segments, reader errors, the owners of names and mappings, and the C SDK's example
// host against a live writer.
#include <fogbeam/fogbeam_host.h>
#include <fogbeam/ipc/shm_channel.hpp>
#include <fogbeam/ipc/shm_mapping.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <csignal>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
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

// Layout version 2's fields (docs/shm.md): the frustum of an off-axis view and the host frame an
// overlay answers; and a segment of another layout version is refused by name, both ways.
TEST(ShmChannel, Version2FieldsRoundTripAndAnotherVersionIsRefused) {
  const std::string ch = channelName("v2");
  auto w = ShmWriter::create(opts(ch));
  ASSERT_TRUE(w) << w.error().message;
  FrameMeta out;
  out.frame = 3;
  out.frustum_deg = {10.0f, 50.0f, 20.0f, 18.5f};
  out.host_frame = 1234567;
  std::vector<std::byte> pixels(64 * 32 * 8);
  (*w)->publish(out, pixels, std::vector<float>(64 * 32, 1.0f));
  {
    auto r = ShmReader::attach(ch);
    ASSERT_TRUE(r) << r.error().message;
    FrameMeta m;
    std::vector<std::byte> px;
    ASSERT_EQ((*r)->latest(m, px), ReadStatus::Ok);
    EXPECT_EQ(m.frustum_deg, out.frustum_deg);
    EXPECT_EQ(m.host_frame, 1234567u);
  }
  // A version-1 segment (a writer built before the change), as this reader sees it.
  UniqueFd fd(::shm_open(("/fogbeam." + ch).c_str(), O_RDWR, 0));
  ASSERT_TRUE(fd);
  const std::uint16_t v1 = 1;
  ASSERT_EQ(::pwrite(fd.get(), &v1, sizeof v1, FOGBEAM_HDR_VERSION), static_cast<ssize_t>(sizeof v1));
  auto old = ShmReader::attach(ch);
  ASSERT_FALSE(old);
  EXPECT_NE(old.error().message.find("layout version 1, this reader knows 2"), std::string::npos) << old.error().message;
}

// `fogbeam view` polls latestTag() and copies only when it changed: it must change with every
// publish, even when the frame number repeats (lock-step answers the host's frame numbers).
TEST(ShmChannel, LatestTagChangesWithEveryPublish) {
  const std::string ch = channelName("tag");
  auto w = ShmWriter::create(opts(ch));
  ASSERT_TRUE(w) << w.error().message;
  auto r = ShmReader::attach(ch);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ((*r)->latestTag(), 0u);
  std::vector<std::byte> pixels(64 * 32 * 8);
  FrameMeta m;
  m.frame = 7;
  std::uint64_t previous = 0;
  for (int i = 0; i < 4; ++i) {
    const std::uint32_t slot = (*w)->publish(m, pixels);
    const std::uint64_t tag = (*r)->latestTag();
    EXPECT_EQ(tag, (std::uint64_t{7} << 8) | slot);
    EXPECT_NE(tag, previous);
    previous = tag;
  }
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

// The writer publishes as fast as it can for 2 s, each frame filled with one byte value derived
// from its number, while two readers copy frames; no reader may accept a frame whose bytes or
// metadata disagree. (On 2 cores the three threads interleave, so overlaps do happen.)
TEST(ShmChannel, NoTornFrameWhileAWriterAndTwoReadersHammerForTwoSeconds) {
  const std::string ch = channelName("torn");
  auto w = ShmWriter::create(opts(ch, 256, 128));
  ASSERT_TRUE(w);
  std::atomic<bool> done{false};
  std::atomic<std::uint64_t> published{0};
  std::thread writer([&] {
    std::vector<std::byte> px(256 * 128 * 8);
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(2);
    for (std::uint64_t f = 1; std::chrono::steady_clock::now() < end; ++f) {
      std::fill(px.begin(), px.end(), static_cast<std::byte>(f & 0xFF));
      FrameMeta m;
      m.frame = f;
      m.sim_time_s = static_cast<double>(f);
      (*w)->publish(m, px);
      published = f;
    }
    done = true;
  });
  struct Count {
    std::size_t ok = 0, bad = 0, busy = 0;
    std::uint64_t retries = 0;
  };
  auto readLoop = [&](Count& c) {
    auto r = ShmReader::attach(ch);
    ASSERT_TRUE(r);
    FrameMeta m;
    std::vector<std::byte> px;
    while (!done.load()) {
      const ReadStatus s = (*r)->latest(m, px);
      if (s == ReadStatus::Busy) ++c.busy;
      if (s != ReadStatus::Ok) continue;
      ++c.ok;
      const auto v = static_cast<std::byte>(m.frame & 0xFF);
      if (m.sim_time_s != static_cast<double>(m.frame) ||
          std::any_of(px.begin(), px.end(), [&](std::byte b) { return b != v; }))
        ++c.bad;
    }
    c.retries = (*r)->retries();
  };
  Count c1, c2;
  std::thread r1([&] { readLoop(c1); }), r2([&] { readLoop(c2); });
  writer.join();
  r1.join();
  r2.join();
  std::printf("  %llu frames published; readers: %zu + %zu whole frames, %llu + %llu retries, %zu + %zu torn accepted\n",
              static_cast<unsigned long long>(published.load()), c1.ok, c2.ok,
              static_cast<unsigned long long>(c1.retries), static_cast<unsigned long long>(c2.retries), c1.bad, c2.bad);
  EXPECT_EQ(c1.bad + c2.bad, 0u);
  EXPECT_GT(c1.ok, 0u);
  EXPECT_GT(c2.ok, 0u);
}

// Processes: a reader killed in the middle of its reads leaves the writer and other readers
// unaffected (it has no write access); a writer killed with SIGKILL is seen as gone at once (its
// pid is dead), and a restarted writer replaces its segment with a new generation.
TEST(ShmChannel, KilledReaderAndKilledThenRestartedWriter) {
  const std::string ch = channelName("kill");
  {
    auto w = ShmWriter::create(opts(ch));
    ASSERT_TRUE(w);
    std::vector<std::byte> px(64 * 32 * 8, std::byte{3});
    (*w)->publish(FrameMeta{1}, px);
    const pid_t reader = ::fork();
    if (reader == 0) {
      auto r = ShmReader::attach(ch);
      FrameMeta m;
      std::vector<std::byte> out;
      for (;;)
        if (r) (void)(*r)->latest(m, out);
    }
    ASSERT_GT(reader, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ::kill(reader, SIGKILL);
    ::waitpid(reader, nullptr, 0);
    for (std::uint64_t f = 2; f < 10; ++f) (*w)->publish(FrameMeta{f}, px);
    auto r = ShmReader::attach(ch);
    ASSERT_TRUE(r);
    FrameMeta m;
    std::vector<std::byte> out;
    ASSERT_EQ((*r)->latest(m, out), ReadStatus::Ok);
    EXPECT_EQ(m.frame, 9u);
  }
  // A writer process killed without cleaning up.
  const pid_t writer = ::fork();
  if (writer == 0) {
    auto w = ShmWriter::create(opts(ch));
    if (!w) ::_exit(2);
    std::vector<std::byte> px(64 * 32 * 8, std::byte{5});
    for (std::uint64_t f = 1;; ++f) {
      (*w)->publish(FrameMeta{f}, px);
      ::usleep(1000);
    }
  }
  ASSERT_GT(writer, 0);
  std::unique_ptr<ShmReader> r;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  FrameMeta m;
  std::vector<std::byte> out;
  while (std::chrono::steady_clock::now() < end) {
    auto a = ShmReader::attach(ch);
    if (a && (*a)->latest(m, out) == ReadStatus::Ok) {
      r = std::move(a).value();
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_TRUE(r) << "the child writer never published";
  const std::uint64_t oldGeneration = r->generation();
  ::kill(writer, SIGKILL);
  ::waitpid(writer, nullptr, 0);
  EXPECT_EQ(r->latest(m, out), ReadStatus::WriterGone);  // at once: the pid is dead
  auto restarted = ShmWriter::create(opts(ch));           // no wait for the heartbeat to age
  ASSERT_TRUE(restarted) << restarted.error().message;
  EXPECT_TRUE((*restarted)->replacedStale());
  auto again = ShmReader::attach(ch);
  ASSERT_TRUE(again);
  EXPECT_NE((*again)->generation(), oldGeneration);
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
  const UniqueFd fd(::shm_open(("/fogbeam." + ch).c_str(), O_RDWR, 0));
  ASSERT_TRUE(fd);
  struct stat st {};
  ASSERT_EQ(::fstat(fd.get(), &st), 0);
  auto map = ShmMapping::map(fd.get(), static_cast<std::size_t>(st.st_size), true, ch);
  ASSERT_TRUE(map) << map.error().message;
  auto* seq = reinterpret_cast<std::uint64_t*>(map->data() + FOGBEAM_SHM_HEADER_SIZE + FOGBEAM_SLOT_SEQ);
  const std::uint64_t even = *seq;
  EXPECT_EQ(even % 2, 0u);
  *seq = even + 1;  // odd: being written
  FrameMeta m;
  std::vector<std::byte> out;
  EXPECT_EQ((*r)->latest(m, out), ReadStatus::Busy);
  EXPECT_GE((*r)->retries(), 8u);
  *seq = even;
  EXPECT_EQ((*r)->latest(m, out), ReadStatus::Ok);
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
  // Released without running its destructor until the end of the test: like a crash.
  ShmWriter* crashed = std::move(first).value().release();
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
  // Now free the "crashed" writer (its mapping is of the old, unlinked segment), so that the
  // leak checker of the sanitizer build stays meaningful. Its name is its replacement's now: it
  // must leave that segment alone (ShmName's identity check).
  delete crashed;
  EXPECT_EQ(::access(("/dev/shm/fogbeam." + ch).c_str(), F_OK), 0) << "the replaced writer unlinked its replacement";
  auto r3 = ShmReader::attach(ch);
  ASSERT_TRUE(r3) << r3.error().message;
  EXPECT_EQ((*r3)->generation(), (*replacement)->generation());
}

// ShmName (shm_mapping.hpp): the name of a segment this process created is unlinked once, by
// unlink() or the destructor; not when released; and not once another segment has taken the name.
TEST(ShmChannel, ASegmentNameIsUnlinkedOnceAndOnlyWhileItIsOurs) {
  const std::string name = "/fogbeam." + channelName("name");
  auto exists = [&] { return ::access(("/dev/shm" + name).c_str(), F_OK) == 0; };
  auto createSegment = [&] {
    UniqueFd fd(::shm_open(name.c_str(), O_CREAT | O_EXCL | O_RDWR | O_CLOEXEC, 0600));
    EXPECT_TRUE(fd) << std::strerror(errno);
    return fd;
  };
  {
    const UniqueFd fd = createSegment();
    ShmName owner(name, fd.get());
    EXPECT_EQ(owner.name(), name);
    const Status first = owner.unlink();
    EXPECT_TRUE(first) << first.error().message;
    EXPECT_FALSE(exists());
    EXPECT_FALSE(owner);
    // Another writer creates the name again: neither a second unlink() nor the destructor may
    // remove its segment.
    const UniqueFd other = createSegment();
    EXPECT_TRUE(owner.unlink());
  }
  EXPECT_TRUE(exists());
  ASSERT_EQ(::shm_unlink(name.c_str()), 0);
  {  // The destructor unlinks; a moved-from owner does not.
    const UniqueFd fd = createSegment();
    ShmName a(name, fd.get());
    {
      const ShmName b(std::move(a));
      EXPECT_FALSE(a);  // NOLINT(bugprone-use-after-move): moved-from owns nothing, by contract
      EXPECT_TRUE(exists());
    }
    EXPECT_FALSE(exists());
  }
  {  // Released: left in place.
    const UniqueFd fd = createSegment();
    ShmName owner(name, fd.get());
    EXPECT_EQ(owner.release(), name);
  }
  EXPECT_TRUE(exists());
  {  // A name replaced by another segment is left alone, and unlink() says why.
    UniqueFd fd(::shm_open(name.c_str(), O_RDWR | O_CLOEXEC, 0));
    ASSERT_TRUE(fd);
    ShmName owner(name, fd.get());
    ASSERT_EQ(::shm_unlink(name.c_str()), 0);
    const UniqueFd replacement = createSegment();
    const Status s = owner.unlink();
    ASSERT_FALSE(s);
    EXPECT_EQ(s.error().message, "shm_unlink " + name + ": the name refers to another writer's segment now: left alone");
    EXPECT_TRUE(exists());
  }
  ASSERT_EQ(::shm_unlink(name.c_str()), 0);
}

// ShmMapping (shm_mapping.hpp): maps what it is asked to, says why it could not, and unmaps on
// destruction (mincore(2) fails with ENOMEM for an address range that is not mapped).
TEST(ShmChannel, AMappingIsUnmappedByItsOwner) {
  const std::string name = "/fogbeam." + channelName("map");
  const UniqueFd fd(::shm_open(name.c_str(), O_CREAT | O_EXCL | O_RDWR | O_CLOEXEC, 0600));
  ASSERT_TRUE(fd);
  const ShmName owner(name, fd.get());
  const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  ASSERT_EQ(::ftruncate(fd.get(), static_cast<off_t>(page)), 0);
  void* address = nullptr;
  unsigned char resident = 0;
  {
    auto m = ShmMapping::map(fd.get(), page, true, name);
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_EQ(m->size(), page);
    m->data()[0] = std::byte{42};
    address = m->data();
    EXPECT_EQ(::mincore(address, page, &resident), 0);
    ShmMapping moved = std::move(m).value();
    EXPECT_EQ(moved.data(), address);
  }
  EXPECT_EQ(::mincore(address, page, &resident), -1);
  EXPECT_EQ(errno, ENOMEM);
  auto again = ShmMapping::map(fd.get(), page, false, name);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->data()[0], std::byte{42});  // the bytes live in the segment, not the mapping
  EXPECT_TRUE(again->unmap());
  EXPECT_FALSE(*again);
  const auto bad = ShmMapping::map(-1, page, false, "nothing");
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().message,
            "mmap nothing (" + std::to_string(page) + " bytes): " + std::strerror(EBADF));
}

// A writer that cannot give its new segment its size (ftruncate fails: here the file-size limit,
// in a child process) reports it and leaves no segment behind: the half-made one is unlinked by its
// owner, once.
TEST(ShmChannel, AWriterThatCannotSizeItsSegmentLeavesNoneBehind) {
  const std::string ch = channelName("trunc");
  const pid_t child = ::fork();
  if (child == 0) {
    ::signal(SIGXFSZ, SIG_IGN);  // the limit also sends SIGXFSZ; ftruncate then fails with EFBIG
    rlimit limit{};
    ::getrlimit(RLIMIT_FSIZE, &limit);
    limit.rlim_cur = 4096;
    if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) ::_exit(10);
    auto w = ShmWriter::create(opts(ch));
    if (w) ::_exit(11);
    const std::string expected = "ftruncate /fogbeam." + ch + " to ";
    if (w.error().message.rfind(expected, 0) != 0) ::_exit(12);
    if (w.error().message.find(std::strerror(EFBIG)) == std::string::npos) ::_exit(13);
    ::_exit(::access(("/dev/shm/fogbeam." + ch).c_str(), F_OK) == 0 ? 14 : 0);
  }
  ASSERT_GT(child, 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "10 setrlimit, 11 created, 12/13 message, 14 segment left behind";
  EXPECT_NE(::access(("/dev/shm/fogbeam." + ch).c_str(), F_OK), 0);
  auto w = ShmWriter::create(opts(ch));  // and the name is free for a writer that can
  ASSERT_TRUE(w) << w.error().message;
  EXPECT_FALSE((*w)->replacedStale());
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
