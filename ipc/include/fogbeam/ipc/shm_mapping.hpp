// fogbeam — owners of the two shared-memory resources besides the descriptor (which is a
// fogbeam::UniqueFd): a mapped region, and the name of a segment this process created.
//
//   ShmMapping  mmap(2)'d bytes and their length; munmap(2) on destruction.
//   ShmName     "/fogbeam.<channel>" created with shm_open(O_CREAT | O_EXCL); shm_unlink(3)ed at
//               most once, by unlink() or on destruction, whichever comes first, never when
//               released, and only while the name still refers to the segment this process created.
//
// ShmWriter and ShmReader (shm_channel.hpp) hold their segment through these, so every error path
// of ShmWriter::create() unlinks the half-made segment once, by the destructor. Why the identity
// check: a writer whose heartbeat stopped for 2 s is replaced by a new writer under the same name
// (docs/shm.md, "Segment"); if the old one then exits, unlinking by name alone would remove its
// replacement's segment. The check (shm_open + fstat: same device and inode) and the unlink are two
// calls, so a replacement made between them is still removed; the window is two system calls wide.
//
// Failures while destroying are logged (spdlog), not thrown: munmap fails only for a region it did
// not map (the region then stays mapped); shm_unlink is skipped when the name was removed or now
// refers to another segment, and fails when permissions changed.
//
// Thread-safety: values owned by one thread at a time; members are not synchronised. The mapped
// bytes themselves are shared with other processes: see shm_layout.h for how they are accessed.
#pragma once

#include <fogbeam/util/result.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>

namespace fogbeam::ipc {

class ShmMapping {
 public:
  /// Maps the first `length` bytes (> 0) of the shared-memory object `fd`, MAP_SHARED, readable,
  /// and writable when `writable`. `what` names the object in the error, e.g. "mmap /fogbeam.main
  /// (1048832 bytes): Cannot allocate memory". The descriptor may be closed afterwards.
  [[nodiscard]] static Result<ShmMapping> map(int fd, std::size_t length, bool writable, const std::string& what);

  ShmMapping() noexcept = default;  ///< empty
  ~ShmMapping();                    ///< munmap (a failure is logged)
  ShmMapping(ShmMapping&& other) noexcept;
  ShmMapping& operator=(ShmMapping&& other) noexcept;
  ShmMapping(const ShmMapping&) = delete;
  ShmMapping& operator=(const ShmMapping&) = delete;

  /// The first mapped byte (nullptr when empty). Readers map read-only: do not write through it.
  [[nodiscard]] std::byte* data() const noexcept { return data_; }
  /// Mapped length in bytes (0 when empty).
  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  explicit operator bool() const noexcept { return data_ != nullptr; }

  /// Unmaps now and reports munmap's failure; empty afterwards either way.
  [[nodiscard]] Status unmap();

 private:
  ShmMapping(std::byte* data, std::size_t size) noexcept : data_(data), size_(size) {}
  std::byte* data_ = nullptr;
  std::size_t size_ = 0;
};

class ShmName {
 public:
  ShmName() = default;  ///< owns no name
  /// Takes the duty to unlink `name` ("/fogbeam.<channel>"), whose segment is open as `fd`: call it
  /// right after shm_open with O_CREAT | O_EXCL succeeded, i.e. only for a segment this process
  /// created. Records the segment's identity (fstat of `fd`); should fstat fail, the identity is
  /// unknown and unlink() removes whatever the name refers to then.
  ShmName(std::string name, int fd) noexcept;
  ~ShmName();  ///< unlink() unless done or released (a failure is logged)
  ShmName(ShmName&& other) noexcept
      : dev_(other.dev_), ino_(other.ino_), identityKnown_(other.identityKnown_), name_(other.release()) {}
  ShmName& operator=(ShmName&& other) noexcept;
  ShmName(const ShmName&) = delete;
  ShmName& operator=(const ShmName&) = delete;

  /// The owned name; empty when none is owned (never owned, unlinked or released).
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  explicit operator bool() const noexcept { return !name_.empty(); }

  /// shm_unlink now, if the name still refers to the segment created; owns no name afterwards
  /// either way, so the name is never unlinked twice. Owning none: Ok. Errors say why nothing was
  /// removed: "shm_unlink /fogbeam.main: No such file or directory", "… refers to another
  /// writer's segment now: left alone".
  [[nodiscard]] Status unlink();
  /// Gives up the duty to unlink without unlinking; returns the name.
  [[nodiscard]] std::string release() noexcept { return std::exchange(name_, std::string()); }

 private:
  std::uint64_t dev_ = 0, ino_ = 0;  // the created segment's st_dev, st_ino
  bool identityKnown_ = false;
  std::string name_;
};

}  // namespace fogbeam::ipc
