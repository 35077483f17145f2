// Deterministic Monte Carlo tallies over independent paths, shared by every geometric-optics
// estimator (the explicit path tracer, the microflake random walk). A path tallies its weights
// (one per wavelength of its group) into (component, exit bin); paths run in fixed chunks on TBB
// threads and the chunks are merged in order, so the sums do not depend on the thread count. The
// result is the bin-averaged BSDF f(Ωo) = Σ w / (N Ω⊥(Ωo)) with the
// standard error of that mean (docs/physics.md §3–4).
#pragma once
#include <algorithm>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "core/direction_grid.h"
#include "core/rng.h"
#include "scattering/components.h"
#include "scattering/tile_result.h"

namespace mbsdf {

class PathChunk {
 public:
  explicit PathChunk(int nLambda) : truncated(nLambda, 0.0), leaked(nLambda, 0.0), missed(nLambda, 0.0) {}
  // Record weights w[0..lambdas.size()) of wavelength group `group` into (c, bin).
  void tally(int bin, Component c, int group, const double* w, size_t n) {
    events.push_back({bin, int(c), group, int(weights.size())});
    weights.insert(weights.end(), w, w + n);
  }
  // Empty again for nLambda wavelengths, keeping the storage.
  void clear(int nLambda) {
    events.clear();
    weights.clear();
    truncated.assign(size_t(nLambda), 0.0);
    leaked.assign(size_t(nLambda), 0.0);
    missed.assign(size_t(nLambda), 0.0);
    rays = 0;
  }
  // Room for `paths` paths of `eventsPerPath` events with n weights each, so that tallying
  // does not reallocate (and copy) as it goes.
  void reserve(size_t paths, size_t eventsPerPath, size_t n) {
    events.reserve(paths * eventsPerPath);
    weights.reserve(paths * eventsPerPath * n);
  }
  struct Event {
    int32_t bin, component, group, weightOffset;
  };
  std::vector<Event> events;
  std::vector<double> weights;
  std::vector<double> truncated, leaked, missed;  // per wavelength, summed weights
  uint64_t rays = 0;
};

struct PathTallyPlan {
  // The tile these paths belong to (copied into the result).
  int tile = 0, incidenceIndex = 0, incidenceBin = 0;
  const DirectionGrid* grid = nullptr;
  int nLambda = 0;
  std::vector<std::vector<int>> groups;  // wavelengths that share one path
  uint64_t paths = 0;                    // per group
  uint64_t firstPath = 0;                // path indices firstPath … firstPath + paths − 1 (RNG keys)
  std::vector<Component> components;     // tallied components
};

// Runs `trace(path, group, chunk)` for every path of every group and reduces; the result carries
// the plan's tile identity and the wall time. `progress(done)` is
// called from the calling thread between batches with the number of paths done over all groups
// (it may throw to abandon the tile).
using PathFunction = std::function<void(uint64_t path, int group, PathChunk& out)>;
TileResult runPaths(const PathTallyPlan& plan, const PathFunction& trace,
                    const std::function<void(uint64_t)>& progress);
// The same with `trace(firstPath, count, group, chunks)` called once for each batch of consecutive
// chunks (an estimator that advances all their paths together, such as a wavefront ordered by
// origin), which tallies path firstPath + i into chunks[i / kPathChunk], in path order within a
// chunk.
inline constexpr uint64_t kPathChunk = 1024;  // paths per chunk: the unit of deterministic merging
using PathBatchFunction =
    std::function<void(uint64_t firstPath, uint64_t count, int group, std::span<PathChunk> chunks)>;
TileResult runPaths(const PathTallyPlan& plan, const PathBatchFunction& trace,
                    const std::function<void(uint64_t)>& progress);

// Paths per batch of runPaths: the chunks a PathBatchFunction gets at once (at most).
inline constexpr uint64_t kPathChunksPerBatch = 256;
// Makes runPaths' tally storage for the plan's first batch now, its pages touched, so that the
// run's first batch does not fault them in (kept until a run takes them).
void reservePathChunks(const PathTallyPlan& plan);

// A path's incidence: cosine-distributed in its bin from the sampler's first block (two numbers,
// the azimuth's first), or the exact direction, which skips that block, so that the rest of the
// path draws the same numbers either way.
DirectionSample pathIncidence(const DirectionGrid& grid, int incidenceBin, const std::optional<Vec3>& exact,
                              Sampler& s);

// Wavelength groups: one group for all wavelengths when paths do not depend on λ, else one each.
std::vector<std::vector<int>> wavelengthGroups(int nLambda, bool shared);

}  // namespace mbsdf
