// Runs a job over MPI ranks (docs/running.md "How the work is divided"). The work is cut into tiles (one incidence
// direction x all wavelengths, so rays are shared across wavelengths). Rank 0 schedules them
// dynamically, most expensive first (cost estimate: grazing incidence first), computes tiles too,
// serves the other ranks between its own batches, and writes each slice as it arrives (memory at
// rank 0 bounded by the tiles in flight). Results depend only on the tile and sample keys, never on
// the rank or thread count.
//
// Checkpoint and restart (GROMACS -cpi / -maxh style): `resume` keeps the finished slices of an
// earlier run of the same job (harmless on a fresh run); `maxHours` stops cleanly when the next
// tile would not finish in time; SIGTERM, SIGINT and SIGUSR1 stop cleanly too (tiles in flight are
// abandoned at their next batch). A clean stop closes the partial file and returns stoppedEarly;
// the same command with --resume completes it.
#pragma once
#include <chrono>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "cluster/mpi_session.h"
#include "core/direction_grid.h"
#include "core/error.h"
#include "job/effects_planner.h"
#include "job/job.h"
#include "job/tile_computer.h"
#include "scattering/tile_result.h"

namespace mbsdf {

// What a run builds before its first tile without any other rank: the job's direction grid and
// its tile computer (scenes, facet tables, wave estimator). `run` builds it on a second thread
// while MPI starts (a small job's whole compute is of MPI start-up's order); runJob builds it when
// it is not given. It refers to the job, which must outlive it unchanged.
struct RunSetup {
  RunSetup(const Job& job, const PilotResults& pilots,
           std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now());
  DirectionGrid grid;
  TileComputer tiles;
  double seconds = 0;  // how long building it took
};

struct RunOptions {
  std::string outputPath;  // overrides the job's [output] path when not empty
  int threads = 0;         // 0: all cores
  bool resume = false;
  double maxHours = 0;  // 0: no limit
  // Rank 0 ends the run (exit code 6, the partial file resumable) when a worker with a tile sends
  // nothing, neither a result nor a heartbeat, for this long; 0: never.
  double rankTimeoutSeconds = 120;
  // What the effects planner's pilots computed on this rank (planEffects): paths and wave terms of
  // tiles it need not compute again.
  PilotResults pilots;
  // Built beforehand for this job and these pilots (else runJob builds it), and whether that was
  // while MPI started (for the start-up log line).
  std::shared_ptr<const RunSetup> setup;
  bool setupDuringMpiStart = false;
  // Rank 0: why the output folder or its lock does not reach every rank's node (shared_output.h),
  // repeated in the run's closing summary.
  std::optional<std::string> outputFolderCaveat;
};

struct RunSummary {
  int tiles = 0;     // tiles of the job
  int computed = 0;  // tiles computed in this run (all ranks)
  int resumed = 0;   // tiles kept from an earlier run
  bool stoppedEarly = false;
  bool alreadyFinished = false;  // --resume found the output finished by this job: nothing written
  // Not Ok when the run could not start or finish: BadInput (a resume that does not match, too
  // little memory), WriteFailed (the output or a log could not be written). Same on every rank;
  // `error` says why (rank 0).
  ExitCode exit = ExitCode::Ok;
  std::string error;
  double seconds = 0;
  uint64_t paths = 0;
};

RunSummary runJob(const Job& job, const MpiSession& mpi, const RunOptions& options);

}  // namespace mbsdf
