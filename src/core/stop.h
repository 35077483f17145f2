// Clean stops on request: SIGTERM (Slurm, srun), SIGINT (Ctrl-C) and SIGUSR1 (forwarded by mpirun,
// sent by `scancel --signal=USR1` before the time limit) set a flag that long loops poll, so any
// phase — pilots, tiles, the reciprocity fill — ends within a second of the signal. The handler
// only sets the flag (async-signal-safe); the loops throw StopRequested, which unwinds to the
// command, which exits with ExitCode::Stopped.
#pragma once

namespace mbsdf {

struct StopRequested {};

void installStopHandlers();
bool stopRequested();
// Throws StopRequested when a stop was requested.
void throwIfStopped();

}  // namespace mbsdf
