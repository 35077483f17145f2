#include "cmd/allocator.h"

#include <jemalloc/jemalloc.h>

#include <fmt/format.h>

#include <string>

// jemalloc reads this string at its first allocation, before main. Why it and these options:
// a run's working memory (the mesh and its clean-up, Embree's build, the tallies) is tens of MB
// of vectors that grow and are freed. glibc's malloc gives each block of 128 KiB or more its own
// mapping, returned to the kernel when freed and faulted in again, 4 KiB at a time, at the next
// allocation; a page fault costs 1-12 µs (the upper figure on virtual machines), and the
// quickstart job took 17 000 of them, a fifth of its run. jemalloc keeps freed pages for reuse.
// It does not ask for transparent huge pages for all its memory (thp:always would madvise it
// MADV_HUGEPAGE): under the kernel's default "madvise" defrag mode every such fault may compact
// memory synchronously, and on a virtual machine whose host has taken pages back that cost the
// 390 MB fft job 0.8-0.9 s of system time against 0.25-0.3 s without the advice (1.8-2.0 s as
// a command against 1.25-1.4 s).
// The few buffers whose random access gains from huge pages ask for them themselves
// (core/huge_page_allocator.h), and Embree advises the large blocks it maps itself.
extern "C" {
// NOLINTNEXTLINE: the name jemalloc looks for.
const char* malloc_conf = "thp:default,metadata_thp:disabled";
}

namespace mbsdf {

std::string allocatorNote() {
  const char* thp = nullptr;
  size_t size = sizeof(thp);
  if (mallctl("opt.thp", &thp, &size, nullptr, 0) != 0 || !thp) return "jemalloc (transparent huge pages: unknown)";
  const std::string mode = thp;
  return fmt::format("jemalloc (transparent huge pages: {})",
                     mode == "default" ? "where the program asks, elsewhere as the system sets them" : mode);
}

unsigned currentArena() {
  unsigned arena = 0;
  size_t size = sizeof(arena);
  if (mallctl("thread.arena", &arena, &size, nullptr, 0) != 0) return 0;
  return arena;
}

void useArena(unsigned arena) {
  // A failure leaves the thread on its own arena: slower first touches, nothing else.
  (void)mallctl("thread.arena", nullptr, nullptr, &arena, sizeof(arena));
}

}  // namespace mbsdf
