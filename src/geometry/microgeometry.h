// The explicit microgeometry: a triangle mesh in micrometres over a rectangular footprint
// [-sizeX/2, sizeX/2] x [-sizeY/2, sizeY/2] centred on the origin (Embree is float: keeping the
// patch centred keeps the absolute coordinates, and so the float rounding, small).
// Triangle normals (counter-clockwise winding) point into the upper medium (docs/physics.md §1).
// periodic = true: the patch repeats in x and y (docs/physics.md §4 step 2).
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/vecmath.h"

namespace mbsdf {

struct Microgeometry {
  std::vector<Vec3> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;
  double sizeX = 0, sizeY = 0;
  bool periodic = true;
  std::string description;

  // Bounds of the vertices in z.
  double zMin() const;
  double zMax() const;
  // Geometric (unnormalised) normal of a triangle.
  Vec3 triangleNormal(size_t t) const;
  double triangleArea(size_t t) const { return 0.5 * length(triangleNormal(t)); }
  double surfaceArea() const;
  // FNV-1a hash of the vertex and index data (hex), for provenance in the output file.
  std::string hash() const;
  // Weld vertices closer than tol (µm); removes triangles that became degenerate.
  void weld(double tol);
  // Remove zero-area triangles; returns how many were removed.
  size_t removeDegenerate();
  // Remove triangles with the same three corners (matched by position, in any order and winding)
  // as an earlier one, keeping the first; returns how many were removed. A face repeated by an
  // exporter would otherwise scatter twice: its Kirchhoff amplitude doubles, its power fourfold.
  size_t removeDuplicates();
  // Throws InputError (with `where` in the message) on non-finite vertices, out-of-range indices or
  // an empty mesh.
  void validate(const std::string& where) const;
  // Add a triangle whose normal should point along `outward`; flips the winding if needed.
  void addOriented(uint32_t a, uint32_t b, uint32_t c, const Vec3& outward);
  uint32_t addVertex(const Vec3& v) {
    vertices.push_back(v);
    return uint32_t(vertices.size() - 1);
  }
};

// Whether a patch is a closed surface over its footprint. Light through a hole is not scattered;
// the path tracer counts it as `missed` (or `leaked`), and the facet sum of single scattering, which
// assumes every ray meets the surface, does not apply.
//   openEdges: edges used by one triangle only (vertices matched by position), not counting the
//     footprint's border of a periodic patch, where the next copy continues the surface;
//   uncoveredFraction: 1 − |Σ projected (signed) triangle area| / footprint. A closed surface over
//     the footprint projects onto it exactly once, overhangs included (their up- and down-facing
//     parts cancel), so this is the fraction of vertical rays that meet nothing. Below zero the
//     triangles cover the footprint more than once: overlapping sheets, which one interface
//     between two media cannot be (coveredMoreThanOnce).
//   windingEdges: edges whose two faces pass them in the same direction, i.e. one of the two is
//     wound the other way round and faces the other medium;
//   seamEdges: a periodic patch's border edges with no partner on the opposite border (the same
//     ends shifted by the period): a crack where the copies meet, e.g. a heightfield whose two
//     sides differ in height.
struct SurfaceClosure {
  size_t openEdges = 0;
  size_t windingEdges = 0;
  size_t seamEdges = 0;
  size_t unusedVertices = 0;  // vertices no triangle uses
  double uncoveredFraction = 0;
  bool closed() const { return openEdges == 0 && seamEdges == 0 && std::abs(uncoveredFraction) < 1e-6; }
  bool coveredMoreThanOnce() const { return uncoveredFraction < -1e-6; }
  std::string describe() const;
};
SurfaceClosure surfaceClosureOf(const Microgeometry& g);

// Periodic heightfield on an nx x ny grid of heights (row-major, h[j*nx + i] at
// x = -sizeX/2 + i*sizeX/nx, y likewise); the grid wraps around, so the mesh is seamless.
Microgeometry heightfieldMesh(const std::vector<double>& h, int nx, int ny, double sizeX, double sizeY);

// The heights of a mesh laid out as heightfieldMesh lays it out (same vertex grid and triangle
// order, any heights), e.g. for the Fourier-domain wave evaluator; none for any other mesh.
struct HeightGrid {
  int nx = 0, ny = 0;
  std::vector<double> h;  // h[j*nx + i]
};
std::optional<HeightGrid> heightGridOf(const Microgeometry& g);

// Directions no point of a periodic heightfield can be shadowed or masked from: a ray leaving the
// surface at an elevation whose tangent exceeds the steepest facet slope s rises faster than the
// surface can (a piecewise-linear height rises at most s per unit of horizontal distance), so it
// never meets it again. Empty (nothing is clear) for any other mesh.
struct SlopeBound {
  std::optional<double> maxSlope;
  static SlopeBound of(const Microgeometry& g);
  // tan(elevation) = |d_z| / |d_xy| > s, squared and without division (d_xy may vanish).
  bool clear(const Vec3& d) const { return maxSlope && d.z * d.z > *maxSlope * *maxSlope * (d.x * d.x + d.y * d.y); }
};

// Write the patch as binary little-endian PLY (for looking at it in MeshLab/Blender).
void writePly(const Microgeometry& g, const std::string& path);

}  // namespace mbsdf
