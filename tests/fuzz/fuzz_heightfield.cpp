// libFuzzer target: the EXR heightfield loader. Bad files must end in InputError naming the file.
#include <cstddef>
#include <cstdint>

#include "core/error.h"
#include "geometry/mesh_loader.h"
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mbsdf::fuzz::quietLogs();
  std::string path = mbsdf::fuzz::writeTemp(data, size, ".exr");
  int w = 0, h = 0;
  try {
    mbsdf::loadHeightfieldExr(path, &w, &h);
  } catch (const mbsdf::InputError&) {
  }
  return 0;
}
