#include "geometry/generators.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "geometry/random_field.h"

namespace mbsdf {
namespace {

// Extrudes a closed periodic profile (x_k, z_k), x from -sizeX/2 to +sizeX/2 with z_first = z_last,
// along y with `rows` rows of quads. Normals point to the side with larger z (the upper medium).
Microgeometry extrudeProfile(const std::vector<std::pair<double, double>>& profile, double sizeX, double sizeY,
                             int rows) {
  Microgeometry g;
  g.sizeX = sizeX;
  g.sizeY = sizeY;
  size_t n = profile.size();
  for (int r = 0; r <= rows; ++r) {
    double y = -sizeY / 2 + sizeY * r / rows;
    for (auto [x, z] : profile) g.vertices.push_back({x, y, z});
  }
  for (int r = 0; r < rows; ++r)
    for (size_t k = 0; k + 1 < n; ++k) {
      uint32_t a = uint32_t(r * n + k), b = a + 1, c = uint32_t((r + 1) * n + k + 1), d = c - 1;
      double dx = profile[k + 1].first - profile[k].first, dz = profile[k + 1].second - profile[k].second;
      Vec3 outward{-dz, 0, dx};
      if (dx == 0 && dz == 0) continue;
      g.addOriented(a, b, c, outward);
      g.addOriented(a, c, d, outward);
    }
  return g;
}

// Splits the segments of a profile so that no segment is longer than maxLen.
std::vector<std::pair<double, double>> refineProfile(const std::vector<std::pair<double, double>>& p, double maxLen) {
  std::vector<std::pair<double, double>> out{p.front()};
  for (size_t k = 0; k + 1 < p.size(); ++k) {
    double len = std::hypot(p[k + 1].first - p[k].first, p[k + 1].second - p[k].second);
    int m = std::max(1, int(std::ceil(len / maxLen - 1e-9)));
    for (int s = 1; s <= m; ++s) {
      double t = double(s) / m;
      out.push_back(
          {p[k].first + t * (p[k + 1].first - p[k].first), p[k].second + t * (p[k + 1].second - p[k].second)});
    }
  }
  return out;
}

int periodsIn(double size, double period) {
  double n = size / period;
  int k = int(std::lround(n));
  if (k < 1 || std::abs(n - k) > 1e-6 * std::max(1.0, n))
    throw std::invalid_argument("the patch size must hold a whole number of periods");
  return k;
}

int rowsFor(double sizeY, double resolution_um) {
  return resolution_um > 0 ? std::max(1, int(std::ceil(sizeY / resolution_um))) : 1;
}

// Angles around a cell centre: n uniform samples plus the four corner directions, symmetric under
// x -> -x and y -> -y so that neighbouring cells produce identical edge vertices.
std::vector<double> cellAngles(int n, double hx, double hy) {
  std::vector<double> a;
  for (int k = 0; k < n; ++k) a.push_back(2 * kPi * k / n);
  double c = std::atan2(hy, hx);
  for (double v : {c, kPi - c, kPi + c, 2 * kPi - c}) a.push_back(v);
  std::sort(a.begin(), a.end());
  std::vector<double> out;
  for (double v : a)
    if (out.empty() || v - out.back() > 1e-9) out.push_back(v);
  return out;
}

// Ground of one cell: the square [cx ± hx] x [cy ± hy] at z = 0 with an elliptical hole (ex, ey),
// triangulated in `rings` rings between hole and square. Returns the hole's vertex indices (one per
// angle) for the structure standing on it.
std::vector<uint32_t> addCellGround(Microgeometry& g, double cx, double cy, double hx, double hy, double ex, double ey,
                                    const std::vector<double>& angles, int rings) {
  size_t na = angles.size();
  std::vector<std::vector<uint32_t>> ring(rings + 1, std::vector<uint32_t>(na));
  for (size_t k = 0; k < na; ++k) {
    double ca = std::cos(angles[k]), sa = std::sin(angles[k]);
    double t =
        std::min(std::abs(ca) > 1e-15 ? hx / std::abs(ca) : 1e300, std::abs(sa) > 1e-15 ? hy / std::abs(sa) : 1e300);
    Vec3 e{cx + ex * ca, cy + ey * sa, 0}, s{cx + t * ca, cy + t * sa, 0};
    for (int m = 0; m <= rings; ++m) ring[m][k] = g.addVertex(e + (s - e) * (double(m) / rings));
  }
  for (int m = 0; m < rings; ++m)
    for (size_t k = 0; k < na; ++k) {
      size_t k1 = (k + 1) % na;
      g.addOriented(ring[m][k], ring[m][k1], ring[m + 1][k1], {0, 0, 1});
      g.addOriented(ring[m][k], ring[m + 1][k1], ring[m + 1][k], {0, 0, 1});
    }
  return ring[0];
}

// Half-ellipsoid dome on a base ring (indices `base`, at height z0, centre (cx, cy)).
void addDome(Microgeometry& g, const std::vector<uint32_t>& base, const std::vector<double>& angles, double cx,
             double cy, double z0, double rx, double ry, double rz, int rings) {
  size_t na = angles.size();
  std::vector<uint32_t> prev = base;
  Vec3 c{cx, cy, z0};
  auto outward = [&](uint32_t a, uint32_t b, uint32_t d) {
    Vec3 m = (g.vertices[a] + g.vertices[b] + g.vertices[d]) / 3.0 - c;
    return Vec3{m.x / (rx * rx), m.y / (ry * ry), m.z / (rz * rz)};
  };
  for (int j = 1; j < rings; ++j) {
    double beta = 0.5 * kPi * j / rings;
    std::vector<uint32_t> cur(na);
    for (size_t k = 0; k < na; ++k)
      cur[k] = g.addVertex({cx + rx * std::cos(beta) * std::cos(angles[k]),
                            cy + ry * std::cos(beta) * std::sin(angles[k]), z0 + rz * std::sin(beta)});
    for (size_t k = 0; k < na; ++k) {
      size_t k1 = (k + 1) % na;
      g.addOriented(prev[k], prev[k1], cur[k1], outward(prev[k], prev[k1], cur[k1]));
      g.addOriented(prev[k], cur[k1], cur[k], outward(prev[k], cur[k1], cur[k]));
    }
    prev = cur;
  }
  uint32_t pole = g.addVertex({cx, cy, z0 + rz});
  for (size_t k = 0; k < na; ++k) {
    size_t k1 = (k + 1) % na;
    g.addOriented(prev[k], prev[k1], pole, outward(prev[k], prev[k1], pole));
  }
}

int angularSamples(double radius, double resolution_um) {
  int n = int(std::ceil(2 * kPi * radius / resolution_um / 4.0)) * 4;
  return std::clamp(n, 16, 1024);
}

}  // namespace

int gridSizeFor(double size, double texel, int maxN) {
  int n = int(std::ceil(size / texel));
  return std::clamp(n, 8, maxN);
}

Microgeometry makeFlat(double sizeX, double sizeY, double resolution_um) {
  int nx = resolution_um > 0 ? gridSizeFor(sizeX, resolution_um, 4096) : 1;
  int ny = resolution_um > 0 ? gridSizeFor(sizeY, resolution_um, 4096) : 1;
  Microgeometry g = heightfieldMesh(std::vector<double>(size_t(nx) * ny, 0.0), nx, ny, sizeX, sizeY);
  g.description = "flat";
  return g;
}

Microgeometry makeSineGrating(double sizeX, double sizeY, double period, double amplitude, int samplesPerPeriod,
                              double resolution_um) {
  int np = periodsIn(sizeX, period);
  std::vector<std::pair<double, double>> p;
  int n = np * samplesPerPeriod;
  for (int k = 0; k <= n; ++k) {
    double x = -sizeX / 2 + sizeX * k / n;
    p.push_back({x, amplitude * std::sin(2 * kPi * (x + sizeX / 2) / period)});
  }
  p.back().second = p.front().second;
  Microgeometry g = extrudeProfile(p, sizeX, sizeY, rowsFor(sizeY, resolution_um));
  g.description = "sine-grating";
  return g;
}

Microgeometry makeBinaryGrating(double sizeX, double sizeY, double period, double depth, double duty,
                                double resolution_um) {
  if (!(duty > 0 && duty < 1)) throw std::invalid_argument("duty must be in (0, 1)");
  int np = periodsIn(sizeX, period);
  std::vector<std::pair<double, double>> p;
  double a = period * (1 - duty) / 2, w = period * duty;
  for (int k = 0; k < np; ++k) {
    double x0 = -sizeX / 2 + k * period;
    p.push_back({x0, 0});
    p.push_back({x0 + a, 0});
    p.push_back({x0 + a, depth});
    p.push_back({x0 + a + w, depth});
    p.push_back({x0 + a + w, 0});
  }
  p.push_back({sizeX / 2, 0});
  if (resolution_um > 0) p = refineProfile(p, resolution_um);
  Microgeometry g = extrudeProfile(p, sizeX, sizeY, rowsFor(sizeY, resolution_um));
  g.description = "binary-grating";
  return g;
}

Microgeometry makeRidged(double sizeX, double sizeY, double period, double apexDeg, double resolution_um) {
  if (!(apexDeg > 0 && apexDeg < 180)) throw std::invalid_argument("apex angle must be in (0, 180) degrees");
  int np = periodsIn(sizeX, period);
  double depth = period / (2 * std::tan(radians(apexDeg) / 2));
  std::vector<std::pair<double, double>> p;
  for (int k = 0; k < np; ++k) {
    double x0 = -sizeX / 2 + k * period;
    p.push_back({x0, 0});
    p.push_back({x0 + period / 2, depth});
  }
  p.push_back({sizeX / 2, 0});
  if (resolution_um > 0) p = refineProfile(p, resolution_um);
  Microgeometry g = extrudeProfile(p, sizeX, sizeY, rowsFor(sizeY, resolution_um));
  g.description = "ridged";
  return g;
}

Microgeometry makeGaussian(double sizeX, double sizeY, double rms, double corr, int nx, int ny, uint64_t seed) {
  Microgeometry g = heightfieldMesh(gaussianRandomField(nx, ny, sizeX, sizeY, rms, corr, seed), nx, ny, sizeX, sizeY);
  g.description = "gaussian";
  return g;
}

Microgeometry makeNoise(const NoiseShape& shape) {
  const double sizeX = shape.size_um[0], sizeY = shape.size_um[1], rms = shape.rms_um, radius = shape.feature_radius_um,
               density = shape.density_per_um2;
  const int nx = shape.texels[0], ny = shape.texels[1];
  const uint64_t seed = shape.seed;
  Microgeometry g =
      heightfieldMesh(sparseConvolutionNoise(nx, ny, sizeX, sizeY, rms, radius, density, seed), nx, ny, sizeX, sizeY);
  g.description = "noise";
  return g;
}

Microgeometry makeDomeLattice(const DomeLatticeShape& shape) {
  const double sizeX = shape.size_um[0], sizeY = shape.size_um[1], spacingX = shape.spacing_um[0],
               spacingY = shape.spacing_um[1], rx = shape.radii_um[0], ry = shape.radii_um[1], rz = shape.radii_um[2],
               resolution_um = shape.resolution_um;
  int cx = periodsIn(sizeX, spacingX), cy = periodsIn(sizeY, spacingY);
  if (!(2 * rx < spacingX && 2 * ry < spacingY)) throw std::invalid_argument("the domes must fit inside their cells");
  Microgeometry g;
  g.sizeX = sizeX;
  g.sizeY = sizeY;
  auto angles = cellAngles(angularSamples(std::max(rx, ry), resolution_um), spacingX / 2, spacingY / 2);
  int groundRings = std::max(2, int(std::ceil((std::max(spacingX, spacingY) / 2 - std::min(rx, ry)) / resolution_um)));
  int domeRings = std::max(4, int(std::ceil(0.5 * kPi * std::max({rx, ry, rz}) / resolution_um)));
  for (int j = 0; j < cy; ++j)
    for (int i = 0; i < cx; ++i) {
      double x = -sizeX / 2 + (i + 0.5) * spacingX, y = -sizeY / 2 + (j + 0.5) * spacingY;
      auto base = addCellGround(g, x, y, spacingX / 2, spacingY / 2, rx, ry, angles, groundRings);
      addDome(g, base, angles, x, y, 0.0, rx, ry, rz, domeRings);
    }
  g.weld(1e-7 * std::max(sizeX, sizeY));
  g.description = "dome-lattice";
  return g;
}

Microgeometry makeOverhang(const OverhangShape& shape) {
  const double sizeX = shape.size_um[0], sizeY = shape.size_um[1], spacing = shape.spacing_um,
               stemR = shape.stem_radius_um, stemH = shape.stem_height_um, capR = shape.cap_radius_um,
               capH = shape.cap_height_um, resolution_um = shape.resolution_um;
  int cx = periodsIn(sizeX, spacing), cy = periodsIn(sizeY, spacing);
  if (!(capR > stemR)) throw std::invalid_argument("the cap radius must exceed the stem radius");
  if (!(2 * capR < spacing)) throw std::invalid_argument("the caps must fit inside their cells");
  Microgeometry g;
  g.sizeX = sizeX;
  g.sizeY = sizeY;
  auto angles = cellAngles(angularSamples(capR, resolution_um), spacing / 2, spacing / 2);
  size_t na = angles.size();
  int groundRings = std::max(2, int(std::ceil((spacing / 2 - stemR) / resolution_um)));
  int stemRings = std::max(1, int(std::ceil(stemH / resolution_um)));
  int underRings = std::max(1, int(std::ceil((capR - stemR) / resolution_um)));
  int domeRings = std::max(4, int(std::ceil(0.5 * kPi * std::max(capR, capH) / resolution_um)));
  for (int j = 0; j < cy; ++j)
    for (int i = 0; i < cx; ++i) {
      double x = -sizeX / 2 + (i + 0.5) * spacing, y = -sizeY / 2 + (j + 0.5) * spacing;
      std::vector<uint32_t> prev = addCellGround(g, x, y, spacing / 2, spacing / 2, stemR, stemR, angles, groundRings);
      // Stem wall, outward = radial.
      for (int r = 1; r <= stemRings; ++r) {
        std::vector<uint32_t> cur(na);
        for (size_t k = 0; k < na; ++k)
          cur[k] =
              g.addVertex({x + stemR * std::cos(angles[k]), y + stemR * std::sin(angles[k]), stemH * r / stemRings});
        for (size_t k = 0; k < na; ++k) {
          size_t k1 = (k + 1) % na;
          double am = 0.5 * (angles[k] + (k1 ? angles[k1] : angles[k1] + 2 * kPi));
          Vec3 out{std::cos(am), std::sin(am), 0};
          g.addOriented(prev[k], prev[k1], cur[k1], out);
          g.addOriented(prev[k], cur[k1], cur[k], out);
        }
        prev = cur;
      }
      // Flat underside of the cap, facing down.
      for (int r = 1; r <= underRings; ++r) {
        double rad = stemR + (capR - stemR) * r / underRings;
        std::vector<uint32_t> cur(na);
        for (size_t k = 0; k < na; ++k)
          cur[k] = g.addVertex({x + rad * std::cos(angles[k]), y + rad * std::sin(angles[k]), stemH});
        for (size_t k = 0; k < na; ++k) {
          size_t k1 = (k + 1) % na;
          g.addOriented(prev[k], prev[k1], cur[k1], {0, 0, -1});
          g.addOriented(prev[k], cur[k1], cur[k], {0, 0, -1});
        }
        prev = cur;
      }
      addDome(g, prev, angles, x, y, stemH, capR, capR, capH, domeRings);
    }
  g.weld(1e-7 * std::max(sizeX, sizeY));
  g.description = "overhang";
  return g;
}

void addGroundNoise(Microgeometry& g, double rms, double corr, uint64_t seed) {
  if (!(rms > 0)) return;
  int nx = gridSizeFor(g.sizeX, corr / 4, 2048), ny = gridSizeFor(g.sizeY, corr / 4, 2048);
  auto h = gaussianRandomField(nx, ny, g.sizeX, g.sizeY, rms, corr, seed ^ 0x9E3779B97F4A7C15ull);
  for (auto& v : g.vertices) v.z += periodicLookup(h, nx, ny, g.sizeX, g.sizeY, v.x, v.y);
}

}  // namespace mbsdf
