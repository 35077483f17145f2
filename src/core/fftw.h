// RAII for FFTW (the Debian libfftw3 double-precision API): buffers from fftw_malloc and plans.
// Planning is not thread-safe in FFTW; executing a plan on other buffers of the same alignment
// (fftw_execute_dft, new-array execution) is, so plans are made under `planMutex()` and shared.
#pragma once
#include <fftw3.h>

#include <memory>
#include <mutex>
#include <type_traits>

namespace mbsdf::fftw {

struct Free {
  void operator()(void* p) const { fftw_free(p); }
};
struct PlanDestroy {
  void operator()(fftw_plan p) const { fftw_destroy_plan(p); }
};
using Plan = std::unique_ptr<std::remove_pointer_t<fftw_plan>, PlanDestroy>;
template <class T>
using Buffer = std::unique_ptr<T, Free>;

template <class T>
Buffer<T> allocate(size_t n) {
  return Buffer<T>(static_cast<T*>(fftw_malloc(sizeof(T) * n)));
}

inline std::mutex& planMutex() {
  static std::mutex m;
  return m;
}

}  // namespace mbsdf::fftw
