// libFuzzer target: the job-file parser and validator (TOML -> Job, including the geometry built
// from it). Bad input must end in InputError, never in a crash, a hang or another exception.
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/error.h"
#include "job/geometry_factory.h"
#include "job/job.h"
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mbsdf::fuzz::quietLogs();
  // Every generator path stays reachable; 1e7-facet patches (about 80 s each under ASan, found by CI
  // as a timeout in the patch symmetry check) are tested as ordinary jobs instead.
  mbsdf::setMaxGeneratedTriangles(2e5);
  std::string text(reinterpret_cast<const char*>(data), size);
  try {
    mbsdf::loadJobFromString(text, "fuzz.toml", "/nonexistent");
  } catch (const mbsdf::InputError&) {
  }
  return 0;
}
