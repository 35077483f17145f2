// What an output file holds, as its writer needs it: the provenance it records, its axes
// (wavelengths, incidences; the grid is passed beside it) and which component datasets it has. The
// writer knows nothing of job files: cluster/output_schema_of.h builds this from a job.
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/direction_grid.h"
#include "core/file_digest.h"
#include "core/storage_profile.h"
#include "scattering/components.h"

namespace mbsdf {

struct OutputSchema {
  // Provenance, and the identity a resumed run must match.
  std::string jobText, jobFile;
  std::vector<InputFile> inputFiles;
  std::string geometryKind, geometryHash;
  std::string material;  // its description
  uint64_t seed = 0, pathsPerSlice = 0;
  // Per incidence index, its slice's paths where the job allocates them per slice
  // ([sampling] path_allocation = "equal-error"); empty: pathsPerSlice everywhere.
  std::vector<uint64_t> slicePaths;
  uint64_t pathsFor(int incidence) const { return slicePaths.empty() ? pathsPerSlice : slicePaths[size_t(incidence)]; }
  int64_t maxDepth = 0;
  bool exactIncidence = false;  // incidence_sampling = "exact" (else bin-averaged)
  std::string effectsPlan;      // the effects planner's decisions (JSON); empty unless components = "auto"
  std::string waveEstimator;    // the wave estimator's name; empty without a wave term
  // Why the wave term's stored errors are not vouched for (root attribute `wave_errors`), if so.
  std::optional<std::string> waveErrorsCaveat;
  // Where the scalar model is not vouched for to the tolerance (root attribute `scalar_model`), if so.
  std::optional<std::string> scalarModelCaveat;
  std::string symmetry;  // how the symmetry reduction computed the slices, in words
  // Reciprocity: the wave term computed once per pair of incidence bins (the other half filled by
  // BsdfFileWriter::completeReciprocal), or why not.
  bool halvesWaveByReciprocity = false;
  std::string reciprocityOffReason;
  bool lossless = false;    // the material absorbs nothing: every energy deficit is the model's error
  double tolerance = 0.02;  // [scene] tolerance: the energy balance and lost paths a slice may have
  // Axes and datasets.
  std::vector<double> lambda_nm;
  std::vector<IncidenceDirection> incidence;
  ComponentSet components;
  ComponentSet guarded;  // skipped by the effects planner and verified per slice
  StorageProfile storage;
  // Per incidence index, the computed tile its slice comes from (itself, or its representative
  // under the job's symmetry): two slices from one tile are not independent estimates.
  std::vector<int> sourceTile;
  // The components whose same-side pairs the file stores once (storage.pairs = once): the
  // reciprocal ones (isReciprocal).
  bool foldsPairs(Component c) const {
    return storage.pairs == TablePairs::Once && components.has(c) && isReciprocal(c);
  }

  // Whether component c has a table of per-bin standard errors: always in the per-bin profile, and
  // for the two tables the reciprocity fill reads (incoherent and coherent) when the job halves the
  // wave term, whose filled bins' errors come from them.
  bool storesBinErrors(Component c) const {
    return storage.errors == TableErrors::PerBin ||
           (halvesWaveByReciprocity && (c == Component::Incoherent || c == Component::Coherent));
  }
  // Whether the partial file (during the run) has a table of component c's per-bin errors: the
  // final file's, and those of a table whose pairs the fold averages and rounds to the noise of
  // the mean (dropped from the final file when its errors are per slice).
  bool keepsBinErrorsWhileRunning(Component c) const {
    return storesBinErrors(c) || (foldsPairs(c) && storage.rounding == TableRounding::Noise);
  }
};

}  // namespace mbsdf
