// The output file (docs/output.md): a self-describing, versioned HDF5 schema.
//   /                       attributes Conventions, schema_version, program_version, job_text, seed,
//                           geometry_hash, input_files (JSON: key, path and SHA-256 of each file the
//                           job reads), geometry_kind, material, grid_kind
//   /spectrum/wavelength_nm (nλ)                           dimension scale
//   /grid/{theta_deg, phi_deg, solid_angle, projected_solid_angle} (nBins, full sphere)
//   /incidence/{bin, theta_deg, phi_deg} (nInc)             `bin` is a dimension scale
//   /bsdf/<component>       float32 (nInc, nλ, nBins), 1/sr, chunk = one incidence slice (split if
//                           > 4 MiB), shuffle + deflate, fill value NaN (unwritten = visible)
//   /bsdf_stderr/<component> the standard error of each value, same layout
//   Storage profiles (core/storage_profile.h, docs/output.md "Storage profiles"): float16 tables
//   hold each slice and wavelength divided by a power of two, /bsdf_scale/<c> and
//   /bsdf_stderr_scale/<c> (nInc, nλ, 1), so that neither a specular peak overflows nor a tail
//   underflows; with errors per slice /bsdf_stderr is left out (but for the tables the reciprocity
//   fill reads). The root attribute storage_profile says which.
//   /bsdf/done              uint8 (nInc), 1 when that slice is complete
//   /stats/...              per slice: samples, wave_samples, seconds, sampling_stop (0 fixed budget, 1 target
//                           relative error reached, 2 budget spent), truncated/leaked/missed (nInc, nλ),
//                           energy_reflected/<c>, energy_transmitted/<c> (nInc, nλ) = Σ f·Ω⊥,
//                           rel_error/<c> (nInc, nλ): estimated relative standard error,
//                           energy_reflected_stderr/<c>, energy_transmitted_stderr/<c> (nInc, nλ): the
//                           energies' standard errors, paths_albedo_stderr (nInc, nλ): that of the
//                           path-traced components' summed energy, energy_balance and
//                           energy_balance_stderr (nInc, nλ): see writeEnergyBalance
// The writer writes each tile as it arrives and flushes; it writes to `<path>.partial` and renames
// on completion, so an existing output is never damaged by a failed run.
//
// Crash safety (docs/running.md "What a run checks before it computes, and while it writes"): the partial
// file is written in HDF5's single-writer / multiple-reader mode (SWMR, libver latest), whose
// ordered metadata flushes keep the file readable whenever the writer dies. A slice's rows are
// written (each dataset closed, with the close checked: HDF5's chunk cache writes there), flushed
// and fsync'ed; then its done flag, flushed and fsync'ed;
// then its tile number is appended to `<path>.journal` and fsync'ed. Every failed write throws (a
// WriteError where the operating system refused it). `--resume` opens the old partial file as a
// SWMR reader, checks that the job text, the input files' digests and the geometry hash match (an
// InputError saying what differs), keeps the slices that are both marked done in the file and
// listed in the journal, copies them into a fresh partial file and goes on with the rest. A SIGKILL
// therefore loses at most the tiles in flight; a full disk loses none that the journal lists.
//
// Reciprocity (docs/physics.md §8, scattering/reciprocity.h): when the job halves the wave term, each
// tile leaves the reflection bins it did not compute as NaN in /bsdf/incoherent, and completeReciprocal()
// fills them from the reciprocal tiles once every slice is done, before the file gets its final
// name. The stored slices are complete (every reader reads one row), the root attribute
// `reciprocity` says what was computed. The datasets involved are chunked by blocks of exit bins
// so that the fill reads a block of columns of every row once; it only writes entries a tile did
// not compute, so it is idempotent (a kill during the fill is resumed by running it again).
#pragma once
#include <nlohmann/json.hpp>

#include <cmath>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/colour.h"
#include "core/direction_grid.h"
#include "io/hdf5_handle.h"
#include "io/output_schema.h"
#include "scattering/reciprocity.h"
#include "scattering/tile_result.h"

namespace mbsdf {

inline constexpr int kSchemaVersion = 1;

// A chunk of a slice's BSDF table as the file stores it (float32, shuffle + deflate): the rank that
// computed a tile packs its slices (prepareSlice), so that rank 0 writes bytes instead of compressing
// every slice of the run itself. path: the table ("/bsdf/coherent", "/bsdf_stderr/coherent", …);
// (a, b): the chunk's offset in (wavelength, bin); c1 x c2: the chunk shape it was packed for (the
// writer compresses a chunk itself when its file's layout differs).
struct PackedChunk {
  std::string path;
  uint64_t a = 0, b = 0, c1 = 0, c2 = 0;
  std::vector<unsigned char> bytes;
};

// A slice's energy balance per wavelength (BsdfFileWriter::writeEnergyBalance).
// What makes a slice non-physical, a bit each in /stats/nonphysical (per wavelength): its energy
// (Σ f Ω⊥ of the components but lost, both sides) below 0 or above 1 beyond 3 standard errors (and
// 1e-3, the deterministic rules' rounding), its energy balance beyond [scene] tolerance + 3 standard
// errors, or more than the tolerance of its paths truncated at max_depth, leaked or missed.
enum class SliceFlag : uint8_t { NegativeEnergy = 1, ExcessEnergy = 2, Unbalanced = 4, PathsLost = 8 };
std::string describeSliceFlags(unsigned flags);  // "energy below 0, paths lost", or "" for none

struct EnergyBalance {
  std::vector<double> value, stdError;
  std::vector<double> energy;     // Σ f Ω⊥ of the components but lost, both sides (stdError is its error too)
  std::vector<double> pathsLost;  // truncated + leaked + missed
  std::vector<double> flags;      // SliceFlag bits per wavelength (as stored)
  unsigned anyFlags() const {     // the bits of every wavelength
    unsigned f = 0;
    for (double x : flags) f |= unsigned(x);
    return f;
  }
};

// A slice as the file stores it, made where its tile was computed (prepareSlice): its statistics
// rows (every row dataset but the tables: energies, errors, counts, energy balance) and its tables'
// packed chunks. Rank 0 then only writes (BsdfFileWriter::writePrepared).
struct PreparedSlice {
  int index = -1;
  std::map<std::string, std::vector<double>> rows;
  std::vector<PackedChunk> chunks;
};
PreparedSlice prepareSlice(const TileResult& r, const OutputSchema& schema, const DirectionGrid& grid);
// A byte message (between ranks) and back; a malformed one throws.
std::vector<unsigned char> serializePrepared(const PreparedSlice& p);
PreparedSlice deserializePrepared(const std::vector<unsigned char>& bytes);

// Whether `path` is a finished table of the job `schema` describes: the identity --resume checks
// (job text, input files' contents, geometry hash) and every slice done. `run --resume` then has
// nothing to compute.
bool isFinishedOutputOf(const std::string& path, const OutputSchema& schema);

// Why `--resume` computes a slice again that the journal lists as done.
enum class KeptSliceFault {
  EnergiesNotFinite,  // its energies were never written: a forged or damaged done flag
  Unreadable,         // a chunk fails its checksum (Adler-32 of the deflated tables, Fletcher-32 of the rest)
  ValuesDamaged,      // a table holds NaN, an infinity, or a negative value where it cannot
};
struct RecomputedSlice {
  int index = 0;
  KeptSliceFault fault = KeptSliceFault::EnergiesNotFinite;
  std::string dataset;  // the dataset found damaged (empty for EnergiesNotFinite)
};

// The first value of a table row that the program cannot have written: not finite (where
// `unfilled` allows, NaN stands for a mirrored half the reciprocity fill has yet to write), or
// negative in a table of sums of non-negative terms (path tallies, standard errors).
enum class UnfilledHalf { Refused, Allowed };
struct DamagedValue {
  size_t at = 0;
  double value = 0;
};
std::optional<DamagedValue> damagedValueOf(const std::string& path, const std::vector<double>& v,
                                           UnfilledHalf unfilled);

class BsdfFileWriter {
 public:
  // resume: keep the finished slices of an earlier run of the same job (see above). Throws
  // std::runtime_error if the partial file belongs to another job.
  BsdfFileWriter(const std::string& path, OutputSchema schema, const DirectionGrid& grid, bool resume = false);
  ~BsdfFileWriter();
  // Writes a slice (see above); returns its energy balance (writeEnergyBalance).
  using EnergyBalance = mbsdf::EnergyBalance;
  EnergyBalance writeTile(const TileResult& r);
  // The same in two steps, so that several slices (a tile and the slices symmetry maps it to) are
  // committed as one: writeSlice writes a slice's rows and returns its energy balance; commitSlices
  // flushes and syncs them, sets their done flags, flushes and syncs again and journals them with
  // one sync. A slice written but not committed is not done (a resume recomputes it).
  EnergyBalance writeSlice(const TileResult& r);
  // The same for a slice prepared where its tile was computed (prepareSlice for this file's schema
  // and grid: prepare). raw() gives the slice's values where its packed chunks do not fit the file's
  // layout (a file resumed from another layout), which is then compressed here.
  PreparedSlice prepare(const TileResult& r) const;
  EnergyBalance writePrepared(const PreparedSlice& p, const std::function<TileResult()>& raw);
  void commitSlices(const std::vector<int>& indices);
  // Fills the reciprocal half of /bsdf/incoherent (see above); every slice must be done. Returns
  // the mean over slices and wavelengths of the incoherent Σ f·Ω⊥.
  double completeReciprocal(const ReciprocalPairs& pairs);
  // Closes the file and renames it to its final path; removes the journal. With pairs stored once
  // (storage profile) the final file is written anew from the partial one (foldPairs).
  void finish();
  // The reciprocity check of the fold (per component: pairs, mean z² of independent pairs, …).
  const nlohmann::json& pairsReport() const { return pairsReport_; }
  // Closes the partial file cleanly without finishing (clean stop); it stays resumable.
  void close();
  // Incidence indices whose slices are already complete (after a resume).
  const std::vector<int>& resumedTiles() const { return resumed_; }
  // finish() renamed the partial file to the output (even if syncing its folder then failed).
  bool outputInPlace() const { return inPlace_; }
  // Slices the journal listed that the partial file does not hold intact: computed again.
  const std::vector<RecomputedSlice>& recomputedTiles() const { return recomputed_; }

 private:
  void create(const std::string& file);
  // Writes `target`: this file with the reciprocal components' same-side pairs stored once (the
  // mean of both estimates, with its error) in square blocks; every other dataset copied.
  nlohmann::json foldPairs(const std::string& target);
  void appendJournal(const std::vector<int>& tiles);
  // The row datasets stay open while the writer runs (opening one per row cost more than the
  // write); closed, checked, before the file closes.
  struct OpenDataset {
    H5Dataset d;
    // A table whose chunks the writer compresses itself (float32, 3-D, shuffle + deflate): its
    // dimensions, chunk shape and deflate level.
    bool direct = false;
    bool half = false;  // float16 (the profile's), scaled per slice and wavelength
    size_t elemSize = 4;
    hsize_t dims[3] = {0, 0, 0}, chunk[3] = {0, 0, 0};
    int deflateLevel = 0;
  };
  OpenDataset& dataset(const std::string& path);
  // Row i of a dataset, held until the next commit (flushPending), which writes each dataset's
  // consecutive rows with one call: a slice has some thirty small rows, and one write per row was
  // most of rank 0's time per slice. getRow sees the rows held.
  void putRow(const std::string& path, int i, const std::vector<double>& v);
  // The same for a table (/bsdf/…, /bsdf_stderr/…) given its values: a half table's row is held
  // scaled, with its scales. getTable gives the values back.
  void putTable(const std::string& path, int i, const std::vector<double>& v);
  std::vector<double> getTable(const std::string& path, int i);
  void flushPending();
  // Rows i of several tables (path, values): their chunks compressed in parallel, then written as
  // they are (H5Dwrite_chunk), so that HDF5's one-threaded filter pipeline is not rank 0's limit.
  void putTableRows(const std::vector<std::pair<std::string, const std::vector<double>*>>& rows, int i,
                    const std::vector<PackedChunk>* packed);
  std::vector<double> getRow(const std::string& path, int i);
  void closeDatasets();
  // /stats/energy_reflected, energy_transmitted and rel_error of component c for r's slice.
  void writeSliceStats(const TileResult& r, Component c);
  // /stats/energy_balance and its standard error for slice i, from the slice's stored energies:
  // reflected + transmitted + truncated + leaked + missed − 1 over the components but lost. For a
  // lossless material (Material::lossless) the scalar model's energy error; for an absorbing one
  // only an excess over 1 is an error (a deficit is absorption), so only that is stored.
  EnergyBalance writeEnergyBalance(int i);
  std::string path_, partial_, journal_;
  const OutputSchema schema_;
  const DirectionGrid& grid_;
  H5File file_;
  std::map<std::string, OpenDataset> datasets_;                        // declared after file_: closed before it
  std::map<std::string, std::map<int, std::vector<double>>> pending_;  // path → row → values (putRow)
  std::vector<int> resumed_;
  std::vector<RecomputedSlice> recomputed_;
  bool inPlace_ = false;
  nlohmann::json pairsReport_ = nlohmann::json::object();
  bool finished_ = false;
};

struct SliceStats {
  uint64_t samples = 0;
  uint64_t waveSamples = 0;  // Kirchhoff samples per wavelength (0 in files without the dataset)
  double seconds = 0;
  int samplingStop = 0;                 // TileResult::SamplingStop
  double multipleCheck = std::nan("");  // TileResult::multipleCheck (NaN: not verified)
  bool multipleReenabled = false;
  double diffractionCheck = std::nan("");  // TileResult::diffractionCheck (NaN: not verified)
  bool diffractionReenabled = false;
  std::vector<double> truncated, leaked, missed;
  std::map<std::string, std::vector<double>> energyReflected, energyTransmitted;
  std::map<std::string, std::vector<double>> relError;  // per component, per wavelength
  std::vector<double> pathsRelError;  // of the path-traced table, per wavelength (empty in older files)
  // Standard errors of the energies above (empty in files without them), and of the summed energy
  // of the path-traced components (both hemispheres), per wavelength.
  std::map<std::string, std::vector<double>> energyReflectedStdError, energyTransmittedStdError;
  std::vector<double> pathsAlbedoStdError;
  std::vector<double> energyBalance, energyBalanceStdError;  // (writeEnergyBalance) empty in older files
  std::vector<double> nonphysical;                           // SliceFlag bits per wavelength; empty in older files
};

// Seconds the writer spends on one slice of this job's layout (a flush and a journal fsync each),
// measured by writing up to 3 zero slices to a scratch file in the temporary directory: `plan`'s
// estimate of rank 0's serial writing.
double measureWriteSecondsPerSlice(const OutputSchema& schema, const DirectionGrid& grid, int slicesPerCommit);
// Bytes a slice takes in the file, the mean over `tiles` (pilot tiles, each filled as the job's
// paths will fill it): its table chunks compressed as the writer stores them and its statistics
// rows (prepareSlice); a table whose pairs are stored once counts the share of its entries it
// keeps. A component a tile lacks (a guarded skip) counts as zeros. `plan`'s estimate of the file's
// size.
double storedBytesPerSlice(const OutputSchema& schema, const DirectionGrid& grid, const std::vector<TileResult>& tiles);

class BsdfFileReader {
 public:
  explicit BsdfFileReader(const std::string& path);
  // The computed wavelengths (the axis of /stats; of the tables too unless they hold colour).
  const std::vector<double>& wavelengths_nm() const { return lambda_nm_; }
  // The tables' rows per slice: one per wavelength, or three colour channels (storage profile).
  bool spectral() const { return colourSpace_.empty(); }
  int channelCount() const { return int(channels_.size()); }
  const std::vector<std::string>& channelNames() const { return channels_; }  // "450nm", … or "X", "Y", "Z"
  const std::string& colourSpace() const { return colourSpace_; }             // "" when spectral
  // The conversion of a bin's rows to CIE XYZ (of the wavelengths, or of the stored colour);
  // std::invalid_argument when a spectral table has no visible wavelength.
  SpectrumToColour toColour() const;
  const DirectionGrid& grid() const { return *grid_; }
  int incidenceCount() const { return int(incBin_.size()); }
  int incidenceBin(int i) const { return incBin_[i]; }
  double incidenceTheta(int i) const { return incTheta_[i]; }
  double incidencePhi(int i) const { return incPhi_[i]; }
  std::vector<std::string> components() const;
  bool done(int i) const { return done_[i] != 0; }
  int doneCount() const;
  // One slice of a component: nλ x nBins (λ-major), float converted to double.
  std::vector<double> slice(const std::string& component, int incidence) const;
  // Its per-bin standard errors; throws where the file keeps them per slice only (hasBinErrors).
  std::vector<double> sliceStdError(const std::string& component, int incidence) const;
  bool hasBinErrors(const std::string& component) const;
  // How the tables are stored (the root attribute storage_profile; "full" in files before it).
  std::string storageProfile() const;
  SliceStats stats(int incidence) const;
  // A root attribute as text (a number written out in decimal).
  std::string attribute(const std::string& name) const;
  bool hasAttribute(const std::string& name) const;
  int64_t intAttribute(const std::string& name) const;
  // Incidence index closest (in angle) to the given direction.
  int nearestIncidence(double theta_deg, double phi_deg) const;

 private:
  void readStructure(const std::string& path);  // the axes, grid and done flags (the constructor)
  std::vector<double> readTableValues(const std::string& path, int incidence) const;
  std::string path_;
  std::vector<double> readRow(const std::string& dataset, int incidence) const;
  // A table's row, multiplied by its scales in a half-precision file, its mirrored half filled
  // where pairs are stored once.
  std::vector<double> readTable(const std::string& path, int incidence) const;
  struct OpenTable {
    H5Dataset d;
    bool folded = false;         // pairs stored once (the dataset's attribute `pairs`)
    H5Dataset scale;             // a float16 table's scales
    std::vector<double> scales;  // (nInc, rows), read once for a folded table
  };
  const OpenTable& table(const std::string& path) const;
  H5File file_;
  mutable std::map<std::string, OpenTable> tables_;  // declared after file_: closed before it
  std::vector<double> lambda_nm_;
  std::vector<std::string> channels_;
  std::string colourSpace_;
  std::unique_ptr<DirectionGrid> grid_;
  std::vector<int> incBin_;
  std::vector<double> incTheta_, incPhi_;
  std::vector<uint8_t> done_;
};

}  // namespace mbsdf
