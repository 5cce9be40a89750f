#include <fogbeam/util/thread_pool.hpp>

namespace fogbeam {

ThreadPool::ThreadPool(unsigned threads) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  for (unsigned i = 1; i < threads; ++i) workers_.emplace_back([this, i] { workerLoop(i); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (auto& t : workers_) t.join();
}

void ThreadPool::runChunks(unsigned index) {
  for (std::size_t i = next_.fetch_add(1); i < n_; i = next_.fetch_add(1)) (*fn_)(i, index);
}

void ThreadPool::workerLoop(unsigned index) {
  std::size_t seen = 0;
  while (true) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
      // fn_ is null once the loop that woke this worker has returned (its caller did all of it
      // before this worker took the lock). Then there is nothing to take: its count and counter
      // are about to be the next loop's, which wakes this worker again (generation_ moves on).
      // A worker counted in busy_ is waited for before fn_, n_ and next_ change, so runChunks
      // reads them without the lock.
      if (fn_ == nullptr) continue;
      ++busy_;
    }
    runChunks(index);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      --busy_;
    }
    done_.notify_one();
  }
}

void ThreadPool::parallelFor(std::size_t n, const std::function<void(std::size_t)>& fn) {
  // A closure of one pointer: std::function keeps it without allocating.
  const auto* f = &fn;
  parallelForIndexed(n, [f](std::size_t i, unsigned) { (*f)(i); });
}

void ThreadPool::parallelForIndexed(std::size_t n, const std::function<void(std::size_t, unsigned)>& fn) {
  if (workers_.empty() || n <= 1) {
    for (std::size_t i = 0; i < n; ++i) fn(i, 0);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    fn_ = &fn;
    n_ = n;
    next_.store(0);
    ++generation_;
  }
  wake_.notify_all();
  runChunks(0);
  std::unique_lock<std::mutex> lock(mutex_);
  // Every worker that woke for this generation has finished when busy_ returns to 0 and the
  // counter has run past n (a worker that has not woken yet will find no work left).
  done_.wait(lock, [&] { return busy_ == 0 && next_.load() >= n_; });
  fn_ = nullptr;
}

}  // namespace fogbeam
