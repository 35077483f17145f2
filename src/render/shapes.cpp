#include "render/shapes.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "geometry/mesh_loader.h"

namespace mbsdf {

namespace {

void append(RenderMesh& to, const RenderMesh& from) {
  const uint32_t base = uint32_t(to.positions.size());
  to.positions.insert(to.positions.end(), from.positions.begin(), from.positions.end());
  to.normals.insert(to.normals.end(), from.normals.begin(), from.normals.end());
  for (const auto& t : from.triangles) to.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

// A surface of revolution about z: profile points (r, z) with their outward normals (nr, nz),
// swept over nLon azimuths.
RenderMesh lathe(const std::vector<std::array<double, 4>>& profile, int nLon) {
  RenderMesh m;
  for (const auto& [r, z, nr, nz] : profile)
    for (int j = 0; j < nLon; ++j) {
      const double phi = 2 * kPi * j / nLon, c = std::cos(phi), s = std::sin(phi);
      m.positions.push_back({r * c, r * s, z});
      m.normals.push_back(normalize(Vec3{nr * c, nr * s, nz}));
    }
  auto v = [&](size_t i, int j) { return uint32_t(i * size_t(nLon) + size_t(j % nLon)); };
  for (size_t i = 0; i + 1 < profile.size(); ++i)
    for (int j = 0; j < nLon; ++j) {
      // Counter-clockwise seen from outside, for a profile running from the top down.
      if (profile[i][0] > 0) m.triangles.push_back({v(i, j), v(i + 1, j), v(i, j + 1)});
      if (profile[i + 1][0] > 0) m.triangles.push_back({v(i, j + 1), v(i + 1, j), v(i + 1, j + 1)});
    }
  return m;
}

// A flat disc at height z facing up (+1) or down (−1).
RenderMesh disc(double radius, double z, double facing, int nLon) {
  return lathe({{0, z, 0, facing}, {radius, z, 0, facing}}, nLon);
}

}  // namespace

RenderMesh sphereMesh(const Vec3& centre, double radius, int nLat, int nLon) {
  std::vector<std::array<double, 4>> profile;
  for (int i = 0; i <= nLat; ++i) {
    const double th = kPi * i / nLat;
    profile.push_back({std::sin(th), std::cos(th), std::sin(th), std::cos(th)});
  }
  RenderMesh m = lathe(profile, nLon);
  for (Vec3& p : m.positions) p = centre + radius * p;
  return m;
}

RenderMesh shaderBallMesh() {
  // A ball of radius 0.62 on a waisted stand on a round base, height 2 over z in [−1, 1].
  RenderMesh m = sphereMesh({0, 0, 0.38}, 0.62, 128, 256);
  std::vector<std::array<double, 4>> stand;
  for (int i = 0; i <= 24; ++i) {
    const double t = double(i) / 24, z = -0.16 - 0.66 * t;  // under the ball down to the base
    const double r = 0.20 + 0.10 * std::pow(2 * t - 1, 2), dr = 0.40 * (2 * t - 1) * (-1 / 0.66);
    stand.push_back({r, z, 1, -dr});
  }
  append(m, lathe(stand, 128));
  append(m, disc(0.85, -0.82, 1, 256));
  append(m, lathe({{0.85, -0.82, 1, 0}, {0.85, -1.0, 1, 0}}, 256));
  append(m, disc(0.85, -1.0, -1, 256));
  return m;
}

RenderMesh planeMesh(double h) {
  RenderMesh m;
  m.positions = {{-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0}};
  m.normals.assign(4, {0, 0, 1});
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

RenderMesh shapeByName(const std::string& name) {
  if (name == "sphere") return sphereMesh({0, 0, 0}, 1.0, 128, 256);
  if (name == "ball") return shaderBallMesh();
  if (name == "plane") return planeMesh(1.0);
  const auto dotAt = name.rfind('.');
  std::string ext = dotAt == std::string::npos ? "" : name.substr(dotAt + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext != "obj" && ext != "ply")
    throw InputError("--shape: \"" + name + "\" is neither sphere, ball, plane nor an .obj or .ply file");
  const Microgeometry g = loadMesh(name, 1.0);
  if (g.triangles.empty()) throw InputError(name + ": the mesh has no triangles");
  // Centred on its bounding box and scaled into the unit ball.
  Vec3 lo = g.vertices.front(), hi = lo;
  for (const Vec3& p : g.vertices)
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)},
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  const Vec3 c = 0.5 * (lo + hi);
  double rMax = 0;
  for (const Vec3& p : g.vertices) rMax = std::max(rMax, length(p - c));
  if (!(rMax > 0)) throw InputError(name + ": the mesh has no extent");
  RenderMesh m;
  for (const Vec3& p : g.vertices) m.positions.push_back((1 / rMax) * (p - c));
  m.triangles = g.triangles;
  // Vertex normals: the faces' normals weighted by their angle at the vertex (Thürmer & Wüthrich 1998),
  // independent of how the faces around a vertex are split. Degenerate faces add nothing.
  m.normals.assign(m.positions.size(), {0, 0, 0});
  for (const auto& t : m.triangles) {
    const Vec3 n = cross(m.positions[t[1]] - m.positions[t[0]], m.positions[t[2]] - m.positions[t[0]]);
    if (!(length(n) > 0)) continue;
    for (int k = 0; k < 3; ++k) {
      const Vec3 a = m.positions[t[(k + 1) % 3]] - m.positions[t[k]],
                 b = m.positions[t[(k + 2) % 3]] - m.positions[t[k]];
      if (length(a) > 0 && length(b) > 0)
        m.normals[t[k]] = m.normals[t[k]] + safeAcos(dot(normalize(a), normalize(b))) * normalize(n);
    }
  }
  for (Vec3& n : m.normals) n = length(n) > 0 ? normalize(n) : Vec3{0, 0, 1};
  return m;
}

}  // namespace mbsdf
