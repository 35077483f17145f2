#include "microflake/compare_smith.h"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "core/direction_grid.h"
#include "core/vecmath.h"
#include "geometry/embree_scene.h"
#include "geometry/generators.h"
#include "microflake/microflake_walk.h"
#include "scattering/path_tracer.h"

namespace mbsdf {

namespace {

// Projected-area weighted mean of |slope|² over the facets: α² of the mesh's slope distribution
// (Beckmann: each slope component has variance α²/2).
double meshAlpha(const Microgeometry& g) {
  double w = 0, s2 = 0;
  for (const auto& t : g.triangles) {
    const Vec3 &a = g.vertices[t[0]], &b = g.vertices[t[1]], &c = g.vertices[t[2]];
    const Vec3 n = cross(b - a, c - a);  // length = 2 × area, n.z/2 = projected area
    if (n.z <= 0) continue;
    const double sx = -n.x / n.z, sy = -n.y / n.z;
    w += n.z;
    s2 += n.z * (sx * sx + sy * sy);
  }
  return std::sqrt(s2 / w);
}

}  // namespace

nlohmann::json compareSmith(const CompareSmithOptions& o) {
  if (!(o.alpha > 0 && o.alpha <= 3)) throw std::invalid_argument("--alpha must be in (0, 3]");
  Material mat;
  if (!builtinMaterial(o.material, &mat) || !mat.isConductor())
    throw std::invalid_argument("--material must be a built-in conductor (Al, Ag, Au, Cu, mirror)");
  const int n = gridSizeFor(o.size_um, o.texel_um, 4096);
  // Gaussian correlation exp(−r²/ℓ²) has slope variance 2h²/ℓ² per axis; start from h = αℓ/2 and
  // rescale by the measured facet slopes (the mesh smooths slopes below the texel).
  Microgeometry g = makeGaussian(o.size_um, o.size_um, o.alpha * o.correlation_um / 2, o.correlation_um, n, n, o.seed);
  const double a0 = meshAlpha(g);
  for (auto& v : g.vertices) v.z *= o.alpha / a0;
  const double aMesh = meshAlpha(g);

  const std::vector<double> lambda_um = {o.lambda_nm * 1e-3};
  DirectionGrid grid(ThetaPhiGrid{o.nTheta, o.nPhi});
  PeriodicScene scene(g);
  PathTracerSettings ps;
  ps.paths = o.paths;
  ps.maxDepth = 1000;
  ps.seed = o.seed;
  PathTracer tracer(scene, mat, lambda_um, grid, ps);
  MicroflakeDistribution dist(BeckmannNdf{o.alpha, o.alpha});
  MicroflakeSettings ms;
  ms.paths = o.paths;
  ms.maxDepth = 1000;
  ms.seed = o.seed;
  MicroflakeWalk walk(dist, mat, lambda_um, grid, ms);

  nlohmann::json res;
  res["alpha"] = o.alpha;
  res["mesh_alpha"] = aMesh;
  res["mesh_triangles"] = g.triangles.size();
  res["material"] = o.material;
  res["lambda_nm"] = o.lambda_nm;
  res["paths"] = o.paths;
  res["grid"] = {o.nTheta, o.nPhi};
  res["correlation_um"] = o.correlation_um;
  res["size_um"] = o.size_um;
  double tExplicit = 0, tWalk = 0;
  for (size_t k = 0; k < o.theta_deg.size(); ++k) {
    const double th = o.theta_deg[k];
    const Vec3 wi = sphericalDirection(radians(th), 0.0);
    const int bin = grid.binOf(wi);
    TileResult e = tracer.run(int(k), int(k), bin, wi);
    TileResult s = walk.run(int(k), int(k), bin, wi);
    tExplicit += e.seconds;
    tWalk += s.seconds;
    nlohmann::json row;
    row["theta_deg"] = th;
    for (const char* name : {"coherent", "multiple", "total"}) {
      std::vector<Component> comps;
      if (std::string(name) != "multiple") comps.push_back(Component::Coherent);
      if (std::string(name) != "coherent") comps.push_back(Component::Multiple);
      // l1_noise: the L1 distance expected from Monte Carlo noise alone, Σ √(2/π) σ_Δ Ω⊥ (mean of a
      // folded normal), so a difference well above it is the Smith model's, not the sampling's.
      double ae = 0, as = 0, l1 = 0, se2e = 0, se2s = 0, l1Noise = 0;
      for (int b = 0; b < grid.binsPerHemisphere(); ++b) {
        const double op = grid.projectedSolidAngle(b);
        double fe = 0, fs = 0, var = 0;
        for (Component c : comps) {
          fe += e.at(c, 0, b);
          fs += s.at(c, 0, b);
          se2e += std::pow(e.stdError[int(c)][b] * op, 2);
          se2s += std::pow(s.stdError[int(c)][b] * op, 2);
          var += std::pow(e.stdError[int(c)][b], 2) + std::pow(s.stdError[int(c)][b], 2);
        }
        l1Noise += std::sqrt(2 / kPi) * std::sqrt(var) * op;
        ae += fe * op;
        as += fs * op;
        l1 += std::abs(fe - fs) * op;
      }
      row[name] = {{"albedo_explicit", ae},
                   {"albedo_smith", as},
                   {"albedo_se_explicit", std::sqrt(se2e)},
                   {"albedo_se_smith", std::sqrt(se2s)},
                   {"lobe_l1", l1},
                   {"lobe_l1_noise", l1Noise}};
    }
    // Plane-of-incidence lobe (φ = 0 and φ = 180° columns), total of both components.
    nlohmann::json lobe = nlohmann::json::array();
    const auto& tp = std::get<ThetaPhiGrid>(grid.layout());
    for (int side : {0, tp.nPhi / 2})
      for (int t = 0; t < tp.nTheta; ++t) {
        const int b = t * tp.nPhi + side;
        const double thetaOut = (t + 0.5) * 90.0 / tp.nTheta * (side == 0 ? 1 : -1);
        lobe.push_back({thetaOut, e.at(Component::Coherent, 0, b) + e.at(Component::Multiple, 0, b),
                        s.at(Component::Coherent, 0, b) + s.at(Component::Multiple, 0, b)});
      }
    row["lobe_plane_of_incidence"] = lobe;  // [theta_o (negative: φ = 180°), f explicit, f smith]
    row["truncated_explicit"] = e.truncated[0];
    row["leaked_explicit"] = e.leaked[0];
    res["rows"].push_back(row);
  }
  res["seconds_explicit"] = tExplicit;
  res["seconds_smith"] = tWalk;
  res["paths_per_second_explicit"] = double(o.paths * o.theta_deg.size()) / tExplicit;
  res["paths_per_second_smith"] = double(o.paths * o.theta_deg.size()) / tWalk;
  return res;
}

std::string formatCompareSmith(const nlohmann::json& r) {
  std::ostringstream os;
  os << fmt::format(
      "Smith microflake model vs explicit Gaussian heightfield: Beckmann α = {} (mesh α = {:.4f}, {} "
      "triangles), {} at {} nm, {} paths per angle\n",
      r["alpha"].get<double>(), r["mesh_alpha"].get<double>(), r["mesh_triangles"].get<size_t>(),
      r["material"].get<std::string>(), r["lambda_nm"].get<double>(), r["paths"].get<uint64_t>());
  os << fmt::format("{:>7} | {:>21} | {:>21} | {:>21} | {:>17} | {:>17}\n", "θi (°)", "single albedo e/S",
                    "multiple albedo e/S", "total albedo e/S", "L1 total (noise)", "L1 mult (noise)");
  for (const auto& row : r["rows"]) {
    auto pair = [&](const char* c) {
      return fmt::format("{:.4f} / {:.4f}", row[c]["albedo_explicit"].get<double>(),
                         row[c]["albedo_smith"].get<double>());
    };
    auto l1 = [&](const char* c) {
      return fmt::format("{:.4f} ({:.4f})", row[c]["lobe_l1"].get<double>(), row[c]["lobe_l1_noise"].get<double>());
    };
    os << fmt::format("{:>7.1f} | {:>21} | {:>21} | {:>21} | {:>17} | {:>17}\n", row["theta_deg"].get<double>(),
                      pair("coherent"), pair("multiple"), pair("total"), l1("total"), l1("multiple"));
  }
  os << fmt::format("speed: explicit path tracer {:.3g} paths/s, microflake walk {:.3g} paths/s\n",
                    r["paths_per_second_explicit"].get<double>(), r["paths_per_second_smith"].get<double>());
  return os.str();
}

}  // namespace mbsdf
