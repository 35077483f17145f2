// Logging through spdlog: one file per rank, and rank 0 also on the console.
// Progress of long loops is reported as periodic log lines (done/total, rate, ETA).
#pragma once
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace mbsdf {

// Sets the default spdlog logger. logDir empty: console only (rank 0) / nothing (other ranks).
// Throws InputError naming the folder when the log file cannot be created there.
void setupLogging(int rank, const std::string& logDir, const std::string& stem, bool verbose);

// The log lines of work done before logging is set up (`run` loads the job while MPI starts, before
// it knows its rank): from construction they are held instead of logged, and replay() logs them
// through the default logger set since, with the times they were made at.
class DeferredLog {
 public:
  DeferredLog();
  void replay() const;

 private:
  struct Holder;
  std::shared_ptr<Holder> holder_;
};

// The first failed write or flush of a log file since setupLogging ("" if none). Every log line is
// flushed, so a full disk shows here at the next line; the runner checks it between tiles and
// stops with a WriteError instead of computing on without a log.
std::string logWriteFailure();

// A progress callback for a phase whose total is not known in advance (a pilot): logs "<what>:
// running for N s (<count> done)" at most every `intervalSeconds`, and throws StopRequested
// (core/stop.h) when a stop was requested, so pilots answer signals like tiles do.
std::function<void(uint64_t)> heartbeat(const std::string& what, double intervalSeconds = 10.0);

class ProgressReporter {
 public:
  ProgressReporter(std::string what, uint64_t total, double intervalSeconds = 10.0, bool logCompletion = true);
  // Logs a line when the interval has passed since the last one (or when done == total).
  void update(uint64_t done);

 private:
  std::string what_;
  uint64_t total_;
  double interval_;
  bool logCompletion_;
  std::chrono::steady_clock::time_point start_, last_;
};

}  // namespace mbsdf
