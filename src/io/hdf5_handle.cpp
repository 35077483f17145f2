#include "io/hdf5_handle.h"

#include <regex>

#include "core/error.h"

namespace mbsdf {
namespace {

struct StackText {
  std::string innermost;   // the first (deepest) description
  std::string systemDesc;  // the description of a failed system call, if any
};

herr_t collect(unsigned n, const H5E_error2_t* e, void* data) {
  auto* t = static_cast<StackText*>(data);
  const std::string desc = e->desc ? e->desc : "";
  if (n == 0) t->innermost = desc;
  if (t->systemDesc.empty() && desc.find("errno = ") != std::string::npos) t->systemDesc = desc;
  return 0;
}

}  // namespace

void h5fail(const std::string& what) {
  StackText t;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, collect, &t);
  H5Eclear2(H5E_DEFAULT);
  // The sec2 driver's text: "file write failed: ..., filename = 'x.h5', ..., errno = 28, error
  // message = 'No space left on device', ...".
  std::smatch m;
  if (!t.systemDesc.empty() && std::regex_search(t.systemDesc, m, std::regex("errno = ([0-9]+)"))) {
    const int err = std::stoi(m[1]);
    std::smatch f;
    const std::string file =
        std::regex_search(t.systemDesc, f, std::regex("filename = '([^']*)'")) ? std::string(f[1]) : std::string("?");
    const std::string msg = osErrorMessage("HDF5 " + what, file, err);
    if (t.systemDesc.find("read") != std::string::npos && t.systemDesc.find("write") == std::string::npos)
      throw std::runtime_error(msg);
    throw WriteError(msg);
  }
  throw std::runtime_error("HDF5: " + what + " failed" + (t.innermost.empty() ? "" : ": " + t.innermost));
}

void setUpHdf5() {
  H5dont_atexit();
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}

}  // namespace mbsdf
