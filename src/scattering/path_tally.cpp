#include "scattering/path_tally.h"

#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>

#include "core/spare_pool.h"
#include "core/stop.h"

namespace mbsdf {

DirectionSample pathIncidence(const DirectionGrid& grid, int incidenceBin, const std::optional<Vec3>& exact,
                              Sampler& s) {
  if (exact) {
    s.setDimension(1);
    return {*exact, 1.0};
  }
  return grid.sampleCosine(incidenceBin, s);
}

std::vector<std::vector<int>> wavelengthGroups(int nLambda, bool shared) {
  std::vector<std::vector<int>> groups;
  if (shared) {
    std::vector<int> all;
    for (int i = 0; i < nLambda; ++i) all.push_back(i);
    groups.push_back(all);
  } else {
    for (int i = 0; i < nLambda; ++i) groups.push_back({i});
  }
  return groups;
}

TileResult runPaths(const PathTallyPlan& plan, const PathFunction& trace,
                    const std::function<void(uint64_t)>& progress) {
  return runPaths(plan, PathBatchFunction([&](uint64_t p0, uint64_t n, int g, std::span<PathChunk> chunks) {
                    tbb::parallel_for(size_t(0), chunks.size(), [&](size_t ci) {
                      const uint64_t c0 = ci * kPathChunk, c1 = std::min(n, c0 + kPathChunk);
                      for (uint64_t p = p0 + c0; p < p0 + c1; ++p) trace(p, g, chunks[ci]);
                    });
                  }),
                  progress);
}

namespace {

// The events a path tallies at most: one exit event (coherent or multiple), and the geo_masked
// copy when it is tallied.
size_t eventsPerPath(const PathTallyPlan& plan) {
  return 1 + size_t(std::count(plan.components.begin(), plan.components.end(), Component::GeoMasked));
}

// Chunk storage kept between runs: a batch's chunks hold some 10 MB of tallies, and allocating
// them for every tile costs thousands of page faults and the copies of growing vectors. A run
// leases two sets (the batch it merges and the one computed meanwhile); a batch uses the first
// chunks of a set, and a smaller batch leaves the others' storage for the next.
SparePool<std::vector<PathChunk>>& chunkPool() {
  static SparePool<std::vector<PathChunk>> pool;
  return pool;
}

// A batch's chunks of `set`, emptied and with room for their paths' tallies.
std::span<PathChunk> prepareChunks(const PathTallyPlan& plan, int group, uint64_t c0, uint64_t c1,
                                   std::vector<PathChunk>& set) {
  const int nL = plan.nLambda;
  const size_t used = c1 - c0;
  if (set.size() < used) set.resize(used, PathChunk(nL));
  const std::span<PathChunk> chunks(set.data(), used);
  const uint64_t p0 = c0 * kPathChunk, p1 = std::min(plan.paths, c1 * kPathChunk);
  for (size_t i = 0; i < chunks.size(); ++i) {
    chunks[i].clear(nL);
    chunks[i].reserve(std::min(kPathChunk, p1 - p0 - i * kPathChunk), eventsPerPath(plan),
                      plan.groups[size_t(group)].size());
  }
  return chunks;
}

}  // namespace

void reservePathChunks(const PathTallyPlan& plan) {
  if (plan.groups.empty() || plan.paths == 0) return;
  SparePool<std::vector<PathChunk>>::Lease set(chunkPool());
  const uint64_t nChunks = std::min(kPathChunksPerBatch, (plan.paths + kPathChunk - 1) / kPathChunk);
  for (PathChunk& c : prepareChunks(plan, 0, 0, nChunks, *set)) {
    // Reserved storage is only mapped; writing it once faults its pages in.
    c.events.resize(c.events.capacity());
    c.weights.resize(c.weights.capacity());
    c.clear(plan.nLambda);
  }
}

TileResult runPaths(const PathTallyPlan& plan, const PathBatchFunction& trace,
                    const std::function<void(uint64_t)>& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  const DirectionGrid& grid = *plan.grid;
  const int nL = plan.nLambda, nB = grid.binCount();
  const uint64_t N = plan.paths;
  TileResult r;
  r.tile = plan.tile;
  r.incidenceIndex = plan.incidenceIndex;
  r.incidenceBin = plan.incidenceBin;
  r.nLambda = nL;
  r.nBins = nB;
  r.samples = N;
  std::array<std::vector<double>, kComponentCount> sum, sum2;
  for (Component c : plan.components) {
    sum[int(c)].assign(size_t(nL) * nB, 0.0);
    sum2[int(c)].assign(size_t(nL) * nB, 0.0);
  }
  std::array<std::vector<double>, kComponentCount> energy1, energy2;  // per (side, λ): Σ w, Σ w²
  for (int c = 0; c < kComponentCount; ++c) {
    energy1[size_t(c)].assign(2 * size_t(nL), 0.0);
    energy2[size_t(c)].assign(2 * size_t(nL), 0.0);
  }
  r.truncated.assign(nL, 0.0);
  r.leaked.assign(nL, 0.0);
  r.missed.assign(nL, 0.0);

  struct Batch {
    int group;
    uint64_t c0, c1;  // chunks [c0, c1) of the group
  };
  // The batches in order, each made from its index: a list of them would take 24 bytes a batch,
  // 90 GB for 1e15 paths per slice.
  const uint64_t nChunks = (N + kPathChunk - 1) / kPathChunk;
  const uint64_t perGroup = (nChunks + kPathChunksPerBatch - 1) / kPathChunksPerBatch;
  const uint64_t nBatches = perGroup * plan.groups.size();
  auto batch = [&](uint64_t i) {
    const uint64_t c0 = (i % perGroup) * kPathChunksPerBatch;
    return Batch{int(i / perGroup), c0, std::min(nChunks, c0 + kPathChunksPerBatch)};
  };

  auto compute = [&](const Batch& b, std::vector<PathChunk>& set, size_t& used) {
    // The chunks' storage is kept from batch to batch and from run to run (chunkPool).
    used = b.c1 - b.c0;
    const std::span<PathChunk> chunks = prepareChunks(plan, b.group, b.c0, b.c1, set);
    const uint64_t p0 = b.c0 * kPathChunk, p1 = std::min(N, b.c1 * kPathChunk);
    trace(plan.firstPath + p0, p1 - p0, b.group, chunks);
  };
  // Merge in chunk order: identical sums for any number of threads.
  auto merge = [&](std::span<const PathChunk> chunks) {
    for (const PathChunk& c : chunks) {
      for (const PathChunk::Event& e : c.events) {
        const auto& lambdas = plan.groups[e.group];
        for (size_t k = 0; k < lambdas.size(); ++k) {
          const double w = c.weights[e.weightOffset + k];
          const size_t idx = size_t(lambdas[k]) * nB + e.bin;
          sum[e.component][idx] += w;
          sum2[e.component][idx] += w * w;
          // One exit event per path: per-path energy moments by component and side.
          const size_t side = grid.isUpper(e.bin) ? 0 : 1;
          energy1[e.component][side * size_t(nL) + size_t(lambdas[k])] += w;
          energy2[e.component][side * size_t(nL) + size_t(lambdas[k])] += w * w;
        }
      }
      r.rays += c.rays;
      for (int l = 0; l < nL; ++l) {
        r.truncated[l] += c.truncated[l];
        r.leaked[l] += c.leaked[l];
        r.missed[l] += c.missed[l];
      }
    }
  };
  // The merge is serial (its order makes the sums independent of the threads): it runs on this
  // thread while the other threads compute the next batch, so that many threads per rank do not
  // wait for it (about 5 ns per path, a tenth of a walk's path on 8 threads).
  // The two sets trade roles by pointer: a run of one batch gives its filled set back last, so
  // that the next run (the pool gives the last set back first) takes it again, not the empty one.
  SparePool<std::vector<PathChunk>>::Lease first(chunkPool()), second(chunkPool());
  std::vector<PathChunk>* current = &*first;
  std::vector<PathChunk>* next = &*second;
  size_t currentUsed = 0, nextUsed = 0;
  if (nBatches > 0) compute(batch(0), *current, currentUsed);
  for (uint64_t i = 0; i < nBatches; ++i) {
    throwIfStopped();
    tbb::task_group ahead;
    if (i + 1 < nBatches) ahead.run([&] { compute(batch(i + 1), *next, nextUsed); });
    try {
      merge({current->data(), currentUsed});
      const Batch b = batch(i);
      if (progress) progress(uint64_t(b.group) * N + std::min(N, b.c1 * kPathChunk));
    } catch (...) {
      ahead.cancel();
      ahead.wait();
      throw;
    }
    ahead.wait();
    std::swap(current, next);
    std::swap(currentUsed, nextUsed);
  }
  const double dN = double(N);
  for (Component c : plan.components) {
    auto& v = r.value[int(c)];
    auto& e = r.stdError[int(c)];
    v.assign(size_t(nL) * nB, 0.0);
    e.assign(size_t(nL) * nB, 0.0);
    for (int l = 0; l < nL; ++l)
      for (int b = 0; b < nB; ++b) {
        const size_t i = size_t(l) * nB + b;
        const double op = grid.projectedSolidAngle(b);
        if (op <= 0) continue;
        const double s1 = sum[int(c)][i], s2 = sum2[int(c)][i];
        v[i] = s1 / (dN * op);
        // Standard error of the mean of N i.i.d. per-path contributions (zero for most paths).
        const double var = N > 1 ? std::max(0.0, (s2 - s1 * s1 / dN) / (dN - 1)) : 0.0;
        e[i] = std::sqrt(var / dN) / op;
      }
  }
  for (Component c : plan.components) {
    auto& m = r.pathMoments[int(c)];
    m.assign(4 * size_t(nL), 0.0);
    for (size_t side = 0; side < 2; ++side)
      for (int l = 0; l < nL; ++l) {
        m[(side * 2 + 0) * size_t(nL) + size_t(l)] = energy1[int(c)][side * size_t(nL) + size_t(l)] / dN;
        m[(side * 2 + 1) * size_t(nL) + size_t(l)] = energy2[int(c)][side * size_t(nL) + size_t(l)] / dN;
      }
  }
  for (int l = 0; l < nL; ++l) {
    r.truncated[l] /= dN;
    r.leaked[l] /= dN;
    r.missed[l] /= dN;
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace mbsdf
