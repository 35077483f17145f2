#include "job/tile_computer.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>

#include "job/effects_planner.h"

namespace mbsdf {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// Full-depth paths that bound a skipped `multiple` on a tile whose single scattering came from the
// facet sum: its energy (+ 3 standard errors) is resolved to about 0.01 at this many.
constexpr uint64_t kMultipleCheckPaths = 4096;

// The largest over λ of the `multiple` energy (both hemispheres) + 3 standard errors of a path tile.
double multipleBound(const TileResult& r, const DirectionGrid& grid) {
  const std::vector<double> se = r.pathEnergyStdError({Component::Multiple}, -1);
  double bound = 0;
  for (int l = 0; l < r.nLambda; ++l) {
    double e = 0;
    for (int b = 0; b < r.nBins; ++b) e += r.at(Component::Multiple, l, b) * grid.projectedSolidAngle(b);
    bound = std::max(bound, e + 3 * (se.empty() ? 0.0 : se[size_t(l)]));
  }
  return bound;
}

// A skipped component whose check held: the slice stores it as 0 (with no error).
void zeroComponent(TileResult& r, Component c) {
  r.value[int(c)].assign(size_t(r.nLambda) * size_t(r.nBins), 0.0);
  r.stdError[int(c)].assign(size_t(r.nLambda) * size_t(r.nBins), 0.0);
}

// The tile computes the planner's components first (a skipped `multiple` lets single scattering come
// from the facet sum); a guarded skip is then verified on the tile.
Job withoutGuarded(const Job& job) {
  Job planned = job;
  for (Component c : job.guarded.list()) planned.components.remove(c);
  return planned;
}

// Whether a wave estimator with settings `a` computes, along a collimated direction, exactly what
// one with `b` does: the same estimator, seed, masked sums and visibility table, and for the Monte
// Carlo ones the same samples (the incidence rule plays no part for one direction).
bool sameWaveTerm(const WaveSettings& a, const WaveSettings& b) {
  return a.estimator == b.estimator && a.seed == b.seed && a.computeMasked == b.computeMasked &&
         a.visibilityTable == b.visibilityTable &&
         (deterministicEstimator(a.estimator) ||
          (a.samplesPerBin == b.samplesPerBin && a.pointsPerDirection == b.pointsPerDirection));
}

}  // namespace

TileComputer::TileComputer(const Job& job, const DirectionGrid& grid, PilotResults pilots, bool waveTerm)
    : job_(job), grid_(grid), planned_(withoutGuarded(job)), transport_(planned_, grid, job.pathsPerSlice) {
  if (!job.effectsPlan.empty()) {
    const EffectsPlan plan = EffectsPlan::fromJson(nlohmann::json::parse(job.effectsPlan));
    if (plan.pilotTilesKept && plan.pilotPaths > 0 && plan.pilotPaths <= job.pathsPerSlice) {
      pilotIncidences_.insert(plan.pilots.begin(), plan.pilots.end());
      pilotPaths_ = plan.pilotPaths;
      // A result that is not this job's first round (another wavelength set or path count) is dropped.
      for (auto& [t, r] : pilots.tiles)
        if (pilotIncidences_.count(t) && r.samples == pilotPaths_ && r.nLambda == int(job.lambda_nm.size()) &&
            r.nBins == grid.binCount())
          keptPilots_.emplace(t, std::move(r));
    }
  }
  if (job.guarded.has(Component::Multiple)) singleBounceLimit_ = singleBounceLimit_deg(job);
  if (job.guarded.has(Component::Multiple) && transport_.mayUseFacetSum()) {
    checkTransport_ =
        std::make_unique<GeometricTransport>(job, grid, std::min<uint64_t>(job.pathsPerSlice, kMultipleCheckPaths));
    fullTransport_ = std::make_unique<GeometricTransport>(job, grid, job.pathsPerSlice);
  }
  if (waveTerm && job.needsWave()) wave_ = makeJobWaveEstimator(job, grid, *transport_.scene(), waveSettingsOf(job));
  if (wave_ && job.halvesWaveByReciprocity())
    pairs_.emplace(job.incidenceBins(), grid.binCount(), grid.binsPerHemisphere());
  if (wave_ && !pairs_ && job.waveTransmission && job.exactIncidence &&
      sameWaveTerm(pilots.waveSettings, waveSettingsOf(job)))
    for (auto& [t, w] : pilots.waveTerms)
      if (w.nLambda == int(job.lambda_nm.size()) && w.nBins == grid.binCount() && w.computed.empty())
        keptWave_.emplace(t, std::move(w));
  if (job.guarded.has(Component::Incoherent)) {
    cellOf_ = resolutionCells(grid, job.scene.angularResolution_deg);
    const EffectsPlan plan = EffectsPlan::fromJson(nlohmann::json::parse(job.effectsPlan));
    if (const EffectDecision* d = plan.find(Effect::Incoherent); d && d->evidence.contains("pilot_verified"))
      for (const auto& v : d->evidence["pilot_verified"])
        pilotDiffraction_[v["incidence"].get<int>()] = v["upper"].get<double>();
  }
}

// A later round's progress counted on from the paths before it, so that a tile's count only grows.
static std::function<void(uint64_t)> continuedFrom(const std::function<void(uint64_t)>& cb, uint64_t before) {
  if (!cb) return {};
  return [&cb, before](uint64_t done) { cb(before + done); };
}

TileResult TileComputer::compute(const TileRequest& request, const std::function<void(uint64_t)>& cb,
                                 double* pathSeconds, double* waveSeconds,
                                 const std::function<void(uint64_t)>& waveProgress) const {
  const Job& job = job_;
  const DirectionGrid& grid = grid_;
  const int t = request.tile;
  auto ts = Clock::now();
  // A slice's own paths where the job allocates them per slice (Job::slicePaths).
  TileRequest q = request;
  if (q.paths == 0 && !job.slicePaths.empty()) q.paths = job.pathsFor(q.incidenceIndex);
  TileResult r = firstRound(q, cb);
  if (job.targetRelError > 0 && r.samples > 0) {  // a facet-sum tile is deterministic
    // Progressive sampling: more rounds of fresh paths (the next path indices, so the result is
    // the same estimator as one run of all of them) until the path-traced table (coherent +
    // multiple: a rare component adds little to its error) reaches the target relative error
    // or the budget is spent.
    std::vector<Component> traced;
    for (Component c : {Component::Coherent, Component::Multiple})
      if (job.components.has(c)) traced.push_back(c);
    auto relError = [&](const TileResult& x) {
      const std::vector<double> e = relativeError(x, traced, grid);
      return e.empty() ? 0.0 : *std::max_element(e.begin(), e.end());
    };
    while (true) {
      if (relError(r) <= job.targetRelError) {
        r.samplingStop = TileResult::SamplingStop::TargetReached;
        break;
      }
      if (r.samples + job.pathsPerSlice > job.maxPathsPerSlice) {
        r.samplingStop = TileResult::SamplingStop::BudgetExhausted;
        break;
      }
      TileRequest more = request;
      more.firstPath = r.samples;
      r.poolPaths(transport_.run(more, continuedFrom(cb, r.samples)));
    }
  }
  if (job.guarded.has(Component::Multiple)) verifySkippedMultiple(q, cb, r);
  *pathSeconds += since(ts);
  if (wave_ && (!job.guarded.has(Component::Incoherent) || verifySkippedDiffraction(t, r))) {
    auto tw = Clock::now();
    addWaveTerm(q, waveProgress ? waveProgress : cb, r);
    if (job.guarded.has(Component::Incoherent)) recordDiffractionCheck(t, r);
    *waveSeconds += since(tw);
  }
  r.seconds = since(ts);
  return r;
}

TileResult TileComputer::firstRound(const TileRequest& q, const std::function<void(uint64_t)>& cb) const {
  const uint64_t paths = q.paths > 0 ? q.paths : job_.pathsPerSlice;
  if (!pilotIncidences_.count(q.tile) || pilotPaths_ > paths || transport_.estimatorFor(q).deterministic())
    return transport_.run(q, cb);
  const auto kept = keptPilots_.find(q.tile);
  TileRequest pilot = q, rest = q;
  pilot.paths = pilotPaths_;
  TileResult r = kept != keptPilots_.end() ? kept->second : transport_.run(pilot, cb);
  if (kept != keptPilots_.end() && cb) cb(0);
  if (pilotPaths_ < paths) {
    rest.firstPath = pilotPaths_;
    rest.paths = paths - pilotPaths_;
    r.poolPaths(transport_.run(rest, continuedFrom(cb, pilotPaths_)));
  }
  return r;
}

void TileComputer::addWaveTerm(const TileRequest& request, const std::function<void(uint64_t)>& cb,
                               TileResult& r) const {
  const Job& job = job_;
  const DirectionGrid& grid = grid_;
  const std::optional<Vec3>& exact = request.exactDirection;
  std::vector<uint8_t> mask = pairs_ ? pairs_->exitMask(request.tile) : std::vector<uint8_t>{};
  // No BTDF needed (effects planner): the transmitted bins keep geometric optics.
  const bool incidentAbove = exact ? exact->z >= 0 : grid.isUpper(request.incidenceBin);
  auto transmitted = [&](int b) { return grid.isUpper(b) != incidentAbove; };
  if (!job.waveTransmission) {
    mask.resize(size_t(grid.binCount()), 1);
    for (int b = 0; b < grid.binCount(); ++b)
      if (transmitted(b)) mask[size_t(b)] = 0;
  }
  const auto kept = keptWave_.find(request.tile);
  const bool own =
      kept != keptWave_.end() && request.exactDirection == tileRequestOf(job_, request.tile).exactDirection;
  if (own && cb) cb(0);
  WaveTileResult w = own ? kept->second : wave_->run(request, cb, mask);
  addWaveComponents(r, w, job.components.has(Component::Incoherent), job.components.has(Component::Lost));
  if (!job.waveTransmission && r.has(Component::Incoherent))
    for (int l = 0; l < r.nLambda; ++l)
      for (int b = 0; b < r.nBins; ++b)
        if (transmitted(b)) {
          r.at(Component::Incoherent, l, b) = 0;
          r.stdError[int(Component::Incoherent)][size_t(l) * r.nBins + b] = 0;
        }
  r.rays += w.rays;
  r.waveSamples = w.samples;
}

// A `multiple` the effects planner skipped (Job::guarded), verified on tile t. A path tile traced
// it anyway: it is kept, and the bound says whether the skip would have held. A facet-sum tile
// (single scattering without paths) runs a few thousand full-depth paths; past the tolerance the
// tile is traced in full after all, otherwise its `multiple` is stored as zero (within the
// tolerance by the bound). Either way the slice records the bound and whether it was re-enabled.
// An incidence below the geometry's single-bounce limit (effects_planner.h) has none: its check is 0.
void TileComputer::verifySkippedMultiple(const TileRequest& request, const std::function<void(uint64_t)>& cb,
                                         TileResult& r) const {
  const int t = request.tile;
  // The check's paths are its transport's own count from path 0, the full tile's the slice's.
  const TileRequest whole{request.tile, request.incidenceIndex, request.incidenceBin, request.exactDirection};
  TileRequest allPaths = whole;
  allPaths.paths = request.paths;
  const Job& job = job_;
  const DirectionGrid& grid = grid_;
  const GeometricTransport* check = checkTransport_.get();
  const GeometricTransport* full = fullTransport_.get();
  const std::optional<double>& singleBounceLimit = singleBounceLimit_;
  const auto& inc = job.incidence[size_t(t)];
  if (r.has(Component::Multiple)) {
    r.multipleCheck = multipleBound(r, grid);
  } else if (scattersOnce(job, grid, t, singleBounceLimit)) {
    r.multipleCheck = 0;
    zeroComponent(r, Component::Multiple);
  } else {
    const TileResult checked = check->run(whole, cb);
    r.multipleCheck = multipleBound(checked, grid);
    r.rays += checked.rays;  // the check is the tile's work too
    if (r.multipleCheck > job.scene.tolerance) {
      const uint64_t spent = r.rays;
      r = full->run(allPaths, cb);
      r.rays += spent;
      r.multipleCheck = multipleBound(r, grid);
    } else {
      zeroComponent(r, Component::Multiple);
    }
  }
  r.multipleReenabled = r.multipleCheck > job.scene.tolerance;
  if (r.multipleReenabled)
    spdlog::warn(
        "tile {} (theta_i {:.3g} deg, phi_i {:.3g} deg): multiple scattering up to {:.4f} (+3 standard errors), "
        "beyond the tolerance {}: the effects planner's pilots did not see it, this slice has it",
        t, inc.theta_deg, inc.phi_deg, r.multipleCheck, job.scene.tolerance);
}

bool TileComputer::verifySkippedDiffraction(int t, TileResult& r) const {
  const auto pilot = pilotDiffraction_.find(t);
  // `lost` needs the wave term's masked sums anyway: the check then comes from it.
  if (pilot == pilotDiffraction_.end() || job_.components.has(Component::Lost)) return true;
  r.diffractionCheck = pilot->second;
  r.diffractionReenabled = false;  // the pilot's figure was below the tolerance, or diffraction would be on
  zeroComponent(r, Component::Incoherent);
  return false;
}

void TileComputer::recordDiffractionCheck(int t, TileResult& r) const {
  const auto& inc = job_.incidence[size_t(t)];
  r.diffractionCheck = diffractionUpperBound(r, grid_, cellOf_);
  r.diffractionReenabled = r.diffractionCheck > job_.scene.tolerance;
  if (r.diffractionReenabled)
    spdlog::warn(
        "tile {} (theta_i {:.3g} deg, phi_i {:.3g} deg): diffraction changes the slice by up to {:.4f} beyond noise, "
        "beyond the tolerance {}: the effects planner's pilots did not see it, this slice has it",
        t, inc.theta_deg, inc.phi_deg, r.diffractionCheck, job_.scene.tolerance);
}

}  // namespace mbsdf
