// UniqueFd (util/unique_fd.hpp): closes exactly once, hands ownership over on move and release,
// reports close()'s failure, keeps errno, and aborts on a double close.
#include <fogbeam/util/unique_fd.hpp>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <utility>

namespace fogbeam {
namespace {

bool isOpen(int fd) { return ::fcntl(fd, F_GETFD) != -1; }

// A pipe's read end sees end-of-file once every write end is closed: proof that the owner of the
// write end closed it (not merely forgot the number).
struct Pipe {
  UniqueFd readEnd, writeEnd;
  Pipe() {
    int fds[2] = {-1, -1};
    EXPECT_EQ(::pipe2(fds, O_CLOEXEC), 0);
    readEnd.reset(fds[0]);
    writeEnd.reset(fds[1]);
  }
  bool writeEndClosed() const {
    char c = 0;
    return ::read(readEnd.get(), &c, 1) == 0;
  }
};

TEST(UniqueFd, EmptyByDefaultAndForNegativeDescriptors) {
  const UniqueFd none;
  EXPECT_EQ(none.get(), -1);
  EXPECT_FALSE(none.valid());
  EXPECT_FALSE(static_cast<bool>(none));
  const UniqueFd failed(-5);  // e.g. socket(2)'s −1
  EXPECT_EQ(failed.get(), -1);
}

TEST(UniqueFd, DestructorClosesTheDescriptor) {
  Pipe p;
  {
    const UniqueFd owner(std::move(p.writeEnd));
    EXPECT_FALSE(p.writeEnd.valid());  // moved from: empty
    EXPECT_TRUE(isOpen(owner.get()));
  }
  EXPECT_TRUE(p.writeEndClosed());
}

TEST(UniqueFd, MoveAssignmentClosesWhatTheTargetHeld) {
  Pipe a, b;
  const int bWrite = b.writeEnd.get();
  a.writeEnd = std::move(b.writeEnd);
  EXPECT_TRUE(a.writeEndClosed());  // a's own write end is gone
  EXPECT_EQ(a.writeEnd.get(), bWrite);
  EXPECT_FALSE(b.writeEnd.valid());
  a.writeEnd.reset();
  EXPECT_TRUE(b.writeEndClosed());
}

TEST(UniqueFd, ReleaseHandsOwnershipOverWithoutClosing) {
  Pipe p;
  const int fd = p.writeEnd.release();
  EXPECT_FALSE(p.writeEnd.valid());
  EXPECT_TRUE(isOpen(fd));
  ::close(fd);
  EXPECT_TRUE(p.writeEndClosed());
}

TEST(UniqueFd, ResetClosesTheOldAndTakesTheNew) {
  Pipe a, b;
  const int bWrite = b.writeEnd.release();
  a.writeEnd.reset(bWrite);
  EXPECT_TRUE(a.writeEndClosed());
  EXPECT_EQ(a.writeEnd.get(), bWrite);
}

TEST(UniqueFd, CloseReportsTheResultAndEmpties) {
  Pipe p;
  const Status ok = p.writeEnd.close();
  EXPECT_TRUE(ok);
  EXPECT_FALSE(p.writeEnd.valid());
  EXPECT_TRUE(p.writeEndClosed());
  EXPECT_TRUE(p.writeEnd.close());  // empty: nothing to close

  // A descriptor closed behind the owner's back: close() says so instead of aborting.
  Pipe q;
  const int fd = q.writeEnd.get();
  ::close(fd);
  const Status bad = q.writeEnd.close();
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().message, "close(fd " + std::to_string(fd) + "): " + std::strerror(EBADF));
  EXPECT_FALSE(q.writeEnd.valid());
}

TEST(UniqueFd, ResetKeepsErrnoForTheCallersMessage) {
  Pipe p;
  errno = EADDRINUSE;
  p.writeEnd.reset();
  EXPECT_EQ(errno, EADDRINUSE);
}

TEST(UniqueFdDeathTest, ADoubleCloseAborts) {
  EXPECT_DEATH(
      {
        Pipe p;
        ::close(p.writeEnd.get());  // someone else closes what the UniqueFd owns
        p.writeEnd.reset();
      },
      "closed twice");
  EXPECT_DEATH(
      {
        Pipe p;
        p.writeEnd.reset(p.writeEnd.get());
      },
      "already holds");
}

}  // namespace
}  // namespace fogbeam
