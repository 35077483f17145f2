#include "core/stop.h"

#include <csignal>
#include <initializer_list>

namespace mbsdf {
namespace {
volatile std::sig_atomic_t gStop = 0;
extern "C" void onStopSignal(int) { gStop = 1; }
}  // namespace

void installStopHandlers() {
  struct sigaction sa {};
  sa.sa_handler = onStopSignal;
  sigemptyset(&sa.sa_mask);
  for (int s : {SIGTERM, SIGINT, SIGUSR1}) sigaction(s, &sa, nullptr);
}

bool stopRequested() { return gStop != 0; }

void throwIfStopped() {
  if (gStop) throw StopRequested{};
}

}  // namespace mbsdf
