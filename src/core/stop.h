// Clean stops on request: SIGTERM (Slurm, srun), SIGINT (Ctrl-C) and SIGUSR1 (forwarded by mpirun,
// sent by `scancel --signal=USR1` before the time limit) set a flag that long loops poll, so any
// phase — pilots, tiles, the reciprocity fill — ends within a second of the signal. The handler
// only sets the flag (async-signal-safe); the loops throw StopRequested, which unwinds to the
// command, which exits with ExitCode::Stopped.
#pragma once

#include <string>

namespace mbsdf {

struct StopRequested {};

void installStopHandlers();
bool stopRequested();
// Throws StopRequested when a stop was requested.
void throwIfStopped();
// Seconds since the first stop signal arrived (-1 without one): the stop messages report it, so a
// user (and the fault tests) see how fast a phase answered, measured by the program itself.
double secondsSinceStopSignal();
// "answered 0.12 s after the signal" (or "answered on request" when no signal set the flag).
std::string stopAnswerNote();

}  // namespace mbsdf
