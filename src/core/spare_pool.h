// Objects kept between uses for the next, where uses may run on several threads at once: large
// working buffers whose pages would cost thousands of faults to touch anew for every tile (the path
// tracer's wavefront, runPaths' tally chunks). take() gives a spare, or a default-constructed
// object when none is left; a Lease takes one and gives it back when it ends, also when an
// exception ends it.
#pragma once
#include <mutex>
#include <utility>
#include <vector>

namespace mbsdf {

template <typename T>
class SparePool {
 public:
  T take() {
    std::lock_guard lock(mutex_);
    if (spare_.empty()) return T{};
    T v = std::move(spare_.back());
    spare_.pop_back();
    return v;
  }
  void giveBack(T&& v) {
    std::lock_guard lock(mutex_);
    spare_.push_back(std::move(v));
  }

  class Lease {
   public:
    explicit Lease(SparePool& pool) : pool_(pool), value_(pool.take()) {}
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    ~Lease() { pool_.giveBack(std::move(value_)); }
    T& operator*() { return value_; }
    T* operator->() { return &value_; }

   private:
    SparePool& pool_;
    T value_;
  };

 private:
  std::mutex mutex_;
  std::vector<T> spare_;
};

}  // namespace mbsdf
