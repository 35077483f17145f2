#include "core/stop.h"

#include <atomic>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <initializer_list>

namespace mbsdf {
namespace {
volatile std::sig_atomic_t gStop = 0;
// When the first stop signal arrived (CLOCK_MONOTONIC, ns). clock_gettime is async-signal-safe
// (POSIX.1-2008, signal-safety(7)) and a lock-free atomic may be stored from a handler
// (C++17 [support.signal]).
std::atomic<std::int64_t> gStopAt_ns{0};
static_assert(std::atomic<std::int64_t>::is_always_lock_free);

std::int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

extern "C" void onStopSignal(int) {
  std::int64_t expected = 0;
  gStopAt_ns.compare_exchange_strong(expected, monotonicNs());
  gStop = 1;
}
}  // namespace

void installStopHandlers() {
  struct sigaction sa {};
  sa.sa_handler = onStopSignal;
  sigemptyset(&sa.sa_mask);
  for (int s : {SIGTERM, SIGINT, SIGUSR1}) sigaction(s, &sa, nullptr);
}

bool stopRequested() {
  return gStop != 0;
}

void throwIfStopped() {
  if (gStop) throw StopRequested{};
}

double secondsSinceStopSignal() {
  const std::int64_t at = gStopAt_ns.load();
  return at == 0 ? -1.0 : double(monotonicNs() - at) * 1e-9;
}

std::string stopAnswerNote() {
  const double s = secondsSinceStopSignal();
  if (s < 0) return "answered on request";
  char text[64];
  std::snprintf(text, sizeof text, "answered %.3f s after the signal", s);
  return text;
}

}  // namespace mbsdf
