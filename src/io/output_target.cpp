#include "io/output_target.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>

#include "core/error.h"

namespace mbsdf {
namespace fs = std::filesystem;

namespace {
std::string folderOf(const std::string& path) {
  fs::path dir = fs::path(path).parent_path();
  return dir.empty() ? std::string(".") : dir.string();
}

std::string readAll(int fd) {
  std::string s;
  char buf[512];
  ssize_t n;
  if (::lseek(fd, 0, SEEK_SET) < 0) return s;
  while ((n = ::read(fd, buf, sizeof buf)) > 0) s.append(buf, size_t(n));
  while (!s.empty() && (s.back() == '\n' || s.back() == '\0')) s.pop_back();
  return s;
}
}  // namespace

void checkWritableFolder(const std::string& folder, const std::string& role) {
  std::error_code ec;
  if (fs::exists(folder, ec) && !fs::is_directory(folder, ec))
    throw InputError(role + " folder " + folder + " is not a folder");
  fs::create_directories(folder, ec);
  if (ec) throw InputError(role + " folder " + folder + ": cannot create it (" + ec.message() + ")");
  // access(2) is not enough (read-only mounts, ACLs, root): create and remove a probe file.
  const std::string probe = (fs::path(folder) / (".microbsdf-probe-" + std::to_string(::getpid()))).string();
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0600);
  if (fd < 0) {
    const int err = errno;
    throw InputError(role + " folder " + folder + " is not writable: " + std::strerror(err));
  }
  ::close(fd);
  ::unlink(probe.c_str());
}

void checkOutputPath(const std::string& outPath) {
  std::error_code ec;
  if (outPath.empty()) throw InputError("output path is empty");
  if (fs::is_directory(outPath, ec))
    throw InputError("output " + outPath + " is a folder; give a file name such as " +
                     (fs::path(outPath) / "out.h5").string());
  checkWritableFolder(folderOf(outPath), "output");
  for (const char* suffix : {".partial", ".journal"})
    if (fs::is_directory(outPath + suffix, ec)) throw InputError("output " + outPath + suffix + " is a folder");
}

double freeBytesAt(const std::string& path) {
  struct statvfs s {};
  std::string p = path;
  std::error_code ec;
  if (!fs::exists(p, ec)) p = folderOf(path);
  if (::statvfs(p.c_str(), &s) != 0) return -1;
  return double(s.f_bavail) * double(s.f_frsize);
}

void syncPath(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) throw WriteError(osErrorMessage("open for fsync", path, errno));
  if (::fsync(fd) != 0) {
    const int err = errno;
    ::close(fd);
    // Folders on some file systems do not support fsync; the data itself was synced.
    if (err == EINVAL || err == ENOTSUP) return;
    throw WriteError(osErrorMessage("fsync", path, err));
  }
  ::close(fd);
}

void writeViaPartial(const std::string& path, const std::function<void(const std::string& partial)>& write) {
  // Every atomic write refuses a folder or an unwritable location the same way, before any work
  // (InputError, naming it: the user's to fix).
  checkOutputPath(path);
  const std::string partial = path + ".partial";
  auto removePartial = [&] {
    std::error_code ignored;
    std::filesystem::remove(partial, ignored);
  };
  try {
    errno = 0;  // so that a writer which reports no OS error is not blamed for a stale one
    write(partial);
    syncPath(partial);
  } catch (const WriteError&) {
    removePartial();
    throw;
  } catch (const std::exception& e) {
    // The writer's own report (an ofstream's errno, OpenEXR's or libpng's message).
    const int err = errno;
    removePartial();
    throw WriteError("cannot write " + path + " (writing " + partial + " failed: " + e.what() +
                     (err ? std::string("; ") + std::strerror(err) : std::string()) + ")");
  }
  std::error_code ec;
  std::filesystem::rename(partial, path, ec);
  if (ec) {
    removePartial();
    throw WriteError("cannot write " + path + ": " + ec.message());
  }
}

void writeFileAtomically(const std::string& path, const std::string& text) {
  writeViaPartial(path, [&](const std::string& partial) {
    std::ofstream f(partial, std::ios::binary | std::ios::trunc);
    f.write(text.data(), std::streamsize(text.size()));
    f.close();
    if (!f)
      throw WriteError("cannot write " + path + " (writing " + partial + " failed: " + std::strerror(errno) + ")");
  });
}

OutputLock::OutputLock(const std::string& outPath) : path_(outPath + ".lock") {
  // Open, lock, then check that the path still names the locked file: a releasing run unlinks it,
  // and a lock on an unlinked file would protect nothing.
  for (int attempt = 0; attempt < 100; ++attempt) {
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) throw InputError(osErrorMessage("cannot create the lock file", path_, errno));
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      std::string holder = readAll(fd_);
      ::close(fd_);
      fd_ = -1;
      if (err == EWOULDBLOCK)
        throw OutputBusyError("output " + outPath + " is being written by another run (" +
                              (holder.empty() ? std::string("holder unknown") : holder) + "; lock file " + path_ +
                              "): wait for it to end or choose another output path");
      throw InputError(osErrorMessage("cannot lock", path_, err));
    }
    struct stat a {
    }, b{};
    if (::fstat(fd_, &a) == 0 && ::stat(path_.c_str(), &b) == 0 && a.st_ino == b.st_ino && a.st_dev == b.st_dev) break;
    ::close(fd_);
    fd_ = -1;
  }
  if (fd_ < 0) throw InputError("cannot lock " + path_ + ": it keeps being replaced");
  previous_ = readAll(fd_);
  char host[256] = {0};
  ::gethostname(host, sizeof host - 1);
  const std::time_t now = std::time(nullptr);
  char when[64];
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", std::localtime(&now));
  record_ = "host " + std::string(host) + ", PID " + std::to_string(::getpid()) + ", since " + when;
  const std::string record = record_ + "\n";
  // Synced, so that ranks on other nodes of a network file system read the record (viewOfLock).
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, record.data(), record.size(), 0) != ssize_t(record.size()) ||
      ::fsync(fd_) != 0) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    throw WriteError(osErrorMessage("write", path_, err));
  }
}

LockView viewOfLock(const std::string& lockPath, const std::string& record) {
  const int fd = ::open(lockPath.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return LockView::Missing;
  LockView view = LockView::Foreign;
  if (readAll(fd) == record) {
    view = LockView::Held;
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
      ::flock(fd, LOCK_UN);
      view = LockView::Unenforced;
    }
  }
  ::close(fd);
  return view;
}

OutputLock::~OutputLock() {
  if (fd_ < 0) return;
  ::unlink(path_.c_str());  // still holding the lock: no other run can be between open and lock on it
  ::close(fd_);
}

}  // namespace mbsdf
