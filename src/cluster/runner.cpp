#include "cluster/runner.h"

#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <numeric>
#include <optional>
#include <set>

#include "cluster/output_schema_of.h"
#include "core/log.h"
#include "core/stop.h"
#include "geometry/embree_scene.h"
#include "io/bsdf_file.h"
#include "io/output_target.h"
#include "job/effects_planner.h"
#include "job/plan.h"
#include "job/symmetry.h"
#include "job/tile_computer.h"
#include "job/transport.h"
#include "scattering/reciprocity.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
namespace {

constexpr int kTagRequest = 11, kTagResult = 12, kTagStopped = 13, kTagAssign = 21;

// How a rank ends; the maximum over the ranks is the run's.
enum RankStatus : int { kRankOk = 0, kRankWriteFailed = 1 };

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
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

// A worker rank: asks rank 0 for tiles until told there are none (or a stop abandons one), sends
// each result back, then joins the ranks' agreement on how the run ended (RankStatus).
void serveAsWorker(const std::function<TileResult(int)>& computeTile, RunSummary& summary) {
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
      TileResult r = computeTile(t);
      std::vector<double> buf = r.serialize();
      MPI_Send(buf.data(), int(buf.size()), MPI_DOUBLE, 0, kTagResult, MPI_COMM_WORLD);
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

}  // namespace

RunSummary runJob(const Job& job, const MpiSession& mpi, const RunOptions& options) {
  const auto t0 = Clock::now();
  std::optional<tbb::global_control> threads;
  if (options.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, size_t(options.threads));

  const std::string outPath = options.outputPath.empty() ? job.outputPath : options.outputPath;
  DirectionGrid grid(job.gridLayout);
  // What a tile is (job/tile_computer.h); this file only hands tiles out and writes them.
  const TileComputer tiles(job, grid);
  const GeometricTransport& transport = tiles.transport();
  const WaveEstimator* wave = tiles.wave();
  if (wave && mpi.rank() == 0) {
    const std::string notes = wave->notes();
    spdlog::info("scalar diffraction: {} estimator, {}, coherence length {} µm{}", wave->name(),
                 notes.empty() ? std::to_string(job.waveSamplesPerBin) + " samples per bin" : notes,
                 job.scene.coherenceLength_um,
                 job.scene.coherenceLength_um > 0 ? "" : " (no window: one copy of the patch)");
  }

  if (std::string shortfall = memoryShortfall(job, wave); mpi.anyRank(!shortfall.empty())) {
    RunSummary refused;
    refused.exit = ExitCode::BadInput;
    refused.error = shortfall.empty() ? "another rank's node has too little memory for the job" : shortfall;
    return refused;
  }

  const int nTiles = int(job.incidence.size());
  // Reciprocity (docs/physics.md §8): each pair of incidence bins gets the wave term once.
  const std::optional<ReciprocalPairs>& pairs = tiles.pairs();
  if (wave && mpi.rank() == 0)
    spdlog::info("reciprocity: {}", pairs ? fmt::format("the wave term is computed for {:.1f}% of the same-side bin "
                                                        "pairs, the rest mirrored when every slice is done",
                                                        100 * pairs->computedFraction())
                                          : "not used (" + job.reciprocityOffReason() + ")");
  if (mpi.rank() == 0)
    spdlog::info("job {}: {} ({}), {}, {} wavelengths, grid {} ({} bins), {} slices on {} ranks, {} paths per slice",
                 job.file, job.geometryKind,
                 job.statistical ? transport.describe()
                                 : fmt::format("{} triangles, {:.3g} x {:.3g} µm{}, {}", job.geometry.triangles.size(),
                                               job.geometry.sizeX, job.geometry.sizeY,
                                               job.geometry.periodic ? ", periodic" : "", job.closure.describe()),
                 job.material.describe(), job.lambda_nm.size(), grid.kind(), grid.binCount(), nTiles, mpi.size(),
                 job.pathsPerSlice);

  if (mpi.rank() == 0 && transport.mayUseFacetSum()) spdlog::info("geometric optics: {}", transport.describe());

  // One tile: path tracing, then the wave estimator; the callback may abandon it (stop).
  double tileSecondsSum = 0, pathSecondsSum = 0, waveSecondsSum = 0;
  int tilesDone = 0;
  auto computeTile = [&](int t, const std::function<void()>& between) {
    ProgressReporter pathProgress("tile " + std::to_string(t), job.pathsPerSlice, 30.0, false);
    auto cb = [&](uint64_t done) {
      pathProgress.update(done);
      throwIfStopped();
      if (between) between();
    };
    double pathSeconds = 0, waveSeconds = 0;
    TileResult r = tiles.compute(t, cb, &pathSeconds, &waveSeconds);
    pathSecondsSum += pathSeconds;
    waveSecondsSum += waveSeconds;
    tileSecondsSum += r.seconds;
    ++tilesDone;
    return r;
  };

  RunSummary summary;
  summary.tiles = nTiles;

  if (mpi.rank() != 0) {
    serveAsWorker([&](int t) { return computeTile(t, {}); }, summary);
    double times[2] = {pathSecondsSum, waveSecondsSum};
    MPI_Reduce(times, nullptr, 2, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    int outcome = 0;  // rank 0's ExitCode, once it has finished or closed the file
    MPI_Bcast(&outcome, 1, MPI_INT, 0, MPI_COMM_WORLD);
    summary.stoppedEarly = outcome == exitCode(ExitCode::Stopped);
    if (outcome != exitCode(ExitCode::Stopped)) summary.exit = ExitCode(outcome);
    summary.seconds = since(t0);
    return summary;
  }

  // Rank 0: writer, queue, serving the workers between its own batches. The writer is created
  // before any tile is handed out; if it cannot be (a resume that does not match, an unwritable
  // file), the workers are told there is nothing to do and every rank returns the same error.
  std::unique_ptr<BsdfFileWriter> writerPtr;
  {
    ExitCode setupExit = ExitCode::Ok;
    try {
      checkDiskSpace(outPath, job, grid);
      writerPtr = std::make_unique<BsdfFileWriter>(outPath, outputSchemaOf(job), grid, options.resume);
    } catch (const InputError& e) {
      setupExit = ExitCode::BadInput, summary.error = e.what();
    } catch (const WriteError& e) {
      setupExit = ExitCode::WriteFailed, summary.error = e.what();
    }
    if (setupExit != ExitCode::Ok) {
      // Every worker has asked for a tile: answer each with "none", then end like a stopped run.
      for (int w = 1; w < mpi.size(); ++w) {
        int request = 0, none = -1;
        MPI_Status st;
        MPI_Recv(&request, 1, MPI_INT, MPI_ANY_SOURCE, kTagRequest, MPI_COMM_WORLD, &st);
        MPI_Send(&none, 1, MPI_INT, st.MPI_SOURCE, kTagAssign, MPI_COMM_WORLD);
      }
      int status = kRankOk, worst = 0, outcome = exitCode(setupExit);
      MPI_Allreduce(&status, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
      double times[2] = {0, 0}, total[2];
      MPI_Reduce(times, total, 2, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
      MPI_Bcast(&outcome, 1, MPI_INT, 0, MPI_COMM_WORLD);
      summary.exit = setupExit;
      return summary;
    }
  }
  BsdfFileWriter& writer = *writerPtr;
  std::set<int> finished(writer.resumedTiles().begin(), writer.resumedTiles().end());
  summary.resumed = int(finished.size());
  if (summary.resumed)
    spdlog::info("resuming: {} of {} slices already complete in {}.partial", summary.resumed, nTiles, outPath);
  // Symmetry (symmetry.h): one tile per ring (or per n-th of a ring) of a symmetric surface; queued if any slice of its
  // ring is missing (a kill may fall between a ring's slices).
  std::optional<AzimuthalSymmetry> symmetry;
  if (job.symmetryReduced()) symmetry.emplace(job, grid);
  std::vector<int> queue;
  for (int t = 0; t < nTiles; ++t) {
    if (symmetry && symmetry->representative(t) != t) continue;
    bool missing = !finished.count(t);
    if (symmetry)
      for (int m : symmetry->members(t)) missing = missing || !finished.count(m);
    if (missing) queue.push_back(t);
  }
  if (symmetry)
    spdlog::info("symmetry: {}; {} tiles for {} slices", job.symmetryReason, symmetry->representativeCount(), nTiles);
  // Most expensive first: grazing incidence bounces and wraps more.
  auto cost = [&](int t) { return 1.0 / (std::abs(std::cos(radians(job.incidence[size_t(t)].theta_deg))) + 0.05); };
  std::stable_sort(queue.begin(), queue.end(), [&](int a, int b) { return cost(a) > cost(b); });
  size_t next = 0;
  bool stopAssigning = false;
  ProgressReporter progress("slices written", uint64_t(nTiles));  // symmetry copies count: a tile may write several
  int written = int(finished.size());
  // The energy balance of each slice (BsdfFileWriter::writeEnergyBalance): beyond [scene] tolerance
  // and its standard error it is the model's error (scalar theory on deep or steep structures), and
  // the log says so; `info` shows it for every slice.
  int unbalanced = 0;
  double worstBalance = 0;
  auto noteEnergyBalance = [&](const TileResult& r, const BsdfFileWriter::EnergyBalance& b) {
    for (size_t l = 0; l < b.value.size(); ++l) {
      if (!(std::abs(b.value[l]) > job.scene.tolerance + 4 * b.stdError[l])) continue;
      if (unbalanced++ < 10)
        spdlog::warn(
            "slice {} (theta_i {:.3g} deg, {} nm): energy balance {:+.4f} ± {:.4f} (reflected + transmitted + "
            "lost paths − 1{}), beyond the tolerance {}: the model's own error there",
            r.incidenceIndex, job.incidence[size_t(r.incidenceIndex)].theta_deg, job.lambda_nm[l], b.value[l],
            b.stdError[l], job.material.lossless() ? "" : ", counted only above 1: the material absorbs",
            job.scene.tolerance);
      if (std::abs(b.value[l]) > std::abs(worstBalance)) worstBalance = b.value[l];
      break;
    }
  };
  // A failed write stops the run: no more tiles are handed out and results still in flight are
  // dropped (the journal lists only slices whose data reached the disk).
  std::string writeFailure;
  auto noteStop = [&](const char* why) {
    if (!stopAssigning) spdlog::warn("{}: stopping cleanly after the tiles in flight", why);
    stopAssigning = true;
  };
  // --max-hours: stop when the next tile would not finish in time (with a 1.5x margin).
  auto outOfTime = [&]() {
    if (options.maxHours <= 0) return false;
    double mean = tilesDone ? tileSecondsSum / tilesDone : 0.0;
    return since(t0) + 1.5 * mean > options.maxHours * 3600.0;
  };
  auto takeTile = [&]() -> int {
    if (stopRequested()) noteStop("signal received");
    if (writeFailure.empty() && !logWriteFailure().empty()) {
      writeFailure = "log write failed: " + logWriteFailure();
      noteStop("the log could not be written");
    }
    if (!stopAssigning && outOfTime()) noteStop("--max-hours reached");
    if (stopAssigning || next >= queue.size()) return -1;
    return queue[next++];
  };
  // Mean over the slices written now of each component's Σ f Ω⊥ (averaged over wavelengths).
  std::map<std::string, double> energySum;
  auto writeOne = [&](const TileResult& r) {
    if (finished.count(r.incidenceIndex) || !writeFailure.empty()) return;
    try {
      noteEnergyBalance(r, writer.writeTile(r));
    } catch (const WriteError& e) {
      writeFailure = e.what();
      noteStop("the output could not be written");
      return;
    }
    finished.insert(r.incidenceIndex);
    ++written;
    progress.update(uint64_t(written));
  };
  auto writeResult = [&](const TileResult& r) {
    writeOne(r);
    if (symmetry)
      for (int m : symmetry->members(r.incidenceIndex))
        if (m != r.incidenceIndex) writeOne(symmetry->mappedSlice(r, m, job.incidence[size_t(m)].bin));
    for (Component c : job.components.list()) {
      if (pairs && c == Component::Incoherent) continue;  // complete only after the reciprocity fill
      double e = 0;
      for (int l = 0; l < r.nLambda; ++l)
        for (int b = 0; b < r.nBins; ++b) e += r.at(c, l, b) * grid.projectedSolidAngle(b) / r.nLambda;
      energySum[componentName(c)] += e;
    }
  };
  int activeWorkers = mpi.size() - 1;
  bool lostTiles = false;
  // Handles one message from a worker; returns false if none was waiting (non-blocking).
  auto serveOne = [&](bool blocking) {
    MPI_Status st;
    int flag = 0;
    if (blocking) {
      MPI_Probe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &st);
      flag = 1;
    } else {
      MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st);
    }
    if (!flag) return false;
    if (st.MPI_TAG == kTagResult) {
      int count = 0;
      MPI_Get_count(&st, MPI_DOUBLE, &count);
      std::vector<double> buf(static_cast<size_t>(count));
      MPI_Recv(buf.data(), count, MPI_DOUBLE, st.MPI_SOURCE, kTagResult, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      TileResult r = TileResult::deserialize(buf);
      summary.paths += r.samples;
      ++summary.computed;
      writeResult(r);
    } else {
      int v = 0;
      MPI_Recv(&v, 1, MPI_INT, st.MPI_SOURCE, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      if (st.MPI_TAG == kTagStopped) {
        lostTiles = true;
        noteStop("a rank was stopped");
      }
    }
    int t = takeTile();
    MPI_Send(&t, 1, MPI_INT, st.MPI_SOURCE, kTagAssign, MPI_COMM_WORLD);
    if (t < 0) --activeWorkers;
    return true;
  };
  auto serveAll = [&]() {
    while (serveOne(false)) {
    }
  };

  while (true) {
    serveAll();
    int t = takeTile();
    if (t < 0) break;
    try {
      TileResult r = computeTile(t, serveAll);
      summary.paths += r.samples;
      ++summary.computed;
      writeResult(r);
    } catch (const StopRequested&) {
      spdlog::info("stop requested: tile {} abandoned ({})", t, stopAnswerNote());
      lostTiles = true;
      noteStop("signal received");
    }
  }
  while (activeWorkers > 0) serveOne(true);

  int status = writeFailure.empty() ? kRankOk : kRankWriteFailed, worst = 0;
  MPI_Allreduce(&status, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  if (worst == kRankWriteFailed && writeFailure.empty())
    writeFailure = "another rank could not write its log file (see its stderr)";
  double times[2] = {pathSecondsSum, waveSecondsSum}, total[2] = {0, 0};
  MPI_Reduce(times, total, 2, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  const bool incomplete = written < nTiles;
  std::optional<double> filledIncoherent;  // mean over all slices, after the reciprocity fill
  try {
    if (!incomplete && writeFailure.empty() && pairs) {
      auto tf = Clock::now();
      filledIncoherent = writer.completeReciprocal(*pairs);
      spdlog::info("reciprocity: filled the mirrored half of {} slices in {:.2f} s", nTiles, since(tf));
    }
  } catch (const WriteError& e) {
    writeFailure = e.what();
  }
  {
    std::string energies;
    for (auto& [c, e] : energySum)
      energies += fmt::format("{}{} {:.4f}", energies.empty() ? "" : ", ", c, e / std::max(1, summary.computed));
    if (filledIncoherent)
      energies += fmt::format(", incoherent {:.4f} (all slices, after the fill)", *filledIncoherent);
    spdlog::info(
        "summary: {} tiles computed now, {} slices resumed; {:.1f} s wall; tile time summed over ranks: "
        "path tracing {:.1f} s, scalar diffraction {:.1f} s; {} paths; mean energy per slice: {}",
        summary.computed, summary.resumed, since(t0), total[0], total[1], summary.paths, energies);
  }
  if (unbalanced)
    spdlog::warn(
        "energy balance beyond the tolerance {} in {} slice(s) computed now (the worst {:+.4f}); `microbsdf info` "
        "lists it per slice",
        job.scene.tolerance, unbalanced, worstBalance);
  // Finish (close, fsync, rename) or close; a failure of either is a write failure, which leaves the
  // partial file and its journal (every slice in the journal is on disk) and any old output as they were.
  try {
    if (writeFailure.empty() && !incomplete)
      writer.finish();
    else
      writer.close();
  } catch (const WriteError& e) {
    if (writeFailure.empty()) writeFailure = e.what();
  }
  if (!writeFailure.empty()) {
    summary.exit = ExitCode::WriteFailed;
    summary.error = fmt::format(
        "{}. {}/{} slices are safe in {}.partial (listed in its journal); free space or fix the "
        "file system, then run the same command with --resume. {} was not changed",
        writeFailure, written, nTiles, outPath, outPath);
  } else if (incomplete) {
    summary.stoppedEarly = true;
    spdlog::warn("stopped early: {}/{} slices complete in {}.partial{}; run the same command with --resume to finish",
                 written, nTiles, outPath, lostTiles ? " (tiles in flight were abandoned)" : "");
  }
  int outcome = exitCode(summary.exit == ExitCode::Ok && summary.stoppedEarly ? ExitCode::Stopped : summary.exit);
  MPI_Bcast(&outcome, 1, MPI_INT, 0, MPI_COMM_WORLD);
  summary.seconds = since(t0);
  return summary;
}

}  // namespace mbsdf
