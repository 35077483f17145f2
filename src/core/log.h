// Logging through spdlog (non-negotiable 8): one file per rank, and rank 0 also on the console.
// Progress of long loops is reported as periodic log lines (done/total, rate, ETA).
#pragma once
#include <chrono>
#include <cstdint>
#include <string>

namespace mbsdf {

// Sets the default spdlog logger. logDir empty: console only (rank 0) / nothing (other ranks).
void setupLogging(int rank, const std::string& logDir, const std::string& stem, bool verbose);

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
