// Rays ordered by where they start, so that rays traced one after the other, or together as a
// packet, traverse the same part of the scene's tree while it is in the cache. The idea is ray
// reordering for memory coherence (Pharr, Kolb, Gershbein & Hanrahan 1997, "Rendering complex
// scenes with memory-coherent ray tracing"; Garanzha & Loop 2010 sort rays by a hash of origin and
// direction): on the 20 x 20 µm `hemispheres` patch Embree traces a path tracer's rays ordered this
// way 1.4x (all its rays) to 2.5x (first rays) faster than in the order of their paths
// (bench/bench_path_tracer.cpp, BM_TracerRaysAgain and BM_FirstRays; docs/performance.md).
//
// The order is a stable counting sort by the Morton (Z-order) cell of the origin within the
// periodic cell of the patch: rays in one cell keep their given order, so the order is unique for
// given rays, whatever the number of threads that computes it. Only which rays are traced next to
// each other changes, never a ray's answer.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "core/vecmath.h"

namespace mbsdf {

class OriginOrder {
 public:
  // Cells for n rays on a patch of sizeX x sizeY: 4^bits Morton cells of the period, about 16
  // rays in each (at most 2^14 cells). The buffers are kept from one use to the next.
  void prepare(size_t n, double sizeX, double sizeY);

  // The cell of origin o (coordinates wrapped into the period [−size/2, size/2), so a finite
  // patch's rays from outside it are grouped too).
  uint32_t cellOf(const Vec3& o) const { return mortonCode(axisCell(o.x, sizeX_), axisCell(o.y, sizeY_)); }
  uint32_t cellCount() const { return 1u << (2 * bits_); }

  // The places of rays whose cells are cells[i] (from cellOf) in origin order: ray i is the
  // places[i]-th. The span lives until the next call; cells.size() is at most the n prepared for.
  std::span<const uint32_t> places(std::span<const uint32_t> cells);

  // Interleaves the bits of a 16-bit x and y: the position of (x, y) along a Morton (Z-order) curve.
  static uint32_t mortonCode(uint32_t x, uint32_t y) {
    auto spread = [](uint32_t v) {
      v &= 0xFFFF;
      v = (v | (v << 8)) & 0x00FF00FF;
      v = (v | (v << 4)) & 0x0F0F0F0F;
      v = (v | (v << 2)) & 0x33333333;
      return (v | (v << 1)) & 0x55555555;
    };
    return spread(x) | (spread(y) << 1);
  }

 private:
  uint32_t axisCell(double x, double size) const {
    if (!(size > 0) || !std::isfinite(x)) return 0;
    const double f = x / size + 0.5;
    return std::min(uint32_t((f - std::floor(f)) * side_), side_ - 1);
  }

  int bits_ = 0;
  uint32_t side_ = 1;
  double sizeX_ = 0, sizeY_ = 0;
  std::vector<uint32_t> places_, offsets_;
};

}  // namespace mbsdf
