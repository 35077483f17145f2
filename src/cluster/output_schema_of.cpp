#include "cluster/output_schema_of.h"

#include <optional>

#include "job/scalar_validity.h"
#include "job/symmetry.h"

namespace mbsdf {
namespace {

std::string symmetryDescription(const Job& job) {
  if (job.isotropic)
    return "isotropic: one incidence azimuth per theta ring computed, the other slices of the ring rotated from it (" +
           job.symmetryReason + ")";
  if (job.symmetryReduced())
    return "reduced: part of each theta ring computed, the other slices mapped from it (" + job.symmetryReason + ")";
  return job.symmetryReason;
}

}  // namespace

OutputSchema outputSchemaOf(const Job& job) {
  OutputSchema s;
  s.jobText = job.text;
  s.jobFile = job.file;
  s.inputFiles = job.inputFiles;
  s.geometryKind = job.geometryKind;
  s.geometryHash = job.geometry.hash();
  s.material = job.material.describe();
  s.seed = job.seed;
  s.pathsPerSlice = job.pathsPerSlice;
  s.slicePaths = job.slicePaths;
  s.maxDepth = job.maxDepth;
  s.exactIncidence = job.exactIncidence;
  s.effectsPlan = job.effectsPlan;
  if (job.components.has(Component::Incoherent) && !job.statistical)
    s.waveEstimator = waveEstimatorName(job.resolvedWaveEstimator());
  s.waveErrorsCaveat = job.waveErrorsCaveat();
  s.scalarModelCaveat = scalarModelCaveat(job);
  s.symmetry = symmetryDescription(job);
  s.halvesWaveByReciprocity = job.halvesWaveByReciprocity();
  if (!s.halvesWaveByReciprocity) s.reciprocityOffReason = job.reciprocityOffReason();
  s.lossless = job.material.lossless();
  s.tolerance = job.scene.tolerance;
  s.lambda_nm = job.lambda_nm;
  s.incidence = job.incidence;
  s.components = job.components;
  s.guarded = job.guarded;
  s.storage = job.storage;
  s.sourceTile.resize(job.incidence.size());
  std::optional<AzimuthalSymmetry> symmetry;
  if (job.symmetryReduced()) symmetry.emplace(job, DirectionGrid(job.gridLayout));
  for (size_t i = 0; i < job.incidence.size(); ++i)
    s.sourceTile[i] = symmetry ? symmetry->representative(int(i)) : int(i);
  return s;
}

}  // namespace mbsdf
