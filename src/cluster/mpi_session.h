// RAII for MPI_Init/MPI_Finalize, plus the few collective helpers the job needs.
#pragma once
#include <mpi.h>

#include <string>
#include <vector>

namespace mbsdf {

class MpiSession {
 public:
  MpiSession(int* argc, char*** argv);
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  int rank() const { return rank_; }
  int size() const { return size_; }
  // True on every rank if `flag` is true on any rank (used to fail together, never hang).
  bool anyRank(bool flag) const;
  // Rank 0's `s` on every rank.
  std::string broadcast(const std::string& s) const;

 private:
  int rank_ = 0, size_ = 1;
  bool owns_ = false;
};

}  // namespace mbsdf
