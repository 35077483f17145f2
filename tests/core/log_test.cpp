// DeferredLog: lines logged before logging is set up are held, at every level and from any thread,
// and replayed through the logger set since in the order they were made, with their own times and
// that logger's level; nothing is logged before the replay.
#include "core/log.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <sstream>
#include <thread>

namespace mbsdf {
namespace {

TEST(DeferredLog, HoldsLinesUntilReplayedThroughTheLoggerSetSince) {
  const auto before = spdlog::default_logger();
  std::ostringstream out;
  {
    DeferredLog early;
    spdlog::debug("held debug");
    std::thread([] { spdlog::warn("held warning from {}", "another thread"); }).join();
    spdlog::info("held info");
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
    auto logger = std::make_shared<spdlog::logger>("test", sink);
    logger->set_pattern("%Y-%m-%d %H:%M:%S.%e|%l|%v");
    logger->set_level(spdlog::level::info);
    spdlog::set_default_logger(logger);
    EXPECT_EQ(out.str(), "");
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const auto replayedAt = std::chrono::system_clock::now();
    early.replay();
    const std::string text = out.str();
    EXPECT_EQ(text.find("held debug"), std::string::npos) << text;  // below the logger's level
    const size_t warn = text.find("|warning|held warning from another thread");
    const size_t info = text.find("|info|held info");
    ASSERT_NE(warn, std::string::npos) << text;
    ASSERT_NE(info, std::string::npos) << text;
    EXPECT_LT(warn, info) << text;
    // Each line carries the time it was made, not the replay's.
    const std::time_t t = std::chrono::system_clock::to_time_t(replayedAt);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%d %H:%M:%S", std::localtime(&t));
    const long replayMs =
        long(std::chrono::duration_cast<std::chrono::milliseconds>(replayedAt.time_since_epoch()).count() % 1000);
    const std::string lineTime = text.substr(0, text.find('|'));
    EXPECT_NE(lineTime, std::string(stamp) + "." + fmt::format("{:03d}", replayMs)) << text;
  }
  spdlog::set_default_logger(before);
}

}  // namespace
}  // namespace mbsdf
