#include "geometry/microgeometry.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <algorithm>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "core/error.h"

namespace mbsdf {

double Microgeometry::zMin() const {
  double z = std::numeric_limits<double>::infinity();
  for (auto& v : vertices) z = std::min(z, v.z);
  return z;
}
double Microgeometry::zMax() const {
  double z = -std::numeric_limits<double>::infinity();
  for (auto& v : vertices) z = std::max(z, v.z);
  return z;
}

Vec3 Microgeometry::triangleNormal(size_t t) const {
  const auto& tri = triangles[t];
  return cross(vertices[tri[1]] - vertices[tri[0]], vertices[tri[2]] - vertices[tri[0]]);
}

double Microgeometry::surfaceArea() const {
  double a = 0;
  for (size_t t = 0; t < triangles.size(); ++t) a += triangleArea(t);
  return a;
}

std::string Microgeometry::hash() const {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&](const void* p, size_t n) {
    auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) {
      h ^= b[i];
      h *= 1099511628211ull;
    }
  };
  mix(vertices.data(), vertices.size() * sizeof(Vec3));
  mix(triangles.data(), triangles.size() * sizeof(triangles[0]));
  mix(&sizeX, sizeof sizeX);
  mix(&sizeY, sizeof sizeY);
  char buf[20];
  std::snprintf(buf, sizeof buf, "%016llx", (unsigned long long)h);
  return buf;
}

void Microgeometry::weld(double tol) {
  // Sort the vertices by their quantised position and merge equal keys: O(n log n) with a small
  // constant (a std::map made 10^7-triangle patches take seconds; found by fuzz_job).
  struct Key {
    long long x, y, z;
    uint32_t index;
  };
  std::vector<Key> keys(vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    const Vec3& v = vertices[i];
    keys[i] = {std::llround(v.x / tol), std::llround(v.y / tol), std::llround(v.z / tol), uint32_t(i)};
  }
  std::sort(keys.begin(), keys.end(), [](const Key& a, const Key& b) {
    return std::tie(a.x, a.y, a.z, a.index) < std::tie(b.x, b.y, b.z, b.index);
  });
  // Each group of equal keys maps to the vertex of its smallest original index; the new vertices
  // keep the original order of those representatives.
  std::vector<uint32_t> rep(vertices.size());
  for (size_t k = 0; k < keys.size();) {
    size_t e = k;
    while (e < keys.size() && keys[e].x == keys[k].x && keys[e].y == keys[k].y && keys[e].z == keys[k].z) ++e;
    for (size_t j = k; j < e; ++j) rep[keys[j].index] = keys[k].index;
    k = e;
  }
  std::vector<uint32_t> remap(vertices.size());
  std::vector<Vec3> out;
  for (size_t i = 0; i < vertices.size(); ++i) {
    if (rep[i] == i) {
      remap[i] = uint32_t(out.size());
      out.push_back(vertices[i]);
    }
  }
  for (size_t i = 0; i < vertices.size(); ++i) remap[i] = remap[rep[i]];
  vertices = std::move(out);
  for (auto& t : triangles)
    for (auto& i : t) i = remap[i];
  removeDegenerate();
}

size_t Microgeometry::removeDegenerate() {
  size_t before = triangles.size();
  std::vector<std::array<uint32_t, 3>> keep;
  keep.reserve(triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const auto& tri = triangles[t];
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) continue;
    if (!(triangleArea(t) > 0)) continue;
    keep.push_back(tri);
  }
  triangles = std::move(keep);
  return before - triangles.size();
}

void Microgeometry::validate(const std::string& where) const {
  if (vertices.empty() || triangles.empty())
    throw InputError(where + ": the mesh is empty (no vertices or no triangles)");
  for (size_t i = 0; i < vertices.size(); ++i)
    if (!isFinite(vertices[i]))
      throw InputError(where + ": vertex " + std::to_string(i) + " is not finite (NaN or Inf)");
  for (size_t t = 0; t < triangles.size(); ++t)
    for (uint32_t i : triangles[t])
      if (i >= vertices.size())
        throw InputError(where + ": triangle " + std::to_string(t) + " refers to vertex " + std::to_string(i) +
                         " but there are only " + std::to_string(vertices.size()));
  if (!(sizeX > 0) || !(sizeY > 0)) throw InputError(where + ": the patch footprint must be positive");
}

void Microgeometry::addOriented(uint32_t a, uint32_t b, uint32_t c, const Vec3& outward) {
  Vec3 n = cross(vertices[b] - vertices[a], vertices[c] - vertices[a]);
  if (dot(n, outward) < 0) std::swap(b, c);
  triangles.push_back({a, b, c});
}

Microgeometry heightfieldMesh(const std::vector<double>& h, int nx, int ny, double sizeX, double sizeY) {
  if (nx < 1 || ny < 1 || h.size() != size_t(nx) * ny) throw std::invalid_argument("heightfield size");
  Microgeometry g;
  g.sizeX = sizeX;
  g.sizeY = sizeY;
  // (nx+1) x (ny+1) vertices; the last row/column repeats the first heights (periodic seam).
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i)
      g.vertices.push_back({-sizeX / 2 + sizeX * i / nx, -sizeY / 2 + sizeY * j / ny, h[(j % ny) * nx + (i % nx)]});
  auto id = [&](int i, int j) { return uint32_t(j * (nx + 1) + i); };
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      // Counter-clockwise seen from above: normals point up.
      g.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      g.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return g;
}

std::optional<HeightGrid> heightGridOf(const Microgeometry& g) {
  if (g.vertices.size() < 4 || g.sizeX <= 0 || g.sizeY <= 0) return std::nullopt;
  // nx from the first row's spacing, then everything is checked against heightfieldMesh's layout.
  const double dx0 = g.vertices[1].x - g.vertices[0].x;
  if (!(dx0 > 0)) return std::nullopt;
  const long nxl = std::lround(g.sizeX / dx0);
  if (nxl < 1 || nxl > (1 << 20) || g.vertices.size() % size_t(nxl + 1) != 0) return std::nullopt;
  const int nx = int(nxl), ny = int(g.vertices.size() / size_t(nx + 1)) - 1;
  if (ny < 1 || g.triangles.size() != 2 * size_t(nx) * size_t(ny)) return std::nullopt;
  const double tol = 1e-9 * std::max(g.sizeX, g.sizeY);
  HeightGrid hg{nx, ny, std::vector<double>(size_t(nx) * ny)};
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) {
      const Vec3& v = g.vertices[size_t(j) * (nx + 1) + i];
      if (std::abs(v.x - (-g.sizeX / 2 + g.sizeX * i / nx)) > tol ||
          std::abs(v.y - (-g.sizeY / 2 + g.sizeY * j / ny)) > tol)
        return std::nullopt;
      const double& seam = hg.h[size_t(j % ny) * nx + (i % nx)];
      if (i < nx && j < ny)
        hg.h[size_t(j) * nx + i] = v.z;
      else if (v.z != seam)
        return std::nullopt;  // the seam must repeat the first row/column
    }
  auto id = [&](int i, int j) { return uint32_t(j * (nx + 1) + i); };
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const size_t t = 2 * (size_t(j) * nx + i);
      const std::array<uint32_t, 3> a{id(i, j), id(i + 1, j), id(i + 1, j + 1)},
          b{id(i, j), id(i + 1, j + 1), id(i, j + 1)};
      if (g.triangles[t] != a || g.triangles[t + 1] != b) return std::nullopt;
    }
  return hg;
}

SlopeBound SlopeBound::of(const Microgeometry& g) {
  SlopeBound b;
  if (!g.periodic || !heightGridOf(g)) return b;
  double s = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const Vec3 n = g.triangleNormal(t);
    if (dot(n, n) > 0) s = std::max(s, std::hypot(n.x, n.y) / n.z);
  }
  b.maxSlope = s;
  return b;
}

void writePly(const Microgeometry& g, const std::string& path) {
  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << "ply\nformat binary_little_endian 1.0\ncomment microbsdf patch, units um, size " << g.sizeX << " x " << g.sizeY
    << (g.periodic ? " periodic" : "") << "\nelement vertex " << g.vertices.size()
    << "\nproperty double x\nproperty double y\nproperty double z\nelement face " << g.triangles.size()
    << "\nproperty list uchar uint vertex_indices\nend_header\n";
  for (auto& v : g.vertices) f.write(reinterpret_cast<const char*>(&v), sizeof v);
  for (auto& t : g.triangles) {
    unsigned char n = 3;
    f.write(reinterpret_cast<const char*>(&n), 1);
    f.write(reinterpret_cast<const char*>(t.data()), sizeof t);
  }
  if (!f) throw std::runtime_error("error writing " + path);
}

namespace {

// Per vertex, an id shared by the vertices at the same position (quantised to 1e-7 of the patch;
// meshes may repeat vertices per face), by sorting: maps allocated a node per vertex (0.15 s on a
// 512² heightfield).
std::vector<uint32_t> positionIds(const Microgeometry& g) {
  const double tol = 1e-7 * std::max({g.sizeX, g.sizeY, 1e-3});
  std::vector<std::pair<std::array<long long, 3>, uint32_t>> byPosition(g.vertices.size());
  for (size_t v = 0; v < g.vertices.size(); ++v) {
    const Vec3& p = g.vertices[v];
    byPosition[v] = {{std::llround(p.x / tol), std::llround(p.y / tol), std::llround(p.z / tol)}, uint32_t(v)};
  }
  std::sort(byPosition.begin(), byPosition.end());
  std::vector<uint32_t> id(g.vertices.size());
  for (size_t i = 0; i < byPosition.size(); ++i)
    id[byPosition[i].second] =
        i > 0 && byPosition[i].first == byPosition[i - 1].first ? id[byPosition[i - 1].second] : uint32_t(i);
  return id;
}

// A periodic patch continues across its border into the next copy: an edge on the border x = x0
// must meet one on x = x1 with the same (y, z) ends, and likewise in y. One that does not is a
// crack at the seam (the two sides' heights differ, or their vertices do), through which light
// leaves the surface. border[axis][side]: the edges on x = x0, x = x1 (axis 0), y = y0, y = y1
// (axis 1), each as its two ends' (coordinate along the border, z).
using SeamKey = std::array<long long, 4>;
size_t unmatchedSeamEdges(std::vector<SeamKey> (&border)[2][2]) {
  size_t unmatched = 0;
  for (auto& axis : border) {
    std::sort(axis[0].begin(), axis[0].end());
    std::sort(axis[1].begin(), axis[1].end());
    std::vector<SeamKey> lone;
    std::set_symmetric_difference(axis[0].begin(), axis[0].end(), axis[1].begin(), axis[1].end(),
                                  std::back_inserter(lone));
    unmatched += lone.size();
  }
  return unmatched;
}

}  // namespace

size_t Microgeometry::removeDuplicates() {
  const std::vector<uint32_t> id = positionIds(*this);
  std::vector<std::array<uint32_t, 3>> corners(triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    corners[t] = {id[triangles[t][0]], id[triangles[t][1]], id[triangles[t][2]]};
    std::sort(corners[t].begin(), corners[t].end());
  }
  std::vector<uint32_t> order(triangles.size());
  for (size_t t = 0; t < order.size(); ++t) order[t] = uint32_t(t);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return corners[a] < corners[b]; });
  std::vector<uint8_t> repeated(triangles.size(), 0);
  for (size_t i = 1; i < order.size(); ++i) repeated[order[i]] = corners[order[i]] == corners[order[i - 1]];
  const size_t before = triangles.size();
  std::vector<std::array<uint32_t, 3>> keep;
  keep.reserve(before);
  for (size_t t = 0; t < before; ++t)
    if (!repeated[t]) keep.push_back(triangles[t]);
  triangles = std::move(keep);
  return before - triangles.size();
}

SurfaceClosure surfaceClosureOf(const Microgeometry& g) {
  SurfaceClosure c;
  if (g.triangles.empty()) return c;
  double signedArea = 0;
  std::vector<uint8_t> used(g.vertices.size(), 0);
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    signedArea += 0.5 * g.triangleNormal(t).z;
    for (uint32_t v : g.triangles[t]) used[v] = 1;
  }
  for (uint8_t u : used) c.unusedVertices += u ? 0 : 1;
  const double footprint = g.sizeX * g.sizeY;
  c.uncoveredFraction = footprint > 0 ? 1.0 - std::abs(signedArea) / footprint : 0.0;
  if (std::abs(c.uncoveredFraction) < 1e-9) c.uncoveredFraction = 0;
  // Each edge's count of triangles, by sorting (a map allocated a node per edge).
  const std::vector<uint32_t> id = positionIds(g);
  struct Edge {
    uint64_t key;  // the two position ids, smaller first
    uint32_t a, b;
  };
  std::vector<Edge> edges;
  edges.reserve(3 * g.triangles.size());
  for (const auto& tri : g.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = tri[size_t(k)], b = tri[size_t((k + 1) % 3)];
      const auto [lo, hi] = std::minmax(id[a], id[b]);
      edges.push_back({(uint64_t(lo) << 32) | hi, a, b});
    }
  std::sort(edges.begin(), edges.end(), [](const Edge& x, const Edge& y) { return x.key < y.key; });
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (size_t v = 0; v < g.vertices.size(); ++v)
    if (used[v]) {
      x0 = std::min(x0, g.vertices[v].x), x1 = std::max(x1, g.vertices[v].x);
      y0 = std::min(y0, g.vertices[v].y), y1 = std::max(y1, g.vertices[v].y);
    }
  const double btol = 1e-6 * std::max({g.sizeX, g.sizeY, 1e-3});
  // A periodic patch's border edges by border, keyed by their ends along it (quantised to btol).
  std::vector<SeamKey> border[2][2];
  auto addIfOnBorder = [&](const Vec3& a, const Vec3& b) {
    auto both = [&](double u, double v, double edge) { return std::abs(u - edge) < btol && std::abs(v - edge) < btol; };
    auto key = [&](double u0, double z0, double u1, double z1) {
      std::array<long long, 2> p{std::llround(u0 / btol), std::llround(z0 / btol)},
          r{std::llround(u1 / btol), std::llround(z1 / btol)};
      if (r < p) std::swap(p, r);
      return SeamKey{p[0], p[1], r[0], r[1]};
    };
    // The x borders first: an edge along a corner (x and y both on the border) is an x border's.
    for (int side = 0; side < 2; ++side)
      if (both(a.x, b.x, side ? x1 : x0)) {
        border[0][side].push_back(key(a.y, a.z, b.y, b.z));
        return true;
      }
    for (int side = 0; side < 2; ++side)
      if (both(a.y, b.y, side ? y1 : y0)) {
        border[1][side].push_back(key(a.x, a.z, b.x, b.z));
        return true;
      }
    return false;
  };
  for (size_t i = 0; i < edges.size(); ++i) {
    const bool alone =
        (i == 0 || edges[i - 1].key != edges[i].key) && (i + 1 == edges.size() || edges[i + 1].key != edges[i].key);
    if (alone && !(g.periodic && addIfOnBorder(g.vertices[edges[i].a], g.vertices[edges[i].b]))) ++c.openEdges;
    // Two faces wound the same way pass their shared edge in opposite directions.
    const bool pair = i + 1 < edges.size() && edges[i + 1].key == edges[i].key &&
                      (i == 0 || edges[i - 1].key != edges[i].key) &&
                      (i + 2 == edges.size() || edges[i + 2].key != edges[i].key);
    if (pair && (id[edges[i].a] < id[edges[i].b]) == (id[edges[i + 1].a] < id[edges[i + 1].b])) ++c.windingEdges;
  }
  c.seamEdges = unmatchedSeamEdges(border);
  return c;
}

std::string SurfaceClosure::describe() const {
  if (windingEdges)
    return std::to_string(windingEdges) +
           " edges between faces wound against each other (a face's corners run counter-clockwise seen from "
           "the medium it faces, the upper one for a surface lit from above)";
  if (closed() && unusedVertices == 0) return "closed surface";
  std::string s;
  if (!closed()) {
    char buf[256];
    std::snprintf(buf, sizeof buf, "%zu open edges (holes or cracks), %.3g %% of the footprint uncovered", openEdges,
                  100 * uncoveredFraction);
    s = buf;
    if (seamEdges)
      s += ", " + std::to_string(seamEdges) +
           " edges on the period's border with no partner on the opposite border (a crack where the copies meet)";
  } else
    s = "closed surface";
  if (unusedVertices) s += ", " + std::to_string(unusedVertices) + " vertices used by no triangle (ignored)";
  return s;
}

}  // namespace mbsdf
