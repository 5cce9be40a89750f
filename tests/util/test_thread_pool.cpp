// The frame path's worker pool (util/thread_pool.hpp): every index exactly once, thread ids in
// [0, size()), the caller working too, and repeated loops on the same workers.
#include <fogbeam/util/thread_pool.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

namespace fogbeam {
namespace {

TEST(ThreadPool, EveryIndexRunsExactlyOnce) {
  ThreadPool pool(3);
  EXPECT_EQ(pool.size(), 3u);
  for (std::size_t n : {0u, 1u, 7u, 1000u, 100'003u}) {
    std::vector<std::atomic<int>> hits(n);
    pool.parallelFor(n, [&](std::size_t i) { hits[i].fetch_add(1, std::memory_order_relaxed); });
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << "n " << n << " index " << i;
  }
}

TEST(ThreadPool, ThreadIndicesNameDistinctThreadsAndTheCallerIsZero) {
  // Every body waits (up to 10 s) until both threads have taken an index: otherwise a worker
  // that wakes while the caller is descheduled may take all of them, which is correct behaviour
  // but would leave nothing to check (CI saw that once on a loaded machine). A pool whose caller
  // never works makes this wait time out, and the test fails.
  ThreadPool pool(2);
  std::mutex m;
  std::condition_variable bothSeen;
  std::set<unsigned> seen;
  std::set<std::thread::id> ids0, ids1;
  const std::thread::id caller = std::this_thread::get_id();
  pool.parallelForIndexed(1'000, [&](std::size_t, unsigned t) {
    ASSERT_LT(t, pool.size());
    std::unique_lock lock(m);
    seen.insert(t);
    (t == 0 ? ids0 : ids1).insert(std::this_thread::get_id());
    bothSeen.notify_all();
    bothSeen.wait_for(lock, std::chrono::seconds(10), [&] { return seen.size() == 2; });
  });
  ASSERT_EQ(seen.size(), 2u) << "one thread took every index while the other waited 10 s";
  ASSERT_EQ(ids0.size(), 1u);
  EXPECT_EQ(*ids0.begin(), caller);
  ASSERT_EQ(ids1.size(), 1u);
  EXPECT_NE(*ids1.begin(), caller);
}

// Loops back to back, each so short that the caller often does all of it before a worker has
// woken: the worker then wakes into a loop that has returned (or into the next one). It must
// take nothing of the loop that has returned (its function and count are gone, its counter is
// the next loop's) and each index of the next must still run once. CI's ThreadSanitizer run
// caught a worker reading the count of a loop that had returned while the next loop set it
// (scripts/tsan.sh runs this test); in a plain build the same fault can run an index twice.
TEST(ThreadPool, AWorkerWakingLateTakesNothingOfALoopThatHasReturned) {
  ThreadPool pool(2);
  std::vector<std::atomic<int>> hits(4);
  for (int k = 0; k < 20'000; ++k) {
    const std::size_t n = 2 + static_cast<std::size_t>(k % 3);
    for (std::size_t i = 0; i < n; ++i) hits[i].store(0, std::memory_order_relaxed);
    pool.parallelFor(n, [&hits, n](std::size_t i) {
      ASSERT_LT(i, n);
      hits[i].fetch_add(1, std::memory_order_relaxed);
    });
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << "loop " << k << " index " << i;
  }
}

TEST(ThreadPool, AOneThreadPoolRunsOnTheCaller) {
  ThreadPool pool(1);
  EXPECT_EQ(pool.size(), 1u);
  const std::thread::id caller = std::this_thread::get_id();
  bool allOnCaller = true;
  pool.parallelFor(100, [&](std::size_t) { allOnCaller = allOnCaller && std::this_thread::get_id() == caller; });
  EXPECT_TRUE(allOnCaller);
}

}  // namespace
}  // namespace fogbeam
