// fogbeam — ShmMapping, ShmName (fogbeam/ipc/shm_mapping.hpp).
#include <fogbeam/ipc/shm_mapping.hpp>
#include <fogbeam/util/unique_fd.hpp>

#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstring>

namespace fogbeam::ipc {

Result<ShmMapping> ShmMapping::map(int fd, std::size_t length, bool writable, const std::string& what) {
  const int prot = writable ? PROT_READ | PROT_WRITE : PROT_READ;
  void* p = ::mmap(nullptr, length, prot, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED)
    return Error{"mmap " + what + " (" + std::to_string(length) + " bytes): " + std::strerror(errno)};
  return ShmMapping(static_cast<std::byte*>(p), length);
}

ShmMapping::~ShmMapping() {
  if (Status s = unmap(); !s) spdlog::error("shm: {}", s.error().message);
}

ShmMapping::ShmMapping(ShmMapping&& other) noexcept
    : data_(std::exchange(other.data_, nullptr)), size_(std::exchange(other.size_, 0)) {}

ShmMapping& ShmMapping::operator=(ShmMapping&& other) noexcept {
  if (this != &other) {
    if (Status s = unmap(); !s) spdlog::error("shm: {}", s.error().message);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
  }
  return *this;
}

Status ShmMapping::unmap() {
  std::byte* const data = std::exchange(data_, nullptr);
  const std::size_t size = std::exchange(size_, 0);
  if (data == nullptr || ::munmap(data, size) == 0) return Ok{};
  return Error{"munmap of " + std::to_string(size) + " bytes: " + std::strerror(errno)};
}

ShmName::ShmName(std::string name, int fd) noexcept : name_(std::move(name)) {
  struct stat st {};
  if (::fstat(fd, &st) == 0) {
    dev_ = st.st_dev;
    ino_ = st.st_ino;
    identityKnown_ = true;
  }
}

ShmName::~ShmName() {
  if (Status s = unlink(); !s) spdlog::warn("shm: {}", s.error().message);
}

ShmName& ShmName::operator=(ShmName&& other) noexcept {
  if (this != &other) {
    if (Status s = unlink(); !s) spdlog::warn("shm: {}", s.error().message);
    dev_ = other.dev_;
    ino_ = other.ino_;
    identityKnown_ = other.identityKnown_;
    name_ = other.release();
  }
  return *this;
}

Status ShmName::unlink() {
  const std::string name = release();
  if (name.empty()) return Ok{};
  if (identityKnown_) {
    // Is the name still ours? (See the header: a replacement may have taken it.)
    const UniqueFd current(::shm_open(name.c_str(), O_RDONLY | O_CLOEXEC, 0));
    if (!current) return Error{"shm_unlink " + name + ": " + std::strerror(errno)};
    struct stat st {};
    if (::fstat(current.get(), &st) != 0) return Error{"shm_unlink " + name + ": fstat: " + std::strerror(errno)};
    if (st.st_dev != dev_ || st.st_ino != ino_)
      return Error{"shm_unlink " + name + ": the name refers to another writer's segment now: left alone"};
  }
  if (::shm_unlink(name.c_str()) == 0) return Ok{};
  return Error{"shm_unlink " + name + ": " + std::strerror(errno)};
}

}  // namespace fogbeam::ipc
