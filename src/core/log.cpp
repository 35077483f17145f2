#include "core/log.h"

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <filesystem>

namespace mbsdf {

void setupLogging(int rank, const std::string& logDir, const std::string& stem, bool verbose) {
  std::vector<spdlog::sink_ptr> sinks;
  if (rank == 0) sinks.push_back(std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
  if (!logDir.empty()) {
    std::filesystem::create_directories(logDir);
    auto path = (std::filesystem::path(logDir) / (stem + ".rank" + std::to_string(rank) + ".log")).string();
    sinks.push_back(std::make_shared<spdlog::sinks::basic_file_sink_mt>(path, true));
  }
  auto logger = std::make_shared<spdlog::logger>("microbsdf", sinks.begin(), sinks.end());
  logger->set_pattern("[%Y-%m-%d %H:%M:%S.%e] [rank " + std::to_string(rank) + "] [%l] %v");
  logger->set_level(verbose ? spdlog::level::debug : spdlog::level::info);
  logger->flush_on(spdlog::level::info);
  spdlog::set_default_logger(logger);
}

ProgressReporter::ProgressReporter(std::string what, uint64_t total, double intervalSeconds, bool logCompletion)
    : what_(std::move(what)), total_(total), interval_(intervalSeconds), logCompletion_(logCompletion),
      start_(std::chrono::steady_clock::now()), last_(start_) {}

void ProgressReporter::update(uint64_t done) {
  auto now = std::chrono::steady_clock::now();
  double sinceLast = std::chrono::duration<double>(now - last_).count();
  bool complete = done >= total_;
  if ((!complete || !logCompletion_) && sinceLast < interval_) return;
  last_ = now;
  double elapsed = std::chrono::duration<double>(now - start_).count();
  double rate = elapsed > 0 ? done / elapsed : 0.0;
  double eta = rate > 0 ? (total_ - done) / rate : 0.0;
  spdlog::info("{}: {}/{} ({:.1f}%), {:.3g}/s, elapsed {:.1f} s, ETA {:.1f} s", what_, done, total_,
               total_ ? 100.0 * done / total_ : 100.0, rate, elapsed, eta);
}

}  // namespace mbsdf
