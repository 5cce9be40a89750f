// The frame path's worker pool (util/thread_pool.hpp): every index exactly once, thread ids in
// [0, size()), the caller working too, and repeated loops on the same workers.
#include <fogbeam/util/thread_pool.hpp>

#include <gtest/gtest.h>

#include <atomic>
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
  ThreadPool pool(2);
  std::mutex m;
  std::set<unsigned> seen;
  std::set<std::thread::id> callerIds;
  const std::thread::id caller = std::this_thread::get_id();
  pool.parallelForIndexed(20'000, [&](std::size_t, unsigned t) {
    ASSERT_LT(t, pool.size());
    std::lock_guard lock(m);
    seen.insert(t);
    if (t == 0) callerIds.insert(std::this_thread::get_id());
  });
  EXPECT_TRUE(seen.count(0));
  if (!callerIds.empty()) {
    EXPECT_EQ(callerIds.size(), 1u);
    EXPECT_EQ(*callerIds.begin(), caller);
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
