// Runs a job over MPI ranks: the work is cut into tiles (one incidence direction x all
// wavelengths, so rays are shared across wavelengths); tile t goes to rank t mod size. Every rank
// computes its tiles with TBB threads; rank 0 also receives the others' TileResults and writes each
// slice as it arrives (memory at rank 0 bounded by the tiles in flight). Results depend only on the
// tile and sample keys, never on the rank or thread count.
#pragma once
#include <string>

#include "dist/mpi_session.h"
#include "job/job.h"

namespace mbsdf {

struct RunOptions {
  std::string outputPath;  // overrides the job's [output] path when not empty
  int threads = 0;         // 0: all cores
};

struct RunSummary {
  int tiles = 0;
  double seconds = 0;
  uint64_t paths = 0;
};

RunSummary runJob(const Job& job, const MpiSession& mpi, const RunOptions& options);

}  // namespace mbsdf
