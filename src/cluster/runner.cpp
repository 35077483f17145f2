#include "cluster/runner.h"

#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <numeric>
#include <deque>
#include <filesystem>
#include <future>
#include <optional>
#include <set>
#include <thread>

#include "cluster/output_schema_of.h"
#include "core/log.h"
#include "core/stop.h"
#include "geometry/embree_scene.h"
#include "io/bsdf_file.h"
#include "io/output_target.h"
#include "job/effects_planner.h"
#include "job/plan.h"
#include "job/scalar_validity.h"
#include "job/symmetry.h"
#include "job/tile_computer.h"
#include "job/transport.h"
#include "scattering/reciprocity.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
namespace {

constexpr int kTagRequest = 11, kTagResult = 12, kTagStopped = 13, kTagPrepared = 14, kTagAlive = 15, kTagAssign = 21;

// How a rank ends; the maximum over the ranks is the run's.
enum RankStatus : int { kRankOk = 0, kRankWriteFailed = 1 };

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// A worker's heartbeat interval: a tenth of the timeout rank 0 judges it by, at most 2 s.
double heartbeatSecondsFor(double rankTimeoutSeconds) {
  return rankTimeoutSeconds > 0 ? std::min(2.0, rankTimeoutSeconds / 10) : 0.0;
}

// Memory: a footprint this node cannot hold is refused before anything is written ("" if it fits).
// Every rank checks its own node's share: the estimate per rank times the ranks on the node.
std::string memoryShortfall(const Job& job, const WaveEstimator* wave) {
  int local = 1;
  MPI_Comm node;
  if (MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node) == MPI_SUCCESS) {
    MPI_Comm_size(node, &local);
    MPI_Comm_free(&node);
  }
  const double need = memoryBytesPerRank(job, wave ? wave->memoryBytes() : 0.0) * local;
  const double avail = availableMemoryBytes();
  if (!(avail > 0 && need > avail)) return "";
  return fmt::format(
      "the job needs about {:.2f} GB of memory per node ({} rank(s) here) but {:.2f} GB are available: "
      "use fewer bins, wavelengths or ranks per node, or a larger node (`microbsdf plan` shows the "
      "estimate)",
      need / 1e9, local, avail / 1e9);
}

// Room on the output's file system. The uncompressed size is an upper bound (deflate shrinks it), so
// only the grid tables and a margin are certain to be needed: less than that is an error, less than
// the bound a warning.
void checkDiskSpace(const std::string& outPath, const Job& job, const DirectionGrid& grid) {
  const double free = freeBytesAt(outPath), upper = outputBytesUncompressed(job);
  const double certain = std::min(upper, double(grid.binCount()) * 8.0 * 4.0 + 65536.0);
  if (free >= 0 && free < certain)
    throw WriteError(
        fmt::format("output {}: {:.3g} MB free on its file system, the file needs at least {:.3g} MB "
                    "(and up to {:.3g} MB uncompressed)",
                    outPath, free / 1e6, certain / 1e6, upper / 1e6));
  if (free >= 0 && free < upper)
    spdlog::warn(
        "output {}: {:.3g} MB free on its file system; the file may need up to {:.3g} MB (uncompressed "
        "size; deflate usually makes it smaller). A full disk stops the run with exit code 4, resumable",
        outPath, free / 1e6, upper / 1e6);
}

// A tile's slices in the order both sides of the exchange take them: the tile's own, then the
// slices symmetry maps it to (symmetry.h).
std::vector<int> sliceIndices(const TileResult& r, const std::optional<AzimuthalSymmetry>& symmetry) {
  std::vector<int> v{r.incidenceIndex};
  if (symmetry)
    for (int m : symmetry->members(r.incidenceIndex))
      if (m != r.incidenceIndex) v.push_back(m);
  return v;
}
TileResult sliceOf(const Job& job, const TileResult& r, const std::optional<AzimuthalSymmetry>& symmetry, int m) {
  return m == r.incidenceIndex ? r : symmetry->mappedSlice(r, m, job.incidence[size_t(m)].bin);
}

// A worker's slices as the file stores them (PreparedSlice: statistics and compressed table
// chunks), sent to rank 0 one message per slice after the tile's result: preparing them is most of
// writing, spread here over the ranks that computed the tiles. Prepared before the result is sent
// (up to kPrepareAheadBytes; the rest as they are sent), so that rank 0 does not wait for them.
constexpr double kPrepareAheadBytes = 256e6;
std::function<void()> prepareSlices(const Job& job, const TileResult& r,
                                    const std::optional<AzimuthalSymmetry>& symmetry, const OutputSchema& schema,
                                    const DirectionGrid& grid) {
  const std::vector<int> indices = sliceIndices(r, symmetry);
  auto message = [&job, &schema, &grid, &symmetry, r](int m) {
    return serializePrepared(prepareSlice(sliceOf(job, r, symmetry, m), schema, grid));
  };
  auto ahead = std::make_shared<std::vector<std::vector<unsigned char>>>();
  double bytes = 0;
  for (int m : indices) {
    if (bytes > kPrepareAheadBytes) break;
    ahead->push_back(message(m));
    bytes += double(ahead->back().size());
  }
  return [indices, ahead, message] {
    auto send = [](const std::vector<unsigned char>& m) {
      MPI_Send(m.data(), int(m.size()), MPI_BYTE, 0, kTagPrepared, MPI_COMM_WORLD);
    };
    for (size_t k = 0; k < indices.size(); ++k)
      if (k < ahead->size())
        send((*ahead)[k]);
      else
        send(message(indices[k]));
  };
}

// A worker's work on a tile (computing it, preparing its slices), done on a thread of its own while
// this thread (the one that calls MPI) tells rank 0 every `heartbeatSeconds` that the rank is alive
// (kTagAlive), however long the tile's inner loops run between progress callbacks: rank 0 can then
// tell a long tile from a rank that is stopped, frozen or cut off (TileServer::checkSilence). The
// work's exceptions (a stop) reach the caller.
template <class Work>
auto withHeartbeat(Work work, int t, double heartbeatSeconds) -> decltype(work()) {
  if (heartbeatSeconds <= 0) return work();
  auto done = std::async(std::launch::async, std::move(work));
  const auto interval = std::chrono::milliseconds(int64_t(heartbeatSeconds * 1000));
  while (done.wait_for(interval) != std::future_status::ready) MPI_Send(&t, 1, MPI_INT, 0, kTagAlive, MPI_COMM_WORLD);
  return done.get();
}

// A worker rank: asks rank 0 for tiles until told there are none (or a stop abandons one), sends
// each result back (and its prepared slices, prepareSlicesOf), then joins the ranks' agreement on
// how the run ended (RankStatus).
void serveAsWorker(const std::function<TileResult(int)>& computeTile,
                   const std::function<std::function<void()>(const TileResult&)>& prepareSlicesOf,
                   double heartbeatSeconds, RunSummary& summary) {
  int request = -1;
  MPI_Send(&request, 1, MPI_INT, 0, kTagRequest, MPI_COMM_WORLD);
  while (true) {
    int t = -1;
    MPI_Recv(&t, 1, MPI_INT, 0, kTagAssign, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    if (t < 0) break;
    if (!logWriteFailure().empty()) {  // no log, no run: give the tile back and stop
      MPI_Send(&t, 1, MPI_INT, 0, kTagStopped, MPI_COMM_WORLD);
      MPI_Recv(&t, 1, MPI_INT, 0, kTagAssign, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      break;
    }
    try {
      auto [r, sendSlices] = withHeartbeat(
          [&] {
            TileResult computed = computeTile(t);
            std::function<void()> send = prepareSlicesOf(computed);
            return std::make_pair(std::move(computed), std::move(send));
          },
          t, heartbeatSeconds);
      std::vector<double> buf = r.serialize();
      MPI_Send(buf.data(), int(buf.size()), MPI_DOUBLE, 0, kTagResult, MPI_COMM_WORLD);
      sendSlices();
      summary.paths += r.samples;
      ++summary.computed;
    } catch (const StopRequested&) {
      spdlog::info("stop requested: tile {} abandoned ({})", t, stopAnswerNote());
      MPI_Send(&t, 1, MPI_INT, 0, kTagStopped, MPI_COMM_WORLD);
      // Rank 0 answers every message with an assignment; it will be -1 now.
      MPI_Recv(&t, 1, MPI_INT, 0, kTagAssign, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      break;
    }
  }
  if (!logWriteFailure().empty()) spdlog::error("log write failed: {}", logWriteFailure());
  int status = logWriteFailure().empty() ? kRankOk : kRankWriteFailed, worst = 0;
  MPI_Allreduce(&status, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
}

// The run's header in the log (rank 0): the wave estimator, reciprocity, the job, geometric optics.
void logJobHeader(const Job& job, const DirectionGrid& grid, const TileComputer& tiles, int ranks) {
  const WaveEstimator* wave = tiles.wave();
  if (wave) {
    const std::string notes = wave->notes();
    spdlog::info(
        "scalar diffraction: {} estimator ({}), {}, coherence length {} µm{}", wave->name(), job.waveEstimatorChoice(),
        notes.empty() ? std::to_string(job.waveSamplesPerBin) + " samples per bin" : notes,
        job.scene.coherenceLength_um, job.scene.coherenceLength_um > 0 ? "" : " (no window: one copy of the patch)");
    // Reciprocity (docs/physics.md §8): each pair of incidence bins gets the wave term once.
    const std::optional<ReciprocalPairs>& pairs = tiles.pairs();
    if (const std::optional<std::string> caveat = job.waveErrorsCaveat()) spdlog::warn("{}", *caveat);
    spdlog::info("reciprocity: {}", pairs ? fmt::format("the wave term is computed for {:.1f}% of the same-side bin "
                                                        "pairs, the rest mirrored when every slice is done",
                                                        100 * pairs->computedFraction())
                                          : "not used (" + job.reciprocityOffReason() + ")");
  }
  const GeometricTransport& transport = tiles.transport();
  spdlog::info(
      "job {}: {} ({}), {}, {} wavelengths, grid {} ({} bins), {} slices on {} ranks, {}", job.file, job.geometryKind,
      job.statistical
          ? transport.describe()
          : fmt::format("{} triangles, {:.3g} x {:.3g} µm{}, {}", job.geometry.triangles.size(), job.geometry.sizeX,
                        job.geometry.sizeY, job.geometry.periodic ? ", periodic" : "", job.closure.describe()),
      job.material.describe(), job.lambda_nm.size(), grid.kind(), grid.binCount(), job.incidence.size(), ranks,
      job.describePaths());
  if (transport.mayUseFacetSum()) spdlog::info("geometric optics: {}", transport.describe());
}

// One rank's tiles, computed and timed; the callback between inner loops may abandon a tile (stop)
// or serve the workers (rank 0).
struct TimedTiles {
  const Job& job;
  const TileComputer& tiles;
  double tileSeconds = 0, pathSeconds = 0, waveSeconds = 0;
  int done = 0;

  TileResult compute(int t, const std::function<void()>& between) {
    // Progressive sampling stops at its target or at max_paths_per_slice: the count runs up to that.
    const uint64_t budget = job.targetRelError > 0 ? job.maxPathsPerSlice : job.pathsFor(t);
    ProgressReporter pathProgress("tile " + std::to_string(t), budget, 30.0, false);
    auto cb = [&](uint64_t n) {
      pathProgress.update(n);
      throwIfStopped();
      if (between) between();
    };
    // The wave term counts its own work (facet sums, orders), not paths: a reporter of its own.
    auto waveBeat = heartbeat("tile " + std::to_string(t) + ": wave term", 30.0);
    auto waveCb = [&](uint64_t n) {
      waveBeat(n);
      if (between) between();
    };
    double paths = 0, waveTerm = 0;
    // What the wave estimator builds once for every tile (exact's visibility table) is paid by the
    // tile that first needs it: said apart, so a tile's time stays comparable with `plan`'s.
    const double setupBefore = tiles.wave() ? tiles.wave()->setupSeconds() : 0.0;
    TileResult r = tiles.compute(t, cb, &paths, &waveTerm, waveCb);
    const double setup = (tiles.wave() ? tiles.wave()->setupSeconds() : 0.0) - setupBefore;
    pathSeconds += paths;
    waveSeconds += waveTerm;
    tileSeconds += r.seconds;
    ++done;
    spdlog::debug("tile {}: {:.3f} s (path tracing {:.3f} s, scalar diffraction {:.3f} s{})", t, r.seconds, paths,
                  waveTerm, setup > 0 ? fmt::format(", of which {:.3f} s building what every tile shares", setup) : "");
    return r;
  }
};

// Rank 0 when the writer could not be set up: every worker has asked for a tile; each is answered
// "none" and the run ends on every rank with rank 0's exit code.
void refuseWorkers(const MpiSession& mpi, ExitCode exit) {
  for (int w = 1; w < mpi.size(); ++w) {
    int request = 0, none = -1;
    MPI_Status st;
    MPI_Recv(&request, 1, MPI_INT, MPI_ANY_SOURCE, kTagRequest, MPI_COMM_WORLD, &st);
    MPI_Send(&none, 1, MPI_INT, st.MPI_SOURCE, kTagAssign, MPI_COMM_WORLD);
  }
  int status = kRankOk, worst = 0, outcome = exitCode(exit);
  MPI_Allreduce(&status, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  double times[2] = {0, 0}, total[2];
  MPI_Reduce(times, total, 2, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  MPI_Bcast(&outcome, 1, MPI_INT, 0, MPI_COMM_WORLD);
}

// Rank 0's side of a run: the queue of tiles still missing, its own tiles, the workers served
// between them (dynamic scheduling: a worker gets the next tile when it returns one), and the
// writer. Tiles are written as they arrive; a failed write, a signal or --max-hours stops the
// handing out, and the tiles in flight are collected before the file is finished or closed.
class TileServer {
 public:
  TileServer(const Job& job, const DirectionGrid& grid, const MpiSession& mpi, const RunOptions& options,
             const std::string& outPath, BsdfFileWriter& writer, TimedTiles& own, RunSummary& summary,
             Clock::time_point t0)
      : job_(job),
        grid_(grid),
        options_(options),
        outPath_(outPath),
        writer_(writer),
        own_(own),
        summary_(summary),
        t0_(t0),
        finished_(writer.resumedTiles().begin(), writer.resumedTiles().end()),
        progress_("slices written", uint64_t(job.incidence.size())),  // symmetry copies count
        activeWorkers_(mpi.size() - 1),
        lastHeard_(size_t(mpi.size()), Clock::now()),
        holdsTile_(size_t(mpi.size()), 1) {
    holdsTile_[0] = 0;
    const int nTiles = int(job.incidence.size());
    summary_.resumed = int(finished_.size());
    written_ = int(finished_.size());
    if (summary_.resumed)
      spdlog::info("resuming: {} of {} slices already complete in {}.partial", summary_.resumed, nTiles, outPath);
    for (const RecomputedSlice& r : writer.recomputedTiles()) {
      const std::string why =
          r.fault == KeptSliceFault::EnergiesNotFinite ? "its energies are not finite (a damaged or forged flag)"
          : r.fault == KeptSliceFault::Unreadable
              ? "its " + r.dataset + " cannot be read back (a chunk fails its checksum: the file was damaged)"
              : "its " + r.dataset + " holds a value the program cannot have written (NaN, infinite or negative)";
      spdlog::warn("resuming: slice {} is marked done in {}.partial but {}: computing it again", r.index, outPath, why);
    }
    // Symmetry (symmetry.h): one tile per ring (or per n-th of a ring) of a symmetric surface;
    // queued if any slice of its ring is missing (a kill may fall between a ring's slices).
    if (job.symmetryReduced()) symmetry_.emplace(job, grid);
    for (int t = 0; t < nTiles; ++t) {
      if (symmetry_ && symmetry_->representative(t) != t) continue;
      bool missing = !finished_.count(t);
      if (symmetry_)
        for (int m : symmetry_->members(t)) missing = missing || !finished_.count(m);
      if (missing) queue_.push_back(t);
    }
    if (symmetry_)
      spdlog::info("symmetry: {}; {} tiles for {} slices", job.symmetryReason, symmetry_->representativeCount(),
                   nTiles);
    // Most expensive first: grazing incidence bounces and wraps more.
    auto cost = [&](int t) { return 1.0 / (std::abs(std::cos(radians(job.incidence[size_t(t)].theta_deg))) + 0.05); };
    std::stable_sort(queue_.begin(), queue_.end(), [&](int a, int b) { return cost(a) > cost(b); });
    // Tiles whose pilot paths this rank holds (the effects planner's) are its own first: elsewhere
    // they would be traced again. Workers get them only when nothing else is left.
    for (int t : queue_)
      if (own_.tiles.holdsPilot(t)) reserved_.push_back(t);
    std::erase_if(queue_, [&](int t) { return own_.tiles.holdsPilot(t); });
  }

  // Computes and serves until every tile is written or the run stops.
  void run() {
    while (true) {
      while (serveOne(false)) {
      }
      checkSilence();
      const int t = takeTile(true);
      if (t < 0) break;
      try {
        const TileResult r = computeWhileServing(t);
        summary_.paths += r.samples;
        ++summary_.computed;
        writeResult(r);
      } catch (const StopRequested&) {
        spdlog::info("stop requested: tile {} abandoned ({})", t, stopAnswerNote());
        lostTiles_ = true;
        noteStop("signal received");
      }
    }
    while (activeWorkers_ > 0) serveOne(true);
  }

  // After run(): the ranks agree on write failures, the reciprocity fill, the summary; the file is
  // finished (complete) or closed (resumable); summary_ says how the run ended.
  void complete(const std::optional<ReciprocalPairs>& pairs);

 private:
  void noteStop(const char* why) {
    if (!stopAssigning_) spdlog::warn("{}: stopping cleanly after the tiles in flight", why);
    stopAssigning_ = true;
  }
  // --max-hours: stop when the next tile would not finish in time (with a 1.5x margin).
  bool outOfTime() const {
    if (options_.maxHours <= 0) return false;
    const double mean = ownDone_ ? ownTileSeconds_ / ownDone_ : 0.0;
    return since(t0_) + 1.5 * mean > options_.maxHours * 3600.0;
  }
  // The next tile for rank 0 itself (own) or for a worker; -1 when none is left or the run stops.
  int takeTile(bool own) {
    if (stopRequested()) noteStop("signal received");
    if (writeFailure_.empty() && !logWriteFailure().empty()) {
      writeFailure_ = "log write failed: " + logWriteFailure();
      noteStop("the log could not be written");
    }
    if (!stopAssigning_ && outOfTime()) noteStop("--max-hours reached");
    if (stopAssigning_) return -1;
    std::optional<int> t;
    if (own && !reserved_.empty()) {
      t = reserved_.front();
      reserved_.pop_front();
    } else if (next_ < queue_.size()) {
      t = queue_[next_++];
    } else if (!reserved_.empty()) {
      t = reserved_.back();
      reserved_.pop_back();
    }
    return t.value_or(-1);
  }
  void noteSliceChecks(int slice, const EnergyBalance& b);
  // Rank 0's own tile, computed on a thread of its own while this thread (the one that calls MPI
  // and writes) serves the workers: a worker that returns a tile gets its next one at once, not
  // after rank 0's next batch of paths, and a tile's inner loops need no callback to serve.
  TileResult computeWhileServing(int t);
  void writeResult(const TileResult& r, int worker = 0);
  bool serveOne(bool blocking);
  // Waits for a message from `source` (or any) with `tag` (or any), watching for silent workers
  // meanwhile: a short sleep between probes, so that waiting costs rank 0 no core.
  MPI_Status waitForMessage(int source, int tag);
  // Ends the run if a worker that holds a tile has sent nothing for --rank-timeout seconds: its
  // tile would never come, and every other rank would wait for it in the collectives that end the
  // run. Called only after every waiting message was received, so a busy rank 0 misjudges no one.
  void checkSilence();
  // Nothing waits: watch for silent workers, then sleep 200 µs (a poll that costs no core).
  void idle() {
    checkSilence();
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  [[noreturn]] void abandonSilentRank(int rank, double seconds);

  const Job& job_;
  const DirectionGrid& grid_;
  const RunOptions& options_;
  const std::string& outPath_;
  BsdfFileWriter& writer_;
  TimedTiles& own_;
  RunSummary& summary_;
  const Clock::time_point t0_;
  std::set<int> finished_;
  std::optional<AzimuthalSymmetry> symmetry_;
  std::vector<int> queue_;
  size_t next_ = 0;
  std::deque<int> reserved_;  // rank 0's own first (TileComputer::holdsPilot)
  bool stopAssigning_ = false, lostTiles_ = false;
  ProgressReporter progress_;
  int written_ = 0, activeWorkers_ = 0;
  // A failed write stops the run: no more tiles are handed out and results still in flight are
  // dropped (the journal lists only slices whose data reached the disk).
  std::string writeFailure_;
  // Slices written now that are not physical (noteSliceChecks), and the worst of them.
  int nonphysical_ = 0, worstSlice_ = -1;
  unsigned worstFlags_ = 0;
  double worstBadness_ = 0;
  double writeSeconds_ = 0;    // rank 0's time in the writer (slices, their flags, the journal)
  double prepareSeconds_ = 0;  // rank 0 preparing the slices of its own tiles (prepareSlice)
  double ownTileSeconds_ = 0;  // rank 0's own tiles (computeWhileServing), for --max-hours
  int ownDone_ = 0;
  std::vector<Clock::time_point> lastHeard_;  // per rank: its last message (a request, result or heartbeat)
  std::vector<char> holdsTile_;               // per rank: a worker that has a tile (or asked for its first)
  std::map<std::string, double> energySum_;   // Σ over the slices written now of each component's Σ f Ω⊥
};

// What makes a slice non-physical (SliceFlag, stored in /stats/nonphysical): the log names the slice
// and the figure, for the first ten; the closing summary counts them and names the worst. An energy
// balance beyond the tolerance is the model's own error (scalar theory on deep or steep structures);
// energy outside [0, 1] beyond its error is an estimator that cannot vouch for the slice; lost paths
// are light the table does not hold (a max_depth too small for deep trenches, rays leaking).
void TileServer::noteSliceChecks(int slice, const EnergyBalance& b) {
  for (size_t l = 0; l < b.flags.size(); ++l) {
    const unsigned f = unsigned(b.flags[l]);
    if (!f) continue;
    const double badness = std::max({std::abs(b.value[l]), -b.energy[l], b.energy[l] - 1, b.pathsLost[l]});
    if (nonphysical_++ < 10) {
      std::string figures;
      if (f & (unsigned(SliceFlag::NegativeEnergy) | unsigned(SliceFlag::ExcessEnergy)))
        figures += fmt::format("; energy {:.4f} ± {:.4f}", b.energy[l], b.stdError[l]);
      if (f & unsigned(SliceFlag::Unbalanced))
        figures += fmt::format(
            "; energy balance {:+.4f} ± {:.4f} (reflected + transmitted + lost paths − 1{}), "
            "beyond the tolerance {}: the model's own error there",
            b.value[l], b.stdError[l], job_.material.lossless() ? "" : ", counted only above 1: the material absorbs",
            job_.scene.tolerance);
      if (f & unsigned(SliceFlag::PathsLost))
        figures += fmt::format("; {:.4f} of the paths truncated at max_depth, leaked or missed", b.pathsLost[l]);
      spdlog::warn("slice {} (theta_i {:.3g} deg, {} nm) is not physical: {}{}", slice,
                   job_.incidence[size_t(slice)].theta_deg, job_.lambda_nm[l], describeSliceFlags(f), figures);
    }
    if (badness > worstBadness_) {
      worstBadness_ = badness;
      worstSlice_ = slice;
      worstFlags_ = f;
    }
    break;
  }
}

// A tile's slice and the slices symmetry maps it to, committed together (one sync for all). A
// worker's tile comes with its slices prepared (worker >= 1: one message each, in sliceIndices'
// order, every one received even where the slice is not written); rank 0 prepares its own here,
// counted apart from writing (prepareSeconds_: a computing rank's share of the work).
void TileServer::writeResult(const TileResult& r, int worker) {
  const std::vector<int> indices = sliceIndices(r, symmetry_);
  const size_t expected = worker > 0 ? indices.size() : 0;
  size_t received = 0;
  auto nextPrepared = [&]() -> std::optional<PreparedSlice> {
    if (received >= expected) return std::nullopt;
    ++received;
    MPI_Status st = waitForMessage(worker, kTagPrepared);
    lastHeard_[size_t(worker)] = Clock::now();
    int count = 0;
    MPI_Get_count(&st, MPI_BYTE, &count);
    std::vector<unsigned char> bytes(static_cast<size_t>(count));
    MPI_Recv(bytes.data(), count, MPI_BYTE, worker, kTagPrepared, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return deserializePrepared(bytes);
  };
  auto drain = [&] {
    while (received < expected) nextPrepared();
  };
  if (!writeFailure_.empty()) return drain();
  std::vector<int> written;
  try {
    for (int m : indices) {
      auto tw = Clock::now();
      std::optional<PreparedSlice> p = nextPrepared();
      if (finished_.count(m)) continue;
      auto slice = [&] { return sliceOf(job_, r, symmetry_, m); };
      if (!p || p->index != m) {
        const auto tp = Clock::now();
        p = writer_.prepare(slice());
        prepareSeconds_ += since(tp);
        tw = Clock::now();
      }
      noteSliceChecks(m, writer_.writePrepared(*p, slice));
      written.push_back(m);
      writeSeconds_ += since(tw);
    }
    const auto tc = Clock::now();
    if (!written.empty()) writer_.commitSlices(written);
    writeSeconds_ += since(tc);
  } catch (const WriteError& e) {
    writeFailure_ = e.what();
    noteStop("the output could not be written");
    return drain();
  }
  finished_.insert(written.begin(), written.end());
  written_ += int(written.size());
  progress_.update(uint64_t(written_));
  for (Component c : job_.components.list()) {
    if (own_.tiles.pairs() && c == Component::Incoherent) continue;  // complete only after the reciprocity fill
    double e = 0;
    for (int l = 0; l < r.nLambda; ++l)
      for (int b = 0; b < r.nBins; ++b) e += r.at(c, l, b) * grid_.projectedSolidAngle(b) / r.nLambda;
    energySum_[componentName(c)] += e;
  }
}

// Handles one message from a worker (a result or a stop) and answers with its next tile (-1: none);
// returns false if none was waiting (non-blocking).
bool TileServer::serveOne(bool blocking) {
  MPI_Status st;
  int flag = 0;
  if (blocking) {
    st = waitForMessage(MPI_ANY_SOURCE, MPI_ANY_TAG);
    flag = 1;
  } else {
    MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st);
  }
  if (!flag) return false;
  lastHeard_[size_t(st.MPI_SOURCE)] = Clock::now();
  if (st.MPI_TAG == kTagAlive) {  // a heartbeat: nothing to answer
    int tile = 0;
    MPI_Recv(&tile, 1, MPI_INT, st.MPI_SOURCE, kTagAlive, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return true;
  }
  if (st.MPI_TAG == kTagResult) {
    int count = 0;
    MPI_Get_count(&st, MPI_DOUBLE, &count);
    std::vector<double> buf(static_cast<size_t>(count));
    MPI_Recv(buf.data(), count, MPI_DOUBLE, st.MPI_SOURCE, kTagResult, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    const TileResult r = TileResult::deserialize(buf);
    summary_.paths += r.samples;
    ++summary_.computed;
    writeResult(r, st.MPI_SOURCE);
  } else {
    int v = 0;
    MPI_Recv(&v, 1, MPI_INT, st.MPI_SOURCE, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    if (st.MPI_TAG == kTagStopped) {
      lostTiles_ = true;
      noteStop("a rank was stopped");
    }
  }
  const int t = takeTile(false);
  MPI_Send(&t, 1, MPI_INT, st.MPI_SOURCE, kTagAssign, MPI_COMM_WORLD);
  holdsTile_[size_t(st.MPI_SOURCE)] = t >= 0;
  if (t < 0) --activeWorkers_;
  return true;
}

TileResult TileServer::computeWhileServing(int t) {
  auto tile = std::async(std::launch::async, [this, t] { return own_.compute(t, {}); });
  while (tile.wait_for(std::chrono::seconds(0)) != std::future_status::ready) {
    if (!serveOne(false)) idle();
  }
  TileResult r = tile.get();  // a stop in the tile is thrown here
  ownTileSeconds_ += r.seconds;
  ++ownDone_;
  return r;
}

MPI_Status TileServer::waitForMessage(int source, int tag) {
  MPI_Status st;
  int flag = 0;
  while (true) {
    MPI_Iprobe(source, tag, MPI_COMM_WORLD, &flag, &st);
    if (flag) return st;
    idle();
  }
}

void TileServer::checkSilence() {
  if (options_.rankTimeoutSeconds <= 0) return;
  for (size_t w = 1; w < lastHeard_.size(); ++w)
    if (holdsTile_[w] && since(lastHeard_[w]) > options_.rankTimeoutSeconds)
      abandonSilentRank(int(w), since(lastHeard_[w]));
}

// The partial file is closed cleanly (every journaled slice stays), then the job is aborted: the
// silent rank cannot join the collectives of a clean end, and only the launcher can end it.
void TileServer::abandonSilentRank(int rank, double seconds) {
  spdlog::error(
      "rank {} sent nothing for {:.0f} s (no result and no heartbeat; --rank-timeout {}): it is stopped, frozen or cut "
      "off. {}/{} slices are safe in {}.partial (listed in its journal); run the same command with --resume "
      "(exit code {})",
      rank, seconds, options_.rankTimeoutSeconds, written_, int(job_.incidence.size()), outPath_,
      exitCode(ExitCode::RankSilent));
  try {
    writer_.close();
  } catch (const std::exception& e) {
    spdlog::error("closing {}.partial: {} (the journal lists only slices on disk)", outPath_, e.what());
  }
  spdlog::default_logger()->flush();
  MPI_Abort(MPI_COMM_WORLD, exitCode(ExitCode::RankSilent));
  std::abort();  // MPI_Abort does not return
}

void TileServer::complete(const std::optional<ReciprocalPairs>& pairs) {
  int status = writeFailure_.empty() ? kRankOk : kRankWriteFailed, worst = 0;
  MPI_Allreduce(&status, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  if (worst == kRankWriteFailed && writeFailure_.empty())
    writeFailure_ = "another rank could not write its log file (see its stderr)";
  double times[2] = {own_.pathSeconds, own_.waveSeconds}, total[2] = {0, 0};
  MPI_Reduce(times, total, 2, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  const bool incomplete = written_ < int(job_.incidence.size());
  std::optional<double> filledIncoherent;  // mean over all slices, after the reciprocity fill
  try {
    if (!incomplete && writeFailure_.empty() && pairs) {
      auto tf = Clock::now();
      filledIncoherent = writer_.completeReciprocal(*pairs);
      spdlog::info("reciprocity: filled the mirrored half of {} slices in {:.2f} s", int(job_.incidence.size()),
                   since(tf));
    }
  } catch (const WriteError& e) {
    writeFailure_ = e.what();
  }
  {
    std::string energies;
    for (auto& [c, e] : energySum_)
      energies += fmt::format("{}{} {:.4f}", energies.empty() ? "" : ", ", c, e / std::max(1, summary_.computed));
    if (filledIncoherent)
      energies += fmt::format(", incoherent {:.4f} (all slices, after the fill)", *filledIncoherent);
    spdlog::info(
        "summary: {} tiles computed now, {} slices resumed; {:.1f} s wall, of which rank 0 wrote slices for "
        "{:.2f} s ({:.0f} %) and prepared those of its own tiles (statistics, compression) for {:.2f} s; tile time "
        "summed over ranks: path tracing {:.1f} s, scalar diffraction {:.1f} s; {} paths; mean energy per slice: {}",
        summary_.computed, summary_.resumed, since(t0_), writeSeconds_, 100.0 * writeSeconds_ / since(t0_),
        prepareSeconds_, total[0], total[1], summary_.paths, energies);
  }
  if (const std::optional<std::string> caveat = job_.waveErrorsCaveat()) spdlog::warn("{}", *caveat);
  if (const std::optional<std::string> caveat = scalarModelCaveat(job_)) spdlog::warn("{}", *caveat);
  if (options_.outputFolderCaveat) spdlog::warn("{}", *options_.outputFolderCaveat);
  if (nonphysical_)
    spdlog::warn(
        "{} slice(s) computed now are not physical (the worst: slice {}, {}); `microbsdf info` lists them, "
        "/stats/nonphysical flags them",
        nonphysical_, worstSlice_, describeSliceFlags(worstFlags_));
  // Finish (close, fsync, rename) or close; a failure of either is a write failure, which leaves the
  // partial file and its journal (every slice in the journal is on disk) and any old output as they were.
  try {
    if (writeFailure_.empty() && !incomplete) {
      if (job_.storage.pairs == TablePairs::Once) spdlog::info("storing each same-side pair of incidence bins once");
      const auto tf = std::chrono::steady_clock::now();
      writer_.finish();
      if (job_.storage.pairs == TablePairs::Once) spdlog::info("pairs folded in {:.2f} s", since(tf));
      // The two estimates of every pair, compared: reciprocity holds within their errors when the
      // mean z² is about 1 (docs/output.md "Pairs stored once").
      for (const auto& [component, check] : writer_.pairsReport().items()) {
        const uint64_t tested = check["tested_pairs"].get<uint64_t>();
        spdlog::info("pairs of {}: {} stored once (relative L1 difference of the two estimates {:.4f}); {}", component,
                     check["pairs"].get<uint64_t>(), check["relative_l1_difference"].get<double>(),
                     tested ? fmt::format("reciprocity check over {} pairs of independent estimates: mean z² {:.3f}, "
                                          "max |z| {:.2f}",
                                          tested, check["mean_z2"].get<double>(), check["max_abs_z"].get<double>())
                            : std::string("no per-bin errors kept (storage profile): no z-scores"));
      }
    } else {
      writer_.close();
    }
  } catch (const WriteError& e) {
    if (writeFailure_.empty()) writeFailure_ = e.what();
  }
  if (!writeFailure_.empty() && writer_.outputInPlace()) {
    summary_.exit = ExitCode::WriteFailed;
    summary_.error = fmt::format(
        "{}. {} is complete and in place (every slice; the partial file and journal are gone), but the sync of its "
        "folder failed: after a crash or power loss the folder may still show the file as it was. Check the file "
        "system; `microbsdf info {}` shows the table",
        writeFailure_, outPath_, outPath_);
  } else if (!writeFailure_.empty()) {
    summary_.exit = ExitCode::WriteFailed;
    summary_.error = fmt::format(
        "{}. {}/{} slices are safe in {}.partial (listed in its journal); free space or fix the "
        "file system, then run the same command with --resume. {} was not changed",
        writeFailure_, written_, int(job_.incidence.size()), outPath_, outPath_);
  } else if (incomplete) {
    summary_.stoppedEarly = true;
    spdlog::warn("stopped early: {}/{} slices complete in {}.partial{}; run the same command with --resume to finish",
                 written_, int(job_.incidence.size()), outPath_, lostTiles_ ? " (tiles in flight were abandoned)" : "");
  }
}

}  // namespace

RunSetup::RunSetup(const Job& job, const PilotResults& pilots, Clock::time_point started)
    : grid(job.gridLayout), tiles(job, grid, pilots), seconds(since(started)) {}

RunSummary runJob(const Job& job, const MpiSession& mpi, const RunOptions& options) {
  const auto t0 = Clock::now();
  std::optional<tbb::global_control> threads;
  if (options.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, size_t(options.threads));

  const std::string outPath = options.outputPath.empty() ? job.outputPath : options.outputPath;
  std::shared_ptr<const RunSetup> setup = options.setup;
  if (!setup) setup = std::make_shared<const RunSetup>(job, options.pilots);
  const DirectionGrid& grid = setup->grid;
  // What a tile is (job/tile_computer.h); this file only hands tiles out and writes them.
  const TileComputer& tiles = setup->tiles;
  if (std::string shortfall = memoryShortfall(job, tiles.wave()); mpi.anyRank(!shortfall.empty())) {
    RunSummary refused;
    refused.exit = ExitCode::BadInput;
    refused.error = shortfall.empty() ? "another rank's node has too little memory for the job" : shortfall;
    return refused;
  }
  spdlog::debug("start-up: the tile computer (scenes, facet tables, wave estimator) {:.3f} s{}", setup->seconds,
                options.setupDuringMpiStart ? ", while MPI started" : "");
  if (mpi.rank() == 0) logJobHeader(job, grid, tiles, mpi.size());

  TimedTiles own{job, tiles};
  RunSummary summary;
  summary.tiles = int(job.incidence.size());
  if (mpi.rank() != 0) {
    std::optional<AzimuthalSymmetry> symmetry;
    if (job.symmetryReduced()) symmetry.emplace(job, grid);
    const OutputSchema schema = outputSchemaOf(job);
    serveAsWorker([&](int t) { return own.compute(t, {}); },
                  [&](const TileResult& r) { return prepareSlices(job, r, symmetry, schema, grid); },
                  heartbeatSecondsFor(options.rankTimeoutSeconds), summary);
    double times[2] = {own.pathSeconds, own.waveSeconds};
    MPI_Reduce(times, nullptr, 2, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    int outcome = 0;  // rank 0's ExitCode, once it has finished or closed the file
    MPI_Bcast(&outcome, 1, MPI_INT, 0, MPI_COMM_WORLD);
    summary.stoppedEarly = outcome == exitCode(ExitCode::Stopped);
    if (outcome != exitCode(ExitCode::Stopped)) summary.exit = ExitCode(outcome);
    summary.seconds = since(t0);
    return summary;
  }

  // Rank 0. The writer is created before any tile is handed out; if it cannot be (a resume that
  // does not match, an unwritable file), the workers are told there is nothing to do and every rank
  // returns the same error.
  std::unique_ptr<BsdfFileWriter> writer;
  if (options.resume && !std::filesystem::exists(outPath + ".partial") &&
      isFinishedOutputOf(outPath, outputSchemaOf(job))) {
    spdlog::info(
        "{} is already a finished table of this job (the same job text, input files and geometry, every "
        "slice done): nothing to resume",
        outPath);
    summary.resumed = summary.tiles;
    summary.alreadyFinished = true;
    refuseWorkers(mpi, ExitCode::Ok);
    return summary;
  }
  try {
    checkDiskSpace(outPath, job, grid);
    writer = std::make_unique<BsdfFileWriter>(outPath, outputSchemaOf(job), grid, options.resume);
  } catch (const InputError& e) {
    summary.exit = ExitCode::BadInput, summary.error = e.what();
  } catch (const WriteError& e) {
    summary.exit = ExitCode::WriteFailed, summary.error = e.what();
  }
  if (!writer) {
    refuseWorkers(mpi, summary.exit);
    return summary;
  }
  spdlog::debug("start-up: the output file ready {:.3f} s after the run began", since(t0));
  TileServer server(job, grid, mpi, options, outPath, *writer, own, summary, t0);
  server.run();
  server.complete(tiles.pairs());
  int outcome = exitCode(summary.exit == ExitCode::Ok && summary.stoppedEarly ? ExitCode::Stopped : summary.exit);
  MPI_Bcast(&outcome, 1, MPI_INT, 0, MPI_COMM_WORLD);
  summary.seconds = since(t0);
  return summary;
}

}  // namespace mbsdf
