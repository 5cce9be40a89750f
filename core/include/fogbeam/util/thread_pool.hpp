// fogbeam — a fixed pool of worker threads for data-parallel loops in the frame path.
//
// Why not std::async or OpenMP: the frame loop must not create threads or allocate per frame,
// and the project avoids an OpenMP runtime dependency for one loop shape. Workers are created
// once; parallelFor() hands out indices [0, n) in chunks through one atomic counter.
// Thread-safety: parallelFor() may be called from one thread at a time.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace fogbeam {

class ThreadPool {
 public:
  /// `threads` = 0 uses std::thread::hardware_concurrency(). The calling thread also works,
  /// so a pool of N threads starts N − 1 workers.
  explicit ThreadPool(unsigned threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  [[nodiscard]] unsigned size() const noexcept { return static_cast<unsigned>(workers_.size()) + 1; }

  /// Calls fn(i) for every i in [0, n), spread over the pool; returns when all are done.
  void parallelFor(std::size_t n, const std::function<void(std::size_t)>& fn);
  /// The same, with fn(i, t): t ∈ [0, size()) names the thread running it (0 = the caller), for
  /// per-thread scratch memory. Indices go to threads in no fixed order.
  void parallelForIndexed(std::size_t n, const std::function<void(std::size_t, unsigned)>& fn);

 private:
  void workerLoop(unsigned index);
  void runChunks(unsigned index);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  const std::function<void(std::size_t, unsigned)>* fn_ = nullptr;
  std::size_t n_ = 0;
  std::atomic<std::size_t> next_{0};
  std::size_t generation_ = 0;
  unsigned busy_ = 0;
  bool stop_ = false;
};

/// fn(i) for every i in [0, n): on `pool` when it has workers, else in place on the calling
/// thread, where the lambda is called directly (no std::function, so nothing is allocated).
/// `pool` may be null. Thread-safety as ThreadPool::parallelFor.
template <class Fn>
void parallelFor(ThreadPool* pool, std::size_t n, Fn&& fn) {
  if (pool != nullptr && pool->size() > 1) {
    pool->parallelFor(n, fn);
    return;
  }
  for (std::size_t i = 0; i < n; ++i) fn(i);
}

}  // namespace fogbeam
