// Helpers shared by the path-tracer tests: run one tile on a geometry and sum energies.
#pragma once
#include <memory>
#include <optional>
#include <string>

#include "core/direction_grid.h"
#include "geometry/embree_scene.h"
#include "optics/material.h"
#include "scattering/path_tracer.h"

namespace mbsdf::test {

inline Material material(const std::string& name) {
  Material m;
  if (!builtinMaterial(name, &m)) throw std::runtime_error("no material " + name);
  return m;
}

struct Scenario {
  Microgeometry geometry;
  Material mat;
  DirectionGrid grid;
  std::vector<double> lambda_um;
  std::unique_ptr<PeriodicScene> scene;
  std::unique_ptr<PathTracer> tracer;
  Scenario(Microgeometry g, Material m, DirectionGrid::Layout layout, std::vector<double> lambdas, PathTracerSettings s)
      : geometry(std::move(g)), mat(std::move(m)), grid(layout), lambda_um(std::move(lambdas)) {
    scene = std::make_unique<PeriodicScene>(geometry);
    tracer = std::make_unique<PathTracer>(*scene, mat, lambda_um, grid, s);
  }
  TileResult run(double theta_deg, double phi_deg, bool exact = false, int tile = 0) const {
    int bin = grid.binOfAngles(theta_deg, phi_deg);
    std::optional<Vec3> dir;
    if (exact) dir = sphericalDirection(radians(theta_deg), radians(phi_deg));
    return tracer->run(tile, 0, bin, dir);
  }
};

// Σ_b f·Ω⊥ over the chosen hemisphere (upper = reflection) for one component and wavelength.
inline double energy(const TileResult& r, const DirectionGrid& g, Component c, int lambda, bool upper) {
  double e = 0;
  for (int b = 0; b < r.nBins; ++b)
    if (g.isUpper(b) == upper) e += r.at(c, lambda, b) * g.projectedSolidAngle(b);
  return e;
}
// Standard error of that sum from the per-bin standard errors. A path tallies into one bin, so the
// per-bin contributions are negatively correlated and the root-sum-square is an upper bound.
inline double energyStdError(const TileResult& r, const DirectionGrid& g, Component c, int lambda, bool upper) {
  double v = 0;
  for (int b = 0; b < r.nBins; ++b)
    if (g.isUpper(b) == upper) {
      double e = r.stdError[int(c)][size_t(lambda) * r.nBins + b] * g.projectedSolidAngle(b);
      v += e * e;
    }
  return std::sqrt(v);
}

// No NaN, Inf or negative value in any table, error or energy fraction of a tile.
inline void expectFinite(const TileResult& r) {
  for (int c = 0; c < kComponentCount; ++c) {
    for (double v : r.value[c]) ASSERT_TRUE(std::isfinite(v) && v >= 0);
    for (double v : r.stdError[c]) ASSERT_TRUE(std::isfinite(v) && v >= 0);
  }
  for (const auto* v : {&r.truncated, &r.leaked, &r.missed})
    for (double x : *v) ASSERT_TRUE(std::isfinite(x) && x >= 0 && x <= 1);
}
// Every fate of the paths of wavelength l: tallied (both hemispheres), truncated, leaked, missed.
inline double pathTotal(const TileResult& r, const DirectionGrid& g, int l) {
  double e = r.truncated[l] + r.leaked[l] + r.missed[l];
  for (bool up : {true, false})
    for (Component c : {Component::Coherent, Component::Multiple}) e += energy(r, g, c, l, up);
  return e;
}

}  // namespace mbsdf::test
