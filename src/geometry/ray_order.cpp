#include "geometry/ray_order.h"

#include <tbb/parallel_for.h>

namespace mbsdf {

void OriginOrder::prepare(size_t n, double sizeX, double sizeY) {
  sizeX_ = sizeX;
  sizeY_ = sizeY;
  // About 16 rays per cell: a packet of 16 near-parallel rays shares its cell, and the rays a
  // thread traces in a row lie in a compact block of cells.
  bits_ = 0;
  while (bits_ < 7 && (size_t(16) << (2 * (bits_ + 1))) <= n) ++bits_;
  side_ = 1u << bits_;
}

std::span<const uint32_t> OriginOrder::places(std::span<const uint32_t> cells) {
  // A parallel stable counting sort: blocks of rays count their cells, every (cell, block) gets
  // its place in cell-major, block-minor order, and each block places its rays in its own order.
  const size_t n = cells.size(), nCells = cellCount();
  constexpr size_t kBlock = 32768;
  const size_t nBlocks = (n + kBlock - 1) / kBlock;
  places_.resize(n);
  offsets_.assign(nBlocks * nCells, 0);
  auto blocks = [&](auto&& body) {
    tbb::parallel_for(size_t(0), nBlocks,
                      [&](size_t b) { body(&offsets_[b * nCells], b * kBlock, std::min(n, (b + 1) * kBlock)); });
  };
  blocks([&](uint32_t* count, size_t i0, size_t i1) {
    for (size_t i = i0; i < i1; ++i) ++count[cells[i]];
  });
  uint32_t place = 0;
  for (size_t c = 0; c < nCells; ++c)
    for (size_t b = 0; b < nBlocks; ++b) {
      uint32_t& slot = offsets_[b * nCells + c];
      const uint32_t count = slot;
      slot = place;
      place += count;
    }
  blocks([&](uint32_t* next, size_t i0, size_t i1) {
    for (size_t i = i0; i < i1; ++i) places_[i] = next[cells[i]]++;
  });
  return places_;
}

}  // namespace mbsdf
