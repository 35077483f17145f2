// `microbsdf check JOB.toml`: validates a job file and prints what it describes, with the memory
// per rank and the output size it will need.
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <iostream>

#include "cmd/command.h"
#include "core/direction_grid.h"
#include "core/error.h"
#include "geometry/topography_stats.h"
#include "io/height_map_file.h"
#include "io/output_target.h"
#include "job/job.h"
#include "job/plan.h"
#include "job/scalar_validity.h"
#include "microflake/ndf.h"

namespace mbsdf {
namespace {

// Each incidence's paths as CSV: with path_allocation = "equal-error" they differ by slice, and a
// check of a few slices at the job's own budget (scripts/paper-resolution-check) needs them.
void writeSlicePaths(const std::string& path, const Job& job) {
  std::string csv = "incidence,bin,theta_deg,phi_deg,paths\n";
  for (size_t i = 0; i < job.incidence.size(); ++i) {
    const IncidenceDirection& inc = job.incidence[i];
    csv += fmt::format("{},{},{:.6g},{:.6g},{}\n", i, inc.bin, inc.theta_deg, inc.phi_deg, job.pathsFor(int(i)));
  }
  writeFileAtomically(path, csv);
}

int checkJob(const std::string& jobPath, const std::string& heightsPath, const std::string& slicePathsPath) {
  if (!slicePathsPath.empty()) checkOutputPath(slicePathsPath);  // an unusable location is named at once
  Job job = loadJob(jobPath);
  DirectionGrid grid(job.gridLayout);
  auto warning = [](const std::optional<std::string>& caveat) {
    return caveat ? "  WARNING: " + *caveat + "\n" : std::string();
  };
  std::cout << jobPath << ": ok\n  geometry " << job.geometryKind << ", "
            << (job.statistical
                    ? MicroflakeDistribution(job.statistical->ndf).describe()
                    : std::to_string(job.geometry.triangles.size()) + " triangles, " +
                          std::to_string(job.geometry.sizeX) + " x " + std::to_string(job.geometry.sizeY) + " µm")
            << (job.statistical ? "" : "\n  surface " + job.closure.describe()) << "\n  material "
            << job.material.describe() << "\n  " << job.lambda_nm.size() << " wavelengths, grid " << grid.kind()
            << " with " << grid.binCount() << " bins, " << job.incidence.size() << " incidence directions\n"
            << "  " << job.describePaths() << "\n"
            << (job.needsWave() ? "  wave estimator " + waveEstimatorName(job.resolvedWaveEstimator()) + " (" +
                                      job.waveEstimatorChoice() + ")\n"
                                : std::string())
            << warning(job.waveErrorsCaveat()) << warning(scalarModelCaveat(job)) << "  memory about "
            << fmt::format("{:.3g}", memoryBytesPerRank(job, 0) / 1e9) << " GB per rank before the "
            << "wave estimator's own (`plan` measures it), output up to "
            << fmt::format("{:.3g}", outputBytesUncompressed(job) / 1e9) << " GB\n";
  if (job.topography) {
    // Sal (two FFTs of the grid) is computed here only, not on every rank of a run.
    const TopographyStats stats = topographyStats(*job.topography->heights);
    const double lambdaMin_um = *std::min_element(job.lambda_nm.begin(), job.lambda_nm.end()) * 1e-3;
    if (job.topography->conditioning.nx > 0) std::cout << "  " << job.topography->conditioning.describe() << "\n";
    std::cout << stats.describe(lambdaMin_um);
    if (!heightsPath.empty()) {
      writeHeightMap(heightsPath, *job.topography->heights);
      std::cout << "  heights written to " << heightsPath << "\n";
    }
  } else if (!heightsPath.empty()) {
    throw InputError(
        jobPath + ": --heights needs a heightfield geometry ([geometry] kind = \"heightfield\") or [geometry.defects]");
  }
  if (!slicePathsPath.empty()) {
    writeSlicePaths(slicePathsPath, job);
    std::cout << "  each incidence's paths written to " << slicePathsPath << "\n";
  }
  if (const double avail = availableMemoryBytes(); avail > 0 && memoryBytesPerRank(job, 0) > avail)
    throw InputError(jobPath + ": the job needs about " + fmt::format("{:.3g}", memoryBytesPerRank(job, 0) / 1e9) +
                     " GB per rank but this machine has " + fmt::format("{:.3g}", avail / 1e9) +
                     " GB available ([directions] bins, [spectrum] wavelengths)");
  return 0;
}

}  // namespace

Command addCheckCommand(CLI::App& app) {
  auto jobPath = std::make_shared<std::string>();
  auto heightsPath = std::make_shared<std::string>();
  auto slicePathsPath = std::make_shared<std::string>();
  Command c;
  c.app = app.add_subcommand("check", "validate a job file and print what it describes");
  c.app->add_option("job", *jobPath, "job file (TOML)")->required();
  c.app->add_option("--heights", *heightsPath,
                    "heightfield jobs and [geometry.defects]: write the heights that are meshed (after crop, "
                    "levelling, filling, edges and defects) "
                    "to this HDF5 file");
  c.app->add_option("--slice-paths", *slicePathsPath,
                    "write each incidence's paths (incidence, bin, theta_deg, phi_deg, paths) to this CSV file: "
                    "with path_allocation = \"equal-error\" they differ by slice");
  c.run = [jobPath, heightsPath, slicePathsPath] { return checkJob(*jobPath, *heightsPath, *slicePathsPath); };
  return c;
}

}  // namespace mbsdf
