// The process's memory allocator: jemalloc (Evans 2006, "A scalable concurrent malloc(3)
// implementation for FreeBSD"), linked into the microbsdf program in place of glibc's malloc and
// configured at build time (allocator.cpp).
#pragma once
#include <string>

namespace mbsdf {

// How the allocator is set up, for the start-up log: its name and its transparent-huge-page mode.
std::string allocatorNote();

}  // namespace mbsdf
