// libFuzzer target: the job-file parser and validator (TOML -> Job, including the geometry built
// from it). Bad input must end in InputError, never in a crash, a hang or another exception.
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/error.h"
#include "job/job.h"
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mbsdf::fuzz::quietLogs();
  std::string text(reinterpret_cast<const char*>(data), size);
  try {
    mbsdf::loadJobFromString(text, "fuzz.toml", "/nonexistent");
  } catch (const mbsdf::InputError&) {
  }
  return 0;
}
