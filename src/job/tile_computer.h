// One tile of a job (an incidence direction × every wavelength) as the run computes it, apart from
// where it runs: the geometric transport (paths or the facet sum of single scattering), progressive
// sampling to [sampling] target_rel_error, the checks of a `multiple` or a diffraction the effects
// planner skipped (Job::guarded), and the wave term — with reciprocity's exit mask (docs/physics.md §8) and the
// transmitted bins left to geometric optics where the renderer needs no BTDF. The scheduler
// (cluster/runner.h) hands tiles out and writes them; this is what a tile is.
#pragma once
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>

#include "core/direction_grid.h"
#include "job/effects_planner.h"
#include "job/job.h"
#include "job/transport.h"
#include "scattering/reciprocity.h"
#include "scattering/tile_result.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {

class TileComputer {
 public:
  // pilots: what the effects planner's pilots computed (effects_planner.h planEffects). The
  // geometric pilots are the first paths of their tiles; where the plan says so, every rank traces
  // those tiles in the same two rounds (the pilot's paths, then the rest), and a rank that holds the
  // pilot's result keeps it instead of tracing its paths again. A diffraction pilot's wave term is
  // kept where it is exactly the tile's (the job's collimated direction, estimator, samples and
  // seed, no exit mask). The table does not depend on which rank did.
  // waveTerm false: the tile's geometric part only (`plan` times the wave term apart, at budgets of
  // its own).
  TileComputer(const Job& job, const DirectionGrid& grid, PilotResults pilots = {}, bool waveTerm = true);
  // One tile as the job computes it: the request's incidence (request.tile indexes job.incidence)
  // through the geometric transport, progressive sampling, the checks of skipped effects and the
  // wave term, every estimator asked with the same request. progress(done) is called from the inner
  // loops of the paths, waveProgress(done) from the wave term's (its own unit of work, not paths;
  // progress when empty); either may throw to abandon the tile. The seconds spent on paths and on
  // the wave term are added to the counters given.
  TileResult compute(const TileRequest& request, const std::function<void(uint64_t)>& progress, double* pathSeconds,
                     double* waveSeconds, const std::function<void(uint64_t)>& waveProgress = {}) const;
  // Tile t as the job samples it (tileRequestOf).
  TileResult compute(int t, const std::function<void(uint64_t)>& progress, double* pathSeconds, double* waveSeconds,
                     const std::function<void(uint64_t)>& waveProgress = {}) const {
    return compute(tileRequestOf(job_, t), progress, pathSeconds, waveSeconds, waveProgress);
  }

  // Makes the working buffers of the job's first tile now (GeometricEstimator::reserveBuffers).
  void reserveBuffers() const { transport_.reserveBuffers(); }
  const GeometricTransport& transport() const { return transport_; }
  const WaveEstimator* wave() const { return wave_.get(); }
  // The reciprocal bin pairs when the job halves its wave term by reciprocity, else none.
  const std::optional<ReciprocalPairs>& pairs() const { return pairs_; }
  // Whether this computer holds tile t's pilot paths (so computing t costs less here).
  bool holdsPilot(int t) const { return keptPilots_.count(t) > 0 || keptWave_.count(t) > 0; }

 private:
  // The tile's first round of paths (or its facet sum): as one run, or, for a tile an effects pilot
  // traced, the pilot's paths (kept, or traced again) and then the rest.
  TileResult firstRound(const TileRequest& request, const std::function<void(uint64_t)>& progress) const;
  void verifySkippedMultiple(const TileRequest& request, const std::function<void(uint64_t)>& progress,
                             TileResult& r) const;
  void addWaveTerm(const TileRequest& request, const std::function<void(uint64_t)>& progress, TileResult& r) const;
  // A diffraction the effects planner skipped, verified on tile t: by the pilot that ran this tile
  // as the job does (its upper estimate; the slice's `incoherent` is stored as 0), else by the
  // tile's own wave term (computed and kept; re-enabled when its upper estimate beyond noise at the
  // renderer's resolution exceeds the tolerance). Returns whether the wave term is still to run.
  bool verifySkippedDiffraction(int t, TileResult& r) const;
  void recordDiffractionCheck(int t, TileResult& r) const;

  const Job& job_;
  const DirectionGrid& grid_;
  Job planned_;  // the job without its guarded (skipped, verified) components
  GeometricTransport transport_;
  std::unique_ptr<GeometricTransport> checkTransport_, fullTransport_;
  std::optional<double> singleBounceLimit_;
  std::unique_ptr<WaveEstimator> wave_;
  std::optional<ReciprocalPairs> pairs_;
  std::map<int, double> pilotDiffraction_;  // incidence → upper estimate of the pilot run as the job does
  std::vector<int> cellOf_;                 // the renderer's cells (effects_planner.h resolutionCells)
  std::set<int> pilotIncidences_;           // tiles whose first paths an effects pilot traced
  uint64_t pilotPaths_ = 0;                 // how many
  std::map<int, TileResult> keptPilots_;    // those pilots' results held by this rank
  std::map<int, WaveTileResult> keptWave_;  // diffraction pilots' wave terms that are the tiles' own
};

}  // namespace mbsdf
