#include <fogbeam/ipc/state_store.hpp>

#include <algorithm>

namespace fogbeam::ipc {

StateStore::StateStore(const StateStoreOptions& options) : options_(options) {
  auto s = std::make_shared<SimSnapshot>();
  s->traffic_timeout_s = options_.traffic_timeout_s;
  s->lamps.value.lights = light::kInitialEgo;  // until the first lamp state (docs/service.md)
  current_.store(std::move(s));
}

std::shared_ptr<const SimSnapshot> StateStore::snapshot() const { return current_.load(std::memory_order_acquire); }

template <class F>
void StateStore::update(F&& change) {
  std::lock_guard<std::mutex> lock(writers_);
  auto next = std::make_shared<SimSnapshot>(*current_.load(std::memory_order_relaxed));
  change(*next);
  ++next->version;
  current_.store(std::move(next), std::memory_order_release);
}

void StateStore::setEgo(const EgoState& v, const Stamp& s) {
  update([&](SimSnapshot& n) { n.ego = {v, s}; });
}

void StateStore::setLamps(const LampState& v, const Stamp& s) {
  update([&](SimSnapshot& n) {
    LampState l = v;
    l.lights = (v.lights & ~busOwnedLights_) | (n.lamps.value.lights & busOwnedLights_);
    n.lamps = {l, s};
  });
}

void StateStore::setBusLights(std::uint32_t owned, std::uint32_t known, std::uint32_t bits, const Stamp& s) {
  known &= owned;
  if (known == 0) {
    std::lock_guard<std::mutex> lock(writers_);
    busOwnedLights_ |= owned;
    return;
  }
  update([&](SimSnapshot& n) {
    busOwnedLights_ |= owned;
    const Stamp before = n.lamps.stamp;
    n.lamps.value.lights = (n.lamps.value.lights & ~known) | (bits & known);
    n.lamps.stamp = s;
    if (before.valid) n.lamps.stamp.received = std::max(before.received, s.received);
  });
}

void StateStore::setEnvironment(const Environment& v, const Stamp& s) {
  update([&](SimSnapshot& n) { n.environment = {v, s}; });
}

void StateStore::setFrameRequest(const FrameRequest& v, const Stamp& s) {
  update([&](SimSnapshot& n) { n.frame_request = {v, s}; });
}

void StateStore::setVehicleSpeed(float speed_m_s, const Stamp& s) {
  update([&](SimSnapshot& n) { n.vehicle_speed_m_s = {speed_m_s, s}; });
}

std::size_t StateStore::applyTraffic(const TrafficList& list, const Stamp& s) {
  std::size_t refused = 0;
  update([&](SimSnapshot& n) {
    auto& t = n.traffic;
    auto find = [&](std::uint32_t id) {
      return std::lower_bound(t.begin(), t.end(), id,
                              [](const TrafficEntry& e, std::uint32_t v) { return e.object.id < v; });
    };
    if (list.complete) {
      // Objects the host no longer lists are gone. Ids listed as removed are gone too.
      std::vector<std::uint32_t> listed;
      listed.reserve(list.objects.size());
      for (const TrafficObject& o : list.objects)
        if (!o.removed) listed.push_back(o.id);
      std::sort(listed.begin(), listed.end());
      std::erase_if(t, [&](const TrafficEntry& e) {
        return !std::binary_search(listed.begin(), listed.end(), e.object.id);
      });
    }
    for (const TrafficObject& o : list.objects) {
      auto it = find(o.id);
      const bool present = it != t.end() && it->object.id == o.id;
      if (o.removed) {
        if (present) t.erase(it);
        continue;
      }
      if (present) {
        it->object = o;
        it->stamp = s;
      } else if (t.size() < options_.max_traffic_objects) {
        t.insert(it, TrafficEntry{o, s});
      } else {
        ++refused;
      }
    }
  });
  return refused;
}

std::size_t StateStore::expire(Clock::time_point now) {
  std::size_t purged = 0;
  // Only publish a new snapshot when something expires (readers keep their pointer otherwise).
  const auto cur = snapshot();
  if (std::none_of(cur->traffic.begin(), cur->traffic.end(),
                   [&](const TrafficEntry& e) { return !cur->live(e, now); }))
    return 0;
  update([&](SimSnapshot& n) {
    purged = static_cast<std::size_t>(std::erase_if(n.traffic, [&](const TrafficEntry& e) { return !n.live(e, now); }));
  });
  expired_.fetch_add(purged, std::memory_order_relaxed);
  return purged;
}

}  // namespace fogbeam::ipc
