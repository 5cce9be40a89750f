// fogbeam — a cache of immutable tables shared between the objects that use them.
//
// Tables (G moments, F tables, kernel expansions) cost milliseconds to seconds to build and are
// the same for every evaluator with the same key (a phase function, a profile). SharedCache
// hands out the one alive for a key, builds it under the cache's lock when there is none (one
// build at a time: the others wait for it, none builds twice), and keeps the `keepRecent` most
// recently built alive even when nobody holds them, so that objects built one after another
// (per-frame evaluators, a fog that alternates) do not rebuild them.
//
// `owner` ties an entry to the object it was built from (a profile): an entry whose owner has
// died is stale even if a new owner reuses the same address.
//
// Thread-safety: get() may be called from any thread.
#pragma once

#include <cstddef>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

namespace fogbeam {

template <class Key, class T>
class SharedCache {
 public:
  explicit SharedCache(std::size_t keepRecent) : keepRecent_(keepRecent) {}

  /// The table for `key`, from make() (returning std::shared_ptr<const T>) if none is alive.
  template <class Make>
  [[nodiscard]] std::shared_ptr<const T> get(const Key& key, Make&& make, std::weak_ptr<const void> owner = {}) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (auto it = map_.find(key); it != map_.end()) {
      const bool ownerAlive = !it->second.owner.owner_before(owner) && !owner.owner_before(it->second.owner);
      if (auto sp = it->second.table.lock(); sp && ownerAlive) return sp;
    }
    std::shared_ptr<const T> sp = make();
    map_[key] = Entry{sp, owner};
    recent_.push_back(sp);
    if (recent_.size() > keepRecent_) recent_.erase(recent_.begin());
    return sp;
  }

 private:
  struct Entry {
    std::weak_ptr<const T> table;
    std::weak_ptr<const void> owner;
  };
  std::size_t keepRecent_;
  std::mutex mutex_;
  std::map<Key, Entry> map_;
  std::vector<std::shared_ptr<const T>> recent_;
};

}  // namespace fogbeam
