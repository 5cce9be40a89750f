// The state store: updates, traffic semantics (update, remove, complete lists, expiry, the
// object limit) and consistent snapshots under concurrent writers.
#include <fogbeam/ipc/state_store.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <thread>

namespace fogbeam::ipc {
namespace {

Stamp at(Clock::time_point t, std::uint32_t seq = 1) {
  Stamp s;
  s.valid = true;
  s.received = t;
  s.sequence = seq;
  s.source = "test";
  return s;
}

TrafficObject car(std::uint32_t id, double x, bool removed = false) {
  TrafficObject o;
  o.id = id;
  o.pose.position_m = {x, 3.5, 0.0};
  o.removed = removed;
  return o;
}

TEST(StateStore, UpdatesArePublishedWithTheirStamps) {
  StateStore store;
  const auto t0 = Clock::now();
  EXPECT_FALSE(store.snapshot()->ego.stamp.valid);
  store.setEgo(EgoState{{}, 12.0f}, at(t0, 5));
  store.setLamps(LampState{light::kHighBeam, 0.0f}, at(t0, 6));
  const auto s = store.snapshot();
  EXPECT_TRUE(s->ego.stamp.valid);
  EXPECT_EQ(s->ego.value.speed_m_s, 12.0f);
  EXPECT_EQ(s->ego.stamp.sequence, 5u);
  EXPECT_EQ(s->lamps.value.lights, light::kHighBeam);
  EXPECT_EQ(s->version, 2u);
}

TEST(StateStore, TrafficIsUpdatedRemovedAndReplacedByCompleteLists) {
  StateStore store;
  const auto t0 = Clock::now();
  store.applyTraffic(TrafficList{false, {car(3, 30), car(1, 10), car(2, 20)}}, at(t0));
  auto s = store.snapshot();
  ASSERT_EQ(s->traffic.size(), 3u);
  EXPECT_EQ(s->traffic[0].object.id, 1u);  // sorted by id
  store.applyTraffic(TrafficList{false, {car(2, 25), car(1, 0, true)}}, at(t0));
  s = store.snapshot();
  ASSERT_EQ(s->traffic.size(), 2u);
  EXPECT_EQ(s->traffic[0].object.id, 2u);
  EXPECT_EQ(s->traffic[0].object.pose.position_m[0], 25.0);
  store.applyTraffic(TrafficList{true, {car(7, 70)}}, at(t0));  // complete: 2 and 3 are gone
  s = store.snapshot();
  ASSERT_EQ(s->traffic.size(), 1u);
  EXPECT_EQ(s->traffic[0].object.id, 7u);
}

TEST(StateStore, StaleObjectsExpireAndTheLimitHolds) {
  StateStoreOptions o;
  o.traffic_timeout_s = 0.5;
  o.max_traffic_objects = 4;
  StateStore store(o);
  const auto t0 = Clock::now();
  TrafficList many;
  for (std::uint32_t i = 0; i < 10; ++i) many.objects.push_back(car(i, i));
  EXPECT_EQ(store.applyTraffic(many, at(t0)), 6u);  // 6 refused, 4 kept
  EXPECT_EQ(store.snapshot()->traffic.size(), 4u);
  store.applyTraffic(TrafficList{false, {car(0, 1.0)}}, at(t0 + std::chrono::milliseconds(400)));
  const auto later = t0 + std::chrono::milliseconds(700);
  const auto s = store.snapshot();
  std::size_t live = 0;
  for (const auto& e : s->traffic) live += s->live(e, later) ? 1u : 0u;
  EXPECT_EQ(live, 1u);  // only object 0 was updated within 0.5 s
  EXPECT_EQ(store.expire(later), 3u);
  EXPECT_EQ(store.snapshot()->traffic.size(), 1u);
  EXPECT_EQ(store.expire(later), 0u);
  EXPECT_EQ(store.expiredTotal(), 3u);  // counted once, for the service log and status reply
}

// Writers publish (ego.speed, lamps.bending) pairs that are always equal; a reader that ever
// saw them differ would have seen half of an update.
TEST(StateStore, SnapshotsAreConsistentUnderConcurrentWriters) {
  StateStore store;
  std::atomic<bool> stop{false};
  std::atomic<int> torn{0};
  std::atomic<long> reads{0};
  std::thread reader([&] {
    while (!stop.load()) {
      const auto s = store.snapshot();
      if (s->traffic.size() == 2 && s->traffic[0].object.pose.position_m[0] != s->traffic[1].object.pose.position_m[0])
        ++torn;
      ++reads;
    }
  });
  std::vector<std::thread> writers;
  for (int w = 0; w < 2; ++w)
    writers.emplace_back([&, w] {
      while (reads.load() == 0) std::this_thread::yield();  // the reader is running: overlap guaranteed
      for (int i = 0; i < 2000; ++i) {
        const double x = w * 10000 + i;
        store.applyTraffic(TrafficList{true, {car(1, x), car(2, x)}}, at(Clock::now()));
      }
    });
  for (auto& t : writers) t.join();
  stop = true;
  reader.join();
  EXPECT_EQ(torn.load(), 0);
  EXPECT_GT(reads.load(), 0);
  EXPECT_EQ(store.snapshot()->version, 4000u);
}

}  // namespace
}  // namespace fogbeam::ipc
