// The shared visibility table of the `exact` evaluator:
// whether each facet's four first-level points see each direction of a fixed grid, computed once
// per geometry and shared by every tile, incidence node, order and wavelength, and by every thread.
// Shadowing towards ωi and masking towards an order direction ω_G are the same question — does the
// ray from x along d leave the patch on d's side — so one table answers both.
//
// Directions: per hemisphere the (M+1)² corners of an M x M grid over the projected disk,
// (x, y) = (−1 + 2i/M, −1 + 2j/M), z = ±√(1 − x² − y²). A query direction d falls in one cell; the
// table answers only when the cell's four corners are all inside the disk, all front-facing for the
// point's facet, and all agree — visibility is then taken to be the same at d. Otherwise (the
// cell straddles a shadow boundary, the horizon or the facet's own horizon) it answers nothing and
// the caller casts the ray. An occluder or gap that fits between four corners of a cell (2/M in
// direction cosines: 0.9° at the zenith for M = 128) is missed; tests/scattering/
// visibility_table_test.cpp measures the table's effect on `exact`'s tables against casting every
// ray.
//
// Memory: one bit per (point, corner, hemisphere), one row per corner of every facet's four points
// padded to 64 bits: (M+1)² ⌈4F/64⌉ 8 bytes per hemisphere for F facets (the paper's HEMISPHERES
// cell, F = 6 136, M = 128: 51 MB). Rows by corner, not by facet: the facet sum asks one direction
// of every facet in turn, so its four corners' rows are read in order instead of a cache line of
// its own per facet (a row by facet spread one order's queries over the whole table). The lower
// hemisphere (light from below, transmission) is only built for a dielectric.
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "core/vecmath.h"
#include "geometry/embree_scene.h"
#include "geometry/lattice_cell.h"

namespace mbsdf {

class VisibilityTable {
 public:
  // Casts 4 F (M+1)² rays per hemisphere (in parallel) for the facets of `cell`.
  VisibilityTable(const Microgeometry& g, const PeriodicScene& scene, const LatticeCell& cell, int M,
                  bool lowerHemisphere);
  // wave::escapes(scene, point k of facet t, side, d, t, up) where the table decides it; none where
  // the caller must cast the ray. `side` is the facet's unit normal or its opposite.
  std::optional<bool> escapes(uint32_t t, int k, const Vec3& side, const Vec3& d, bool up) const;

  // The same question in three steps, for a caller that asks one direction of many facets (the
  // facet sum: one order direction, every facet in turn): the direction's cell once, whether the
  // table can answer for a facet at all once per facet, then each point's bits.
  struct Cell {
    bool usable = false;  // on a hemisphere the table holds, with all four corners inside the disk
    bool up = true;
    std::array<Vec3, 4> corner{};
    std::array<const uint64_t*, 4> row{};  // each corner's row
  };
  Cell cellOf(const Vec3& d, bool up) const;
  // Whether facet t, seen from `side` (its unit normal or the opposite), is in the table, on the
  // side it was built from, with all four corners of `cell` in front of it.
  bool answers(const Cell& cell, uint32_t t, const Vec3& side) const;
  // Given answers(cell, t, side): the corners' agreed answer for point k, none where they disagree.
  std::optional<bool> escapes(const Cell& cell, uint32_t t, int k) const {
    const size_t bit = 4 * size_t(slot_[t]) + size_t(k), word = bit / 64, shift = bit % 64;
    const uint64_t b0 = (cell.row[0][word] >> shift) & 1;
    for (int c = 1; c < 4; ++c)
      if (((cell.row[size_t(c)][word] >> shift) & 1) != b0) return std::nullopt;
    return b0 == 1;
  }
  double memoryBytes() const { return double(bits_.size()) * sizeof(uint64_t); }
  // What a table of `facets` facets at resolution M holds (for plans, before building one).
  static double bytesFor(size_t facets, int M, bool lowerHemisphere) {
    return double(lowerHemisphere ? 2 : 1) * double(M + 1) * double(M + 1) * double(wordsPerRow(facets)) *
           sizeof(uint64_t);
  }
  uint64_t raysCast() const { return rays_; }
  double buildSeconds() const { return seconds_; }
  int resolution() const { return M_; }

 private:
  static size_t wordsPerRow(size_t facets) { return (4 * facets + 63) / 64; }
  bool cornerInside(int i, int j) const;
  Vec3 corner(int i, int j, bool up) const;

  int M_;
  bool lower_;
  size_t words_;                // per corner row: bit 4 slot + k
  std::vector<int32_t> slot_;   // triangle -> index into cell.facets (−1: not in the table)
  std::vector<Vec3> normal_;    // per slot: unit normal
  std::vector<uint64_t> bits_;  // [hemisphere][corner (i, j)][word]
  // Per corner index: its coordinate along x or y, and per corner (i, j) its |z| (−1 outside the
  // disk), computed once: a query looks at four corners, and computing them was a sixth of a tile.
  std::vector<double> coord_, cornerZ_;
  uint64_t rays_ = 0;
  double seconds_ = 0;
};

// The four first-level visibility points of a facet (its centroid and three points inset towards
// the vertices), where `exact` decides whether to split it.
inline std::array<Vec3, 4> firstLevelPoints(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ctr = (a + b + c) * (1.0 / 3.0);
  return {ctr, ctr + (a - ctr) * 0.9, ctr + (b - ctr) * 0.9, ctr + (c - ctr) * 0.9};
}

}  // namespace mbsdf
