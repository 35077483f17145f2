#include "cluster/shared_output.h"

#include <mpi.h>

#include <algorithm>
#include <set>
#include <vector>

#include <fmt/format.h>

#include "io/output_target.h"

namespace mbsdf {
namespace {

std::string nodeName() {
  char name[MPI_MAX_PROCESSOR_NAME] = {0};
  int n = 0;
  MPI_Get_processor_name(name, &n);
  return std::string(name, size_t(n));
}

// "2 ranks on node-b, node-c" for the ranks seeing `view`.
std::string ranksOn(const std::vector<int>& views, const std::vector<std::string>& nodes, LockView view) {
  std::set<std::string> names;
  int ranks = 0;
  for (size_t r = 0; r < views.size(); ++r)
    if (views[r] == int(view)) ++ranks, names.insert(nodes[r]);
  std::string list;
  for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
  return fmt::format("{} rank{} on {}", ranks, ranks == 1 ? "" : "s", list);
}

}  // namespace

std::optional<std::string> outputFolderCaveat(const MpiSession& mpi, const std::string& lockPath,
                                              const std::string& record) {
  if (mpi.size() < 2) return std::nullopt;
  const std::string path = mpi.broadcast(lockPath), held = mpi.broadcast(record);
  LockView seen = mpi.rank() == 0 ? LockView::Held : viewOfLock(path, held);
  // A folder of the same name holding another file is as far from rank 0's as none.
  if (seen == LockView::Foreign) seen = LockView::Missing;
  const int view = int(seen);
  std::string node = nodeName();
  node.resize(MPI_MAX_PROCESSOR_NAME, '\0');
  std::vector<int> views(size_t(mpi.rank() == 0 ? mpi.size() : 0));
  std::vector<char> names(size_t(mpi.rank() == 0 ? mpi.size() : 0) * MPI_MAX_PROCESSOR_NAME);
  MPI_Gather(&view, 1, MPI_INT, views.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
  MPI_Gather(node.data(), MPI_MAX_PROCESSOR_NAME, MPI_CHAR, names.data(), MPI_MAX_PROCESSOR_NAME, MPI_CHAR, 0,
             MPI_COMM_WORLD);
  if (mpi.rank() != 0) return std::nullopt;
  std::vector<std::string> nodes;
  for (int r = 0; r < mpi.size(); ++r) nodes.emplace_back(names.data() + size_t(r) * MPI_MAX_PROCESSOR_NAME);
  auto count = [&](LockView v) { return std::count(views.begin(), views.end(), int(v)); };
  std::string caveat;
  if (count(LockView::Missing))
    caveat = fmt::format(
        "the output folder is not shared with {} (they do not see {}, which rank 0 on {} holds): the table is "
        "written on {} only, those ranks' logs stay on their nodes, and a requeue whose rank 0 lands elsewhere "
        "starts afresh; give an output on a file system every node mounts",
        ranksOn(views, nodes, LockView::Missing), path, nodes[0], nodes[0]);
  if (count(LockView::Unenforced))
    caveat += fmt::format(
        "{}the file system of the output does not carry its lock between nodes ({} could take {} while rank 0 "
        "held it): a second run on another node would not be stopped from writing the same output; mount it with "
        "flock (Lustre `-o flock`, NFS without `nolock`)",
        caveat.empty() ? "" : "; ", ranksOn(views, nodes, LockView::Unenforced), path);
  if (caveat.empty()) return std::nullopt;
  return caveat;
}

}  // namespace mbsdf
