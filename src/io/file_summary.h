// What `info` reports of an output file, as data: provenance, completeness, the effects planner's
// decisions and each slice's samples, energies, errors and checks (`microbsdf info --json`), and the
// one-line figures of a slice that `info`'s table and the HTML report show.
#pragma once
#include <nlohmann/json.hpp>

#include <string>

#include "io/bsdf_file.h"

namespace mbsdf {

// The summary `info --json` prints (docs/output.md).
nlohmann::json fileSummary(const BsdfFileReader& f, const std::string& path);

// One finished slice of fileSummary's "slices", in the figures of `info`'s table (means over λ).
struct SliceSummary {
  double reflected = 0, transmitted = 0;  // the components the file holds, without `lost`
  double albedoStdError = 0;              // NaN when the file has no per-path errors
  double truncated = 0;
  double relError = 0;       // the largest relative per-bin error over components and λ
  double balance = 0;        // reflected + transmitted + lost paths − 1, the largest over λ (NaN: none)
  double lost = 0;           // the lost component's energy, NaN without one
  unsigned nonphysical = 0;  // SliceFlag bits over λ (0 in files without /stats/nonphysical)
};
SliceSummary summariseSlice(const nlohmann::json& slice);

}  // namespace mbsdf
