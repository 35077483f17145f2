#include "core/log.h"

#include <spdlog/details/log_msg_buffer.h>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <vector>

#include "core/error.h"
#include "core/stop.h"

namespace mbsdf {
namespace {
std::mutex gLogFailureMutex;
std::string gLogFailure;
}  // namespace

// Keeps every line at every level; the logger they are replayed through filters them.
struct DeferredLog::Holder : spdlog::sinks::base_sink<std::mutex> {
  std::vector<spdlog::details::log_msg_buffer> lines;

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override { lines.emplace_back(msg); }
  void flush_() override {}
};

DeferredLog::DeferredLog() : holder_(std::make_shared<Holder>()) {
  auto logger = std::make_shared<spdlog::logger>("microbsdf", holder_);
  logger->set_level(spdlog::level::trace);
  spdlog::set_default_logger(logger);
}

void DeferredLog::replay() const {
  for (const auto& line : holder_->lines)
    spdlog::default_logger_raw()->log(line.time, line.source, line.level, line.payload);
}

std::string logWriteFailure() {
  std::lock_guard<std::mutex> lock(gLogFailureMutex);
  return gLogFailure;
}

void setupLogging(int rank, const std::string& logDir, const std::string& stem, bool verbose) {
  std::vector<spdlog::sink_ptr> sinks;
  if (rank == 0) sinks.push_back(std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
  if (!logDir.empty()) {
    auto path = (std::filesystem::path(logDir) / (stem + ".rank" + std::to_string(rank) + ".log")).string();
    try {
      std::filesystem::create_directories(logDir);
      sinks.push_back(std::make_shared<spdlog::sinks::basic_file_sink_mt>(path, true));
    } catch (const std::exception& e) {
      throw InputError("log folder " + logDir + ": cannot create " + path + " (" + e.what() +
                       "); choose another with --log-dir");
    }
  }
  auto logger = std::make_shared<spdlog::logger>("microbsdf", sinks.begin(), sinks.end());
  logger->set_error_handler([](const std::string& msg) {
    std::lock_guard<std::mutex> lock(gLogFailureMutex);
    if (gLogFailure.empty()) gLogFailure = msg;
    std::fprintf(stderr, "microbsdf: log write failed: %s\n", msg.c_str());
  });
  logger->set_pattern("[%Y-%m-%d %H:%M:%S.%e] [rank " + std::to_string(rank) + "] [%l] %v");
  logger->set_level(verbose ? spdlog::level::debug : spdlog::level::info);
  logger->flush_on(spdlog::level::info);
  spdlog::set_default_logger(logger);
}

std::function<void(uint64_t)> heartbeat(const std::string& what, double intervalSeconds) {
  auto start = std::chrono::steady_clock::now();
  auto last = std::make_shared<std::chrono::steady_clock::time_point>(start);
  return [what, intervalSeconds, start, last](uint64_t done) {
    throwIfStopped();
    const auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - *last).count() < intervalSeconds) return;
    *last = now;
    spdlog::info("{}: running for {:.0f} s ({} done)", what, std::chrono::duration<double>(now - start).count(), done);
  };
}

ProgressReporter::ProgressReporter(std::string what, uint64_t total, double intervalSeconds, bool logCompletion)
    : what_(std::move(what)),
      total_(total),
      interval_(intervalSeconds),
      logCompletion_(logCompletion),
      start_(std::chrono::steady_clock::now()),
      last_(start_) {}

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
