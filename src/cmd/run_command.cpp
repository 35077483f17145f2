// `microbsdf run JOB.toml [-o OUT.h5] [--threads N] [--log-dir DIR] [--resume] [--max-hours H] [-v]`,
// under mpirun or srun for several ranks: every rank loads the job; rank 0 checks the output
// location and takes its lock before any compute, runs the effects planner's pilots, then all ranks
// run the tiles (cluster/runner.h). Foreseeable failures end every rank with the same exit code and
// one message; only an unexpected one aborts the job.
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>

#include <tbb/global_control.h>

#include "cluster/mpi_session.h"
#include "cluster/runner.h"
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
std::optional<int> planComponents(MpiSession& mpi, Job& job, int threads, PilotResults* kept) {
  std::string planText, stopped;
  if (mpi.rank() == 0) {
    std::optional<tbb::global_control> limit;
    if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(threads));
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

int runCommand(int argc, char** argv, RunArgs a) {
  // The whole run as this process sees it (MPI start-up, the job's geometry, the effects pilots,
  // the tiles, the file): what `plan`'s wall-time estimate predicts (scripts/bench-plan).
  const auto started = std::chrono::steady_clock::now();
  // Where a small job's start-up goes (logged at debug level once the pilots are done): seconds
  // since the program started at each step.
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(); };
  MpiSession mpi(&argc, &argv);
  const double mpiReady = elapsed();
  installStopHandlers();
  setupLogging(mpi.rank(), "", "", a.verbose);
  auto agree = [&](const std::string& outcome) { return agreeOnRankZero(mpi, outcome); };
  std::optional<Job> job;
  std::string error;
  try {
    job = loadJob(a.jobPath);
  } catch (const InputError& e) {
    error = e.what();
  } catch (const std::exception& e) {
    error = std::string(a.jobPath) + ": " + e.what();
  }
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
      if (auto code = planComponents(mpi, *job, a.threads, &opt.pilots)) return *code;
    const double planned = elapsed();
    spdlog::debug(
        "start-up: MPI {:.3f} s, job file and geometry {:.3f} s, output checks and log files {:.3f} s, effects "
        "pilots {:.3f} s ({:.3f} s since the program started); memory allocator {}",
        mpiReady, jobReady - mpiReady, outputChecked - jobReady, planned - outputChecked, planned, allocatorNote());
    opt.outputPath = out;
    opt.threads = a.threads;
    opt.resume = a.resume;
    opt.maxHours = a.maxHours;
    RunSummary s = runJob(*job, mpi, opt);
    if (s.exit != ExitCode::Ok) {
      if (mpi.rank() == 0) spdlog::error("{}", s.error.empty() ? "run failed" : s.error);
      return exitCode(s.exit);
    }
    if (s.stoppedEarly) return exitCode(ExitCode::Stopped);
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
  c.run = [o, argc, argv] { return runCommand(argc, argv, *o); };
  c.handlesOwnErrors = true;
  return c;
}

}  // namespace mbsdf
