// libFuzzer target: the OBJ and PLY loaders (the first byte picks the format). Bad files must end
// in InputError naming the file.
#include <cstddef>
#include <cstdint>

#include "core/error.h"
#include "geometry/mesh_loader.h"
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  mbsdf::fuzz::quietLogs();
  const char* ext = (data[0] & 1) ? ".ply" : ".obj";
  std::string path = mbsdf::fuzz::writeTemp(data + 1, size - 1, ext);
  try {
    mbsdf::loadMesh(path, 1.0);
  } catch (const mbsdf::InputError&) {
  }
  return 0;
}
