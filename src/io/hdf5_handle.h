// RAII for HDF5 identifiers: each handle closes itself with the right H5?close. Errors from the
// HDF5 C API become exceptions naming the operation and, where the operating system refused a
// write (disk full, quota, I/O error), a WriteError naming the file and the reason.
#pragma once
#include <hdf5.h>

#include <stdexcept>
#include <string>
#include <utility>

namespace mbsdf {

// Throws for the failed operation `what`, with the reason from HDF5's error stack (which it clears).
[[noreturn]] void h5fail(const std::string& what);
// Before any other HDF5 call: HDF5 prints its error stack on stderr by default (the exceptions
// above say what failed instead), and at exit closes what is still open — after a close that a
// full disk made fail, a file HDF5 cannot flush, where its exit handler crashed (Debian's 1.10.8).
// Every file is closed, checked, before the program ends; HDF5's exit handler is not installed.
void setUpHdf5();

template <herr_t (*Close)(hid_t)>
class H5Handle {
 public:
  H5Handle() = default;
  explicit H5Handle(hid_t id) : id_(id) {}
  H5Handle(hid_t id, const std::string& what) : id_(id) {
    if (id_ < 0) h5fail(what);
  }
  H5Handle(const H5Handle&) = delete;
  H5Handle& operator=(const H5Handle&) = delete;
  H5Handle(H5Handle&& o) noexcept : id_(std::exchange(o.id_, -1)) {}
  H5Handle& operator=(H5Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = std::exchange(o.id_, -1);
    }
    return *this;
  }
  ~H5Handle() { reset(); }
  // Closing discards errors: an object abandoned after a failure. Use close() where the data must
  // have reached the file (closing a file flushes what HDF5 still caches).
  void reset() {
    if (id_ >= 0) Close(id_);
    id_ = -1;
  }
  void close(const std::string& what) {
    if (id_ < 0) return;
    const herr_t e = Close(std::exchange(id_, -1));
    if (e < 0) h5fail(what);
  }
  hid_t get() const { return id_; }
  operator hid_t() const { return id_; }
  bool valid() const { return id_ >= 0; }

 private:
  hid_t id_ = -1;
};

using H5File = H5Handle<H5Fclose>;
using H5Group = H5Handle<H5Gclose>;
using H5Dataset = H5Handle<H5Dclose>;
using H5Dataspace = H5Handle<H5Sclose>;
using H5Datatype = H5Handle<H5Tclose>;
using H5Plist = H5Handle<H5Pclose>;
using H5Attribute = H5Handle<H5Aclose>;

inline void h5check(herr_t e, const std::string& what) {
  if (e < 0) h5fail(what);
}

}  // namespace mbsdf
