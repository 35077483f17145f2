#include "job/plan.h"

#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sys/resource.h>
#include <unistd.h>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>

#include "core/log.h"
#include "geometry/embree_scene.h"
#include "job/effects_planner.h"
#include "job/scalar_validity.h"
#include "job/symmetry.h"
#include "job/tile_computer.h"
#include "job/transport.h"
#include "scattering/path_tracer.h"
#include "scattering/reciprocity.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {

double memoryBytesPerRank(const Job& job, double waveBytes) {
  const double nL = double(job.lambda_nm.size()), nB = double(DirectionGrid(job.gridLayout).binCount());
  // Per triangle: Embree's tree and float copy, the job's mesh (indices) and the scene's 96-byte
  // double record (corners and normal, PeriodicScene::HitTriangle); per vertex: the job's and
  // Embree's copies.
  const double sceneBytes = double(job.geometry.triangles.size()) * 210.0 + double(job.geometry.vertices.size()) * 36.0;
  const double tileBytes = nL * nB * 8.0 * 2.0 * 5.0 * 2.0;
  const double batchBytes = 256.0 * 1024.0 * (32.0 + 8.0 * nL);
  const double gridBytes = nB * 8.0 * 6.0;  // the direction grid's tables
  return sceneBytes + tileBytes + batchBytes + gridBytes + waveBytes;
}

double outputBytesUncompressed(const Job& job) {
  const double nL = double(job.lambda_nm.size()), nB = double(DirectionGrid(job.gridLayout).binCount());
  return double(job.incidence.size()) * nL * nB * 4.0 * 2.0 * double(job.components.list().size()) + nB * 8.0 * 4.0;
}

double availableMemoryBytes() {
  double avail = -1;
  std::ifstream meminfo("/proc/meminfo");
  for (std::string key; meminfo >> key;) {
    double kb = 0;
    meminfo >> kb;
    if (key == "MemAvailable:") avail = kb * 1024.0;
    meminfo.ignore(256, '\n');
  }
  // cgroup v2 (Slurm's --mem, containers): the limit less what the group already uses.
  std::ifstream maxFile("/sys/fs/cgroup/memory.max"), curFile("/sys/fs/cgroup/memory.current");
  std::string max;
  double current = 0;
  if (maxFile >> max && max != "max" && curFile >> current) {
    const double left = std::stod(max) - current;
    if (avail < 0 || left < avail) avail = left;
  }
  // An address-space limit (ulimit -v, some batch systems): what is left of it.
  struct rlimit lim {};
  if (getrlimit(RLIMIT_AS, &lim) == 0 && lim.rlim_cur != RLIM_INFINITY) {
    double vmSize = 0;
    std::ifstream status("/proc/self/status");
    for (std::string key; status >> key;) {
      if (key == "VmSize:") status >> vmSize;
      status.ignore(256, '\n');
    }
    const double left = double(lim.rlim_cur) - vmSize * 1024.0;
    if (avail < 0 || left < avail) avail = left;
  }
  return avail;
}

namespace {
// The largest relative error per slice of the single-scattering wave table f_ws of a pilot tile:
// √Σ(σ_b Ω⊥_b)² / Σ|f_b| Ω⊥_b, the measure `info` prints, over wavelengths.
double waveRelativeError(const WaveTileResult& w, const DirectionGrid& grid) {
  double worst = 0;
  for (int l = 0; l < w.nLambda; ++l) {
    double v = 0, e = 0;
    for (int b = 0; b < w.nBins; ++b) {
      const size_t i = size_t(l) * size_t(w.nBins) + size_t(b);
      const double op = grid.projectedSolidAngle(b);
      v += std::pow(w.fwsErr[i] * op, 2);
      e += std::abs(w.fws[i]) * op;
    }
    if (e > 0) worst = std::max(worst, std::sqrt(v) / e);
  }
  return worst;
}

// A Monte Carlo wave pass's errors seen from a budget where its errors are `s` times its own. The
// pairwise estimators' tables are mostly noise where the signal is small, so Σ|f| Ω⊥ is itself
// noise and falls with the errors: a relative error against it stays flat whatever the budget
// (the rate read off two passes came out 0), so the rate is read off the absolute errors. For the
// L1 parts the signal is estimated per bin as what |f| holds beyond its noise,
// m = max(0, |f| − √(2/π) σ), and a table's mass at the other budget as Σ √(m² + (√(2/π) s σ)²) Ω⊥
// (its noise shrinks with s, its signal does not).
struct WavePassErrors {
  double relError = 0;  // √Σ(s σ Ω⊥)² / Σ|f| Ω⊥ (waveRelativeError's measure), the worst wavelength
  double absError = 0;  // √Σ(σ Ω⊥)² at the pass's own budget, the worst wavelength (for the rate)
  SliceL1 l1;           // f_ws's L1 parts at the other budget
};
WavePassErrors monteCarloWaveErrors(const WaveTileResult& w, const DirectionGrid& grid, double s) {
  WavePassErrors out;
  out.l1 = {std::vector<double>(size_t(w.nLambda), 0.0), std::vector<double>(size_t(w.nLambda), 0.0)};
  for (int l = 0; l < w.nLambda; ++l) {
    double var = 0, mass = 0;
    for (int b = 0; b < w.nBins; ++b) {
      const size_t i = size_t(l) * size_t(w.nBins) + size_t(b);
      if (!std::isfinite(w.fws[i]) || !std::isfinite(w.fwsErr[i])) continue;
      const double op = grid.projectedSolidAngle(b), sigma = std::abs(w.fwsErr[i]);
      const double m = std::max(0.0, std::abs(w.fws[i]) - kMeanAbsPerSigma * sigma);
      var += std::pow(sigma * op, 2);
      mass += std::abs(w.fws[i]) * op;
      out.l1.deviation[size_t(l)] += kMeanAbsPerSigma * s * sigma * op;
      out.l1.mass[size_t(l)] += std::hypot(m, kMeanAbsPerSigma * s * sigma) * op;
    }
    out.absError = std::max(out.absError, std::sqrt(var));
    if (mass > 0) out.relError = std::max(out.relError, s * std::sqrt(var) / mass);
  }
  return out;
}

// A path-traced tile's time, fixed + perPath × paths. What a tile costs whatever its paths (its
// tallies' allocation, merge and errors, the facet sum, its threads' start) is counted once, not
// scaled with the paths: at the pilots' 20 000 paths it is most of a paper-resolution tile's time,
// and scaled by the 67 million paths per slice of 1 % there it would count 2.5 times what the tiles
// take.
struct PathTileCost {
  double fixed = 0, perPath = 0;
  double seconds(double paths) const { return fixed + perPath * paths; }
};

// The most wave samples per bin a job may ask for (the bound of sampling.wave_samples_per_bin).
constexpr double kMaxWaveSamplesPerBin = 1e9;

// The factor on the job's wave samples per bin that brings a Monte Carlo wave error `err`
// (∝ samples^−rate) to `target`, at least 16 samples per bin and at most the key's bound; `needed`
// is the samples per bin without the bound.
struct WaveBudget {
  double factor = 1, needed = 0;
  bool capped = false;
};
WaveBudget waveBudgetFor(double err, double target, double rate, uint64_t samples) {
  WaveBudget b;
  const double s = double(samples);
  b.factor = std::max(16.0 / s, std::pow(err / target, 1 / rate));
  b.needed = s * b.factor;
  if (b.needed > kMaxWaveSamplesPerBin) {
    b.factor = kMaxWaveSamplesPerBin / s;
    b.capped = true;
  }
  return b;
}

// What `exact` would evaluate per exit bin instead (Job::waveEstimatorChoice's measure), for the
// plan's line on a target no Monte Carlo budget reaches; 0 where it does not apply.
double exactPointsPerBin(const Job& job) {
  if (!job.geometry.periodic || !(job.scene.coherenceLength_um > 0)) return 0;
  return 8 * job.facetsPerCell() * std::max(1.0, job.exactOrdersPerBin());
}

// What accuracy costs for this job. A Monte Carlo part's relative error falls as 1/√N with its
// budget N and its time grows as N, so from the pilots' errors at their own budget the error at the
// job's budget (per pilot incidence, and the largest), and the budget (and core-hours) that reach
// 10 %, 3 % and 1 %, follow; a deterministic part (the facet sum, `exact`, `fft`) has the error of
// its rules whatever the budget.
nlohmann::json accuracyTable(const Job& job, const std::vector<int>& pilots, const std::vector<double>& pathErrPilot,
                             const std::vector<double>& toJob, uint64_t pilotPaths, const PathTileCost& pathCost,
                             bool pathsDeterministic, const std::vector<double>& waveErrAtJob, double waveRate,
                             bool waveDeterministic, double waveSeconds, int computedTiles, int cores) {
  nlohmann::json a;
  // Each pilot's error scaled to the job's budget, listed by incidence, and the largest.
  auto scaled = [&](const std::vector<double>& atPilot, const std::vector<double>& factor, double* worst) {
    nlohmann::json list = nlohmann::json::array();
    *worst = 0;
    for (size_t k = 0; k < atPilot.size() && k < pilots.size(); ++k) {
      const auto& inc = job.incidence[size_t(pilots[k])];
      list.push_back({{"incidence", pilots[k]},
                      {"theta_deg", inc.theta_deg},
                      {"phi_deg", inc.phi_deg},
                      {"rel_error", atPilot[k] * factor[k]}});
      *worst = std::max(*worst, atPilot[k] * factor[k]);
    }
    return list;
  };
  double pathErr = 0;
  const nlohmann::json pathList =
      scaled(pathErrPilot, pathsDeterministic ? std::vector<double>(pilots.size(), 0.0) : toJob, &pathErr);
  a["paths"] = {{"rel_error", pathErr},
                {"per_pilot", pathList},
                {"paths_per_slice", job.pathsPerSlice},
                {"monte_carlo", !pathsDeterministic}};
  const bool wave = job.needsWave();
  double waveErr = 0;
  if (wave) {
    const nlohmann::json waveList = scaled(waveErrAtJob, std::vector<double>(pilots.size(), 1.0), &waveErr);
    a["wave"] = {{"rel_error", waveErr},
                 {"per_pilot", waveList},
                 {"estimator", waveEstimatorName(job.resolvedWaveEstimator())},
                 {"samples_per_bin", job.waveSamplesPerBin},
                 {"monte_carlo", !waveDeterministic}};
    if (!waveDeterministic) a["wave"]["rate"] = waveRate;
  }
  nlohmann::json targets = nlohmann::json::array();
  for (double target : {0.1, 0.03, 0.01}) {
    // Budget factor per part: (error / target)², at least 1000 paths and 16 samples per bin.
    const double fp = pathsDeterministic || pathErr <= 0
                          ? 1.0
                          : std::max(1000.0 / double(job.pathsPerSlice), std::pow(pathErr / target, 2));
    // The wave term's budget from its measured rate; a rate near 0 (an error the pilots could not
    // see fall) buys nothing by samples.
    const bool waveByBudget = wave && !waveDeterministic && waveErr > 0 && waveRate > 0.05;
    const WaveBudget wb = waveByBudget ? waveBudgetFor(waveErr, target, waveRate, job.waveSamplesPerBin) : WaveBudget{};
    const double fw = wb.factor;
    nlohmann::json t = {{"rel_error", target},
                        {"core_hours", (pathCost.seconds(job.meanSlicePaths() * fp) + waveSeconds * fw) *
                                           computedTiles * cores / 3600.0}};
    if (!pathsDeterministic) t["paths_per_slice"] = uint64_t(std::ceil(double(job.pathsPerSlice) * fp));
    if (!pathsDeterministic && job.slicePaths.empty()) {
      // The same accuracy bought progressively ([sampling] target_rel_error): rounds of the job's
      // paths_per_slice until each slice reaches it, so a slice pays for its own error, not the
      // worst one's; the budget is the worst pilot's rounds.
      double meanRounds = 0, maxRounds = 1;
      for (double e : pathErrPilot) {
        const double rounds = std::max(
            1.0, std::ceil(std::pow(e * std::sqrt(double(pilotPaths) / double(job.pathsPerSlice)) / target, 2) - 1e-9));
        meanRounds += rounds / double(pathErrPilot.size());
        maxRounds = std::max(maxRounds, rounds);
      }
      t["progressive"] = {{"target_rel_error", target},
                          {"max_paths_per_slice", uint64_t(maxRounds) * job.pathsPerSlice},
                          {"core_hours", (pathCost.seconds(job.meanSlicePaths()) * meanRounds + waveSeconds * fw) *
                                             computedTiles * cores / 3600.0}};
    }
    if (waveByBudget) t["wave_samples_per_bin"] = uint64_t(std::ceil(double(job.waveSamplesPerBin) * fw));
    if (wb.capped) t["wave_samples_needed"] = wb.needed;
    t["reached"] =
        (pathsDeterministic || pathErr * std::sqrt(1 / fp) <= target * 1.0000001) &&
        (!wave || waveErr <= target || (waveByBudget && waveErr * std::pow(fw, -waveRate) <= target * 1.0000001));
    targets.push_back(t);
  }
  a["targets"] = targets;
  a["exact_points_per_bin"] = exactPointsPerBin(job);
  return a;
}
// The wave term's pilots (a Monte Carlo estimator at two budgets, for its error's rate), each added
// to its path pilot's tile: its cost per tile at the job's budget, its memory and set-up, and the
// predicted relative error per pilot at the job's budget.
struct WavePilotCost {
  double seconds = 0, bytes = 0, setupSeconds = 0;
  std::vector<double> relErrors;
  std::vector<SliceL1> wsL1;  // per pilot, f_ws's L1 parts with the deviation at the job's budget
  double rate = 0.5;          // the wave term's error ∝ samples^−rate
  bool deterministic = true;
  bool finerIncidenceRule = false;  // the pilots ran one incidence node order more than the job
};
WavePilotCost waveTermPilots(const Job& job, const DirectionGrid& grid, const GeometricTransport& transport,
                             const PlanOptions& options, const std::vector<int>& pilots,
                             std::vector<TileResult>& pilotTiles) {
  WavePilotCost out;
  double& waveSeconds = out.seconds;
  double& waveRate = out.rate;
  bool& waveDeterministic = out.deterministic;
  std::vector<double>& waveRelErrors = out.relErrors;
  WaveSettings ws = waveSettingsOf(job);
  ws.samplesPerBin = std::max<int>(int(job.waveSamplesPerBin) / options.pilotWaveDivisor,
                                   ws.estimator == WaveEstimatorKind::Area ? 2 * int(job.wavePointsPerDirection) : 16);
  // A deterministic estimator over the incidence bin estimates its rule's error against the next
  // coarser rule, which at the default n = 2 is a single node: safe but far from sharp (the paper's
  // HEMISPHERES: 18 % as an L1 sum for a table 0.3–0.7 % from n = 4's). The pilots run one node
  // order more, whose estimate is the job's table's distance from the finer rule's (as the effects
  // planner's pilots do), and their facet sums' time is scaled to the job's rule.
  const bool finerRule = out.finerIncidenceRule = deterministicEstimator(ws.estimator) && !job.exactIncidence;
  auto est = makeJobWaveEstimator(job, grid, *transport.scene(), finerRule ? withFinerIncidenceRule(job, ws) : ws);
  waveDeterministic = est->deterministic();
  // A Monte Carlo wave term's error falls as 1/√N only once its samples resolve the lobes (with a
  // few samples per bin the per-bin errors are themselves rough: `orders` on a rough patch went
  // 0.13, 0.11, 0.072, 0.030 at 16, 64, 256, 1024 samples per bin). A second pass at 4× the pilot's
  // samples (at most the job's) measures the rate, e(N) ∝ N^−a with a in [0, 1/2] (never faster
  // than 1/√N), and the error at the job's budget follows from the second pass; so does the time.
  WaveSettings ws2 = ws;
  ws2.samplesPerBin = std::min<int>(int(job.waveSamplesPerBin), 4 * ws.samplesPerBin);
  const bool twoPasses = !waveDeterministic && ws2.samplesPerBin > ws.samplesPerBin;
  std::unique_ptr<WaveEstimator> est2 = twoPasses ? makeJobWaveEstimator(job, grid, *transport.scene(), ws2) : nullptr;
  // A deterministic estimator (exact, fft) has no samples to scale: its pilot is the tile's cost,
  // at the job's rule, which makes fewer facet sums than the finer one the pilots ran (their
  // binning over the sub-directions costs the same at any rule). Each pilot's facet sums give a time
  // per incidence node; a job tile costs the mean of that over the pilots of its kind (the bins at
  // the pole or horizon, or the others) times its own nodes: those rings may have a rule of their
  // own and a cost per node of their own (on the paper's HEMISPHERES 1.5 s at the horizon against
  // 3–4 s elsewhere), and the pilots sample them far more often (two of six) than the job has them
  // (two rings of 75).
  // A Monte Carlo pass costs a fixed part (lobes, shares, set-up per bin) and a part per sample:
  // with two passes both are read off their times (as the path pilot's fixed and per-path parts),
  // with one the time is scaled with the samples. Each pilot's time is taken at the job's budget.
  auto atBudget = [&](double t1, double t2) {
    const double n1 = ws.samplesPerBin, n2 = ws2.samplesPerBin, N = double(job.waveSamplesPerBin);
    if (!twoPasses) return t1 * N / n1;
    const double perSample = (t2 - t1) / (n2 - n1), fixed = t2 - perSample * n2;
    return perSample > 0 && fixed >= 0 ? fixed + perSample * N : t2 * N / n2;
  };
  double binningSeconds = 0;
  std::vector<double> pilotSeconds, pilotNodes;
  const double N = double(job.waveSamplesPerBin);
  for (size_t k = 0; k < pilots.size(); ++k) {
    const int t = pilots[k];
    spdlog::info("plan: wave pilot at theta_i = {:.3g} deg", job.incidence[size_t(t)].theta_deg);
    const WaveTileResult w = est->run(tileRequestOf(job, t), heartbeat("plan: wave pilot"));
    pilotNodes.push_back(finerRule ? job.incidenceRuleNodesAt(grid, job.incidence[size_t(t)].bin, 1) : 1.0);
    const double secondsBefore = waveSeconds;
    // The f_ws table's L1 parts at the job's budget: the pass's deviation scaled as its error is.
    auto keepL1 = [&](const WaveTileResult& pass, double toJob) {
      SliceL1 l1 = sliceL1(pass.fws, pass.fwsErr, pass.nLambda, grid, waveDeterministic ? 1.0 : kMeanAbsPerSigma);
      for (double& d : l1.deviation) d *= toJob;
      out.wsL1.push_back(std::move(l1));
    };
    if (waveDeterministic) {
      waveRelErrors.push_back(waveRelativeError(w, grid));
      waveSeconds += w.seconds - w.binningSeconds;
      binningSeconds += w.binningSeconds;
      keepL1(w, 1.0);
    } else if (!twoPasses) {
      const WavePassErrors pe = monteCarloWaveErrors(w, grid, std::sqrt(double(ws.samplesPerBin) / N));
      waveRelErrors.push_back(pe.relError);
      waveSeconds += atBudget(w.seconds, 0.0);
      out.wsL1.push_back(pe.l1);
    } else {
      // The rate from the absolute errors (monteCarloWaveErrors: the relative ones are flat where
      // the table is noise).
      const WaveTileResult w2 = est2->run(tileRequestOf(job, t), heartbeat("plan: wave pilot"));
      const double a1 = monteCarloWaveErrors(w, grid, 1.0).absError;
      const double a2 = monteCarloWaveErrors(w2, grid, 1.0).absError;
      const double rate =
          a1 > 0 && a2 > 0
              ? std::clamp(std::log(a1 / a2) / std::log(double(ws2.samplesPerBin) / ws.samplesPerBin), 0.0, 0.5)
              : 0.5;
      waveRate = std::min(waveRate, rate);
      const WavePassErrors pe = monteCarloWaveErrors(w2, grid, std::pow(N / double(ws2.samplesPerBin), -rate));
      waveRelErrors.push_back(pe.relError);
      waveSeconds += atBudget(w.seconds, w2.seconds);
      out.wsL1.push_back(pe.l1);
    }
    pilotSeconds.push_back(waveSeconds - secondsBefore);
    if (pilotTiles[k].has(Component::Coherent))
      addWaveComponents(pilotTiles[k], w, job.components.has(Component::Incoherent),
                        job.components.has(Component::Lost));
  }
  // What the first pilot built for every later tile (exact's visibility table) is paid once per
  // rank, not per tile.
  out.setupSeconds = est->setupSeconds();
  if (!pilots.empty()) {
    pilotSeconds[0] -= out.setupSeconds;  // built by the first pilot
    // Per kind (at the pole or horizon, or not): the pilots' mean time per node (all pilots' where
    // none is of that kind).
    double rate[2] = {0, 0}, count[2] = {0, 0}, all = 0;
    for (size_t k = 0; k < pilots.size(); ++k) {
      const int edge = grid.atPoleOrHorizon(job.incidence[size_t(pilots[k])].bin) ? 1 : 0;
      rate[edge] += pilotSeconds[k] / pilotNodes[k];
      count[edge] += 1;
      all += pilotSeconds[k] / pilotNodes[k];
    }
    for (int e = 0; e < 2; ++e) rate[e] = count[e] > 0 ? rate[e] / count[e] : all / double(pilots.size());
    double perTile = 0;
    for (const IncidenceDirection& inc : job.incidence)
      perTile +=
          rate[grid.atPoleOrHorizon(inc.bin) ? 1 : 0] * (finerRule ? job.incidenceRuleNodesAt(grid, inc.bin) : 1.0);
    perTile /= double(job.incidence.size());
    waveSeconds = perTile + binningSeconds / double(pilots.size());
  }
  out.bytes = est->memoryBytes();
  return out;
}

// The energy balance over the pilot tiles (BsdfFileWriter::writeEnergyBalance): for a lossless
// material R + T + lost paths − 1, for an absorbing one the excess over 1; the pilot and wavelength
// furthest beyond the run's own flag (|balance| > tolerance + 3 standard errors), with its error.
struct PilotBalance {
  double value = 0, stdError = 0;
};
PilotBalance worstEnergyBalance(const Job& job, const DirectionGrid& grid, const std::vector<TileResult>& pilotTiles) {
  std::vector<Component> model;
  for (Component c : job.components.list())
    if (c != Component::Lost && c != Component::GeoMasked) model.push_back(c);
  PilotBalance worst;
  double worstMargin = -std::numeric_limits<double>::infinity();
  for (const TileResult& r : pilotTiles) {
    const std::vector<double> b = energyBalance(r, grid, model, job.material.lossless());
    const std::vector<double> se = energyBalanceStdError(r, grid, model);
    for (size_t l = 0; l < b.size(); ++l) {
      const double margin = std::abs(b[l]) - 3 * se[l];
      if (margin > worstMargin) worstMargin = margin, worst = {b[l], se[l]};
    }
  }
  return worst;
}

// Per pilot, the L1 parts of the path-traced components at the pilot's budget (empty where the
// job has no such component).
struct PilotL1 {
  std::vector<SliceL1> coherent, multiple;
};

// The path pilots: each pilot incidence's tile at the pilot's budget, its time scaled to the job's
// paths (a facet-sum tile, with no paths, is the tile's cost: transport.h), and the relative error
// of the path-traced table at the pilot's budget (relativeError, largest over wavelengths; 0 where
// the tile is deterministic).
struct PathPilotCost {
  PathTileCost cost;        // mean over the pilots
  double pilotSeconds = 0;  // per pilot tile as run
  int facetTiles = 0;
  std::vector<TileResult> tiles;
  // The same tiles at four times the paths (their first paths are the tiles' own); samples == 0
  // where the tile is a facet sum.
  std::vector<TileResult> tiles4;
  std::vector<double> relErrors;
  PilotL1 l1;
};
// Per exit bin of incidence `inc`'s slice of a path-traced component, what storing each same-side pair once
// ([output] pairs = "once", BsdfFileWriter's fold) does to the bin's error. The stored value is
// the mean of f(i → o) and f(o → i), the second from the tile of the incidence whose bin o is,
// weighted by the projected solid angles of the bins each was tallied in (reciprocalPairWeight). Where the two come
// from different computed tiles they are independent, and the second's error follows from the first's by reciprocity: a
// tally's variance is about f / (N Ω⊥) of its bin, so σ(o → i)² = σ² Ω⊥_o / Ω⊥_i and the mean's error is σ √(Ω⊥_o /
// (Ω⊥_o + Ω⊥_i)) (1/√2 for bins of equal size). 1 elsewhere (the other hemisphere, a pair from one tile under the job's
// symmetry, `symmetry` when the job has one; a job storing both).
std::vector<double> pairFoldFactors(const Job& job, const DirectionGrid& grid, const AzimuthalSymmetry* symmetry,
                                    int inc) {
  std::vector<double> factor(size_t(grid.binCount()), 1.0);
  if (job.storage.pairs != TablePairs::Once) return factor;
  auto tileOf = [&](int i) { return symmetry ? symmetry->representative(i) : i; };
  const int binI = job.incidence[size_t(inc)].bin;
  for (size_t j = 0; j < job.incidence.size(); ++j) {
    const int o = job.incidence[j].bin;
    if (o < 0 || grid.isUpper(o) != grid.isUpper(binI) || tileOf(int(j)) == tileOf(inc)) continue;
    // With paths of its own per slice (path_allocation), the partner's tally weighs by its paths
    // too (σ(o → i)² = σ² N_i Ω⊥_o / (N_o Ω⊥_i)), as the writer weighs it.
    const double pathsRatio = job.slicePaths.empty() ? 1.0 : double(job.pathsFor(int(j))) / double(job.pathsFor(inc));
    factor[size_t(o)] = std::sqrt(reciprocalPairWeight(grid, o, binI, pathsRatio));
  }
  return factor;
}

// The L1 parts of the pilot tiles' path-traced tables as `job` stores them: the tile's errors, or
// those of the mean of both estimates where pairs are stored once (pairFoldFactors).
PilotL1 foldedL1(const Job& job, const DirectionGrid& grid, const std::vector<int>& pilots,
                 const std::vector<TileResult>& tiles) {
  std::optional<AzimuthalSymmetry> symmetry;
  if (job.symmetryReduced() && job.storage.pairs == TablePairs::Once) symmetry.emplace(job, grid);
  PilotL1 out;
  for (size_t k = 0; k < pilots.size() && k < tiles.size(); ++k) {
    const TileResult& r = tiles[k];
    const std::vector<double> fold = pairFoldFactors(job, grid, symmetry ? &*symmetry : nullptr, pilots[k]);
    for (auto [c, parts] : {std::pair{Component::Coherent, &out.coherent}, {Component::Multiple, &out.multiple}}) {
      if (!r.has(c)) {
        parts->push_back(SliceL1{});
        continue;
      }
      std::vector<double> err = r.stdError[int(c)];
      for (size_t i = 0; i < err.size(); ++i) err[i] *= fold[i % fold.size()];
      parts->push_back(sliceL1(r.value[int(c)], err, r.nLambda, grid, kMeanAbsPerSigma));
    }
  }
  return out;
}

// The L1 parts of the path-traced tables at the pilots' budget N, as the job's budget will see them.
// A bin's error is estimated from its own paths, and √(variance) estimated from few paths is
// biased low: a bin the pilot met once or not at all reports almost no error, though at the job's
// budget it holds hundreds of paths and a proper share of the slice's L1 (a sum of √ per bin, which
// the sparse bins dominate where a table is spread thin). The pilots' own estimate, scaled as 1/√N,
// therefore rose with the pilot: on the paper-resolution HEMISPHERES `multiple` at the pole 0.96 %
// from 20 000 paths, 1.24 % from 80 000, where 67.5 million paths measured 1.49 %. The bias of
// r(N) = √N · L1(N) falls as bins fill; taken to fall as 1/√N (a bin's own √k falls short of √λ by
// O(1/λ) once filled, so this is the slower, safe side), the limit is r(4N) + (r(4N) − r(N)) from
// the tile at N and the same tile at 4N; never below r(4N). On the paper job that gives 1.52 %,
// 0.87 % and 2.49 % against 1.49 %, 0.86 % and 2.55 % measured (pole, horizon, 45°).
PilotL1 pilotL1(const Job& job, const DirectionGrid& grid, const std::vector<int>& pilots,
                const std::vector<TileResult>& tiles, const std::vector<TileResult>& tiles4) {
  PilotL1 out = foldedL1(job, grid, pilots, tiles);
  const PilotL1 at4 = foldedL1(job, grid, pilots, tiles4);
  for (auto [parts, parts4] : {std::pair{&out.coherent, &at4.coherent}, {&out.multiple, &at4.multiple}})
    for (size_t k = 0; k < parts->size() && k < parts4->size() && k < tiles4.size(); ++k) {
      if (tiles4[k].samples == 0) continue;  // a facet sum: no paths, its own bounds
      SliceL1& a = (*parts)[k];
      const SliceL1& b = (*parts4)[k];
      for (size_t l = 0; l < a.mass.size() && l < b.mass.size(); ++l) {
        if (!(b.mass[l] > 0)) continue;
        // Relative L1 at the pilot's budget N, from each tile: r(4N) at N is twice its own.
        const double r1 = a.mass[l] > 0 ? a.deviation[l] / a.mass[l] : 0.0, r4 = 2 * b.deviation[l] / b.mass[l];
        a.deviation[l] = std::max(r4, 2 * r4 - r1) * b.mass[l];
        a.mass[l] = b.mass[l];
      }
    }
  return out;
}

// Per pilot, the factor that takes a Monte Carlo error from the pilot's paths to its slice's.
std::vector<double> pilotToJob(const Job& job, const std::vector<int>& pilots, uint64_t pilotPaths) {
  std::vector<double> toJob;
  for (int t : pilots) toJob.push_back(std::sqrt(double(pilotPaths) / double(job.pathsFor(t))));
  return toJob;
}

PathPilotCost pathPilots(const Job& job, const Job& planned, const DirectionGrid& grid, const TileComputer& computer,
                         const std::vector<int>& pilots, uint64_t pilotPaths) {
  PathPilotCost out;
  std::vector<Component> traced;
  for (Component c : {Component::Coherent, Component::Multiple})
    if (planned.components.has(c)) traced.push_back(c);
  for (int t : pilots) {
    spdlog::info("plan: path pilot at theta_i = {:.3g} deg", job.incidence[size_t(t)].theta_deg);
    double pathSeconds = 0, waveSeconds = 0;
    out.tiles.push_back(
        computer.compute(tileRequestOf(job, t), heartbeat("plan: path pilot"), &pathSeconds, &waveSeconds));
    const TileResult& r = out.tiles.back();
    const std::vector<double> e = r.samples > 0 ? relativeError(r, traced, grid) : std::vector<double>{0.0};
    out.relErrors.push_back(*std::max_element(e.begin(), e.end()));
    out.pilotSeconds += r.seconds / double(pilots.size());
    // The tile again at four times the paths: the difference is the paths' own time. A facet-sum
    // tile (no paths) costs what it cost.
    PathTileCost c{r.seconds, 0.0};
    out.tiles4.emplace_back();
    if (r.samples > 0) {
      TileRequest more = tileRequestOf(job, t);
      more.paths = 4 * pilotPaths;
      out.tiles4.back() = computer.compute(more, heartbeat("plan: path pilot"), &pathSeconds, &waveSeconds);
      const TileResult& r4 = out.tiles4.back();
      c.perPath = (r4.seconds - r.seconds) / double(3 * pilotPaths);
      c.fixed = r.seconds - c.perPath * double(pilotPaths);
      // Timing noise larger than the fixed part: all of the larger tile's time per path.
      if (c.perPath <= 0 || c.fixed < 0) c = {0.0, r4.seconds / double(4 * pilotPaths)};
    }
    out.cost.fixed += c.fixed / double(pilots.size());
    out.cost.perPath += c.perPath / double(pilots.size());
    out.facetTiles += r.samples == 0;
  }
  out.l1 = pilotL1(job, grid, pilots, out.tiles, out.tiles4);
  return out;
}

// One L1 target of l1AccuracyTable at the wave budget wb: the paths that bring every table's path
// part within what its wave part leaves of the target, the core-hours, and where the wave part
// alone stays above it.
struct L1Part {
  double p = 0, w = 0;
};
using L1Parts = std::vector<std::pair<std::string, std::vector<std::vector<L1Part>>>>;  // table → pilot → λ
nlohmann::json l1Target(const Job& job, const std::vector<int>& pilots, const L1Parts& comps, double target,
                        const WaveBudget& wb, double rate, const PathTileCost& pathCost, double waveSeconds,
                        int computedTiles, int cores) {
  double fp = 0;
  bool reached = !wb.capped;
  nlohmann::json waveAbove = nlohmann::json::array();
  for (const auto& [name, perPilot] : comps)
    for (size_t k = 0; k < perPilot.size(); ++k) {
      double above = 0;
      for (const L1Part& part : perPilot[k]) {
        const double w = part.w * std::pow(wb.factor, -rate);
        const bool pathsLeft = target - w > 1e-6 * target;
        if (w > target * (1 + 1e-7) || (part.p > 0 && !pathsLeft)) {
          reached = false;
          above = std::max(above, w);
          continue;
        }
        if (part.p > 0) fp = std::max(fp, std::pow(part.p / (target - w), 2));
      }
      if (above > 0)
        waveAbove.push_back({{"table", name},
                             {"theta_deg", job.incidence[size_t(pilots[k])].theta_deg},
                             {"phi_deg", job.incidence[size_t(pilots[k])].phi_deg},
                             {"rel_l1", above}});
    }
  fp = fp > 0 ? std::max(fp, 1000.0 / double(job.pathsPerSlice)) : 1.0;
  nlohmann::json t = {{"rel_l1", target},
                      {"paths_per_slice", uint64_t(std::min(9e18, std::ceil(double(job.pathsPerSlice) * fp)))},
                      {"core_hours", (pathCost.seconds(job.meanSlicePaths() * fp) + waveSeconds * wb.factor) *
                                         computedTiles * cores / 3600.0},
                      {"reached", reached}};
  if (!reached) t["wave_part_above"] = waveAbove;
  return t;
}

// The accuracy study's measure, the relative L1 distance of each table's slice from its
// expectation (sliceL1), at the job's budget, and what 10 %, 3 % and 1 % in every table cost: the
// path-traced components `coherent` and `multiple`, and the wave term's table f_ws (= coherent +
// incoherent, the paper's WS). Per pilot and wavelength a table's L1 is P/√fp + W·fw^−rate at fp
// times the paths and fw times the wave samples: P the path-traced part, W the wave term's (its
// rules' error for a deterministic estimator, which no budget lowers). `incoherent` alone is not
// measured against its own mass: a signed difference of two larger tables, its mass is mostly its
// noise where the tables agree; its error is f_ws's and coherent's.
nlohmann::json l1AccuracyTable(const Job& job, const std::vector<int>& pilots, const PilotL1& paths,
                               const WavePilotCost& wave, const DirectionGrid& grid, const std::vector<double>& toJob,
                               const PathTileCost& pathCost, double waveSeconds, int computedTiles, int cores) {
  using Part = L1Part;
  auto ratio = [](double d, double m) { return m > 0 ? d / m : 0.0; };
  L1Parts comps;
  for (auto [c, l1] : {std::pair{Component::Coherent, &paths.coherent}, {Component::Multiple, &paths.multiple}}) {
    if (!job.components.has(c)) continue;
    std::vector<std::vector<Part>> perPilot;
    for (size_t k = 0; k < pilots.size() && k < l1->size(); ++k) {
      const SliceL1& own = (*l1)[k];
      std::vector<Part> perLambda(own.mass.size());
      for (size_t l = 0; l < own.mass.size(); ++l) perLambda[l].p = ratio(own.deviation[l] * toJob[k], own.mass[l]);
      perPilot.push_back(std::move(perLambda));
    }
    comps.emplace_back(componentName(c), std::move(perPilot));
  }
  // The wave term's own table, f_ws = coherent + incoherent, against its mass.
  if (!wave.wsL1.empty()) {
    std::vector<std::vector<Part>> perPilot;
    for (const SliceL1& ws : wave.wsL1) {
      std::vector<Part> perLambda(ws.mass.size());
      for (size_t l = 0; l < ws.mass.size(); ++l) perLambda[l].w = ratio(ws.deviation[l], ws.mass[l]);
      perPilot.push_back(std::move(perLambda));
    }
    comps.emplace_back("f_ws", std::move(perPilot));
  }
  nlohmann::json a, byComponent = nlohmann::json::object();
  for (const auto& [name, perPilot] : comps) {
    nlohmann::json list = nlohmann::json::array();
    double worst = 0;
    for (size_t k = 0; k < perPilot.size(); ++k) {
      double e = 0;
      for (const Part& part : perPilot[k]) e = std::max(e, part.p + part.w);
      list.push_back(
          {{"incidence", pilots[k]}, {"theta_deg", job.incidence[size_t(pilots[k])].theta_deg}, {"rel_l1", e}});
      worst = std::max(worst, e);
    }
    byComponent[name] = {{"rel_l1", worst}, {"per_pilot", list}};
  }
  a["components"] = byComponent;
  a["paths_per_slice"] = job.pathsPerSlice;
  if (!job.slicePaths.empty())
    a["path_allocation"] = {{"kind", "equal-error"}, {"mean_paths_per_slice", job.meanSlicePaths()}};
  const bool waveByBudget = job.needsWave() && !wave.deterministic && wave.rate > 0.05;
  const double rate = waveByBudget ? wave.rate : 0.0;
  double worstW = 0;
  for (const auto& [name, perPilot] : comps)
    for (const auto& perLambda : perPilot)
      for (const Part& part : perLambda) worstW = std::max(worstW, part.w);
  nlohmann::json targets = nlohmann::json::array();
  for (double target : {0.1, 0.03, 0.01}) {
    // The wave parts take a share of the target and the paths the rest; of a few shares the one
    // that costs least (all of it when no table has a path-traced part).
    nlohmann::json best;
    double bestHours = std::numeric_limits<double>::infinity();
    for (double share : {0.5, 0.7, 0.9, 1.0}) {
      if (!waveByBudget && share < 1.0) continue;
      const WaveBudget wb = waveByBudget && worstW > 0
                                ? waveBudgetFor(worstW, share * target, rate, job.waveSamplesPerBin)
                                : WaveBudget{};
      nlohmann::json t = l1Target(job, pilots, comps, target, wb, rate, pathCost, waveSeconds, computedTiles, cores);
      if (waveByBudget) t["wave_samples_per_bin"] = uint64_t(std::ceil(double(job.waveSamplesPerBin) * wb.factor));
      if (wb.capped) t["wave_samples_needed"] = wb.needed;
      const double hours = t["core_hours"].get<double>() * (t["reached"].get<bool>() ? 1.0 : 1e300);
      if (best.is_null() || hours < bestHours) best = t, bestHours = hours;
    }
    targets.push_back(best);
  }
  a["targets"] = targets;
  a["wave_by_budget"] = waveByBudget;
  a["wave_deterministic"] = wave.deterministic;
  a["exact_points_per_bin"] = exactPointsPerBin(job);
  return a;
}

// What the job is, for the plan: geometry, material, wavelengths, grid, tiles and symmetry.
nlohmann::json describeJob(const Job& job, const DirectionGrid& grid, int computedTiles) {
  const int nTiles = int(job.incidence.size()), nL = int(job.lambda_nm.size()), nB = grid.binCount();
  nlohmann::json p;
  p["job"] = job.file;
  p["geometry"] = {{"kind", job.geometryKind},
                   {"triangles", job.geometry.triangles.size()},
                   {"size_um", {job.geometry.sizeX, job.geometry.sizeY}},
                   {"periodic", job.geometry.periodic},
                   {"open_edges", job.closure.openEdges},
                   {"uncovered_fraction", job.closure.uncoveredFraction},
                   {"surface", job.statistical ? std::string("statistical") : job.closure.describe()}};
  if (job.statistical) p["geometry"]["model"] = MicroflakeDistribution(job.statistical->ndf).describe();
  p["material"] = job.material.describe();
  p["wavelengths"] = nL;
  p["grid"] = {{"kind", grid.kind()}, {"bins", nB}};
  p["tiles"] = nTiles;
  p["symmetry"] = {{"reduced", job.symmetryReduced()},
                   {"isotropic", job.isotropic},
                   {"rotation_order", job.rotationOrder},
                   {"reason", job.symmetryReason},
                   {"tiles_computed", computedTiles}};
  return p;
}

// Suggested Slurm resources: ranks of 8 cores (a cluster node's share, not this machine's), enough
// to finish in about 12 hours.
std::string slurmHeader(double tileSeconds, double waveSetupSeconds, double coreHours, int computedTiles, int cores,
                        double memoryBytes) {
  const int cpusPerTask = 8;
  int ntasks = std::max(1, std::min(computedTiles, int(std::ceil(coreHours / (12.0 * cpusPerTask)))));
  double wallHours =
      (tileSeconds * std::ceil(double(computedTiles) / ntasks) + waveSetupSeconds) * cores / cpusPerTask / 3600.0;
  int minutes = int(std::ceil(wallHours * 60 * 1.3)) + 10;
  std::ostringstream sb;
  sb << "#SBATCH --ntasks=" << ntasks << "\n#SBATCH --cpus-per-task=" << cpusPerTask
     << "\n#SBATCH --time=" << minutes / 60 << ":" << (minutes % 60 < 10 ? "0" : "") << minutes % 60
     << ":00\n#SBATCH --mem-per-cpu=" << std::max(1, int(std::ceil(memoryBytes / cpusPerTask / 1e9 * 2))) << "G\n"
     << "#SBATCH --signal=B:USR1@300\n#SBATCH --requeue\n";
  return sb.str();
}

// The share of a tile's wave term the run computes on average: only the tiles no pilot verified
// where diffraction was skipped (Job::guarded), the reciprocal pairs' fraction where the job halves
// it by reciprocity (docs/physics.md §8). The plan records which (diffraction_check, reciprocity).
double waveTermShare(const Job& job, const EffectsPlan* effects, const DirectionGrid& grid, int computedTiles,
                     double waveSeconds, int cores, nlohmann::json& p) {
  if (job.guarded.has(Component::Incoherent) && !job.components.has(Component::Lost)) {
    const EffectDecision* d = effects ? effects->find(Effect::Incoherent) : nullptr;
    const int verified = d && d->evidence.contains("pilot_verified") ? int(d->evidence["pilot_verified"].size()) : 0;
    const int checked = std::max(0, computedTiles - verified);
    p["diffraction_check"] = {{"tiles_checked", checked}, {"tiles_verified_by_pilots", verified}};
    return double(checked) / std::max(1, computedTiles);
  }
  if (!job.components.has(Component::Incoherent)) return 1.0;
  if (!job.halvesWaveByReciprocity()) {
    p["reciprocity"] = {{"used", false}, {"reason", job.reciprocityOffReason()}};
    return 1.0;
  }
  const double fraction =
      ReciprocalPairs(job.incidenceBins(), grid.binCount(), grid.binsPerHemisphere()).computedFraction();
  p["reciprocity"] = {{"used", true},
                      {"computed_fraction", fraction},
                      {"wave_seconds_per_tile_without", waveSeconds},
                      {"core_hours_saved", waveSeconds * (1 - fraction) * computedTiles * cores / 3600.0}};
  return fraction;
}

// A rank's start-up before its first tile: MPI_Init, the job read and its tile computer built. The
// run reads a job whose geometry is made from parameters while MPI starts, and builds its tile
// computer then too when no effects pilots are to decide its components (cmd/run_command.cpp
// EarlyStart); files are read after MPI_Init, which sets environment variables their readers read.
double runStartSeconds(const Job& job, const PlanOptions& options, double sceneSeconds) {
  const bool fromParameters = job.geometryKind != "mesh" && job.geometryKind != "heightfield";
  if (!fromParameters) return options.mpiStartSeconds + options.jobLoadSeconds + sceneSeconds;
  if (job.autoComponents) return std::max(options.mpiStartSeconds, options.jobLoadSeconds) + sceneSeconds;
  return std::max(options.mpiStartSeconds, options.jobLoadSeconds + sceneSeconds);
}

}  // namespace

nlohmann::json planJob(const Job& requested, const PlanOptions& options) {
  std::optional<tbb::global_control> threads;
  if (options.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, size_t(options.threads));
  // components = "auto": the effects planner's pilots decide first (the run does the same).
  Job job = requested;
  std::optional<EffectsPlan> effects;
  if (job.autoComponents) {
    effects = planEffects(job);
    applyEffectsPlan(job, *effects);
  }
  const int cores = options.threads > 0 ? options.threads : tbb::info::default_concurrency();
  DirectionGrid grid(job.gridLayout);
  const int nTiles = int(job.incidence.size()), nL = int(job.lambda_nm.size());
  // Symmetry: one computed tile per θ ring of an isotropic surface (symmetry.h).
  const int computedTiles = job.symmetryReduced() ? AzimuthalSymmetry(job, grid).representativeCount() : nTiles;
  nlohmann::json p = describeJob(job, grid, computedTiles);
  if (effects) p["effects"] = effects->toJson();
  std::vector<std::string> comps;
  for (Component c : job.components.list()) comps.push_back(componentName(c));
  p["components"] = comps;
  if (job.needsWave()) p["wave_estimator"] = waveEstimatorName(job.resolvedWaveEstimator());

  // Pilots at a reduced budget, spread as the effects planner spreads them (the most grazing, the
  // closest to normal, the median, then the farthest in angle: the cost depends on θi differently for explicit
  // geometry, which bounces more at grazing incidence, and for the microflake walk, which goes deeper at normal
  // incidence); a tile's cost is their mean.
  const std::vector<int> pilots = pilotIncidences(job);
  const int pilot = *std::min_element(pilots.begin(), pilots.end(), [&](int a, int b) {
    return std::abs(std::cos(radians(job.incidence[size_t(a)].theta_deg))) <
           std::abs(std::cos(radians(job.incidence[size_t(b)].theta_deg)));
  });  // the most grazing, reported
  const auto& inc = job.incidence[size_t(pilot)];
  auto ts = std::chrono::steady_clock::now();
  const uint64_t pilotPaths = std::min<uint64_t>(job.pathsPerSlice, options.pilotPaths);
  // As the run: a guarded skip (Job::guarded) is left out of what the tile computes first, and
  // checked on the tile (its cost is the tile's). The run's tile at the pilot's paths, in one
  // round, without its wave term (timed below at budgets of its own).
  Job planned = job;
  for (Component c : job.guarded.list()) planned.components.remove(c);
  Job pilotJob = job;
  pilotJob.pathsPerSlice = pilotPaths;
  pilotJob.slicePaths.clear();  // every pilot at the pilots' budget, scaled to its slice's paths below
  pilotJob.targetRelError = 0;
  const TileComputer computer(pilotJob, grid, {}, false);
  const GeometricTransport& transport = computer.transport();
  const double sceneSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
  PathPilotCost paths = pathPilots(job, planned, grid, computer, pilots, pilotPaths);
  const double pathSeconds = paths.cost.seconds(job.meanSlicePaths()), pilotSeconds = paths.pilotSeconds;
  const int facetTiles = paths.facetTiles;
  std::vector<TileResult>& pilotTiles = paths.tiles;
  const std::vector<double>& pathRelErrors = paths.relErrors;
  const double groups = job.material.directionsIndependentOfLambda() ? 1.0 : double(nL);
  const WavePilotCost wave =
      job.needsWave() ? waveTermPilots(job, grid, transport, options, pilots, pilotTiles) : WavePilotCost{};
  double waveSeconds = wave.seconds;
  const double waveBytes = wave.bytes, waveSetupSeconds = wave.setupSeconds, waveRate = wave.rate;
  const std::vector<double>& waveRelErrors = wave.relErrors;
  const bool waveDeterministic = wave.deterministic;
  // The pilots ran the whole wave term; on average a tile computes this share of it.
  waveSeconds *= waveTermShare(job, effects ? &*effects : nullptr, grid, computedTiles, waveSeconds, cores, p);
  const double tileSeconds = pathSeconds + waveSeconds;
  // The model's energy error at the pilots (BsdfFileWriter::writeEnergyBalance): for a lossless
  // material R + T + lost paths − 1, for an absorbing one the excess over 1. Scalar diffraction on
  // deep or steep structures does not conserve energy; this is the first warning of it, judged by the
  // run's rule (beyond the tolerance by more than 3 standard errors) so that a pilot's fewer samples
  // widen the margin instead of raising a warning the run would not.
  const PilotBalance balance = worstEnergyBalance(job, grid, pilotTiles);
  p["energy_balance"] = {{"worst_at_pilots", balance.value},
                         {"stderr_at_pilots", balance.stdError},
                         {"tolerance", job.scene.tolerance},
                         {"lossless", job.material.lossless()}};
  p["scalar_validity"] = toJson(scalarValidity(job));
  // Rank 0 writes every slice (rotated ones too) with a flush and a journal fsync: measured by the
  // caller's writer (PlanOptions::writeSecondsPerSlice), which this layer does not know.
  const double writeSeconds =
      options.writeSecondsPerSlice
          ? options.writeSecondsPerSlice(job, grid,
                                         std::max(1, (nTiles + computedTiles - 1) / std::max(1, computedTiles)))
          : 0.0;
  const double coreHours = (tileSeconds * computedTiles + waveSetupSeconds) * cores / 3600.0;
  p["pilot"] = {{"tile", pilot},
                {"tiles", pilots},
                {"theta_deg", inc.theta_deg},
                {"paths", pilotPaths},
                {"path_seconds", pilotSeconds},
                {"path_seconds_per_wavelength_group", pilotSeconds / groups},
                {"scene_build_seconds", sceneSeconds},
                {"facet_sum_tiles", facetTiles},
                {"cores", cores}};
  if (job.targetRelError > 0) {
    // Progressive sampling: the estimate above is the first round; the budget bounds the rest.
    p["progressive"] = {{"target_rel_error", job.targetRelError},
                        {"max_paths_per_slice", job.maxPathsPerSlice},
                        {"path_seconds_per_tile_max", paths.cost.seconds(double(job.maxPathsPerSlice))}};
  }
  const std::vector<double> toJob = pilotToJob(job, pilots, pilotPaths);
  p["accuracy"] =
      accuracyTable(job, pilots, pathRelErrors, toJob, pilotPaths, paths.cost, facetTiles == int(pilots.size()),
                    waveRelErrors, waveRate, waveDeterministic, waveSeconds, computedTiles, cores);
  if (p["accuracy"].contains("wave")) p["accuracy"]["wave"]["finer_incidence_rule"] = wave.finerIncidenceRule;
  p["accuracy"]["l1"] =
      l1AccuracyTable(job, pilots, paths.l1, wave, grid, toJob, paths.cost, waveSeconds, computedTiles, cores);
  // Pairs stored once with the same paths everywhere: what path_allocation = "equal-error" would
  // cost for the same targets, from the same pilot tiles.
  if (job.storage.pairs == TablePairs::Once && job.slicePaths.empty() && job.targetRelError == 0 &&
      facetTiles < int(pilots.size())) {
    Job alt = job;
    alt.pathAllocation = Job::PathAllocation::EqualError;
    alt.slicePaths = job.equalErrorSlicePaths();
    p["accuracy"]["l1"]["with_equal_error"] =
        l1AccuracyTable(alt, pilots, pilotL1(alt, grid, pilots, paths.tiles, paths.tiles4), wave, grid,
                        pilotToJob(alt, pilots, pilotPaths), paths.cost, waveSeconds, computedTiles, cores);
  }
  // The effects pilots' paths that the run keeps as its tiles' first paths (effects_planner.h) are
  // not traced again, where the run traces paths on every tile.
  double keptPilotSeconds = 0;
  if (effects && effects->pilotTilesKept && (job.statistical || effects->components.has(Component::Multiple)))
    keptPilotSeconds = double(effects->pilots.size()) * paths.cost.perPath *
                       double(std::min<uint64_t>(effects->pilotPaths, job.pathsPerSlice));
  const double startSeconds = runStartSeconds(job, options, sceneSeconds);
  p["estimate"] = {
      {"seconds_per_tile", tileSeconds},
      {"kept_pilot_path_seconds", keptPilotSeconds},
      {"path_seconds_per_tile", pathSeconds},
      {"path_seconds_per_tile_fixed", paths.cost.fixed},
      {"path_seconds_per_path", paths.cost.perPath},
      {"wave_seconds_per_tile", waveSeconds},
      {"wave_setup_seconds_per_rank", waveSetupSeconds},
      {"write_seconds_per_slice", writeSeconds},
      {"wall_seconds_on_these_cores", tileSeconds * computedTiles + waveSetupSeconds + writeSeconds * nTiles +
                                          startSeconds + (effects ? effects->pilotSeconds : 0.0) - keptPilotSeconds},
      {"job_load_seconds", options.jobLoadSeconds},
      {"mpi_start_seconds", options.mpiStartSeconds},
      {"start_seconds", startSeconds},
      {"core_hours", coreHours}};
  const double memoryBytes = memoryBytesPerRank(job, waveBytes);
  p["output_bytes_uncompressed"] = outputBytesUncompressed(job);
  if (options.storedBytesPerSlice) {
    const double perSlice = options.storedBytesPerSlice(job, grid, pilotTiles);
    p["output"] = {{"profile", job.storage.name()},
                   {"bytes_per_slice", perSlice},
                   {"slices", nTiles},
                   {"bytes", perSlice * nTiles + double(grid.binCount()) * 8.0 * 4.0}};
  }
  p["memory_bytes_per_rank"] = memoryBytes;
  p["sbatch"] = slurmHeader(tileSeconds, waveSetupSeconds, coreHours, computedTiles, cores, memoryBytes);
  return p;
}

namespace {
// Why a target is not reached, in the plan's words: the wave samples it would need beyond their
// bound (and what `exact` would evaluate instead), a wave error that did not fall with samples, or
// a deterministic estimator's rules; `where` names the tables and pilots that stay above it.
std::string unreachedWhy(const nlohmann::json& table, const nlohmann::json& t, const std::string& where) {
  const double exactPoints = table.value("exact_points_per_bin", 0.0);
  const std::string exact =
      exactPoints > 0
          ? fmt::format("; `exact` would evaluate {:.3g} facet terms per bin, without sampling noise", exactPoints)
          : std::string();
  if (t.contains("wave_samples_needed"))
    return fmt::format("wave_samples_per_bin would need {:.3g}, beyond its bound {:.0e}{}",
                       t["wave_samples_needed"].get<double>(), kMaxWaveSamplesPerBin, exact);
  const std::string at = where.empty() ? "" : ", " + where;
  if (table.value("wave_deterministic", false))
    return "the wave term's rules keep their own error" + at +
           ", whatever the budget: set by [sampling] wave_incidence_directions (wave_incidence_directions_pole_horizon "
           "at the pole and horizon bins) and wave_subdirections";
  if (!table.value("wave_by_budget", true))
    return "the wave term's error did not fall with samples between the pilots' two budgets" + at + exact;
  return "a part's own error stays above it" + at;
}

// "L1 per slice: coherent 1.5 %, multiple 5.8 % at 5000000 paths", then the budget and core-hours
// that bring every component to 10 %, 3 % and 1 %.
std::string fmtL1(const nlohmann::json& l1) {
  if (l1["components"].empty()) return {};
  auto pct = [](double e) { return fmt::format("{:.2g} %", 100 * e); };
  std::string o = "L1 per slice:  ";
  for (const auto& [name, c] : l1["components"].items())
    o += (o.back() == ' ' ? " " : ", ") + name + " " + pct(c["rel_l1"].get<double>());
  o += " at " + l1["paths_per_slice"].dump() + " paths";
  if (l1.contains("path_allocation"))
    o += fmt::format(" (the largest slice's; path_allocation = \"equal-error\", {:.3g} on average)",
                     l1["path_allocation"]["mean_paths_per_slice"].get<double>());
  o += "\n                (Σ|f − E f| Ω⊥ / Σ|f| Ω⊥ of each component's slice, the accuracy study's measure, "
       "expected from its bins' errors at the pilots' paths and four times them; the worst pilot and "
       "wavelength)\n";
  for (const auto& t : l1["targets"]) {
    o += fmt::format("  for {:>4} in every component: paths_per_slice = {}, ", pct(t["rel_l1"].get<double>()),
                     t["paths_per_slice"].dump());
    if (t.contains("wave_samples_per_bin")) o += "wave_samples_per_bin = " + t["wave_samples_per_bin"].dump() + ", ";
    o += fmt::format("{:.3g} core-hours", t["core_hours"].get<double>());
    if (!t["reached"].get<bool>()) {
      std::string where;
      for (const auto& w : t.value("wave_part_above", nlohmann::json::array()))
        where += fmt::format("{}{} {} at ({:.3g}°, {:.3g}°)", where.empty() ? "" : ", ", w["table"].get<std::string>(),
                             pct(w["rel_l1"].get<double>()), w["theta_deg"].get<double>(), w["phi_deg"].get<double>());
      o += " (not reached: " + unreachedWhy(l1, t, where) + ")";
    }
    o += "\n";
  }
  if (l1.contains("with_equal_error"))
    for (const auto& t : l1["with_equal_error"]["targets"])
      o +=
          fmt::format("  for {:>4} with path_allocation = \"equal-error\": paths_per_slice = {}, {:.3g} core-hours{}\n",
                      pct(t["rel_l1"].get<double>()), t["paths_per_slice"].dump(), t["core_hours"].get<double>(),
                      t["reached"].get<bool>() ? "" : " (not reached)");
  return o;
}

// "accuracy: paths 2.1 % per slice ..., wave term ...", then budget → error → core-hours.
std::string fmtAccuracy(const nlohmann::json& a) {
  auto pct = [](double e) { return fmt::format("{:.2g} %", 100 * e); };
  const auto& paths = a["paths"];
  std::string o = "accuracy:       paths " + (paths["monte_carlo"].get<bool>()
                                                  ? pct(paths["rel_error"].get<double>()) + " per slice at " +
                                                        paths["paths_per_slice"].dump() + " paths"
                                                  : std::string("deterministic (the facet sum)"));
  if (a.contains("wave"))
    o += "; wave term (" + a["wave"]["estimator"].get<std::string>() + ") " +
         pct(a["wave"]["rel_error"].get<double>()) +
         (a["wave"]["monte_carlo"].get<bool>()
              ? " at " + a["wave"]["samples_per_bin"].dump() + " samples per bin" +
                    (a["wave"].contains("rate") && a["wave"]["rate"].get<double>() < 0.45
                         ? fmt::format(" (falling as samples^-{:.2g} between the pilots' two budgets, not yet 1/√N)",
                                       a["wave"]["rate"].get<double>())
                         : std::string())
              : std::string(a["wave"].value("finer_incidence_rule", false)
                                ? " (its rules' error, whatever the budget: the job's table's distance from one "
                                  "incidence node order more, at the pilots)"
                                : " (its rules' error, whatever the budget)"));
  o += "\n                (largest relative error of a slice of that table, √Σ(σ Ω⊥)² / Σ|f| Ω⊥, from the pilots; "
       "Monte Carlo errors fall as 1/√budget)\n";
  for (const auto& t : a["targets"]) {
    o += fmt::format("  for {:>4}: ", pct(t["rel_error"].get<double>()));
    if (t.contains("paths_per_slice")) o += "paths_per_slice = " + t["paths_per_slice"].dump() + ", ";
    if (t.contains("wave_samples_per_bin")) o += "wave_samples_per_bin = " + t["wave_samples_per_bin"].dump() + ", ";
    o += fmt::format("{:.3g} core-hours", t["core_hours"].get<double>());
    if (t.contains("progressive") &&
        t["progressive"]["core_hours"].get<double>() < 0.95 * t["core_hours"].get<double>())
      o += fmt::format("; or target_rel_error = {}, max_paths_per_slice = {}: {:.3g} core-hours",
                       t["progressive"]["target_rel_error"].get<double>(),
                       t["progressive"]["max_paths_per_slice"].dump(), t["progressive"]["core_hours"].get<double>());
    if (!t["reached"].get<bool>()) o += " (not reached: " + unreachedWhy(a, t, "") + ")";
    o += "\n";
  }
  if (a.contains("l1")) o += fmtL1(a["l1"]);
  return o;
}

std::string fmtBalance(const nlohmann::json& b) {
  const double worst = b["worst_at_pilots"].get<double>(), tol = b["tolerance"].get<double>();
  const double se = b.value("stderr_at_pilots", 0.0);
  return fmt::format("{:+.4f} ± {:.4f} at the pilots (R + T + lost paths − 1{}); {}", worst, se,
                     b["lossless"].get<bool>() ? "" : ", only an excess counts: the material absorbs",
                     std::abs(worst) > tol + 3 * se
                         ? fmt::format("beyond the tolerance {} by more than 3 standard errors: the scalar model is "
                                       "off here",
                                       tol)
                         : fmt::format("within the tolerance {} + 3 standard errors (the run's rule)", tol));
}
}  // namespace

std::string formatPlan(const nlohmann::json& p) {
  std::ostringstream o;
  auto n = [](const nlohmann::json& v) {
    std::ostringstream s;
    s.precision(3);
    s << v.get<double>();
    return s.str();
  };
  auto gb = [](double b) {
    std::ostringstream s;
    s.precision(3);
    s << b / 1e9 << " GB";
    return s.str();
  };
  o << "job:            " << p["job"].get<std::string>() << "\n"
    << "geometry:       " << p["geometry"]["kind"].get<std::string>() << ", "
    << (p["geometry"].contains("model")
            ? p["geometry"]["model"].get<std::string>()
            : p["geometry"]["triangles"].dump() + " triangles, " + p["geometry"]["surface"].get<std::string>())
    << "\n"
    << "material:       " << p["material"].get<std::string>() << "\n"
    << "components:     " << p["components"].dump()
    << (p.contains("wave_estimator") ? " (wave estimator " + p["wave_estimator"].get<std::string>() + ")" : "") << "\n"
    << "grid:           " << p["grid"]["kind"].get<std::string>() << ", " << p["grid"]["bins"] << " bins; "
    << p["wavelengths"] << " wavelengths\n"
    << (p.contains("effects") ? formatEffects(EffectsPlan::fromJson(p["effects"])) : std::string())
    << "tiles:          " << p["tiles"] << " (one per incidence direction, all wavelengths)"
    << (p["symmetry"]["reduced"].get<bool>()
            ? "; " + p["symmetry"]["tiles_computed"].dump() + " computed, the rest rotated (" +
                  p["symmetry"]["reason"].get<std::string>() + ")"
            : std::string())
    << "\n"
    << "pilot:          tile " << p["pilot"]["tile"] << " (theta " << n(p["pilot"]["theta_deg"]) << "°), "
    << p["pilot"]["paths"] << " paths in " << n(p["pilot"]["path_seconds"]) << " s on " << p["pilot"]["cores"]
    << " cores\n"
    << "per tile:       " << n(p["estimate"]["seconds_per_tile"]) << " s (paths "
    << n(p["estimate"]["path_seconds_per_tile"]) << " s, of which " << n(p["estimate"]["path_seconds_per_tile_fixed"])
    << " s whatever the paths; wave " << n(p["estimate"]["wave_seconds_per_tile"]) << " s) on these cores; writing "
    << n(p["estimate"]["write_seconds_per_slice"]) << " s per slice"
    << (p["estimate"]["wave_setup_seconds_per_rank"].get<double>() > 0
            ? "; once per rank " + n(p["estimate"]["wave_setup_seconds_per_rank"]) + " s (exact's visibility table)"
            : std::string())
    << "\n"
    << "energy balance: " << fmtBalance(p["energy_balance"]) << "\n"
    << (p.contains("accuracy") ? fmtAccuracy(p["accuracy"]) : std::string())
    << (p.contains("scalar_validity") && p["scalar_validity"]["applies"].get<bool>()
            ? "scalar model:   " + p["scalar_validity"]["note"].get<std::string>() + "\n"
            : std::string())
    << "total:          " << n(p["estimate"]["core_hours"]) << " core-hours; "
    << n(p["estimate"]["wall_seconds_on_these_cores"]) << " s on these cores, of which start-up "
    << n(p["estimate"]["start_seconds"]) << " s (MPI_Init " << n(p["estimate"]["mpi_start_seconds"])
    << " s for one process here; more under a launcher of many ranks)\n"
    << (p.contains("progressive")
            ? "progressive:    target " + n(p["progressive"]["target_rel_error"]) + " relative error; at most " +
                  n(p["progressive"]["path_seconds_per_tile_max"]) + " s of paths per tile (" +
                  p["progressive"]["max_paths_per_slice"].dump() + " paths)\n"
            : std::string())
    << (p.contains("reciprocity")
            ? std::string("reciprocity:    ") +
                  (p["reciprocity"]["used"].get<bool>()
                       ? "wave term for " + n(p["reciprocity"]["computed_fraction"].get<double>() * 100) +
                             "% of the same-side bin pairs, the rest mirrored (saves " +
                             n(p["reciprocity"]["core_hours_saved"]) + " core-hours)\n"
                       : "not used: " + p["reciprocity"]["reason"].get<std::string>() + "\n")
            : std::string())
    << (p.contains("diffraction_check")
            ? "diffraction:    skipped; verified by pilots on " +
                  p["diffraction_check"]["tiles_verified_by_pilots"].dump() + " tiles, by their own wave term on " +
                  p["diffraction_check"]["tiles_checked"].dump() + " (counted in the estimate)\n"
            : std::string())
    << (p.contains("output")
            ? "output:         " + gb(p["output"]["bytes"].get<double>()) + " (profile " +
                  p["output"]["profile"].get<std::string>() + ": " +
                  fmt::format("{:.3g} MB", p["output"]["bytes_per_slice"].get<double>() / 1e6) +
                  " per slice: the pilots compressed, projected to the job's paths, x " + p["output"]["slices"].dump() +
                  " slices" +
                  (p["output"]["profile"].get<std::string>().find("pairs = once") != std::string::npos
                       ? "; pairs stored once: each slice's share, packed alone, while the fold packs square "
                         "blocks of neighbouring slices, up to 3 times smaller where they are rotations of one "
                         "another (an isotropic surface)"
                       : std::string()) +
                  "); " + gb(p["output_bytes_uncompressed"].get<double>()) + " uncompressed\n"
            : "output:         " + gb(p["output_bytes_uncompressed"].get<double>()) + " uncompressed (upper bound)\n")
    << "memory / rank:  " << gb(p["memory_bytes_per_rank"].get<double>()) << "\n"
    << "suggested Slurm header:\n"
    << p["sbatch"].get<std::string>();
  return o.str();
}

}  // namespace mbsdf
