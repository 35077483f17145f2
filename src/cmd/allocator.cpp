#include "cmd/allocator.h"

#include <jemalloc/jemalloc.h>

#include <fmt/format.h>

// jemalloc reads this string at its first allocation, before main. Why it and these options:
// a run's working memory (the mesh and its clean-up, Embree's build, the tallies) is tens of MB
// of vectors that grow and are freed. glibc's malloc gives each block of 128 KiB or more its own
// mapping, returned to the kernel when freed and faulted in again, 4 KiB at a time, at the next
// allocation; a page fault costs 1-12 µs (the upper figure on virtual machines), and the
// quickstart job took 17 000 of them, a fifth of its run. jemalloc keeps freed pages for reuse,
// and with thp:always asks for transparent huge pages (madvise MADV_HUGEPAGE, which the kernel's
// default "madvise" mode honours) for all its memory: one fault per 2 MiB. Where the kernel gives
// no huge pages the advice is ignored.
extern "C" {
// NOLINTNEXTLINE: the name jemalloc looks for.
const char* malloc_conf = "thp:always,metadata_thp:auto";
}

namespace mbsdf {

std::string allocatorNote() {
  const char* thp = nullptr;
  size_t size = sizeof(thp);
  if (mallctl("opt.thp", &thp, &size, nullptr, 0) != 0 || !thp) return "jemalloc (transparent huge pages: unknown)";
  return fmt::format("jemalloc (transparent huge pages: {})", thp);
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
