// `microbsdf plan`: what a job will compute and what it will cost, from a short pilot run of the
// most expensive tile (grazing incidence) at a reduced budget, extrapolated linearly in the number
// of paths and wave samples: tiles, seconds per tile, core-hours, output size, memory per rank and
// a suggested #SBATCH header.
#pragma once
#include <nlohmann/json.hpp>

#include <functional>

#include "job/job.h"
#include "scattering/tile_result.h"

namespace mbsdf {

struct PlanOptions {
  uint64_t pilotPaths = 20000;
  int pilotWaveDivisor = 16;  // the pilot uses 1/16 of the wave samples (at least 2 per bin)
  int threads = 0;            // 0: all cores
  // Seconds rank 0 spends writing one slice of this job's layout, committed with the others of its
  // computed tile (the last argument: slices per computed tile) as the run commits them (the output
  // writer lives above this layer: `microbsdf plan` passes io's measureWriteSecondsPerSlice);
  // unset: not counted.
  std::function<double(const Job&, const DirectionGrid&, int)> writeSecondsPerSlice;
  // Bytes one slice takes in the output file in the job's storage profile, measured by compressing
  // the pilot tiles as the writer stores them (io's storedBytesPerSlice); unset: not reported.
  std::function<double(const Job&, const DirectionGrid&, const std::vector<TileResult>&)> storedBytesPerSlice;
  // Seconds the caller spent loading the job (its geometry built and checked), which every rank of
  // the run spends again before its first tile; 0: not counted.
  double jobLoadSeconds = 0;
  // Seconds MPI_Init took in the caller's process (one process, not under a launcher), which every
  // rank of the run spends before its first tile, its job read meanwhile where the geometry is made
  // from parameters; 0: not counted.
  double mpiStartSeconds = 0;
};

// Resident memory of one rank running `job`: the scene (Embree + double copies), one tile result
// (doubles, value + error for up to five tallies), the path tracer's batch of events, and the wave
// estimator's own (`waveBytes`: the fft estimator's facet fields, transforms and tables).
double memoryBytesPerRank(const Job& job, double waveBytes);
// The output file's size without compression (float32 value + standard error per component, the
// grid's four double tables): an upper bound, as deflate only shrinks it.
double outputBytesUncompressed(const Job& job);
// Memory this process can still take: /proc/meminfo's MemAvailable, or less under a cgroup limit
// (Slurm's --mem); a negative value when unknown.
double availableMemoryBytes();

// With components = "auto" the effects planner runs first and its decisions are in "effects".
nlohmann::json planJob(const Job& job, const PlanOptions& options);
std::string formatPlan(const nlohmann::json& plan);

}  // namespace mbsdf
