#include "cluster/mpi_session.h"

#include <cstdlib>

namespace mbsdf {
namespace {

// Whether a launcher (mpirun, srun with PMIx or PMI-2) started this process as one of its ranks.
bool startedByLauncher() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
    if (std::getenv(v)) return true;
  return false;
}

}  // namespace

MpiSession::MpiSession(int* argc, char*** argv) {
  int init = 0;
  MPI_Initialized(&init);
  if (!init) {
    // Started without a launcher, Open MPI's singleton start forks a daemon (orted) that would
    // serve MPI_Comm_spawn, which this program never calls: 2.4 s of a 2.6 s MPI_Init on a Debian 12
    // machine, longer than a small job's physics. Isolated, the singleton starts in 0.2 s. The
    // user's own setting of the variable wins; under a launcher it is not read.
    if (!startedByLauncher()) setenv("OMPI_MCA_ess_singleton_isolated", "1", 0);
    int provided = 0;
    MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
    owns_ = true;
  }
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

MpiSession::~MpiSession() {
  if (owns_) {
    int fin = 0;
    MPI_Finalized(&fin);
    if (!fin) MPI_Finalize();
  }
}

bool MpiSession::anyRank(bool flag) const {
  int in = flag ? 1 : 0, out = 0;
  MPI_Allreduce(&in, &out, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  return out != 0;
}

std::string MpiSession::broadcast(const std::string& s) const {
  unsigned long long n = s.size();
  MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD);
  std::string out = rank_ == 0 ? s : std::string(size_t(n), '\0');
  if (n) MPI_Bcast(out.data(), int(n), MPI_CHAR, 0, MPI_COMM_WORLD);
  return out;
}

}  // namespace mbsdf
