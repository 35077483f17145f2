// The errors a run can end with, and the exit code of each. Errors caused by user input (job files,
// meshes, heightfields) carry where the problem is (file, line, key) so the message can name it;
// the program exits non-zero without touching the output file.
#pragma once
#include <stdexcept>
#include <string>

namespace mbsdf {

// The process exit codes (README "Exit codes" says what each leaves on disk).
enum class ExitCode : int {
  Ok = 0,
  Failure = 1,      // an unexpected failure (a bug, out of memory)
  BadInput = 2,     // job file, input file, command-line argument or output location unusable
  Stopped = 3,      // stopped cleanly (signal, --max-hours): the same command with --resume completes it
  WriteFailed = 4,  // the output could not be written (disk full, quota, I/O error): resumable
  OutputBusy = 5,   // another run holds the output path
  RankSilent = 6,   // a rank sent nothing for --rank-timeout seconds (stopped, frozen, cut off): resumable
};
constexpr int exitCode(ExitCode c) {
  return static_cast<int>(c);
}

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A write to an output (HDF5 file, journal, log) failed. The message names the file and the
// operating system's reason (ENOSPC, EDQUOT, EIO, EFBIG, ...).
class WriteError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Another process holds the output (its host and PID are in the message).
class OutputBusyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "file:line: key: message" with the parts that are known.
std::string formatLocation(const std::string& file, int line, const std::string& key);

// "what: <path>: <strerror(err)> (<errno name>)", e.g. "write: out.h5.journal: No space left on device (ENOSPC)".
std::string osErrorMessage(const std::string& what, const std::string& path, int err);

}  // namespace mbsdf
