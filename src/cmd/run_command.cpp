// `microbsdf run JOB.toml [-o OUT.h5] [--threads N] [--log-dir DIR] [--resume] [--max-hours H]
// [--rank-timeout S] [-v]`, under mpirun or srun for several ranks: every rank loads the job (while
// MPI starts, when it can: EarlyStart); rank 0 checks the output location and takes its lock before
// any tile, runs the effects planner's pilots, then all ranks run the tiles (cluster/runner.h).
// Foreseeable failures end every rank with the same exit code and one message; only an unexpected
// one aborts the job.
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <thread>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>
#include <toml++/toml.h>

#include "cluster/mpi_session.h"
#include "cluster/runner.h"
#include "cluster/shared_output.h"
#include "cmd/allocator.h"
#include "cmd/command.h"
#include "core/error.h"
#include "core/log.h"
#include "core/stop.h"
#include "io/output_target.h"
#include "job/effects_planner.h"
#include "job/job.h"
#include "job/scalar_validity.h"

namespace mbsdf {
namespace {

struct RunArgs {
  std::string jobPath, outPath, logDir;
  int threads = 0;
  bool resume = false, verbose = false;
  double maxHours = 0;
  double rankTimeout = 120;
};

// A step's outcome on rank 0 ("" to go on, else "<exit code> <message>") made every rank's: the
// exit code to end with (rank 0 logs the message once), or none to go on.
std::optional<int> agreeOnRankZero(MpiSession& mpi, const std::string& outcome) {
  const std::string f = mpi.broadcast(outcome);
  if (f.empty()) return std::nullopt;
  if (mpi.rank() == 0) spdlog::error("{}", f.substr(f.find(' ') + 1));
  return std::stoi(f.substr(0, f.find(' ')));
}

std::string failure(ExitCode c, const std::string& msg) {
  return std::to_string(exitCode(c)) + " " + msg;
}

// components = "auto": rank 0 runs the effects planner's pilots, every rank applies the same plan;
// rank 0 keeps what the pilots computed in *kept. Returns the exit code when a stop arrived during
// the pilots.
std::optional<int> planComponents(MpiSession& mpi, Job& job, PilotResults* kept) {
  std::string planText, stopped;
  if (mpi.rank() == 0) {
    try {
      const EffectsPlan p = planEffects(job, {}, kept);
      for (std::istringstream lines(formatEffects(p)); std::getline(lines, planText);) spdlog::info("{}", planText);
      planText = p.toJson().dump();
    } catch (const StopRequested&) {
      stopped = failure(ExitCode::Stopped, "stop requested during the effects planner's pilots (" + stopAnswerNote() +
                                               "); nothing was written (run the same command again to start over)");
    }
  }
  if (auto code = agreeOnRankZero(mpi, stopped)) return code;
  applyEffectsPlan(job, EffectsPlan::fromJson(nlohmann::json::parse(mpi.broadcast(planText))));
  return std::nullopt;
}

// Reads the job: the job, or why it could not be read.
void readJob(const std::string& jobPath, std::optional<Job>& job, std::string& error) {
  try {
    job = loadJob(jobPath);
  } catch (const InputError& e) {
    error = e.what();
  } catch (const std::exception& e) {
    error = jobPath + ": " + e.what();
  }
}

// Whether the job's geometry is made from its parameters, not read from a file. The libraries that
// read files (libzip's dates, OpenSSL's configuration, OpenEXR, HDF5) read environment variables,
// which MPI_Init sets meanwhile: glibc's getenv and setenv are not safe together.
bool geometryFromParameters(const std::string& jobPath) {
  try {
    const toml::table t = toml::parse_file(jobPath);
    const std::optional<std::string> kind = t["geometry"]["kind"].value<std::string>();
    return kind && *kind != "mesh" && *kind != "heightfield";
  } catch (const std::exception&) {
    return false;  // read after MPI has started, which reports what is wrong with it
  }
}

// What a rank does while its main thread starts MPI (0.25 s for one process here, as long as a
// small job's tiles), on a thread of its own: read the job when its geometry is made from
// parameters, and, when no effects pilots are to decide its components and MPI is still starting,
// build its tile computer and the first tile's buffers. Nothing here talks to MPI or reads the
// environment; its log lines wait in a DeferredLog until the rank's logging is set up, and it
// allocates from the main thread's arena (cmd/allocator.h useArena).
struct EarlyStart {
  bool read = false;  // whether the job was read here (else the main thread reads it)
  std::optional<Job> job;
  std::string error;  // why the job could not be read
  std::shared_ptr<const RunSetup> setup;
  std::exception_ptr setupError;  // rethrown where runJob would have thrown it
  double jobSeconds = 0;
  std::atomic<bool> mpiStarted{false};

  // Runs in `arena` (initialized by the main thread: see runCommand).
  void run(const std::string& jobPath, tbb::task_arena& arena) {
    arena.execute([&] { prepare(jobPath); });
  }

 private:
  void prepare(const std::string& jobPath) {
    if (!geometryFromParameters(jobPath)) return;
    const auto t0 = std::chrono::steady_clock::now();
    readJob(jobPath, job, error);
    read = true;
    jobSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // Once MPI has started, the rest is left to runJob, on all of the rank's cores.
    if (!job || job->autoComponents || mpiStarted) return;
    try {
      auto s = std::make_shared<RunSetup>(*job, PilotResults{});
      if (!mpiStarted) s->tiles.reserveBuffers();
      setup = std::move(s);
    } catch (...) {
      setupError = std::current_exception();
    }
  }
};

int runCommand(int argc, char** argv, RunArgs a) {
  // The whole run as this process sees it (MPI start-up, the job's geometry, the effects pilots,
  // the tiles, the file): what `plan`'s wall-time estimate predicts (scripts/bench-plan).
  const auto started = std::chrono::steady_clock::now();
  // Where a small job's start-up goes (logged at debug level once the pilots are done): seconds
  // since the program started at each step.
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(); };
  // --threads holds for the whole command: the job's geometry, the pilots, the tiles.
  std::optional<tbb::global_control> threads;
  if (a.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, size_t(a.threads));
  // The preparing thread works in an arena made here, before MPI starts, for two reasons. TBB
  // counts the cores it may use once, from the process's CPU mask, when first asked: asked on the
  // preparing thread, it could read the mask while MPI's hardware discovery has pinned this thread
  // to one core after another, and run the whole job on one core. And TBB reads its environment
  // variables when it starts, which must not overlap MPI_Init setting its own (glibc's getenv and
  // setenv are not safe together). The arena leaves one core to MPI's start: parallel work whose
  // threads share the cores with it waits on them (the quickstart's tile computer took 8 times
  // longer).
  const int cores = tbb::this_task_arena::max_concurrency();
  tbb::task_arena preparingArena(std::max(1, (a.threads > 0 ? std::min(a.threads, cores) : cores) - 1));
  preparingArena.initialize();
  DeferredLog early;
  EarlyStart pre;
  std::jthread preparing([&, arena = currentArena()] {
    useArena(arena);
    pre.run(a.jobPath, preparingArena);
  });
  MpiSession mpi(&argc, &argv);
  pre.mpiStarted = true;
  const double mpiReady = elapsed();
  installStopHandlers();
  preparing.join();
  setupLogging(mpi.rank(), "", "", a.verbose);
  early.replay();
  auto agree = [&](const std::string& outcome) { return agreeOnRankZero(mpi, outcome); };
  if (!pre.read) {
    const double t0 = elapsed();
    readJob(a.jobPath, pre.job, pre.error);
    pre.jobSeconds = elapsed() - t0;
  }
  std::optional<Job>& job = pre.job;
  std::string error = pre.error;
  // Fail together: every rank exits non-zero, one message from rank 0, no hang.
  if (mpi.anyRank(!error.empty())) {
    if (mpi.rank() == 0) spdlog::error("{}", error.empty() ? "another rank could not read the job" : error);
    return exitCode(ExitCode::BadInput);
  }
  const double jobReady = elapsed();
  const std::string out = a.outPath.empty() ? job->outputPath : a.outPath;
  if (a.logDir.empty()) a.logDir = out + ".logs";
  // The output location, before any compute: a folder, an unwritable place or a busy output fail
  // in a second instead of after the allocation is spent.
  std::optional<OutputLock> lock;
  std::string setup;
  if (mpi.rank() == 0) {
    try {
      checkOutputPath(out);
      checkWritableFolder(a.logDir, "log");
      lock.emplace(out);
    } catch (const InputError& e) {
      setup = failure(ExitCode::BadInput, e.what());
    } catch (const OutputBusyError& e) {
      setup = failure(ExitCode::OutputBusy, e.what());
    } catch (const WriteError& e) {
      setup = failure(ExitCode::WriteFailed, e.what());
    }
  }
  if (auto code = agree(setup)) return *code;
  try {
    setupLogging(mpi.rank(), a.logDir, std::filesystem::path(out).stem().string(), a.verbose);
  } catch (const InputError& e) {
    error = e.what();
  }
  if (mpi.anyRank(!error.empty())) {
    if (!error.empty()) std::cerr << "error: " << error << "\n";
    return exitCode(ExitCode::BadInput);
  }
  if (lock && !lock->previousHolder().empty())
    spdlog::info("output lock {}: the run that held it ({}) is gone; taken over", lock->path(), lock->previousHolder());
  const std::optional<std::string> folderCaveat =
      outputFolderCaveat(mpi, lock ? lock->path() : std::string(), lock ? lock->record() : std::string());
  if (folderCaveat) spdlog::warn("{}", *folderCaveat);
  if (mpi.rank() == 0) {
    const ScalarValidity validity = scalarValidity(*job);
    if (validity.applies) {
      if (validity.beyondTolerance)
        spdlog::warn("scalar model: {}", validity.note);
      else
        spdlog::info("scalar model: {}", validity.note);
    }
  }
  try {
    RunOptions opt;
    const double outputChecked = elapsed();
    if (job->autoComponents)
      if (auto code = planComponents(mpi, *job, &opt.pilots)) return *code;
    const double planned = elapsed();
    spdlog::debug(
        "start-up: MPI {:.3f} s; job file and geometry {:.3f} s{}{}; {:.3f} s after MPI to the job; output checks and "
        "log files {:.3f} s, effects pilots {:.3f} s ({:.3f} s since the program started); memory allocator {}",
        mpiReady, pre.jobSeconds, pre.read ? " while MPI started" : "",
        pre.setup ? fmt::format(", the tile computer {:.3f} s while MPI started", pre.setup->seconds) : "",
        jobReady - mpiReady, outputChecked - jobReady, planned - outputChecked, planned, allocatorNote());
    opt.outputPath = out;
    opt.outputFolderCaveat = folderCaveat;
    opt.threads = a.threads;
    opt.resume = a.resume;
    opt.maxHours = a.maxHours;
    opt.rankTimeoutSeconds = a.rankTimeout;
    if (pre.setupError) std::rethrow_exception(pre.setupError);
    opt.setup = pre.setup;
    opt.setupDuringMpiStart = pre.setup != nullptr;
    RunSummary s = runJob(*job, mpi, opt);
    if (s.exit != ExitCode::Ok) {
      if (mpi.rank() == 0) spdlog::error("{}", s.error.empty() ? "run failed" : s.error);
      return exitCode(s.exit);
    }
    if (s.stoppedEarly) return exitCode(ExitCode::Stopped);
    if (s.alreadyFinished) return exitCode(ExitCode::Ok);
    if (mpi.rank() == 0)
      spdlog::info(
          "done: {} slices ({} tiles computed now, {} slices resumed), {} paths in total, {:.2f} s, wrote {} "
          "({:.2f} s since the program started)",
          s.tiles, s.computed, s.resumed, s.paths, s.seconds, out,
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
  } catch (const std::bad_alloc&) {
    spdlog::error("run failed: out of memory (see `microbsdf plan` for the job's estimate per rank)");
    MPI_Abort(MPI_COMM_WORLD, exitCode(ExitCode::Failure));
    return exitCode(ExitCode::Failure);
  } catch (const std::exception& e) {
    spdlog::error("run failed: {}", e.what());
    MPI_Abort(MPI_COMM_WORLD, exitCode(ExitCode::Failure));
    return exitCode(ExitCode::Failure);
  }
  return exitCode(ExitCode::Ok);
}

}  // namespace

Command addRunCommand(CLI::App& app, int argc, char** argv) {
  auto o = std::make_shared<RunArgs>();
  Command c;
  c.app = app.add_subcommand("run", "compute the BSDF of a job (run it under mpirun/srun for several ranks)");
  c.app->add_option("job", o->jobPath, "job file (TOML)")->required();
  c.app->add_option("-o,--output", o->outPath, "output HDF5 file (default: [output] path of the job)");
  addThreadsOption(c.app, o->threads, "threads per rank (default: all cores)");
  c.app->add_option("--log-dir", o->logDir, "folder for the per-rank log files (default: <output>.logs)");
  c.app->add_flag("-v,--verbose", o->verbose, "debug-level logging");
  c.app->add_flag("--resume", o->resume,
                  "keep the finished slices of an interrupted run of the same job (harmless on a fresh run)");
  c.app->add_option("--max-hours", o->maxHours, "stop cleanly (exit code 3) before this wall time, in hours")
      ->check(CLI::NonNegativeNumber);
  c.app
      ->add_option("--rank-timeout", o->rankTimeout,
                   "end the run (exit code 6, resumable) when a rank computing a tile sends nothing for this many "
                   "seconds (0: never)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  c.run = [o, argc, argv] { return runCommand(argc, argv, *o); };
  c.handlesOwnErrors = true;
  return c;
}

}  // namespace mbsdf
