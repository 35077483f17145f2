#include "job/effects_planner.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <tuple>

#include "core/colour.h"
#include "core/log.h"
#include "job/symmetry.h"
#include "job/transport.h"
#include "optics/fresnel.h"
#include "scattering/coherence_window.h"
#include "scattering/fft_estimator.h"
#include "scattering/flat_interface.h"
#include "scattering/kirchhoff_ensemble.h"
#include "scattering/wave_common.h"
#include "scattering/single_scattering.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
namespace {

// Pilots log that they start and, every 10 s, that they still run; they stop on a signal like tiles
// (core/stop.h): a pilot of a paper-resolution job can take minutes.
std::function<void(uint64_t)> pilotProgress(const std::string& what, const IncidenceDirection& inc) {
  const std::string name = fmt::format("effects planner: {} at theta_i = {:.3g} deg", what, inc.theta_deg);
  spdlog::info("{}", name);
  return heartbeat(name);
}

using Clock = std::chrono::steady_clock;
// The `exact` pilot costs ∝ facets × propagating orders (π sizeX sizeY / λ² above the surface; for a
// patch that repeats a cell, the cell's facets and orders):
// 8.2e6 took 28 s for the 10 µm hemispheres (Monte Carlo: 0.85 s), 2.5e3 for a flat 10 µm patch
// 0.14 s. Above this product the Monte Carlo pilot is used.
constexpr double kExactPilotMaxWork = 2e5;
// The `area` pilot of the wave estimator choice estimates about 1/kAreaPilotStride of the exit bins.
constexpr int kAreaPilotStride = 8;

// The incidences whose tiles the job computes (a symmetric job's other slices are rotations of them).
std::vector<int> computedIncidences(const Job& job) {
  std::vector<int> order;
  if (job.symmetryReduced()) {
    const AzimuthalSymmetry symmetry(job, DirectionGrid(job.gridLayout));
    for (int i = 0; i < int(job.incidence.size()); ++i)
      if (symmetry.representative(i) == i) order.push_back(i);
  } else {
    for (int i = 0; i < int(job.incidence.size()); ++i) order.push_back(i);
  }
  return order;
}

}  // namespace

std::vector<int> pilotIncidences(const Job& job) {
  // Candidates: the computed incidences (a pilot at a rotated slice would repeat one).
  std::vector<int> order = computedIncidences(job);
  const int n = int(order.size());
  const std::vector<int> candidates = order;
  auto cosTheta = [&](int i) { return std::abs(std::cos(radians(job.incidence[size_t(i)].theta_deg))); };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return cosTheta(a) > cosTheta(b); });
  auto dir = [&](int i) {
    return sphericalDirection(radians(job.incidence[size_t(i)].theta_deg), radians(job.incidence[size_t(i)].phi_deg));
  };
  std::vector<int> picks;
  auto add = [&](int i) {
    if (std::find(picks.begin(), picks.end(), i) == picks.end()) picks.push_back(i);
  };
  add(order.back());   // the most grazing: inter-reflection and the specular spike are strongest there
  add(order.front());  // the closest to normal
  add(order[order.size() / 2]);
  // Farthest-point spread: ties go to the lower index, so every rank and run picks the same.
  while (int(picks.size()) < std::min(n, kMaxPilots)) {
    int best = -1;
    double bestDistance = -1;
    for (int i : candidates) {
      double nearest = 1e300;
      for (int p : picks) nearest = std::min(nearest, safeAcos(dot(dir(i), dir(p))));
      if (nearest > bestDistance) bestDistance = nearest, best = i;
    }
    if (best < 0 || std::find(picks.begin(), picks.end(), best) != picks.end()) break;
    picks.push_back(best);
  }
  return picks;
}

std::optional<double> steepestFacet_deg(const Job& job) {
  const Microgeometry& g = job.geometry;
  if (job.statistical || !g.periodic || !job.closure.closed() || g.triangles.empty()) return std::nullopt;
  double slope = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const Vec3 n = g.triangleNormal(t);
    const double len = length(n);
    if (len == 0) continue;                      // degenerate: no area, no light
    if (n.z <= 1e-9 * len) return std::nullopt;  // a wall or an overhang: not a graph
    slope = std::max(slope, std::hypot(n.x, n.y) / n.z);
  }
  return degrees(std::atan(slope));
}

std::optional<double> singleBounceLimit_deg(const Job& job) {
  const std::optional<double> steepest = steepestFacet_deg(job);
  if (!steepest) return std::nullopt;
  const double thetaS = radians(*steepest);
  double limit = kPi / 2 - 3 * thetaS;
  if (!job.material.isConductor()) {
    double eta = 1e300;
    for (double l : job.lambda_um()) eta = std::min(eta, job.material.ior(l).real());
    const double s = eta * std::cos(2 * thetaS);
    if (s < 1) limit = std::min(limit, std::asin(std::max(s, -1.0)) - thetaS);
  }
  if (limit <= 0) return std::nullopt;
  return degrees(limit);
}

bool scattersOnce(const Job& job, const DirectionGrid& grid, int t, const std::optional<double>& limit_deg) {
  if (!limit_deg) return false;
  const IncidenceDirection& inc = job.incidence[size_t(t)];
  if (job.exactIncidence) return inc.theta_deg < *limit_deg;
  if (!grid.isUpper(inc.bin)) return false;
  if (const auto* tp = std::get_if<ThetaPhiGrid>(&grid.layout()))  // the bin's outer ring
    return double(inc.bin / tp->nPhi + 1) * 90.0 / tp->nTheta < *limit_deg;
  double xmin, xmax, ymin, ymax;
  grid.xyBounds(inc.bin, &xmin, &xmax, &ymin, &ymax);
  // The bin's bounding box in the projected disk: its farthest corner bounds sin θ from above.
  const double r = std::hypot(std::max(std::abs(xmin), std::abs(xmax)), std::max(std::abs(ymin), std::abs(ymax)));
  return r < 1 && degrees(std::asin(r)) < *limit_deg;
}

namespace {

// Projected-area-weighted rms height of the microgeometry (for the Rayleigh criterion).
double rmsHeight(const Microgeometry& g) {
  double w = 0, z = 0, z2 = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const auto& tri = g.triangles[t];
    const double a = std::abs(g.triangleNormal(t).z) * 0.5;
    const double c = (g.vertices[tri[0]].z + g.vertices[tri[1]].z + g.vertices[tri[2]].z) / 3.0;
    w += a;
    z += a * c;
    z2 += a * c * c;
  }
  if (w <= 0) return 0;
  z /= w;
  return std::sqrt(std::max(0.0, z2 / w - z * z));
}

// Projected-area-weighted rms slope, sqrt(<tan² θn>), of the microgeometry's facets.
double rmsSlope(const Microgeometry& g) {
  double w = 0, s2 = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const Vec3 n = g.triangleNormal(t);
    const double a = std::abs(n.z) * 0.5;
    if (a <= 0) continue;
    w += a;
    s2 += a * (n.x * n.x + n.y * n.y) / (n.z * n.z);
  }
  return w > 0 ? std::sqrt(s2 / w) : 0.0;
}

}  // namespace

std::vector<int> resolutionCells(const DirectionGrid& grid, double resolution_deg) {
  const int nB = grid.binCount();
  std::vector<int> cellOf(size_t(nB), -1);
  std::map<std::tuple<bool, int, int>, int> index;
  const double res = radians(resolution_deg);
  for (int b = 0; b < nB; ++b) {
    if (grid.projectedSolidAngle(b) <= 0) continue;
    if (res <= 0) {
      cellOf[size_t(b)] = int(index.size());
      index[{false, b, 0}] = cellOf[size_t(b)];
      continue;
    }
    // A cap of radius res/2 about the normal on the bin's side (one cell: a peak along the normal
    // is not cut into sectors), then round((90° − res/2)/res) rings of equal width w ≈ res up to
    // the horizon, each cut into sectors of about res² (ring area 2π sin θ_ring w / res²).
    const Vec3 c = grid.centre(b);
    const double theta = safeAcos(std::abs(c.z));
    const double rest = kPi / 2 - res / 2;
    const int rings = std::max(1, int(std::lround(rest / res)));
    const double w = rest / rings;
    const int ring = theta < res / 2 ? 0 : std::min(rings, 1 + int(std::floor((theta - res / 2) / w)));
    const double ringCentre = res / 2 + (ring - 0.5) * w;
    const int sectors = ring == 0 ? 1 : std::max(1, int(std::lround(2 * kPi * std::sin(ringCentre) * w / (res * res))));
    double phi = std::atan2(c.y, c.x);
    if (phi < 0) phi += 2 * kPi;
    const int sector = std::min(sectors - 1, int(std::floor(phi / (2 * kPi) * sectors)));
    auto [it, added] = index.try_emplace({c.z >= 0, ring, sector}, int(index.size()));
    cellOf[size_t(b)] = it->second;
  }
  return cellOf;
}

namespace {

nlohmann::json decision(const std::string& effect, bool on, const std::string& reason) {
  return {{"effect", effect}, {"on", on}, {"reason", reason}};
}

std::string fmt3(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}

// Wavelengths. A renderer fed with colour ([scene] colour = "rgb") needs the XYZ of each bin, not
// the spectrum: the fewest of the job's wavelengths (3, 4, ... spread evenly over the sorted list)
// whose colour — each sample standing for its band, as every reader converts it (core/colour.h) —
// matches the full spectrum's within the tolerance: for every pilot and each of X, Y, Z,
// Σ_cells |Σ_b∈cell (c_subset − c_full) Ω⊥| over the renderer's resolution cells of the model the
// job will store (GS + multiple), less its noise, + 2 sd. The noise is measured, not modelled: the
// geometric pilots run a second time with another seed, the difference is taken from their mean,
// and half the replicas' difference has the noise of that mean (the wavelengths share paths, so
// their errors are correlated and a per-wavelength error model would misjudge it). With
// diffraction on, every wavelength is kept: orders and speckle move with λ, which is what the
// samples resolve (and a Monte Carlo wave pilot is too noisy to show that a subset suffices).
// The saving: a dispersive material traces one path set per wavelength; otherwise the output.
// `replicate` fills a second, independent set of pilots (other seeds).
using PilotReplica = std::function<void(std::vector<TileResult>*)>;
nlohmann::json wavelengthDecision(const Job& job, const DirectionGrid& grid, const std::vector<TileResult>& geo,
                                  const ComponentSet& chosen, const PilotReplica& replicate, EffectsPlan* plan) {
  const int nL = int(job.lambda_nm.size()), nB = grid.binCount();
  const bool shared = job.material.directionsIndependentOfLambda();
  const std::string sharing =
      std::string(shared ? "paths shared by all of them (only Fresnel depends on lambda: per-wavelength weights)"
                         : "one path set per wavelength (dispersive dielectric: refraction depends on lambda)") +
      (chosen.has(Component::Incoherent) ? "; the wave term is evaluated per wavelength" : "");
  if (job.scene.colour != SceneNeeds::Colour::Rgb)
    return decision("wavelengths", true,
                    std::to_string(nL) + " wavelengths (the renderer needs the spectrum); " + sharing);
  if (nL <= 3)
    return decision("wavelengths", true,
                    std::to_string(nL) + " wavelengths, no fewer for colour (needs 3); " + sharing);
  std::vector<int> order(static_cast<size_t>(nL));
  for (int l = 0; l < nL; ++l) order[size_t(l)] = l;
  std::sort(order.begin(), order.end(),
            [&](int a, int b) { return job.lambda_nm[size_t(a)] < job.lambda_nm[size_t(b)]; });
  if (chosen.has(Component::Incoherent))
    return decision("wavelengths", true,
                    std::to_string(nL) +
                        " wavelengths, all kept although the renderer needs colour: diffraction changes "
                        "with lambda (orders and speckle move), which is what the samples resolve; " +
                        sharing);
  if (geo.empty())
    return decision(
        "wavelengths", true,
        std::to_string(nL) + " wavelengths, all kept: the pilot budget allows no geometric pilot; " + sharing);
  std::vector<TileResult> geo2;
  replicate(&geo2);
  const std::vector<int> cellOf = resolutionCells(grid, job.scene.angularResolution_deg);
  const int nCells = *std::max_element(cellOf.begin(), cellOf.end()) + 1;
  // The stored model's f at (replica r, pilot k, wavelength l, bin b).
  auto model = [&](int r, size_t k, int l, int b) {
    const std::vector<TileResult>& g = r == 0 ? geo : geo2;
    double f = g[k].at(Component::Coherent, l, b);
    if (chosen.has(Component::Multiple)) f += g[k].at(Component::Multiple, l, b);
    return f;
  };
  std::vector<double> sortedLambda;
  for (int l : order) sortedLambda.push_back(job.lambda_nm[size_t(l)]);
  const std::vector<Colour3> wFull = SpectrumToColour(sortedLambda).weights();
  double bestWorst = 0, worstL1 = 0;
  for (int n = 3; n < nL; ++n) {
    std::vector<int> pick;  // positions in `order`
    for (int i = 0; i < n; ++i) pick.push_back(int(std::lround(double(i) * (nL - 1) / (n - 1))));
    std::vector<double> subLambda;
    for (int i : pick) subLambda.push_back(sortedLambda[size_t(i)]);
    // c_subset − c_full = Σ_i a_i f_i: a = the subset's weight at its samples minus the full set's.
    std::vector<Colour3> a(static_cast<size_t>(nL));
    const std::vector<Colour3> wSub = SpectrumToColour(subLambda).weights();
    for (int i = 0; i < nL; ++i)
      for (int c = 0; c < 3; ++c) a[size_t(i)][size_t(c)] = -wFull[size_t(i)][size_t(c)];
    for (int j = 0; j < n; ++j)
      for (int c = 0; c < 3; ++c) a[size_t(pick[size_t(j)])][size_t(c)] += wSub[size_t(j)][size_t(c)];
    // Per pilot and channel, at the renderer's resolution (cells, resolutionCells()): L1 =
    // Σ_cells |d̄| of the replicas' mean d̄ = Σ_b∈cell d_b Ω⊥, its noise floor Σ_cells |d1 − d2|/2
    // (the same distribution as d̄'s noise), sd √Σ_cells ((d1 − d2)/2)².
    double worst = -1e300, l1AtWorst = 0;
    for (size_t k = 0; k < geo.size(); ++k) {
      std::vector<Colour3> c1(size_t(nCells), Colour3{0, 0, 0}), c2(size_t(nCells), Colour3{0, 0, 0});
      for (int b = 0; b < nB; ++b) {
        const int cell = cellOf[size_t(b)];
        if (cell < 0) continue;
        const double op = grid.projectedSolidAngle(b);
        for (int i = 0; i < nL; ++i) {
          const double f1 = model(0, k, order[size_t(i)], b) * op, f2 = model(1, k, order[size_t(i)], b) * op;
          for (int c = 0; c < 3; ++c) {
            c1[size_t(cell)][size_t(c)] += a[size_t(i)][size_t(c)] * f1;
            c2[size_t(cell)][size_t(c)] += a[size_t(i)][size_t(c)] * f2;
          }
        }
      }
      Colour3 l1{0, 0, 0}, floor{0, 0, 0}, var{0, 0, 0};
      for (int cell = 0; cell < nCells; ++cell)
        for (int c = 0; c < 3; ++c) {
          const double d1 = c1[size_t(cell)][size_t(c)], d2 = c2[size_t(cell)][size_t(c)];
          l1[size_t(c)] += std::abs(0.5 * (d1 + d2));
          floor[size_t(c)] += std::abs(0.5 * (d1 - d2));
          var[size_t(c)] += 0.25 * (d1 - d2) * (d1 - d2);
        }
      for (int c = 0; c < 3; ++c) {
        const double upper = l1[size_t(c)] - floor[size_t(c)] + 2 * std::sqrt(var[size_t(c)]);
        if (upper > worst) worst = upper, l1AtWorst = l1[size_t(c)];
      }
    }
    if (worst <= job.scene.tolerance) {
      auto d = decision("wavelengths", true,
                        "the renderer needs colour: " + std::to_string(n) + " of " + std::to_string(nL) +
                            " wavelengths reproduce the pilots' XYZ: sum|dXYZ| * proj. solid angle " + fmt3(l1AtWorst) +
                            ", beyond noise at most " + fmt3(worst) + " <= tolerance " + fmt3(job.scene.tolerance) +
                            (n > 3 ? " (" + std::to_string(n - 1) + " would not)" : "") + "; " + sharing);
      d["pilot_colour_l1"] = l1AtWorst;
      d["pilot_colour_upper"] = worst;
      d["wavelengths_nm"] = subLambda;
      plan->lambda_nm = subLambda;
      return d;
    }
    bestWorst = worst, worstL1 = l1AtWorst;
  }
  auto d = decision("wavelengths", true,
                    "the renderer needs colour, but every subset of the " + std::to_string(nL) +
                        " wavelengths changes the pilots' XYZ beyond the tolerance " + fmt3(job.scene.tolerance) +
                        " (" + std::to_string(nL - 1) + " of them: " + fmt3(worstL1) + ", beyond noise " +
                        fmt3(bestWorst) + "): all kept; " + sharing);
  d["pilot_colour_l1"] = worstL1;
  d["pilot_colour_upper"] = bestWorst;
  return d;
}

// The wave estimator ([sampling] wave_estimator = "auto" with components = "auto"),
// from the tolerance and the pilots' measured errors. The static rule (Job::resolvedWaveEstimator)
// picks by regime and measured cost ratios; a Monte Carlo pick (`orders`, `area`) gives way to a
// deterministic estimator that applies (`exact` where the cell's order lobes stay apart and its
// facet sums are cheap enough to pilot, kExactPilotMaxWork; `fft` on a periodic heightfield) when
// its own error misses the tolerance and the other's (safe-side) estimate is smaller. A pilot tile
// runs as the job would (its samples per bin, its incidence integration, the chosen components) and
// measures the tile's time and its predicted L1 error of f_ws per slice: for Monte Carlo
// √(2/π) Σ_b s_b Ω⊥ (the expected Σ|noise| Ω⊥ of Gaussian errors with standard errors s_b), for
// the deterministic ones Σ_b e_b Ω⊥ of their quadrature-error estimates, the larger over the
// wavelengths. Every figure goes in the plan (with the samples per bin `area` would need): what
// each accuracy costs on this job. Where no pilot can change the pick, none is run.
// What one estimator pilot measured: cost per tile (and once per rank), predicted error.
struct MeasuredEstimator {
  WaveEstimatorKind kind;
  std::string name;
  bool deterministic;
  double seconds, setup, error;
};

// One pilot tile of wave estimator c on incidence `pilot` as the job would run it: its predicted
// L1 error of f_ws per slice (the larger over the wavelengths) and its time. `proxy` (per bin, the
// max over λ of f_ws Ω⊥) is filled by the first pilot and tells `area`'s pilot where the lobes are.
MeasuredEstimator measureEstimatorPilot(const Job& job, const ComponentSet& chosen, const DirectionGrid& grid,
                                        const PeriodicScene& scene, int pilot, WaveEstimatorKind c,
                                        std::vector<double>& proxy, bool first) {
  using enum WaveEstimatorKind;
  const int nL = int(job.lambda_nm.size()), nB = grid.binCount();
  const auto& inc = job.incidence[size_t(pilot)];
  Job cj = job;
  cj.waveEstimator = c;
  cj.components = chosen;
  const WaveSettings ws = waveSettingsOf(cj);
  auto est = makeJobWaveEstimator(cj, grid, scene, ws);
  const bool deterministic = est->deterministic();
  // `area`'s cost is per exit bin (a tile of it can cost 40 of `orders`), so its pilot estimates
  // about 1/kAreaPilotStride of the bins at the job's samples per bin: the nB/(2 stride) bins where
  // the other estimators' table puts the most power (where its variance is: narrow lobes), each
  // counted once, and every stride-th of the others, counted stride times; the time scales with the
  // bins. Tried and rejected: a uniform stride (missed a glass grating's lobes: error 2000× too
  // small) and fewer samples per bin scaled by 1/√N (too small an error for `area`, which misses
  // the lobes with few samples, too large for `orders`, whose error does not fall as 1/√N).
  std::vector<uint8_t> mask;
  std::vector<double> weight(size_t(nB), 1.0);
  double binFraction = 1;
  if (c == Area && nB >= 4 * kAreaPilotStride) {
    std::vector<int> byPower(static_cast<size_t>(nB));
    for (int i = 0; i < nB; ++i) byPower[size_t(i)] = i;
    std::stable_sort(byPower.begin(), byPower.end(), [&](int x, int y) { return proxy[size_t(x)] > proxy[size_t(y)]; });
    mask.assign(size_t(nB), 0);
    const int top = nB / (2 * kAreaPilotStride);
    int picked = 0;
    for (int i = 0; i < nB; ++i) {
      const int bin = byPower[size_t(i)];
      if (i < top) {
        mask[size_t(bin)] = 1, ++picked;
      } else if ((i - top) % kAreaPilotStride == 0) {
        mask[size_t(bin)] = 1, ++picked;
        weight[size_t(bin)] = kAreaPilotStride;
      }
    }
    binFraction = double(picked) / nB;
  }
  const WaveTileResult w =
      est->run(tileRequestOf(job, pilot), pilotProgress("estimator pilot (" + waveEstimatorName(c) + ")", inc), mask);
  double error = 0;
  for (int l = 0; l < nL; ++l) {
    double e = 0;
    for (int bin = 0; bin < nB; ++bin) {
      if (!mask.empty() && !mask[size_t(bin)]) continue;
      const size_t x = size_t(l) * nB + bin;
      e += weight[size_t(bin)] * w.fwsErr[x] * grid.projectedSolidAngle(bin);
      if (first) proxy[size_t(bin)] = std::max(proxy[size_t(bin)], w.fws[x] * grid.projectedSolidAngle(bin));
    }
    error = std::max(error, deterministic ? e : std::sqrt(2 / kPi) * e);
  }
  const double seconds = std::max(0.0, w.seconds - est->setupSeconds()) / binFraction;
  return MeasuredEstimator{c, waveEstimatorName(c), deterministic, seconds, est->setupSeconds(), error};
}

nlohmann::json waveEstimatorDecision(const Job& job, const ComponentSet& chosen, const DirectionGrid& grid,
                                     const PeriodicScene& scene, int pilot, const std::string& unaffordable) {
  using enum WaveEstimatorKind;
  const WaveEstimatorKind resolvedKind = job.resolvedWaveEstimator();
  const std::string resolved = waveEstimatorName(resolvedKind);
  const double sigma = windowSigma(job.scene.coherenceLength_um);
  const std::vector<double> lambdas = job.lambda_um();
  const double lambdaMin = *std::min_element(lambdas.begin(), lambdas.end());
  // The deterministic estimator a Monte Carlo pick could give way to: `exact` for `orders` (the
  // cell's order lobes stay apart) where its facet sums are cheap enough to pilot, `fft` for `area`
  // on a periodic heightfield. Otherwise no pilot can change the pick, and none is run.
  std::optional<WaveEstimatorKind> alternative;
  std::string skipped;
  if (resolvedKind == Orders) {
    const double work = job.facetsPerCell() * kPi * job.cellSizeX() * job.cellSizeY() / (lambdaMin * lambdaMin);
    if (work <= kExactPilotMaxWork)
      alternative = Exact;
    else
      skipped = " (exact not piloted: facets x orders " + fmt3(work) + " > " + fmt3(kExactPilotMaxWork) + ")";
  } else if (resolvedKind == Area &&
             fftUnsuitable(job.geometry, job.material, lambdas, sigma, chosen.has(Component::Lost)).empty()) {
    alternative = Fft;
  }
  if (!alternative) {
    auto d =
        decision("estimator", true,
                 resolved + ": the job's own estimator" +
                     (deterministicEstimator(resolvedKind) ? std::string(" is deterministic")
                                                           : std::string(" has no deterministic alternative here")) +
                     skipped + "; no estimator pilot");
    d["estimator"] = resolved;
    return d;
  }
  if (!unaffordable.empty()) {
    auto d = decision("estimator", true,
                      resolved + ": the static rule (Job::resolvedWaveEstimator); no estimator pilot: " + unaffordable);
    d["estimator"] = resolved;
    return d;
  }
  const auto& inc = job.incidence[size_t(pilot)];
  const double tol = job.scene.tolerance;
  using Measured = MeasuredEstimator;
  std::vector<Measured> measured;
  std::vector<double> proxy(size_t(grid.binCount()), 0.0);  // the first table's max over λ of f_ws Ω⊥ per bin
  auto measure = [&](WaveEstimatorKind c) {
    return measureEstimatorPilot(job, chosen, grid, scene, pilot, c, proxy, measured.empty());
  };
  // The deterministic estimators' error over an incidence bin is their interpolation's and binning's
  // (incidence_binning.cpp, binOverIncidenceBin; estimates for the coarser, on the safe side). Raising
  // the node count where it misses the tolerance was tried with the plain Gauss–Legendre rule and
  // dropped (the exit bins' jumps made it converge slowly and not monotonically); with the
  // sub-direction binning the node count is no longer what limits them.
  // `orders`: its pilot, then exact's if it misses. `area`: fft's first (its table tells the area
  // pilot where the lobes are), then area's.
  if (resolvedKind == Orders) {
    measured.push_back(measure(Orders));
    if (measured.back().error > tol) measured.push_back(measure(Exact));
  } else {
    measured.push_back(measure(Fft));
    measured.push_back(measure(Area));
  }
  // The choice depends on the pilots' errors (seeded or deterministic), never on their times, so
  // every run of the job — and a resumed one, on any number of ranks and threads — makes the same:
  // the job's own estimator if it meets the tolerance; else the deterministic one with the smaller
  // error (its estimate is on the safe side; a Monte Carlo one can be too small: samples that miss a
  // lobe, or `orders`' four incidence draws — on the Al grating of the effects test 0.17–0.30
  // reported against 0.24–0.39 from 4096 draws); else the job's own.
  std::string choice = resolved, how;
  const Measured& own = resolvedKind == Orders ? measured.front() : measured.back();
  if (own.error <= tol) {
    how = "the job's own estimator meets the tolerance";
  } else {
    const Measured* best = &own;
    for (const Measured& m : measured)
      if (m.deterministic && m.error < best->error) best = &m;
    choice = best->name;
    how = choice == resolved
              ? "the job's own estimator misses the tolerance, and no deterministic one that applies does better: kept"
              : "the job's own estimator misses the tolerance; " + choice + " (deterministic) has the smaller error" +
                    (best->error <= tol ? " and meets it" : "");
  }
  std::string why = how + " (one pilot tile at theta " + fmt3(inc.theta_deg) +
                    " deg as the job runs it, `area` on about 1/" + std::to_string(kAreaPilotStride) +
                    " of the exit bins; predicted L1 error of f_ws per slice, the larger over the wavelengths; times "
                    "are reported, not used):";
  nlohmann::json figures = nlohmann::json::array();
  for (const Measured& m : measured) {
    why += " " + m.name + " " + fmt3(m.seconds) + " s per tile" +
           (m.setup > 0 ? " + " + fmt3(m.setup) + " s once per rank" : "") + ", error " + fmt3(m.error);
    nlohmann::json f = {{"estimator", m.name},
                        {"deterministic", m.deterministic},
                        {"seconds_per_tile", m.seconds},
                        {"setup_seconds", m.setup},
                        {"predicted_error", m.error}};
    if (m.kind == Area && m.error > tol) {
      // Monte Carlo over exit directions: the error falls as 1/√N in samples per bin.
      const double factor = (m.error / tol) * (m.error / tol);
      f["samples_per_bin_for_tolerance"] = double(job.waveSamplesPerBin) * factor;
      f["seconds_per_tile_for_tolerance"] = m.seconds * factor;
      why += " (" + fmt3(double(job.waveSamplesPerBin) * factor) + " samples per bin would meet it, " +
             fmt3(m.seconds * factor) + " s)";
    }
    why += ";";
    figures.push_back(f);
  }
  why += " chosen: " + choice + (choice == resolved ? "" : " (the static rule gave " + resolved + ")");
  auto d = decision("estimator", true, why);
  d["estimator"] = choice;
  d["pilot_incidence"] = pilot;
  d["candidates"] = figures;
  return d;
}

// What the decisions share: the job and its grid, the pilot incidences (planned, and those the
// budget affords) with their geometric pilot tiles, the wave settings of the pilots, and the pilot
// budget in tiles' work.
struct PilotContext {
  const Job& job;
  const DirectionGrid& grid;
  const GeometricTransport& transport;
  WaveSettings ws;
  std::vector<int> planned, pilots;
  std::vector<TileResult> geo;
  uint64_t paths = 0;
  int computed = 0;
  double budgetTiles = 0;
  double tol = 0;
  // The pilot beam of incidence p: its exact direction for a job of collimated beams, else its
  // bin's centre. Collimated pilot beams through the centres of the incidence bins: the geometric
  // and the wave pilot see the same incidence, a narrow lobe is not smeared over an incidence bin
  // by a handful of wave incidence samples, and a specular reflection lands inside a bin (a beam
  // along a bin edge or the pole would split a diffraction lobe between bins that the geometric
  // delta does not share). So these pilots judge diffraction at the bins' resolution away from
  // their edges: a lobe narrower than the bins but wide enough to spill across their edges in the
  // job's bin-averaged table (a flat mirror under a 50 µm coherence length on 11° bins: WS − GS
  // 0.12–0.33 per slice) is not seen. Averaging both pilots over the bin with a path-traced GS was
  // tried: its noise floor (0.04 at 20 000 paths) hid the flat mirror's 0.007 and the decision fell
  // back to "kept on". Where both sides can be had without noise — a deterministic wave pilot
  // (`exact`, `fft`) and the facet sum of single scattering (scattering/single_scattering.h)
  // affordable at the pilot bins — the diffraction decision averages both over the incidence bins
  // as the job does (runDiffractionPilots). A job of collimated beams (`incidence_sampling =
  // "exact"`) is piloted along its own directions: a grating lit exactly along its grooves scatters
  // nothing twice, where the bin's centre may.
  TileRequest beamRequest(int p) const {
    const IncidenceDirection& inc = job.incidence[size_t(p)];
    return TileRequest{
        p, p, inc.bin,
        job.exactIncidence ? sphericalDirection(radians(inc.theta_deg), radians(inc.phi_deg)) : grid.centre(inc.bin)};
  }
  // The incidence of tile p as the job traces it: its exact direction, or none (averaged over the
  // bin). The geometric pilots (multiple scattering, wavelengths) use it, so that they see what the
  // job's tiles see (a groove's inter-reflection that begins inside an incidence bin but not at its
  // centre) and are the first paths of those tiles.
  TileRequest jobRequest(int p) const { return tileRequestOf(job, p); }
  // The geometric single scattering along beamRequest(p) that a diffraction pilot compares with: the
  // geometric pilot where that is the same beam, else a pilot of its own.
  TileResult beamGeometry(size_t k) const {
    if (job.exactIncidence) return geo[k];
    const int p = pilots[k];
    return transport.run(beamRequest(p), pilotProgress("geometric pilot at the bin centre", job.incidence[size_t(p)]));
  }
};

// Σ f Ω⊥ of a component at wavelength l and its standard error (root-sum-square over bins).
double componentEnergy(const TileResult& r, const DirectionGrid& grid, Component c, int l, double* se) {
  double e = 0, v = 0;
  for (int b = 0; b < r.nBins; ++b) {
    const double op = grid.projectedSolidAngle(b);
    e += r.at(c, l, b) * op;
    v += std::pow(r.stdError[int(c)][size_t(l) * r.nBins + b] * op, 2);
  }
  *se = std::sqrt(v);
  return e;
}

// Multiple scattering: the geometry's bound first (singleBounceLimit_deg), then the pilots at the
// incidences it leaves open. Returns the decision with "on" set.
nlohmann::json multipleDecision(const PilotContext& ctx) {
  const Job& job = ctx.job;
  const DirectionGrid& grid = ctx.grid;
  const std::vector<int>& pilots = ctx.pilots;
  const std::vector<TileResult>& geo = ctx.geo;
  const int nL = int(job.lambda_nm.size());
  const double tol = ctx.tol;
  const std::optional<double> limit = singleBounceLimit_deg(job);
  int open = 0;
  for (int t = 0; t < int(job.incidence.size()); ++t) open += !scattersOnce(job, grid, t, limit);
  const std::string bound = limit ? "the geometry (steepest facet " + fmt3(*steepestFacet_deg(job)) +
                                        " deg) lets no path meet the surface twice below theta " + fmt3(*limit) + " deg"
                                  : "";
  nlohmann::json d;
  bool on = false;
  if (open == 0) {
    d = decision("multiple", false, bound + ", which holds every incidence of the job");
  } else {
    double worst = -1, worstValue = 0, worstTheta = 0;
    int judged = 0;
    for (size_t k = 0; k < geo.size(); ++k) {
      if (scattersOnce(job, grid, pilots[k], limit)) continue;
      ++judged;
      if (worst < 0) worst = 0, worstTheta = job.incidence[size_t(pilots[k])].theta_deg;
      for (int l = 0; l < nL; ++l) {
        double se;
        const double e = componentEnergy(geo[k], grid, Component::Multiple, l, &se);
        if (e + 3 * se > worst) {
          worst = e + 3 * se;
          worstValue = e;
          worstTheta = job.incidence[size_t(pilots[k])].theta_deg;
        }
      }
    }
    on = worst > tol || judged == 0;
    const std::string where =
        (bound.empty() ? ""
                       : bound + " (" + std::to_string(open) + " of " + std::to_string(job.incidence.size()) +
                             " incidences are above it); ");
    d = decision("multiple", on,
                 judged == 0
                     ? where + (pilots.empty() ? "the pilot budget (" + fmt3(job.pilotBudget) +
                                                     " of the job's tiles) allows no pilot: kept"
                                               : "no pilot incidence above it: kept")
                     : where + "pilot multiply scattered energy " + fmt3(worstValue) + " (+3 SE: " + fmt3(worst) +
                           ") at theta " + fmt3(worstTheta) + " deg (" + std::to_string(judged) +
                           " pilot incidences) " + (on ? "exceeds" : "is below") + " the tolerance " + fmt3(tol) +
                           (on ? "" : "; verified on every tile, computed there after all past the tolerance"));
    d["pilot_energy"] = worstValue;
    d["pilot_energy_upper"] = worst;
  }
  if (limit) d["single_bounce_below_deg"] = *limit;
  d["on"] = on;
  return d;
}

// What the diffraction pilots measured: the largest upper and lower estimates beyond noise of the
// WS − GS difference over the pilots and wavelengths, and what they rest on.
struct DiffractionPilots {
  double upper = -1e300, lower = -1e300, worstL1 = 0, worstFloor = 0, worstTheta = 0;
  int wavePilotsRun = 0, replicas = 0, nCells = 0;
  bool binAveraged = false;
  std::string estimatorName;
  double wavePilotCost = 1;
  size_t waveAffordable = 0;
  // (incidence, upper estimate over λ) of each pilot run as the job runs that tile.
  std::vector<std::pair<int, double>> jobLike;
  // The wave terms of the pilots along the job's own collimated directions (PilotResults).
  std::map<int, WaveTileResult> waveTerms;
};

// Runs the diffraction pilots the budget affords (adding their work to *waveSpent) and measures the
// WS − GS difference at the renderer's resolution.
// At wavelength l: L1 of the cells' Σ (f_ws − f_coh) Ω⊥, its expected noise (floor) and the
// variance Σ (s Ω⊥)². With a replica (a second Monte Carlo pilot of another seed) f_ws is the
// two's mean, and each cell's floor is at least the noise the two show, |Σ (w1 − w2) Ω⊥| / 2
// (the mean's noise has the distribution of the half-difference's): the standard errors
// of a heavy-tailed Kirchhoff estimate can be far too small.
struct DiffractionFigures {
  double l1, floor, var;
  double upper() const { return l1 - floor + 2 * std::sqrt(var); }
  double lower() const { return l1 - floor - 2 * std::sqrt(var); }
};
// The figures from each bin's WS − GS difference, its standard deviation and (with a replica) half
// the two pilots' difference: perBin(b) → {diff, sd, spread}.
template <class PerBin>
DiffractionFigures cellFigures(const DirectionGrid& grid, const std::vector<int>& cellOf, int nCells, PerBin perBin) {
  std::vector<double> diff(size_t(nCells), 0.0), cellVar(size_t(nCells), 0.0), spread(size_t(nCells), 0.0);
  for (int b = 0; b < grid.binCount(); ++b) {
    if (cellOf[size_t(b)] < 0) continue;
    const size_t c = size_t(cellOf[size_t(b)]);
    const double op = grid.projectedSolidAngle(b);
    const std::array<double, 3> x = perBin(b);
    diff[c] += x[0] * op;
    cellVar[c] += x[1] * op * x[1] * op;
    spread[c] += x[2] * op;
  }
  DiffractionFigures f{0, 0, 0};
  for (size_t c = 0; c < size_t(nCells); ++c) {
    f.l1 += std::abs(diff[c]);
    f.floor += std::max(std::sqrt(2 / kPi) * std::sqrt(cellVar[c]), std::abs(spread[c]));
    f.var += cellVar[c];
  }
  return f;
}
DiffractionFigures cellDifference(const DirectionGrid& grid, const std::vector<int>& cellOf, int nCells,
                                  const WaveTileResult& w, const WaveTileResult* w2, const TileResult& r, int l) {
  return cellFigures(grid, cellOf, nCells, [&](int b) {
    const size_t x = size_t(l) * grid.binCount() + b;
    const double ws = w2 ? 0.5 * (w.fws[x] + w2->fws[x]) : w.fws[x];
    const double wsErr = w2 ? 0.5 * std::hypot(w.fwsErr[x], w2->fwsErr[x]) : w.fwsErr[x];
    return std::array<double, 3>{ws - r.at(Component::Coherent, l, b),
                                 std::hypot(wsErr, r.stdError[int(Component::Coherent)][x]),
                                 w2 ? 0.5 * (w.fws[x] - w2->fws[x]) : 0.0};
  });
}

int cellCount(const std::vector<int>& cellOf) {
  return cellOf.empty() ? 0 : *std::max_element(cellOf.begin(), cellOf.end()) + 1;
}

// The diffraction pilots' wave estimator and, where they can be averaged over the incidence bins
// without noise, the facet sum of single scattering they compare with. Bin-averaged, noise-free
// pilots where the job averages over incidence bins, the wave pilot is deterministic, the facet sum
// costs at most the geometric pilot's rays at every pilot bin, and the renderer resolves the job's
// bins (a lobe's spill across bin edges is a difference there). Pooled into coarser cells their
// per-bin error bounds, which carry no sign, would add up where the binning errors of neighbouring
// bins cancel (a flat mirror pooled to 30°: difference 3e-10, bounds 0.045); the beams' pilots
// judge those cells, whose edges a lobe rarely meets.
struct DiffractionPilotSetup {
  std::unique_ptr<WaveEstimator> est;
  std::unique_ptr<FacetSingleScattering> facetGs;
  // Whether the pilots at these incidences are bin-averaged (no geometric pilot at the bins' centres).
  bool binAveraged(const Job& job, const std::vector<int>& pilots, uint64_t paths) const {
    if (!facetGs) return false;
    const double groups = job.material.directionsIndependentOfLambda() ? 1.0 : double(job.lambda_nm.size());
    for (int p : pilots)
      if (!facetGs->cheaperThan(job.incidence[size_t(p)].bin, std::nullopt, 2.0 * double(paths) * groups)) return false;
    return true;
  }
};

DiffractionPilotSetup diffractionPilotSetup(const Job& job, const DirectionGrid& grid, const PeriodicScene& scene,
                                            const WaveSettings& ws) {
  DiffractionPilotSetup s;
  s.est = makeJobWaveEstimator(job, grid, scene, ws);
  if (s.est->deterministic() && !job.exactIncidence && job.geometry.periodic && job.scene.angularResolution_deg <= 0)
    s.facetGs = std::make_unique<FacetSingleScattering>(job.geometry, scene, job.material, job.lambda_um(), grid);
  return s;
}

DiffractionPilots runDiffractionPilots(const PilotContext& ctx, DiffractionPilotSetup& setup, double* waveSpentOut,
                                       double* beamPathTiles) {
  const Job& job = ctx.job;
  const DirectionGrid& grid = ctx.grid;
  const GeometricTransport& transport = ctx.transport;
  const WaveSettings& ws = ctx.ws;
  const std::vector<int>& pilots = ctx.pilots;
  const int nL = int(job.lambda_nm.size());
  const double tol = ctx.tol, budgetTiles = ctx.budgetTiles;
  const uint64_t paths = ctx.paths;
  double& waveSpent = *waveSpentOut;
  DiffractionPilots out;
  std::unique_ptr<WaveEstimator>& est = setup.est;
  const FacetSingleScattering* facetGs = setup.facetGs.get();
  bool& binAveraged = out.binAveraged;
  binAveraged = setup.binAveraged(job, pilots, paths);
  if (binAveraged) {
    // One node order more than the job's incidence rule: the wave pilot's error estimate is then
    // the distance to the job's own rule (at the default 2 x 2 nodes the job's estimate, against
    // 1 x 1, is several times its error: a flat Al mirror's 67-79 deg bin reports 0.045 for a
    // table within 0.002 of the facet sum).
    est = makeJobWaveEstimator(job, grid, *transport.scene(), withFinerIncidenceRule(job, ws));
  }
  // Per pilot and wavelength: the L1 difference and its noise at the renderer's angular
  // resolution (bins pooled into cells of that size, resolutionCells()); the decision uses the
  // largest upper estimate (L1 − floor + 2 sd) and the largest lower estimate (L1 − floor − 2 sd).
  const std::vector<int> cellOf = resolutionCells(grid, job.scene.angularResolution_deg);
  const int nCells = out.nCells = cellCount(cellOf);
  double& upper = out.upper;
  double& lower = out.lower;
  double& worstL1 = out.worstL1;
  double& worstFloor = out.worstFloor;
  double& worstTheta = out.worstTheta;
  int& wavePilotsRun = out.wavePilotsRun;
  int& replicas = out.replicas;
  // A wave pilot's work against one of the job's wave terms: its samples per bin against the job's
  // for Monte Carlo, its incidence nodes against the job's for the deterministic ones (the pilots'
  // mean against the job's tiles': the pole and horizon bins may have a rule of their own).
  double ruleRatio = 1.0;
  if (binAveraged && !pilots.empty()) {
    double pilotNodes = 0;
    for (int t : pilots) pilotNodes += job.incidenceRuleNodesAt(grid, job.incidence[size_t(t)].bin, 1);
    ruleRatio = pilotNodes / double(pilots.size()) / job.meanIncidenceRuleNodes(grid);
  }
  const double wavePilotCost = out.wavePilotCost =
      est->deterministic() ? ruleRatio : double(ws.samplesPerBin) / double(std::max<int64_t>(1, job.waveSamplesPerBin));
  const size_t waveAffordable = out.waveAffordable =
      std::min(pilots.size(), size_t(std::floor(budgetTiles / wavePilotCost + 1e-9)));
  for (size_t k = 0; k < waveAffordable && waveSpent + wavePilotCost <= budgetTiles + 1e-9; ++k) {
    const auto& inc = job.incidence[size_t(pilots[k])];
    // Bin-averaged pilots exist only where the job averages over its bins (diffractionPilotSetup).
    const TileRequest request = binAveraged ? ctx.jobRequest(pilots[k]) : ctx.beamRequest(pilots[k]);
    const WaveTileResult w = est->run(request, pilotProgress("diffraction pilot", inc));
    const TileResult r = binAveraged ? facetGs->run(request, {}) : ctx.beamGeometry(k);
    if (!binAveraged && !job.exactIncidence) *beamPathTiles += double(paths) / double(job.pathsPerSlice);
    auto figures = [&](int l, const WaveTileResult* w2) { return cellDifference(grid, cellOf, nCells, w, w2, r, l); };
    std::vector<DiffractionFigures> fig;
    bool marginal = false;
    for (int l = 0; l < nL; ++l) {
      fig.push_back(figures(l, nullptr));
      const DiffractionFigures& f = fig.back();
      // "On" from a Monte Carlo pilot whose noise floor is most of its difference rests on that
      // floor being right: confirmed by a replica (the gentle noise's area pilot: L1 38.6 against
      // a floor of 34.2 claimed 1.99 beyond it at one incidence).
      marginal = marginal || (!est->deterministic() && f.lower() > tol && f.floor > 0.5 * f.l1);
    }
    waveSpent += wavePilotCost;
    // A marginal pilot the budget cannot confirm decides nothing (its lower estimate is dropped).
    const bool unconfirmed = marginal && waveSpent + wavePilotCost > budgetTiles + 1e-9;
    if (marginal && !unconfirmed) {
      waveSpent += wavePilotCost;
      WaveSettings other = ws;
      other.seed = ws.seed ^ 0x5851F42D4C957F2Dull;
      const WaveTileResult w2 = makeJobWaveEstimator(job, grid, *transport.scene(), other)
                                    ->run(request, pilotProgress("diffraction pilot replica", inc));
      ++replicas;
      for (int l = 0; l < nL; ++l) fig[size_t(l)] = figures(l, &w2);
    }
    double pilotUpper = -1e300;
    for (const DiffractionFigures& f : fig) {
      if (!unconfirmed) lower = std::max(lower, f.lower());
      pilotUpper = std::max(pilotUpper, f.upper());
      if (f.upper() > upper) {
        upper = f.upper();
        worstL1 = f.l1;
        worstFloor = f.floor;
        worstTheta = inc.theta_deg;
      }
    }
    // A pilot that treats its incidence as the job does (averaged over the bin, or along the job's
    // own direction) verifies a skip on that tile; a beam through the centre of a bin the job
    // averages over does not (TileComputer checks that tile itself).
    if (binAveraged || job.exactIncidence) out.jobLike.emplace_back(pilots[k], pilotUpper);
    if (!binAveraged && job.exactIncidence) out.waveTerms.emplace(pilots[k], w);
    // One pilot whose difference exceeds the tolerance beyond noise decides: the others would
    // only confirm it (they cost as much as a tile's wave term each).
    wavePilotsRun = int(k) + 1;
    if (lower > tol) break;
  }
  out.estimatorName = est->name();
  return out;
}

}  // namespace

double diffractionUpperBound(const TileResult& r, const DirectionGrid& grid, const std::vector<int>& cellOf) {
  if (!r.has(Component::Incoherent)) return 0;
  const int nCells = cellCount(cellOf);
  double bound = 0;
  for (int l = 0; l < r.nLambda; ++l) {
    const DiffractionFigures f = cellFigures(grid, cellOf, nCells, [&](int b) {
      const double v = r.at(Component::Incoherent, l, b);
      const double e = r.stdError[int(Component::Incoherent)][size_t(l) * r.nBins + b];
      // A bin the wave term left out (none on a checked tile) adds nothing.
      return std::isfinite(v) && std::isfinite(e) ? std::array<double, 3>{v, e, 0.0} : std::array<double, 3>{0, 0, 0};
    });
    bound = std::max(bound, f.upper());
  }
  return bound;
}

namespace {

// The diffraction decision from the pilots' figures, the budget and, where the pilots cannot decide
// and the features are much larger than λ, a Kirchhoff-theory estimate. Returns it with "on" set.
// Kirchhoff-theory estimate, used when the pilot cannot decide (its noise straddles the
// tolerance): the diffraction-limited specular spike 2 R e^{-g} (geometric optics has none;
// R <= 1) plus the blur of a lobe of width 2·slope by the window's diffraction, angular sd
// λ/(2√2 π σ_w) with σ_w = δc/6, which changes a Gaussian lobe by about (blur/width)² in L1.
// Valid only for features much larger than λ: correlation length √2 σ_h / slope >= 5 λ.
// g is the Rayleigh roughness (4π σ_h cos θi / λ)² at the job's most grazing incidence and longest
// wavelength (the smallest g, the strongest specular spike; the longest λ also blurs most), so the
// estimate holds for every tile of the job and needs no check on them; the regime, a rule of thumb,
// is judged at the mean wavelength.
struct KirchhoffEstimate {
  double sigmaH, slope, g, corr, blurRad, lobeRad, physical;
  bool geometricRegime;
};
KirchhoffEstimate kirchhoffEstimate(const Job& job) {
  const double lambda = *std::max_element(job.lambda_nm.begin(), job.lambda_nm.end()) * 1e-3;
  const double sigmaH = rmsHeight(job.geometry), slope = rmsSlope(job.geometry);
  double cosMin = 1;
  for (const IncidenceDirection& inc : job.incidence)
    cosMin = std::min(cosMin, std::abs(std::cos(radians(inc.theta_deg))));
  const double g = std::pow(4 * kPi * sigmaH * cosMin / lambda, 2);
  const double corr = slope > 0 ? std::sqrt(2.0) * sigmaH / slope : 0.0;
  const double sigmaW = windowSigma(job.scene.coherenceLength_um);
  const double blurRad = sigmaW > 0 ? lambda / (2 * std::sqrt(2.0) * kPi * sigmaW) : kPi;
  const double lobeRad = 2 * slope;
  const double physical = 2 * std::exp(-std::min(g, 700.0)) + (lobeRad > 0 ? std::pow(blurRad / lobeRad, 2) : 1e300);
  // The regime (features >> λ) is judged at the mean wavelength, as documented.
  return {sigmaH, slope, g, corr, blurRad, lobeRad, physical, corr >= 5 * job.meanLambda_um() && slope > 0};
}

// Diffraction from physics on a random rough surface, before any pilot (scattering/kirchhoff_ensemble.h):
// the scalar Kirchhoff table of the surface's ensemble against geometric optics, on the job's bins
// pooled to the renderer's resolution, averaged over each incidence bin (a 8 x 8 rule: the job's
// smaller rule is its own quadrature error, not diffraction) or along the job's collimated
// directions, at the computed incidences and the wavelengths of ensembleWavelengths. "On" where the
// L1 distance exceeds the tolerance at any of them (keeping diffraction never makes a table wrong);
// "off" where the upper bound, which counts every bit of the diffuse part as a difference (a
// realisation's speckle included), stays below it at every computed incidence; otherwise the
// pilots decide. It applies to the generated Gaussian surfaces and to a flat with ground noise
// (Gaussian heights of Gaussian correlation), conductors lit from above, and patches of at least
// kEnsembleMinAreas correlation areas (a realisation's slope histogram is then the ensemble's).
constexpr int kEnsembleMaxIncidences = 64;
constexpr int kEnsembleIncidenceNodes = 64;
constexpr double kEnsembleMinAreas = 100;

}  // namespace

std::optional<KirchhoffEnsemble> jobEnsemble(const Job& job) {
  if (job.statistical || (job.geometryKind != "gaussian" && job.geometryKind != "flat") || !job.material.isConductor())
    return std::nullopt;
  for (const IncidenceDirection& inc : job.incidence)
    if (inc.theta_deg >= 90) return std::nullopt;
  const double sigmaH = rmsHeight(job.geometry), alpha = rmsSlope(job.geometry);
  if (sigmaH <= 0 || alpha <= 0) return std::nullopt;
  const KirchhoffEnsemble ensemble(sigmaH, alpha, windowSigma(job.scene.coherenceLength_um));
  const double ell = ensemble.correlationLength_um();
  if (job.geometry.sizeX * job.geometry.sizeY < kEnsembleMinAreas * ell * ell) return std::nullopt;
  return ensemble;
}

namespace {
// Incidence i as the job samples it: kEnsembleIncidenceNodes directions over its bin, or its exact
// direction, with weights summing to 1.
std::vector<std::pair<Vec3, double>> incidenceNodes(const Job& job, const DirectionGrid& grid, int i) {
  const IncidenceDirection& inc = job.incidence[size_t(i)];
  std::optional<Vec3> exact;
  if (job.exactIncidence) exact = sphericalDirection(radians(inc.theta_deg), radians(inc.phi_deg));
  std::vector<std::pair<Vec3, double>> wi;
  for (const wave::IncidenceNode& n : wave::incidenceRule(grid, inc.bin, exact, kEnsembleIncidenceNodes))
    if (n.high) wi.emplace_back(n.wi, n.weight);
  return wi;
}
}  // namespace

EnsembleSlice ensembleSlice(const Job& job, const KirchhoffEnsemble& ensemble, const DirectionGrid& grid, int incidence,
                            double lambda_nm, const std::vector<int>& cellOf) {
  const Complex eta = job.material.ior(lambda_nm * 1e-3);
  const double nOut = job.material.outsideIor;
  const auto reflectance = [&](double c) {
    return job.material.isPerfectConductor() ? 1.0 : fresnelReflectance(c, nOut, eta);
  };
  return ensemble.slice(grid, incidenceNodes(job, grid, incidence), lambda_nm * 1e-3, nOut, reflectance, cellOf,
                        cellCount(cellOf));
}

bool jobFlatInterface(const Job& job) {
  const Microgeometry& g = job.geometry;
  // Without a window the wave model takes one copy of the patch, whose aperture's diffraction the
  // closed form does not hold; holes or cracks diffract too.
  if (job.statistical || !g.periodic || g.vertices.empty() || g.triangles.empty() || !job.closure.closed() ||
      !(job.scene.coherenceLength_um > 0))
    return false;
  const double z0 = g.vertices.front().z, tol = 1e-9 * std::max({1.0, g.sizeX, g.sizeY});
  for (const Vec3& v : g.vertices)
    if (std::abs(v.z - z0) > tol) return false;
  if (job.material.isConductor()) {
    for (const IncidenceDirection& inc : job.incidence)
      if (inc.theta_deg >= 90) return false;
    return true;
  }
  for (double l_nm : job.lambda_nm)
    if (job.material.ior(l_nm * 1e-3).imag() != 0) return false;  // absorbed inside: pilots decide
  return true;
}

EnsembleSlice flatInterfaceSliceOf(const Job& job, const DirectionGrid& grid, int incidence, double lambda_nm,
                                   const std::vector<int>& cellOf) {
  const std::vector<std::pair<Vec3, double>> wi = incidenceNodes(job, grid, incidence);
  const bool fromAbove = wi.empty() || wi.front().first.z >= 0;
  const Material& m = job.material;
  const double nOut = m.outsideIor;
  FlatInterfaceMedia media{nOut, std::nullopt, [](double) { return 1.0; }};
  if (m.isConductor()) {
    const Complex eta = m.ior(lambda_nm * 1e-3);
    if (!m.isPerfectConductor()) media.reflectance = [=](double c) { return fresnelReflectance(c, nOut, eta); };
  } else {
    const double nIn = m.ior(lambda_nm * 1e-3).real();
    media.nIncident = fromAbove ? nOut : nIn;
    media.nBeyond = fromAbove ? nIn : nOut;
    const double n1 = media.nIncident, n2 = *media.nBeyond;
    media.reflectance = [=](double c) { return fresnelReflectance(c, n1, Complex(n2)); };
  }
  return flatInterfaceSlice(grid, wi, lambda_nm * 1e-3, media, windowSigma(job.scene.coherenceLength_um), cellOf,
                            cellCount(cellOf));
}

namespace {

// The wavelengths the ensemble is evaluated at: the shortest (the largest Rayleigh g, the brightest
// halo), the longest (the widest window blur), and those of the highest reflectance R and R/λ² at
// normal incidence (the distances scale with R, the halo's energy with g R).
std::vector<double> ensembleWavelengths(const Job& job) {
  const auto [lMin, lMax] = std::minmax_element(job.lambda_nm.begin(), job.lambda_nm.end());
  auto reflectance = [&](double l_nm) {
    return job.material.isPerfectConductor()
               ? 1.0
               : fresnelReflectance(1.0, job.material.outsideIor, job.material.ior(l_nm * 1e-3));
  };
  const auto brightest = std::max_element(job.lambda_nm.begin(), job.lambda_nm.end(),
                                          [&](double a, double b) { return reflectance(a) < reflectance(b); });
  const auto brightestHalo = std::max_element(job.lambda_nm.begin(), job.lambda_nm.end(), [&](double a, double b) {
    return reflectance(a) / (a * a) < reflectance(b) / (b * b);
  });
  std::vector<double> v{*lMin, *lMax, *brightest, *brightestHalo};
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
  return v;
}

// The largest distance of a closed-form wave table from geometric optics (EnsembleSlice) over the
// job's computed incidences (at most kEnsembleMaxIncidences, else the pilot incidences) and the
// given wavelengths, and where its L1 part lies.
struct ClosedFormDistance {
  double l1 = -1, upper = -1, theta_deg = 0, lambda_nm = 0;
  size_t incidences = 0;
  bool everyIncidence = false;
};
ClosedFormDistance closedFormDistance(const Job& job, const std::vector<double>& lambdas,
                                      const std::function<EnsembleSlice(int, double)>& slice) {
  const std::vector<int> computed = computedIncidences(job);
  ClosedFormDistance d;
  d.everyIncidence = computed.size() <= size_t(kEnsembleMaxIncidences);
  const std::vector<int> evaluated = d.everyIncidence ? computed : pilotIncidences(job);
  d.incidences = evaluated.size();
  for (int i : evaluated)
    for (double l_nm : lambdas) {
      const EnsembleSlice s = slice(i, l_nm);
      if (s.l1() > d.l1) d.l1 = s.l1(), d.theta_deg = job.incidence[size_t(i)].theta_deg, d.lambda_nm = l_nm;
      d.upper = std::max(d.upper, s.upperBound());
    }
  return d;
}

// "On" where the L1 distance exceeds the tolerance anywhere (keeping diffraction never makes a table
// wrong), "off" for every tile where the upper bound stays below it at every computed incidence;
// otherwise none (the pilots decide). `bound` says what the upper bound counts.
std::optional<nlohmann::json> closedFormDiffractionDecision(const Job& job, const ClosedFormDistance& d,
                                                            const std::string& surface, const std::string& bound,
                                                            const std::string& decidedBy) {
  const double tol = job.scene.tolerance;
  const bool on = d.l1 > tol;
  if (!on && !(d.everyIncidence && d.upper <= tol)) return std::nullopt;
  const std::string cells = job.scene.angularResolution_deg > 0 ? " on the bins pooled to the renderer's " +
                                                                      fmt3(job.scene.angularResolution_deg) + " deg"
                                                                : "";
  nlohmann::json j = decision(
      "incoherent", on,
      on ? surface + cells + " differs from geometric optics by " + fmt3(d.l1) +
               " (sum|f_ws - f_gs| * proj. solid angle) at theta " + fmt3(d.theta_deg) + " deg, " + fmt3(d.lambda_nm) +
               " nm, beyond the tolerance " + fmt3(tol) + ": on, no pilot needed"
         : surface + cells + " differs from geometric optics by at most " + fmt3(d.upper) + " (" + bound +
               ") at every one of the " + std::to_string(d.incidences) + " computed incidences, below the tolerance " +
               fmt3(tol) + ": off, for every tile, no pilot needed");
  j["decided_by"] = decidedBy;
  j["closed_form_l1"] = d.l1;
  j["closed_form_upper"] = d.upper;
  j["closed_form_theta_deg"] = d.theta_deg;
  j["closed_form_lambda_nm"] = d.lambda_nm;
  j["closed_form_incidences"] = d.incidences;
  j["wave_pilots_run"] = 0;
  return j;
}

std::optional<nlohmann::json> ensembleDiffractionDecision(const Job& job, const DirectionGrid& grid) {
  const std::optional<KirchhoffEnsemble> ensemble = jobEnsemble(job);
  if (!ensemble) return std::nullopt;
  const std::vector<int> cellOf = resolutionCells(grid, job.scene.angularResolution_deg);
  const ClosedFormDistance d = closedFormDistance(job, ensembleWavelengths(job), [&](int i, double l_nm) {
    return ensembleSlice(job, *ensemble, grid, i, l_nm, cellOf);
  });
  const double sigmaH = ensemble->rmsHeight_um(), alpha = ensemble->rmsSlope();
  const double ell = ensemble->correlationLength_um();
  const std::string surface = "the Kirchhoff ensemble of a Gaussian surface of rms height " + fmt3(sigmaH) +
                              " um and rms slope " + fmt3(alpha) + " (correlation length " + fmt3(ell) +
                              " um; Beckmann & Spizzichino 1963)";
  std::optional<nlohmann::json> j = closedFormDiffractionDecision(
      job, d, surface, "its whole diffuse part counted as a difference", "kirchhoff ensemble");
  if (!j) return j;
  (*j)["rms_height_um"] = sigmaH;
  (*j)["rms_slope"] = alpha;
  (*j)["correlation_length_um"] = ell;
  return j;
}

// A flat interface: every job wavelength up to kFlatWavelengths (the beams' spread grows with λ, R
// and T change with it), beyond that those of the ensemble's choice and the extremes of the index.
constexpr size_t kFlatWavelengths = 16;
std::optional<nlohmann::json> flatDiffractionDecision(const Job& job, const DirectionGrid& grid) {
  if (!jobFlatInterface(job)) return std::nullopt;
  std::vector<double> lambdas = job.lambda_nm;
  if (lambdas.size() > kFlatWavelengths) {
    lambdas = ensembleWavelengths(job);
    auto index = [&](double l_nm) { return job.material.ior(l_nm * 1e-3).real(); };
    const auto [lo, hi] = std::minmax_element(job.lambda_nm.begin(), job.lambda_nm.end(),
                                              [&](double a, double b) { return index(a) < index(b); });
    lambdas.insert(lambdas.end(), {*lo, *hi});
  }
  const std::vector<int> cellOf = resolutionCells(grid, job.scene.angularResolution_deg);
  const ClosedFormDistance d = closedFormDistance(
      job, lambdas, [&](int i, double l_nm) { return flatInterfaceSliceOf(job, grid, i, l_nm, cellOf); });
  return closedFormDiffractionDecision(job, d,
                                       "a flat interface (its specular beams spread by the coherence window's "
                                       "diffraction, in closed form)",
                                       "exact: a flat patch has no speckle", "flat interface");
}

// Diffraction from physics before any pilot, where a closed form holds: a flat interface, or the
// Kirchhoff ensemble of a random rough surface.
std::optional<nlohmann::json> physicsDiffractionDecision(const Job& job, const DirectionGrid& grid) {
  if (std::optional<nlohmann::json> d = flatDiffractionDecision(job, grid)) return d;
  return ensembleDiffractionDecision(job, grid);
}

nlohmann::json diffractionVerdict(const PilotContext& ctx, const DiffractionPilots& m) {
  const Job& job = ctx.job;
  const DirectionGrid& grid = ctx.grid;
  const double tol = ctx.tol;
  const std::vector<int>& planned = ctx.planned;
  const int computed = ctx.computed;
  const double meanLambda = job.meanLambda_um();
  const double binDeg = degrees(std::sqrt(2 * kPi / grid.binsPerHemisphere()));
  const double upper = m.upper, lower = m.lower, worstL1 = m.worstL1, worstFloor = m.worstFloor,
               worstTheta = m.worstTheta;
  const int wavePilotsRun = m.wavePilotsRun, replicas = m.replicas, nCells = m.nCells;
  const bool binAveraged = m.binAveraged;
  const double wavePilotCost = m.wavePilotCost;
  const size_t waveAffordable = m.waveAffordable;
  nlohmann::json d;
  bool on = false;
  std::string decidedBy = "kirchhoff";  // of an "off": the pilots, or the Kirchhoff estimate
  // "On" needs one pilot incidence; "off" the first three of the planned ones (the most grazing,
  // the closest to normal and the median), the spread after them as far as the budget goes.
  const bool complete = wavePilotsRun >= std::min<int>(3, int(planned.size()));
  const KirchhoffEstimate k = kirchhoffEstimate(job);
  const double g = k.g, sigmaH = k.sigmaH, slope = k.slope, corr = k.corr, blurRad = k.blurRad, lobeRad = k.lobeRad,
               physical = k.physical;
  const bool geometricRegime = k.geometricRegime;
  const double blurDeg = job.scene.coherenceLength_um > 0 ? degrees(meanLambda / job.scene.coherenceLength_um) : 0;
  std::string why =
      std::string(binAveraged ? "pilot (averaged over the incidence bins without noise: " + m.estimatorName +
                                    " and the facet sum of single scattering) "
                  : job.exactIncidence ? "pilot (beams along the job's own directions) "
                                       : "pilot (beams at the bins' centres) ") +
      "WS - GS difference sum|f_ws - f_coh| * proj. solid angle = " + fmt3(worstL1) + " (noise floor " +
      fmt3(worstFloor) + "; beyond noise: lower estimate " + fmt3(lower) + ", upper " + fmt3(upper) + ") at theta " +
      fmt3(worstTheta) + " deg" +
      (wavePilotsRun < int(planned.size())
           ? " (" + std::to_string(wavePilotsRun) + " of " + std::to_string(planned.size()) + " wave pilots run)"
           : "") +
      (replicas > 0 ? " (" + std::to_string(replicas) +
                          " marginal wave pilot(s) re-run with another seed: the floor is at "
                          "least the noise the two show)"
                    : "");
  const std::string budgetNote =
      "the pilot budget (" + fmt3(job.pilotBudget) + " of the job's " + std::to_string(computed) +
      " computed tiles, a wave pilot costing " + fmt3(wavePilotCost) + " of a tile's wave term) allows " +
      std::to_string(waveAffordable) + " of " + std::to_string(planned.size()) + " wave pilots";
  if (wavePilotsRun == 0) {
    why = budgetNote;
    if (geometricRegime) {
      on = physical > tol;
      why += "; Kirchhoff estimate 2 exp(-g) + (blur/lobe)^2 = " + fmt3(physical) + " (correlation length " +
             fmt3(corr) + " um >= 5 lambda) " + (on ? "exceeds" : "is below") + " the tolerance " + fmt3(tol);
    } else {
      on = true;
      why += ": kept on";
    }
  } else if (upper <= tol && !complete && !geometricRegime) {
    on = true;
    why += " is below the tolerance " + fmt3(tol) + ", but " + budgetNote + ": kept on";
  } else if (upper <= tol && !complete) {
    on = physical > tol;
    why += " is below the tolerance " + fmt3(tol) + ", but " + budgetNote + "; Kirchhoff estimate " + fmt3(physical) +
           (on ? " exceeds it: kept on" : " is below it too");
  } else if (upper <= tol) {
    on = false;
    decidedBy = "pilots";
    why +=
        " is below the tolerance " + fmt3(tol) + (wavePilotsRun < int(planned.size()) ? " (" + budgetNote + ")" : "");
  } else if (lower > tol) {
    on = true;
    why += " exceeds the tolerance " + fmt3(tol);
  } else if (geometricRegime) {
    on = physical > tol;
    why += " cannot decide at the tolerance " + fmt3(tol) +
           "; Kirchhoff estimate 2 exp(-g) + (blur/lobe)^2 = " + fmt3(physical) + " (correlation length " + fmt3(corr) +
           " um >= 5 lambda, blur " + fmt3(degrees(blurRad)) + " deg, lobe " + fmt3(degrees(lobeRad)) + " deg) " +
           (on ? "exceeds it" : "is below it");
  } else {
    on = true;
    why += " cannot decide at the tolerance " + fmt3(tol) + " and the features (correlation length " + fmt3(corr) +
           " um) are not >> lambda: kept on";
  }
  d = decision(
      "incoherent", on,
      why + "; Rayleigh roughness g = " + fmt3(g) +
          (g < 0.1  ? " (smooth: specular with a diffuse halo)"
           : g > 10 ? " (rough)"
                    : " (intermediate)") +
          "; coherence blur lambda/delta_c = " + fmt3(blurDeg) + " deg vs bins of " + fmt3(binDeg) + " deg" +
          (job.scene.angularResolution_deg > 0 ? " pooled to the renderer's " + fmt3(job.scene.angularResolution_deg) +
                                                     " deg (" + std::to_string(nCells) + " cells)"
                                               : ""));
  d["pilot_incidence"] = binAveraged ? "bin-averaged" : job.exactIncidence ? "exact" : "bin centre";
  d["pilot_lower"] = lower;
  d["kirchhoff_estimate"] = physical;
  d["rms_slope"] = slope;
  d["correlation_length_um"] = corr;
  d["pilot_l1"] = worstL1;
  d["pilot_noise_floor"] = worstFloor;
  d["pilot_upper"] = upper;
  d["rayleigh_g"] = g;
  d["rms_height_um"] = sigmaH;
  d["coherence_blur_deg"] = blurDeg;
  d["bin_deg"] = binDeg;
  d["angular_resolution_deg"] = job.scene.angularResolution_deg;
  d["resolution_cells"] = nCells;
  d["wave_samples_per_bin"] = ctx.ws.samplesPerBin;
  d["wave_pilots_run"] = wavePilotsRun;
  d["wave_pilot_replicas"] = replicas;
  if (!on) d["decided_by"] = decidedBy;
  if (!on && decidedBy == "pilots") {
    nlohmann::json verified = nlohmann::json::array();
    for (const auto& [incidence, bound] : m.jobLike) verified.push_back({{"incidence", incidence}, {"upper", bound}});
    d["pilot_verified"] = verified;
  }
  d["on"] = on;
  return d;
}

// Transmission: a conductor has none; a dielectric's wave term skips the transmitted bins where the
// renderer needs only the BRDF (EffectsPlan::waveTransmission).
nlohmann::json btdfDecision(const Job& job, const ComponentSet& chosen, EffectsPlan* plan) {
  if (job.material.isConductor())
    return decision("btdf", false, "a conductor transmits nothing: no BTDF (transmitted bins are zero)");
  {
    const bool needs = std::find(job.scene.needs.begin(), job.scene.needs.end(), "btdf") != job.scene.needs.end();
    // Without a BTDF to render, the wave term's transmitted bins are not worth their cost; the
    // paths still cross the surface (a dielectric's reflection depends on what comes back through
    // it), so the transmitted table keeps geometric optics. Kept when `lost` is requested (its
    // masked power needs every exit bin).
    const bool skip = !needs && chosen.has(Component::Incoherent) && !chosen.has(Component::Lost);
    auto d = decision("btdf", needs,
                      needs  ? "a dielectric transmits and the renderer needs the BTDF"
                      : skip ? "the renderer needs only the BRDF: the wave term skips the transmitted "
                               "bins, which keep geometric optics (incoherent = 0 there)"
                             : "the renderer needs only the BRDF; transmission is traced with the "
                               "reflection (the paths cross the surface) and costs no wave term here");
    plan->waveTransmission = !skip;
    return d;
  }
}

// The job's wave estimator for the pilots, with at least options.waveSamplesPerBin samples and no
// masked sums (`lost` is decided on request only).
WaveSettings pilotWaveSettings(const Job& job, const EffectsPilotOptions& options) {
  WaveSettings ws = waveSettingsOf(job);
  ws.computeMasked = false;
  // Where the grating-order regime holds (a periodic patch under a window much wider than it), the
  // deterministic `exact` evaluator gives the pilot without sampling noise, so a
  // difference is judged against the tolerance alone; it is used when the facet sums stay cheap.
  {
    const std::vector<double> lambdas = job.lambda_um();
    const double lambdaMin = *std::min_element(lambdas.begin(), lambdas.end());
    // One cell's facets over the cell's orders (lattice_cell.h).
    const double work = job.facetsPerCell() * kPi * job.cellSizeX() * job.cellSizeY() / (lambdaMin * lambdaMin);
    if (ws.estimator == WaveEstimatorKind::Orders && work <= kExactPilotMaxWork)
      ws.estimator = WaveEstimatorKind::Exact;
  }
  ws.samplesPerBin = std::max<int>(options.waveSamplesPerBin, int(job.waveSamplesPerBin));
  return ws;
}

// The incidences the renderer looks up ([scene] incidence_max_deg), reported.
nlohmann::json incidenceDecision(const Job& job, const DirectionGrid& grid) {
  int candidates = 0;
  for (int b = 0; b < (job.material.isConductor() ? grid.binsPerHemisphere() : grid.binCount()); ++b)
    candidates += grid.projectedSolidAngle(b) > 0;
  return decision(
      "incidence", true,
      "the renderer looks up incidences within " + fmt3(job.scene.incidenceMax_deg) +
          " deg of the normal ([scene] incidence_max_deg): " + std::to_string(job.incidence.size()) +
          (job.incidenceAll ? " of " + std::to_string(candidates) + " incidence bins" : " listed incidences"));
}

// Components named beside "auto" are kept whatever the pilots say.
void keepIfRequested(nlohmann::json& d, const ComponentSet& forced, Component c) {
  if (forced.has(c) && !d["on"].get<bool>()) {
    d["reason"] = d["reason"].get<std::string>() + "; kept: requested";
    d["on"] = true;
    d.erase("decided_by");
    d.erase("pilot_verified");
  }
}

}  // namespace

// A diffraction skip the pilots decided is verified on every tile no pilot covered by that tile's
// own wave term (TileComputer), so it never costs more than the wave term it skips — unless the job
// would halve its wave term by reciprocity (docs/physics.md §8), which a slice-by-slice check
// cannot (a slice's diffraction would come from its reciprocal partner's). Then, when more than
// half the computed tiles need the check, computing diffraction is the cheaper way: it stays on.
void keepIfVerifyingCostsMore(const Job& job, int computed, nlohmann::json& d) {
  if (d["on"].get<bool>() || d.value("decided_by", "") != "pilots") return;
  Job withDiffraction = job;
  withDiffraction.components.add(Component::Incoherent);
  const int unverified = computed - int(d["pilot_verified"].size());
  if (!withDiffraction.halvesWaveByReciprocity() || 2 * unverified <= computed) return;
  d["on"] = true;
  d.erase("decided_by");
  d.erase("pilot_verified");
  d["reason"] = d["reason"].get<std::string>() + "; but verifying the skip on the " + std::to_string(unverified) +
                " of " + std::to_string(computed) +
                " tiles no pilot covered would cost more than the wave term the job halves by reciprocity: kept on";
}

namespace {

// The job the geometric pilots trace: every path depth, with the job's tallies, so that a pilot tile
// is the job's own (a requested `lost` tallies one more).
Job geometricPilotJob(const Job& job, const ComponentSet& forced) {
  Job pilotJob = job;
  pilotJob.components = ComponentSet{};
  pilotJob.components.add(Component::Coherent);
  pilotJob.components.add(Component::Multiple);
  if (forced.has(Component::Lost)) pilotJob.components.add(Component::Lost);
  return pilotJob;
}

// The plan's scene and pilot fields, once its decisions are made: which pilots ran, whether they
// are the job's own tiles, and what they cost against the budget.
void recordPilots(const PilotContext& ctx, double beamPathTiles, double waveSpent, EffectsPlan& plan) {
  const Job& job = ctx.job;
  plan.tolerance = ctx.tol;
  plan.coherenceLength_um = job.scene.coherenceLength_um;
  plan.coherenceSource = job.scene.coherenceSource;
  if (job.scene.sourceAngularDiameter_deg > 0) plan.sourceAngularDiameter_deg = job.scene.sourceAngularDiameter_deg;
  plan.pilots = ctx.pilots;
  plan.pilotsPlanned = ctx.planned;
  plan.pilotPaths = ctx.paths;
  // A pilot is the job's tile unless the run computes other wavelengths than the pilots traced.
  plan.pilotTilesKept = !plan.lambda_nm;
  // Kept pilots cost the job nothing when it traces paths on every tile (with `multiple`, or a
  // statistical surface); where it may take single scattering from the facet sum instead, they count.
  const bool pilotsFree = plan.pilotTilesKept && (job.statistical || plan.components.has(Component::Multiple));
  const double geometric = double(ctx.pilots.size()) * double(ctx.paths) / double(job.pathsPerSlice);
  plan.pilotBudget = PilotBudgetUse{job.pilotBudget, ctx.computed, ctx.budgetTiles,
                                    (pilotsFree ? 0.0 : geometric) + beamPathTiles, waveSpent};
}

}  // namespace

EffectsPlan planEffects(const Job& job, const EffectsPilotOptions& options, PilotResults* kept) {
  const auto t0 = Clock::now();
  const DirectionGrid grid(job.gridLayout);
  const double tol = job.scene.tolerance;
  // Components named beside "auto" are kept whatever the pilots say.
  ComponentSet forced;
  for (const auto& c : job.requestedComponents)
    if (auto comp = componentFromName(c)) forced.add(*comp);

  const Job pilotJob = geometricPilotJob(job, forced);
  const uint64_t paths = std::min<uint64_t>(options.paths, job.pathsPerSlice);
  GeometricTransport transport(pilotJob, grid, paths);
  // The pilot budget (Job::pilotBudget), in tiles' work: the job computes `computed` tiles of
  // paths_per_slice paths and one wave term each; a geometric pilot costs paths / paths_per_slice of
  // a tile's paths, a wave pilot its samples against the job's (wavePilotCost below). The pilots run
  // in priority order (pilotIncidences): the budget keeps the first ones.
  const std::vector<int> planned = pilotIncidences(job);
  const WaveSettings ws = pilotWaveSettings(job, options);
  const int computed =
      job.symmetryReduced() ? AzimuthalSymmetry(job, grid).representativeCount() : int(job.incidence.size());
  const double budgetTiles = job.pilotBudget * computed;
  // A job that averages over its incidence bins has its diffraction pilots compared with beams
  // through the bins' centres (PilotContext::beam): room is left for one such geometric pilot each.
  // Diffraction from physics first where it applies (a flat interface, a random rough surface): no
  // wave pilot then.
  const std::optional<nlohmann::json> physicsDiffraction = physicsDiffractionDecision(job, grid);
  const bool diffractionPilots = !job.statistical && !physicsDiffraction;
  std::optional<DiffractionPilotSetup> diffractionSetup;
  if (diffractionPilots) diffractionSetup = diffractionPilotSetup(job, grid, *transport.scene(), ws);
  const bool beams = diffractionPilots && !job.exactIncidence && !diffractionSetup->binAveraged(job, planned, paths);
  const double pathsPerPilot = double(paths) * (beams ? 2.0 : 1.0);
  std::vector<int> pilots = planned;
  pilots.resize(
      std::min(planned.size(),
               size_t(std::max(0.0, std::floor(budgetTiles * double(job.pathsPerSlice) / pathsPerPilot + 1e-9)))));

  PilotContext ctx{job, grid, transport, ws, planned, pilots, {}, paths, computed, budgetTiles, tol};
  for (int p : pilots)
    ctx.geo.push_back(transport.run(ctx.jobRequest(p), pilotProgress("geometric pilot", job.incidence[size_t(p)])));
  const std::vector<TileResult>& geo = ctx.geo;

  EffectsPlan plan;
  std::vector<EffectDecision>& decisions = plan.decisions;
  auto push = [&](const nlohmann::json& d) { decisions.push_back(effectDecisionFromJson(d)); };
  ComponentSet chosen;
  chosen.add(Component::Coherent);
  push(decision("coherent", true, "always: the geometric single scattering every model starts from"));

  // Multiple scattering: the geometry's bound first (singleBounceLimit_deg), then the pilots at the
  // incidences it leaves open.
  {
    nlohmann::json d = multipleDecision(ctx);
    keepIfRequested(d, forced, Component::Multiple);
    push(d);
    if (d["on"].get<bool>()) chosen.add(Component::Multiple);
  }

  // Diffraction.
  double waveSpent = 0;      // wave pilots' work, in the job's wave terms
  double beamPathTiles = 0;  // geometric pilots at bin centres for the diffraction pilots, in tiles' paths
  {
    nlohmann::json d;
    if (job.statistical) {
      d = decision("incoherent", false,
                   "a statistical surface has no explicit geometry to diffract (microflake model)");
    } else if (physicsDiffraction) {
      d = *physicsDiffraction;
    } else {
      DiffractionPilots m = runDiffractionPilots(ctx, *diffractionSetup, &waveSpent, &beamPathTiles);
      d = diffractionVerdict(ctx, m);
      if (kept) kept->waveTerms = std::move(m.waveTerms), kept->waveSettings = ctx.ws;
    }
    keepIfRequested(d, forced, Component::Incoherent);
    keepIfVerifyingCostsMore(job, computed, d);
    push(d);
    if (d["on"].get<bool>()) chosen.add(Component::Incoherent);
  }
  // The wave estimator, from the tolerance and the measured cost (on the middle pilot incidence).
  // Its pilots cost one or two of the job's wave terms (and `area` on an eighth of the bins).
  if (chosen.has(Component::Incoherent) && !job.waveEstimator && !job.statistical) {
    const std::string budgetNote = !pilots.empty() && budgetTiles - waveSpent >= 2
                                       ? ""
                                       : "the pilot budget (" + fmt3(job.pilotBudget) + " of the job's " +
                                             std::to_string(computed) + " computed tiles) has no room for it";
    nlohmann::json d = waveEstimatorDecision(job, chosen, grid, *transport.scene(),
                                             pilots.empty() ? -1 : pilots[pilots.size() / 2], budgetNote);
    if (d.contains("candidates")) waveSpent += double(d["candidates"].size());  // at most one wave term each
    plan.waveEstimator = waveEstimatorKind(d["estimator"].get<std::string>());
    push(d);
  }

  // Lost, transmission, wavelengths.
  {
    const bool lost = forced.has(Component::Lost);
    push(decision("lost", lost, lost ? "requested" : "a diagnostic, not part of any model: only on request"));
    if (lost) chosen.add(Component::Lost);
  }
  push(btdfDecision(job, chosen, &plan));
  const PilotReplica replicate = [&](std::vector<TileResult>* geo2) {
    Job other = pilotJob;
    other.seed = job.seed ^ 0x9E3779B97F4A7C15ull;
    GeometricTransport t2(other, grid, paths);
    for (int p : pilots)
      geo2->push_back(t2.run(ctx.jobRequest(p), pilotProgress("geometric pilot replica", job.incidence[size_t(p)])));
  };
  push(wavelengthDecision(job, grid, geo, chosen, replicate, &plan));
  if (job.scene.incidenceMax_deg < 90) push(incidenceDecision(job, grid));

  plan.components = chosen;
  recordPilots(ctx, beamPathTiles, waveSpent, plan);
  if (kept && plan.pilotTilesKept)
    for (size_t k = 0; k < pilots.size(); ++k) kept->tiles[pilots[k]] = std::move(ctx.geo[k]);
  plan.pilotSeconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return plan;
}

void applyEffectsPlan(Job& job, const EffectsPlan& plan) {
  job.components = plan.components;
  // A skipped `multiple` is verified on every tile (job.h, guarded): the pilots saw a few incidences.
  job.guarded = ComponentSet{};
  if (const EffectDecision* m = plan.find(Effect::Multiple); m && !m->on) {
    job.guarded.add(Component::Multiple);
    job.components.add(Component::Multiple);
  }
  // A diffraction skip the pilots decided is verified on every tile (tile_computer.h); one the
  // Kirchhoff estimate decided holds for every tile by construction (its worst incidence and λ).
  if (const EffectDecision* d = plan.find(Effect::Incoherent);
      d && !d->on && d->evidence.value("decided_by", "") == "pilots") {
    job.guarded.add(Component::Incoherent);
    job.components.add(Component::Incoherent);
  }
  job.waveTransmission = plan.waveTransmission.value_or(true);
  if (plan.lambda_nm) job.lambda_nm = *plan.lambda_nm;
  if (plan.waveEstimator) {
    const bool named = job.waveEstimator.has_value();
    job.waveEstimator = *plan.waveEstimator;
    if (const EffectDecision* e = plan.find(Effect::Estimator); e && !named) job.waveEstimatorPlanned = e->reason;
  }
  job.effectsPlan = plan.toJson().dump();
}

std::string formatEffects(const EffectsPlan& plan) {
  std::ostringstream o;
  o << "effects (auto, tolerance " << fmt3(plan.tolerance) << ", coherence length " << fmt3(plan.coherenceLength_um)
    << " um from " << plan.coherenceSource << "; pilots " << nlohmann::json(plan.pilots).dump() << " in "
    << fmt3(plan.pilotSeconds) << " s):\n";
  if (const auto& b = plan.pilotBudget)
    o << "  pilot budget " << fmt3(b->fraction) << " of " << b->computedTiles << " computed tiles: spent "
      << fmt3(b->pathTilesSpent) << " (paths) and " << fmt3(b->waveTilesSpent) << " (wave terms) of " << fmt3(b->tiles)
      << " tiles' work\n";
  if (plan.pilotTilesKept && !plan.pilots.empty())
    o << "  the geometric pilots traced their tiles as the job does: the run keeps them as the first "
      << plan.pilotPaths << " paths of tiles " << nlohmann::json(plan.pilots).dump() << "\n";
  for (const auto& d : plan.decisions) {
    std::string e = effectName(d.effect);
    e.resize(12, ' ');
    o << "  " << e << (d.on ? "on   " : "off  ") << d.reason << "\n";
  }
  return o.str();
}

}  // namespace mbsdf
