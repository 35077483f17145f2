// The output location of a run, checked before any compute, and held by one run at a time.
//
// A cluster allocation should not be spent on a job whose result cannot be written: the output path
// must not be a folder, its folder and the log folder must be writable, and there should be room for
// the file. A second run on the same output would interleave two jobs' slices, so rank 0 holds an
// exclusive lock (flock(2) on `<output>.lock`, which records the holder's host and PID) from before
// the pilots to the final rename. flock locks die with their process, so the lock of a killed run is
// free at once; the next run notes whose it was and takes it.
#pragma once
#include <functional>
#include <string>

namespace mbsdf {

// Throws InputError (naming the path and the reason) when `outPath` is a folder or its folder cannot
// be created or written; `role` names it in the message ("output", "log").
void checkOutputPath(const std::string& outPath);
void checkWritableFolder(const std::string& folder, const std::string& role);

// Bytes available to this user on the file system holding `path` (its folder if it does not exist).
double freeBytesAt(const std::string& path);

// fsync(2) of a file or folder; throws WriteError naming it.
void syncPath(const std::string& path);

// Writes `text` to `<path>.partial`, syncs it and renames it over `path`: an existing file at `path`
// is replaced whole or left as it was. An unusable location (a folder, a read-only folder) is refused
// first by checkOutputPath (InputError); a failed write throws WriteError naming the path (the
// partial file removed).
void writeFileAtomically(const std::string& path, const std::string& text);
// The same for a writer that makes the file itself (OpenEXR): `write(partial)` writes `<path>.partial`,
// which is then synced and renamed over `path`. Whatever `write` throws becomes a WriteError
// naming `path`, and the partial file is removed. The location is checked first, as above.
void writeViaPartial(const std::string& path, const std::function<void(const std::string& partial)>& write);

class OutputLock {
 public:
  // Takes the lock of `outPath` or throws OutputBusyError naming the holder (host, PID, start time).
  explicit OutputLock(const std::string& outPath);
  ~OutputLock();
  OutputLock(const OutputLock&) = delete;
  OutputLock& operator=(const OutputLock&) = delete;
  // Who held the lock before, if a process that is gone left its record ("" otherwise).
  const std::string& previousHolder() const { return previous_; }
  const std::string& path() const { return path_; }
  // What this run wrote into the lock file (host, PID, start time): how another node's rank tells
  // this lock file from one of its own folder's.
  const std::string& record() const { return record_; }

 private:
  std::string path_, previous_, record_;
  int fd_ = -1;
};

// How a rank sees the lock file another rank holds (`record` being what the holder wrote in it).
enum class LockView {
  Held,       // the file is there, with the record, and flock(2) refuses it: shared and enforced
  Missing,    // no such file here: this rank's file system is not the holder's
  Foreign,    // a file with other contents: a folder of the same name on another file system
  Unenforced  // the file with the record, yet flock(2) granted it: the lock does not reach this node
};
// Looks at `lockPath` as a rank other than the holder; takes and at once releases the lock when the
// file system grants it.
LockView viewOfLock(const std::string& lockPath, const std::string& record);

}  // namespace mbsdf
