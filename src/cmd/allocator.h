// The process's memory allocator: jemalloc (Evans 2006, "A scalable concurrent malloc(3)
// implementation for FreeBSD"), linked into the microbsdf program in place of glibc's malloc and
// configured at build time (allocator.cpp).
#pragma once
#include <string>

namespace mbsdf {

// How the allocator is set up, for the start-up log: its name and its transparent-huge-page mode.
std::string allocatorNote();

// The allocator's arena the calling thread allocates from, and the calling thread made to allocate
// from another. Memory goes back to the arena it came from when freed, whichever thread frees it,
// and only that arena reuses its pages: a thread that prepares work the main thread goes on with
// (`run` reads the job while MPI starts) allocates from the main thread's arena, so that the pages
// it frees (the mesh's clean-up, Embree's build) serve the main thread's later allocations instead
// of the main thread faulting in new ones.
unsigned currentArena();
void useArena(unsigned arena);

}  // namespace mbsdf
