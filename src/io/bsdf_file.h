// The output file (DESIGN.md "HDF5 file"): a self-describing, versioned HDF5 schema.
//   /                       attributes Conventions, schema_version, program_version, job_text, seed,
//                           geometry_hash, geometry_kind, material, grid_kind
//   /spectrum/wavelength_nm (nλ)                           dimension scale
//   /grid/{theta_deg, phi_deg, solid_angle, projected_solid_angle} (nBins, full sphere)
//   /incidence/{bin, theta_deg, phi_deg} (nInc)             `bin` is a dimension scale
//   /bsdf/<component>       float32 (nInc, nλ, nBins), 1/sr, chunk = one incidence slice (split if
//                           > 4 MiB), shuffle + deflate, fill value NaN (unwritten = visible)
//   /bsdf_stderr/<component> the standard error of each value, same layout
//   /bsdf/done              uint8 (nInc), 1 when that slice is complete
//   /stats/...              per slice: samples, seconds, truncated/leaked/missed (nInc, nλ),
//                           energy_reflected/<c>, energy_transmitted/<c> (nInc, nλ) = Σ f·Ω⊥
// The writer writes each tile as it arrives and flushes; it writes to `<path>.partial` and renames
// on completion, so an existing output is never damaged by a failed run.
#pragma once
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/direction_grid.h"
#include "io/hdf5_handle.h"
#include "job/job.h"
#include "scattering/tile_result.h"

namespace mbsdf {

inline constexpr int kSchemaVersion = 1;

class BsdfFileWriter {
 public:
  BsdfFileWriter(const std::string& path, const Job& job, const DirectionGrid& grid);
  ~BsdfFileWriter();
  void writeTile(const TileResult& r);
  // Closes the file and renames it to its final path.
  void finish();

 private:
  std::string path_, partial_;
  const Job& job_;
  const DirectionGrid& grid_;
  H5File file_;
  bool finished_ = false;
};

struct SliceStats {
  uint64_t samples = 0;
  double seconds = 0;
  std::vector<double> truncated, leaked, missed;
  std::map<std::string, std::vector<double>> energyReflected, energyTransmitted;
};

class BsdfFileReader {
 public:
  explicit BsdfFileReader(const std::string& path);
  const std::vector<double>& wavelengths_nm() const { return lambda_nm_; }
  const DirectionGrid& grid() const { return *grid_; }
  int incidenceCount() const { return int(incBin_.size()); }
  int incidenceBin(int i) const { return incBin_[i]; }
  double incidenceTheta(int i) const { return incTheta_[i]; }
  double incidencePhi(int i) const { return incPhi_[i]; }
  std::vector<std::string> components() const;
  bool done(int i) const { return done_[i] != 0; }
  // One slice of a component: nλ x nBins (λ-major), float converted to double.
  std::vector<double> slice(const std::string& component, int incidence) const;
  std::vector<double> sliceStdError(const std::string& component, int incidence) const;
  SliceStats stats(int incidence) const;
  std::string attribute(const std::string& name) const;
  int64_t intAttribute(const std::string& name) const;
  // Incidence index closest (in angle) to the given direction.
  int nearestIncidence(double theta_deg, double phi_deg) const;

 private:
  std::vector<double> readRow(const std::string& dataset, int incidence) const;
  H5File file_;
  std::vector<double> lambda_nm_;
  std::unique_ptr<DirectionGrid> grid_;
  std::vector<int> incBin_;
  std::vector<double> incTheta_, incPhi_;
  std::vector<uint8_t> done_;
};

}  // namespace mbsdf
