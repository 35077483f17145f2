#include "geometry/fabrication_defects.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <queue>

#include "core/error.h"
#include "geometry/embree_scene.h"
#include "geometry/random_field.h"

namespace mbsdf {

std::string FabricationDefects::describe() const {
  std::string s = fmt::format("raster {:.4g} µm", texel_um);
  if (depthScale != 1) s += fmt::format(", depth × {:.4g}", depthScale);
  if (lateralRms_um > 0)
    s += fmt::format(", lateral roughness {:.3g} nm rms over {:.3g} µm", lateralRms_um * 1e3, lateralCorrelation_um);
  if (sidewallAngle_deg < 90) s += fmt::format(", sidewalls ≤ {:.3g}°", sidewallAngle_deg);
  if (edgeRadius_um > 0) s += fmt::format(", edges rounded to {:.3g} µm", edgeRadius_um);
  return s;
}

Topography rasteriseHeights(const Microgeometry& g, double texel_um, const std::string& where) {
  Topography t;
  t.source = where;
  if (texel_um <= 0) {
    const auto grid = heightGridOf(g);
    if (!grid)
      throw InputError(where + ": texel_um is needed: the surface is not a heightfield with a grid of its own");
    t.nx = grid->nx;
    t.ny = grid->ny;
    t.dx_um = g.sizeX / t.nx;
    t.dy_um = g.sizeY / t.ny;
    t.z_um = grid->h;
    return t;
  }
  const double nxd = std::round(g.sizeX / texel_um), nyd = std::round(g.sizeY / texel_um);
  if (nxd < 2 || nyd < 2 || nxd * nyd > 6.4e7)
    throw InputError(where +
                     fmt::format(": texel_um = {} gives {} x {} texels (2 to 8000 per side)", texel_um, nxd, nyd));
  for (size_t k = 0; k < g.triangles.size(); ++k) {
    const Vec3 n = g.triangleNormal(k);
    const double len = length(n);
    if (len > 0 && n.z < -1e-9 * len)
      throw InputError(where + ": the surface is not a height function (triangle " + std::to_string(k) +
                       " faces down: an overhang); fabrication defects act on height maps");
  }
  t.nx = int(nxd);
  t.ny = int(nyd);
  t.dx_um = g.sizeX / t.nx;
  t.dy_um = g.sizeY / t.ny;
  t.z_um.resize(t.size());
  const PeriodicScene scene(g);
  const double z0 = scene.zTop() + 1;
  tbb::parallel_for(0, t.ny, [&](int j) {
    for (int i = 0; i < t.nx; ++i) {
      const Vec3 o{-g.sizeX / 2 + g.sizeX * i / t.nx, -g.sizeY / 2 + g.sizeY * j / t.ny, z0};
      const TraceResult r = scene.trace(o, Vec3{0, 0, -1});
      if (r.kind != TraceResult::Kind::Hit)
        throw InputError(where +
                         fmt::format(": a vertical ray at ({:.4g}, {:.4g}) µm meets no surface (a hole)", o.x, o.y));
      t.z_um[size_t(j) * t.nx + i] = r.p.z;
    }
  });
  return t;
}

namespace {

// Grey-scale erosion (sign = −1) or dilation (+1) with a non-flat structuring function b(d) ≤ 0 on
// the offsets within `reach` texels, periodic: erosion min_d [z(x+d) − b(d)], dilation max_d
// [z(x−d) + b(d)] (b is symmetric, so x−d and x+d range over the same offsets).
struct Offset {
  int di, dj;
  double b;
};
void morph(Topography& t, const std::vector<Offset>& offsets, int sign) {
  std::vector<double> out(t.size());
  tbb::parallel_for(0, t.ny, [&](int j) {
    for (int i = 0; i < t.nx; ++i) {
      double best = sign > 0 ? -1e300 : 1e300;
      for (const Offset& o : offsets) {
        const int ii = ((i + o.di) % t.nx + t.nx) % t.nx, jj = ((j + o.dj) % t.ny + t.ny) % t.ny;
        const double v = t.z_um[size_t(jj) * t.nx + ii] + sign * o.b;
        best = sign > 0 ? std::max(best, v) : std::min(best, v);
      }
      out[size_t(j) * t.nx + i] = best;
    }
  });
  t.z_um.swap(out);
}

std::vector<Offset> ballOffsets(const Topography& t, double r) {
  std::vector<Offset> offsets;
  const int ri = int(std::floor(r / t.dx_um)), rj = int(std::floor(r / t.dy_um));
  for (int dj = -rj; dj <= rj; ++dj)
    for (int di = -ri; di <= ri; ++di) {
      const double d2 = (di * t.dx_um) * (di * t.dx_um) + (dj * t.dy_um) * (dj * t.dy_um);
      if (d2 <= r * r) offsets.push_back({di, dj, std::sqrt(r * r - d2) - r});
    }
  return offsets;
}

// The cone's erosion is the largest function below z whose slope along the grid's 16 neighbour
// directions (offsets up to 2 texels) is at most s: Dijkstra from the lowest points upwards. The
// 16 directions bound the metric's error to 2.6 % between them (exact along axes and diagonals).
void coneEnvelope(Topography& t, double s, int sign) {
  std::vector<std::array<int, 2>> steps;
  for (int dj = -2; dj <= 2; ++dj)
    for (int di = -2; di <= 2; ++di)
      if ((di || dj) && std::gcd(std::abs(di), std::abs(dj)) == 1) steps.push_back({di, dj});
  // Erosion (sign −1): values only fall, lowest first. Dilation (+1) mirrors it: z → −z.
  std::vector<double> v(t.size());
  for (size_t k = 0; k < t.size(); ++k) v[k] = -sign * t.z_um[k];
  using Item = std::pair<double, size_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
  for (size_t k = 0; k < v.size(); ++k) queue.push({v[k], k});
  while (!queue.empty()) {
    const auto [val, k] = queue.top();
    queue.pop();
    if (val > v[k]) continue;
    const int i = int(k % t.nx), j = int(k / t.nx);
    for (const auto& [di, dj] : steps) {
      const int ii = ((i + di) % t.nx + t.nx) % t.nx, jj = ((j + dj) % t.ny + t.ny) % t.ny;
      const size_t kk = size_t(jj) * t.nx + ii;
      const double cand = val + s * std::hypot(di * t.dx_um, dj * t.dy_um);
      if (cand < v[kk]) {
        v[kk] = cand;
        queue.push({cand, kk});
      }
    }
  }
  for (size_t k = 0; k < t.size(); ++k) t.z_um[k] = -sign * v[k];
}

void lateralDisplacement(Topography& t, double rms, double corr, uint64_t seed) {
  const double sx = t.nx * t.dx_um, sy = t.ny * t.dy_um;
  const std::vector<double> ux = gaussianRandomField(t.nx, t.ny, sx, sy, rms, corr, seed * 2 + 101);
  const std::vector<double> uy = gaussianRandomField(t.nx, t.ny, sx, sy, rms, corr, seed * 2 + 102);
  std::vector<double> out(t.size());
  for (int j = 0; j < t.ny; ++j)
    for (int i = 0; i < t.nx; ++i) {
      const size_t k = size_t(j) * t.nx + i;
      const double x = -sx / 2 + i * t.dx_um + ux[k], y = -sy / 2 + j * t.dy_um + uy[k];
      out[k] = periodicLookup(t.z_um, t.nx, t.ny, sx, sy, x, y);
    }
  t.z_um.swap(out);
}

}  // namespace

void openWithBall(Topography& t, double r) {
  const auto offsets = ballOffsets(t, r);
  morph(t, offsets, -1);
  morph(t, offsets, +1);
}
void closeWithBall(Topography& t, double r) {
  const auto offsets = ballOffsets(t, r);
  morph(t, offsets, +1);
  morph(t, offsets, -1);
}
void openWithCone(Topography& t, double slope) {
  coneEnvelope(t, slope, -1);
  coneEnvelope(t, slope, +1);
}

void applyFabricationDefects(Topography& t, const FabricationDefects& d, const std::string& where) {
  if (!(d.depthScale > 0)) throw InputError(where + ": depth_scale must be positive");
  if (d.depthScale != 1) {
    const double zMin = *std::min_element(t.z_um.begin(), t.z_um.end());
    for (double& z : t.z_um) z = zMin + d.depthScale * (z - zMin);
  }
  if (d.lateralRms_um > 0) lateralDisplacement(t, d.lateralRms_um, d.lateralCorrelation_um, d.seed);
  if (d.sidewallAngle_deg < 90) {
    if (!(d.sidewallAngle_deg > 0)) throw InputError(where + ": sidewall_angle_deg must be in (0, 90]");
    openWithCone(t, std::tan(d.sidewallAngle_deg * M_PI / 180));
  }
  if (d.edgeRadius_um > 0) {
    if (d.edgeRadius_um < std::min(t.dx_um, t.dy_um))
      throw InputError(where + fmt::format(": edge_radius_um = {} is below the raster's texel ({:.4g} µm): set a finer "
                                           "texel_um",
                                           d.edgeRadius_um, std::min(t.dx_um, t.dy_um)));
    openWithBall(t, d.edgeRadius_um);
    closeWithBall(t, d.edgeRadius_um);
  }
}

}  // namespace mbsdf
