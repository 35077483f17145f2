// libFuzzer target: the measured-topography readers (X3P, SDF, GSF). The first byte picks the
// format, the rest is the file. Bad files must end in InputError naming the file.
#include <cstddef>
#include <cstdint>

#include "core/error.h"
#include "fuzz_common.h"
#include "geometry/topography.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  mbsdf::fuzz::quietLogs();
  static const char* kExtensions[] = {".x3p", ".sdf", ".gsf"};
  std::string path = mbsdf::fuzz::writeTemp(data + 1, size - 1, kExtensions[data[0] % 3]);
  try {
    mbsdf::Topography t = mbsdf::loadTopography(path);
    if (t.z_um.size() != t.size()) __builtin_trap();
  } catch (const mbsdf::InputError&) {
  }
  return 0;
}
