// fogbeam — UniqueFd: the one owner of a POSIX file descriptor (a socket, a shared-memory object,
// a file). Move-only; the descriptor is closed exactly once, by whoever holds it last.
//
// Why hand-written: GCC 12's libstdc++ has no std::experimental::unique_resource and Debian 12's
// Boost (1.74) predates boost::scope::unique_fd (1.85).
//
// What close(2) failing means on Linux, and what this class does about it:
//   * EINTR, EIO: the descriptor is released all the same (close(2), "Dealing with error returns
//     from close()"); retrying would close a number another thread may have been given since, so
//     nothing is ever retried. For sockets and shm objects nothing is lost; a caller that wrote a
//     file through the descriptor and must know whether the data reached it calls close() and
//     checks the Status. The destructor and reset() ignore these two.
//   * EBADF: the number was not open, i.e. someone else closed it (a double close). That is a bug
//     that may already have closed another owner's descriptor: the destructor and reset() print the
//     descriptor to stderr and abort (error policy, fogbeam/util/result.hpp: bugs abort).
// The destructor and reset() keep errno as it was, so an error path may release its descriptor
// before it reads errno for its message.
//
// Thread-safety: a UniqueFd is a value owned by one thread at a time; its members are not
// synchronised. get() from other threads is safe while the owner neither moves, resets nor
// destroys it (e.g. a receive thread polls get() and the owner closes only after joining that
// thread). Using the descriptor itself from several threads is the system call's business.
#pragma once

#include <fogbeam/util/result.hpp>

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

namespace fogbeam {

class UniqueFd {
 public:
  /// Empty (get() = −1).
  UniqueFd() noexcept = default;
  /// Takes ownership of `fd`; any negative value means empty, so the result of open(2),
  /// socket(2) or shm_open(3) can be wrapped before it is checked (errno is not touched).
  explicit UniqueFd(int fd) noexcept : fd_(fd < 0 ? -1 : fd) {}
  ~UniqueFd() { reset(); }

  UniqueFd(UniqueFd&& other) noexcept : fd_(other.release()) {}
  UniqueFd& operator=(UniqueFd&& other) noexcept {
    if (this != &other) reset(other.release());
    return *this;
  }
  UniqueFd(const UniqueFd&) = delete;
  UniqueFd& operator=(const UniqueFd&) = delete;

  /// The descriptor, −1 when empty. Ownership stays here.
  [[nodiscard]] int get() const noexcept { return fd_; }
  [[nodiscard]] bool valid() const noexcept { return fd_ >= 0; }
  explicit operator bool() const noexcept { return valid(); }

  /// Gives up ownership without closing: the caller now owns the returned descriptor (−1 when
  /// empty).
  [[nodiscard]] int release() noexcept {
    const int fd = fd_;
    fd_ = -1;
    return fd;
  }

  /// Closes the held descriptor (if any; errors as in the header comment) and takes `fd`.
  /// Resetting to the descriptor already held is a bug (it would be closed and kept): aborts.
  void reset(int fd = -1) noexcept {
    if (fd >= 0 && fd == fd_) bug(fd, "reset() to the descriptor it already holds");
    const int old = fd_;
    fd_ = fd < 0 ? -1 : fd;
    if (old < 0) return;
    const int savedErrno = errno;
    if (::close(old) != 0 && errno == EBADF) bug(old, "close: descriptor not open (closed twice?)");
    errno = savedErrno;
  }

  /// Closes now and reports close(2)'s failure ("close(fd 7): Input/output error"); the object is
  /// empty afterwards whatever the result (Linux releases the descriptor even on error). Empty:
  /// Ok. EBADF is returned like any other error here: the caller asked to hear about it.
  [[nodiscard]] Status close() {
    const int old = fd_;
    fd_ = -1;
    if (old < 0 || ::close(old) == 0) return Ok{};
    return Error{"close(fd " + std::to_string(old) + "): " + std::strerror(errno)};
  }

 private:
  [[noreturn]] static void bug(int fd, const char* what) noexcept {
    std::fprintf(stderr, "fogbeam: UniqueFd(fd %d): %s\n", fd, what);
    std::abort();
  }

  int fd_ = -1;
};

}  // namespace fogbeam
