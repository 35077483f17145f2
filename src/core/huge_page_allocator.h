// An allocator for large working buffers that asks the kernel for transparent huge pages
// (madvise(MADV_HUGEPAGE), Linux): a buffer of tens of MB then costs a few dozen page faults when
// first touched instead of thousands, and its random accesses few TLB misses. Where the kernel
// gives none (transparent huge pages set to "never"), the memory is ordinary pages. Used by the
// path tracer's wavefront (scattering/path_tracer.cpp), some 160 bytes per path of a batch.
#pragma once
#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <new>

namespace mbsdf {

template <typename T>
struct HugePageAllocator {
  using value_type = T;
  static constexpr size_t kHugePage = size_t(2) << 20;

  HugePageAllocator() = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>&) {}

  T* allocate(size_t n) {
    const size_t bytes = mappedBytes(n);
    // One huge page more than needed, so that the buffer can start on a huge-page boundary.
    void* p = mmap(nullptr, bytes + kHugePage, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    const uintptr_t start = (uintptr_t(p) + kHugePage - 1) & ~uintptr_t(kHugePage - 1);
    // The slack before and after the aligned range goes back to the kernel.
    if (start > uintptr_t(p)) munmap(p, start - uintptr_t(p));
    const uintptr_t end = uintptr_t(p) + bytes + kHugePage;
    if (end > start + bytes) munmap(reinterpret_cast<void*>(start + bytes), end - (start + bytes));
    madvise(reinterpret_cast<void*>(start), bytes, MADV_HUGEPAGE);  // advice only: no huge pages is fine
    return reinterpret_cast<T*>(start);
  }
  void deallocate(T* p, size_t n) { munmap(p, mappedBytes(n)); }

  template <typename U>
  bool operator==(const HugePageAllocator<U>&) const {
    return true;
  }

 private:
  static size_t mappedBytes(size_t n) { return (n * sizeof(T) + kHugePage - 1) & ~(kHugePage - 1); }
};

}  // namespace mbsdf
