// Whether every rank's node sees the output folder rank 0 writes in, and whether its one-writer lock
// holds on every node.
//
// Only rank 0 writes the table, so a run whose output folder is local to rank 0's node computes a
// correct file; but the other nodes' ranks log into folders of their own, and a requeue whose rank 0
// lands on another node finds no partial file and starts afresh. A file system that does not carry
// flock(2) locks between nodes (Lustre mounted without `-o flock`, NFS mounted `nolock`) lets a second
// run on another node write the same output. Both are found before any compute by every rank looking
// at the lock file rank 0 holds (io/output_target.h viewOfLock).
#pragma once
#include <optional>
#include <string>

#include "cluster/mpi_session.h"

namespace mbsdf {

// Collective. On rank 0: what the run should warn about (the ranks and nodes that do not see the
// lock file, or see it unlocked, and what follows), or none when every rank sees it held. `lockPath`
// and `record` are rank 0's (OutputLock::path and record); other ranks' arguments are ignored.
std::optional<std::string> outputFolderCaveat(const MpiSession& mpi, const std::string& lockPath,
                                              const std::string& record);

}  // namespace mbsdf
