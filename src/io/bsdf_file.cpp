#include "io/bsdf_file.h"
#include "io/noise_rounding.h"

#include <hdf5_hl.h>
#include <fcntl.h>
#include <unistd.h>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>
#include <libdeflate.h>
#include <Imath/half.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <sstream>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <optional>
#include <set>
#include <limits>

#include "core/colour.h"
#include "core/error.h"
#include "core/vecmath.h"
#include "io/output_target.h"
#include "scattering/reciprocity.h"

namespace mbsdf {
namespace {

// Deflate level of the BSDF tables: level 4 took 19 % longer for 1 % less.
constexpr int kTableDeflateLevel = 1;

void setStringAttr(hid_t obj, const std::string& name, const std::string& value) {
  H5Datatype t(H5Tcopy(H5T_C_S1), "H5Tcopy");
  h5check(H5Tset_size(t, std::max<size_t>(1, value.size())), "H5Tset_size");
  h5check(H5Tset_cset(t, H5T_CSET_UTF8), "H5Tset_cset");
  H5Dataspace s(H5Screate(H5S_SCALAR), "H5Screate");
  H5Attribute a(H5Acreate2(obj, name.c_str(), t, s, H5P_DEFAULT, H5P_DEFAULT), "create attribute " + name);
  const char* data = value.empty() ? "" : value.data();
  h5check(H5Awrite(a, t, data), "write attribute " + name);
}

template <class T>
void setScalarAttr(hid_t obj, const std::string& name, hid_t type, T value) {
  H5Dataspace s(H5Screate(H5S_SCALAR), "H5Screate");
  H5Attribute a(H5Acreate2(obj, name.c_str(), type, s, H5P_DEFAULT, H5P_DEFAULT), "create attribute " + name);
  h5check(H5Awrite(a, type, &value), "write attribute " + name);
}

void describe(hid_t obj, const std::string& units, const std::string& longName) {
  setStringAttr(obj, "units", units);
  setStringAttr(obj, "long_name", longName);
}

template <class T>
H5Dataset write1D(hid_t loc, const std::string& name, hid_t type, const std::vector<T>& v, const std::string& units,
                  const std::string& longName, hid_t dcpl = H5P_DEFAULT) {
  hsize_t n = v.size();
  H5Dataspace s(H5Screate_simple(1, &n, nullptr), "H5Screate_simple");
  H5Dataset d(H5Dcreate2(loc, name.c_str(), type, s, H5P_DEFAULT, dcpl, H5P_DEFAULT), "create " + name);
  if (n) h5check(H5Dwrite(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), "write " + name);
  describe(d, units, longName);
  return d;
}

// The chunk of a (nInc, n1, n2) dataset: one incidence slice, split along n1 and then n2 to stay
// <= 4 MiB per chunk (and n2 into blocks of at most maxC2 when given).
std::pair<hsize_t, hsize_t> sliceChunkShape(hsize_t n1, hsize_t n2, size_t typeSize, hsize_t maxC2) {
  const hsize_t maxElems = (4u << 20) / typeSize;
  hsize_t c1 = n1, c2 = n2;
  while (c1 > 1 && c1 * c2 > maxElems) c1 = (c1 + 1) / 2;
  while (c2 > 1 && c1 * c2 > maxElems) c2 = (c2 + 1) / 2;
  if (maxC2 > 0) c2 = std::min(c2, maxC2);
  return {std::max<hsize_t>(1, c1), std::max<hsize_t>(1, c2)};
}

// Slices per chunk of the uncompressed per-slice statistics: a symmetric surface's ring of slices is
// then written in one or two chunks, not one each (on rough-gold one chunk per slice made the
// commit's row writes and flush 0.05 s of rank 0's 0.13 s of writing), while a commit of a single
// slice rewrites a few kilobytes per dataset.
constexpr hsize_t kStatsChunkSlices = 64;

// A per-slice row dataset of scalars (one per incidence), its initial values `v`: chunked by
// kStatsChunkSlices with a Fletcher-32 checksum per chunk, which HDF5 verifies on every read.
template <class T>
H5Dataset writeRows1D(hid_t loc, const std::string& name, hid_t type, const std::vector<T>& v, const std::string& units,
                      const std::string& longName) {
  const hsize_t chunk = std::max<hsize_t>(1, std::min<hsize_t>(v.size(), kStatsChunkSlices));
  H5Plist p(H5Pcreate(H5P_DATASET_CREATE), "H5Pcreate");
  h5check(H5Pset_chunk(p, 1, &chunk), "H5Pset_chunk");
  h5check(H5Pset_fletcher32(p), "H5Pset_fletcher32");
  return write1D(loc, name, type, v, units, longName, p);
}

// The square blocks of a table whose pairs are stored once: kPairBlock incidences x kPairBlock exit
// bins per chunk, so that a slice (a row of blocks) and its mirrored half (a column of blocks) each
// touch n/kPairBlock chunks of a few tens of kilobytes.
constexpr hsize_t kPairBlock = 64;

// A (nInc, a, b) dataset: a compressed table in chunks of one slice (sliceChunkShape) or, with
// `pairBlocks`, in square blocks of the pair matrix (kPairBlock); per-slice statistics in chunks of
// kStatsChunkSlices slices.
H5Dataset create3D(hid_t loc, const std::string& name, hid_t type, hsize_t n0, hsize_t n1, hsize_t n2, double fill,
                   bool compress, hsize_t maxC2 = 0, bool pairBlocks = false) {
  hsize_t dims[3] = {n0, n1, n2};
  H5Dataspace s(H5Screate_simple(3, dims, nullptr), "H5Screate_simple");
  H5Plist p(H5Pcreate(H5P_DATASET_CREATE), "H5Pcreate");
  const auto [c1, c2] = sliceChunkShape(n1, n2, H5Tget_size(type), pairBlocks ? kPairBlock : maxC2);
  hsize_t chunk[3] = {pairBlocks ? std::min(n0, kPairBlock)
                      : compress ? 1
                                 : std::min<hsize_t>(n0, kStatsChunkSlices),
                      c1, c2};
  h5check(H5Pset_chunk(p, 3, chunk), "H5Pset_chunk");
  // Every chunk carries a checksum HDF5 verifies on reading, so that a resume or a reader finds a
  // damaged chunk: zlib's Adler-32 inside each deflated one, Fletcher-32 on the rest.
  if (compress) {
    h5check(H5Pset_shuffle(p), "H5Pset_shuffle");
    h5check(H5Pset_deflate(p, kTableDeflateLevel), "H5Pset_deflate");
  } else {
    h5check(H5Pset_fletcher32(p), "H5Pset_fletcher32");
  }
  if (H5Tequal(type, H5T_NATIVE_FLOAT) > 0) {
    float f = float(fill);
    h5check(H5Pset_fill_value(p, H5T_NATIVE_FLOAT, &f), "H5Pset_fill_value");
  } else {
    h5check(H5Pset_fill_value(p, H5T_NATIVE_DOUBLE, &fill), "H5Pset_fill_value");
  }
  h5check(H5Pset_fill_time(p, H5D_FILL_TIME_ALLOC), "H5Pset_fill_time");
  return H5Dataset(H5Dcreate2(loc, name.c_str(), type, s, H5P_DEFAULT, p, H5P_DEFAULT), "create " + name);
}

// Row `i` (all of dims 1..2) of an open 2D or 3D dataset: the file selection, a memory space of
// the selection's shape (HDF5 then maps it to chunks block by block; a flat one is mapped element
// by element, which cost more than the write) and its value count.
struct RowSelection {
  H5Dataspace file, memory;
  hsize_t n = 0;
};
RowSelection selectRow(hid_t d, const std::string& path, int i) {
  RowSelection s{H5Dataspace(H5Dget_space(d), "H5Dget_space"), H5Dataspace(), 0};
  const int rank = H5Sget_simple_extent_ndims(s.file);
  hsize_t dims[3] = {0, 0, 0};
  H5Sget_simple_extent_dims(s.file, dims, nullptr);
  hsize_t start[3] = {hsize_t(i), 0, 0}, count[3] = {1, rank > 1 ? dims[1] : 1, rank > 2 ? dims[2] : 1};
  h5check(H5Sselect_hyperslab(s.file, H5S_SELECT_SET, start, nullptr, count, nullptr), "select " + path);
  s.memory = H5Dataspace(H5Screate_simple(rank, count, nullptr), "H5Screate_simple");
  s.n = count[1] * count[2];
  return s;
}

// Writes row `i` of an open dataset from doubles, converted on the fly to the dataset's type. The
// chunk cache writes the chunk when the dataset closes or the file is flushed.
void writeRowTo(hid_t d, const std::string& path, int i, const std::vector<double>& v, hid_t memType) {
  const RowSelection s = selectRow(d, path, i);
  if (v.size() != s.n) throw std::runtime_error("HDF5: row size mismatch for " + path);
  h5check(H5Dwrite(d, memType, s.memory, s.file, H5P_DEFAULT, v.data()), "write " + path);
}

// Writes row `i` of the dataset at `path`.
void writeRow(hid_t file, const std::string& path, int i, const std::vector<double>& v, hid_t memType) {
  H5Dataset d(H5Dopen2(file, path.c_str(), H5P_DEFAULT), "open " + path);
  writeRowTo(d, path, i, v, memType);
  // The chunk cache writes the chunk when the dataset closes: an error there (disk full) is only
  // seen by a checked close.
  d.close("write " + path);
}

// The chunk as HDF5's shuffle and deflate filters store it: the values' bytes (elements of
// `elemSize` bytes) regrouped by significance (byte k of every value, then byte k + 1, …), then
// zlib's deflate at `level`.
std::vector<unsigned char> shuffleDeflate(const std::vector<unsigned char>& in, size_t elemSize, int level) {
  const size_t n = in.size() / elemSize, s = elemSize;
  std::vector<unsigned char> shuffled(n * s);
  for (size_t i = 0; i < n; ++i)
    for (size_t b = 0; b < s; ++b) shuffled[b * n + i] = in[i * s + b];
  // libdeflate writes the zlib stream HDF5's deflate filter reads, 2-3 times as fast as zlib
  // itself; one compressor per thread and level (allocating one costs more than a chunk).
  thread_local std::map<int, std::unique_ptr<libdeflate_compressor, void (*)(libdeflate_compressor*)>> compressors;
  auto it = compressors.find(level);
  if (it == compressors.end())
    it = compressors
             .emplace(level, std::unique_ptr<libdeflate_compressor, void (*)(libdeflate_compressor*)>(
                                 libdeflate_alloc_compressor(level), libdeflate_free_compressor))
             .first;
  if (!it->second) throw std::runtime_error("libdeflate: no compressor at level " + std::to_string(level));
  std::vector<unsigned char> out(libdeflate_zlib_compress_bound(it->second.get(), shuffled.size()));
  const size_t size =
      libdeflate_zlib_compress(it->second.get(), shuffled.data(), shuffled.size(), out.data(), out.size());
  if (size == 0) throw std::runtime_error("libdeflate: deflating a chunk failed");
  out.resize(size);
  return out;
}

// IEEE 754 binary16 as the file stores it (HDF5 1.10 has no predefined half type; h5py reads this
// one as numpy's float16).
H5Datatype halfType() {
  H5Datatype t(H5Tcopy(H5T_IEEE_F32LE), "H5Tcopy");
  h5check(H5Tset_fields(t, 15, 10, 5, 0, 10), "H5Tset_fields");
  h5check(H5Tset_precision(t, 16), "H5Tset_precision");
  h5check(H5Tset_size(t, 2), "H5Tset_size");
  h5check(H5Tset_ebias(t, 15), "H5Tset_ebias");
  return t;
}

// The values of one element: single precision, or the bits of half precision (Imath, rounding to
// nearest even).
void storeElement(double x, size_t elemSize, unsigned char* out) {
  if (elemSize == sizeof(float)) {
    const float f = float(x);
    std::memcpy(out, &f, sizeof f);
  } else {
    const uint16_t h = Imath::half(float(x)).bits();
    std::memcpy(out, &h, sizeof h);
  }
}

// Writes doubles to the selection `file` of a table: float32 by HDF5's conversion, or float16 bits
// rounded here as the packed chunks are (storeElement), not by HDF5's own conversion.
void writeValues(hid_t d, hid_t memory, hid_t file, const std::vector<double>& v, bool half, const std::string& path) {
  if (!half) {
    h5check(H5Dwrite(d, H5T_NATIVE_DOUBLE, memory, file, H5P_DEFAULT, v.data()), "write " + path);
    return;
  }
  std::vector<unsigned char> bits(v.size() * 2);
  for (size_t k = 0; k < v.size(); ++k) storeElement(v[k], 2, &bits[2 * k]);
  const H5Datatype t = halfType();
  h5check(H5Dwrite(d, t, memory, file, H5P_DEFAULT, bits.data()), "write " + path);
}

// The bytes of chunk (a, b) of shape c1 x c2 of an n1 x n2 row, elements of `elemSize` bytes; an
// edge chunk is stored whole, the part outside the dataset holding the fill value (NaN).
std::vector<unsigned char> chunkBytes(const std::vector<double>& v, hsize_t n1, hsize_t n2, hsize_t a, hsize_t b,
                                      hsize_t c1, hsize_t c2, size_t elemSize) {
  std::vector<unsigned char> out(c1 * c2 * elemSize);
  for (hsize_t x = 0; x < c1; ++x)
    for (hsize_t y = 0; y < c2; ++y) {
      const bool inside = a + x < n1 && b + y < n2;
      storeElement(inside ? v[(a + x) * n2 + (b + y)] : std::nan(""), elemSize, &out[(x * c2 + y) * elemSize]);
    }
  return out;
}

// A table row (nλ x nBins) in half precision: each wavelength's values over a power of two, chosen
// so that the row's largest |value| falls in [2^14, 2^15). Half's largest finite value is 65504 and
// its relative precision 2^-11 down to 2^-14 (its normal range): a row keeps that precision over 29
// binary orders of magnitude (5·10^8) below its peak, subnormals below that — a specular bin of
// 10^5 /sr or a far tail of 10^-4 /sr alike, which an unscaled half could not hold.
struct ScaledRow {
  std::vector<double> values, scales;  // values / scale (λ-major), scale per wavelength
};
ScaledRow scaleForHalf(const std::vector<double>& v, size_t nL) {
  const size_t nB = nL ? v.size() / nL : 0;
  ScaledRow out{v, std::vector<double>(nL, 1.0)};
  for (size_t l = 0; l < nL; ++l) {
    double peak = 0;
    for (size_t b = 0; b < nB; ++b)
      if (std::isfinite(v[l * nB + b])) peak = std::max(peak, std::abs(v[l * nB + b]));
    if (peak == 0) continue;
    int e = 0;
    std::frexp(peak, &e);  // peak = m 2^e, m in [0.5, 1)
    const double scale = std::ldexp(1.0, e - 15);
    out.scales[l] = scale;
    for (size_t b = 0; b < nB; ++b) out.values[l * nB + b] = v[l * nB + b] / scale;
  }
  return out;
}

// A table's scale dataset in a half-precision file: /bsdf/x -> /bsdf_scale/x,
// /bsdf_stderr/x -> /bsdf_stderr_scale/x.
std::string scalePathOf(const std::string& table) {
  const size_t slash = table.rfind('/');
  return table.substr(0, slash) + "_scale" + table.substr(slash);
}

// The tables a schema stores: each component's values and, where the profile keeps them, its
// per-bin standard errors — in the final file, or (`running`) in the partial file of the run, which
// also keeps the errors the fold rounds the mean of a pair with.
struct TableRef {
  std::string path;
  Component c;
  bool error;
};
enum class FileStage { Running, Final };
std::vector<TableRef> tablesOf(const OutputSchema& schema, FileStage stage = FileStage::Running) {
  std::vector<TableRef> out;
  for (Component c : schema.components.list()) {
    out.push_back({std::string("/bsdf/") + componentName(c), c, false});
    if (stage == FileStage::Running ? schema.keepsBinErrorsWhileRunning(c) : schema.storesBinErrors(c))
      out.push_back({std::string("/bsdf_stderr/") + componentName(c), c, true});
  }
  return out;
}
size_t tableElementSize(const OutputSchema& schema) {
  return schema.storage.values == TableValues::Float16 ? 2 : sizeof(float);
}

// Rows of a table per slice: the wavelengths, or three colour channels.
int channelCount(const OutputSchema& schema) {
  return schema.storage.spectral() ? int(schema.lambda_nm.size()) : 3;
}

// Each wavelength's weight in each colour channel (core/colour.h: CIE 1931 XYZ, each sample standing
// for its band, Y = 1 for a spectrum of 1; linear sRGB through the E -> D65 adaptation).
std::vector<Colour3> channelWeights(const OutputSchema& schema) {
  std::vector<Colour3> w = SpectrumToColour(schema.lambda_nm).weights();
  if (schema.storage.colour == TableColour::LinearSrgb)
    for (Colour3& c : w) c = xyzToLinearSrgb(c);
  return w;
}

// The row a table stores for one slice (nλ x nBins as computed): the same, or its colour, channel
// c = Σ_λ w_λc f_λ; for a table of standard errors Σ_λ |w_λc| σ_λ, exact where the wavelengths'
// errors are fully correlated (they share their paths) and an upper bound otherwise.
std::vector<double> storedRow(const std::vector<double>& v, bool error, const OutputSchema& schema,
                              const std::vector<Colour3>& weights) {
  if (schema.storage.spectral()) return v;
  const size_t nL = weights.size(), nB = nL ? v.size() / nL : 0;
  std::vector<double> out(3 * nB, 0.0);
  for (size_t l = 0; l < nL; ++l)
    for (size_t c = 0; c < 3; ++c) {
      const double w = error ? std::abs(weights[l][c]) : weights[l][c];
      if (w == 0) continue;
      for (size_t b = 0; b < nB; ++b) out[c * nB + b] += w * v[l * nB + b];
    }
  return out;
}

// The row table t stores for slice r (storedRow), rounded to its noise where the profile says so:
// a value by its own error (as stored, in colour the channel's error), an error to kErrorBits bits.
std::vector<double> storedTableRow(const TileResult& r, const TableRef& t, const OutputSchema& schema,
                                   const std::vector<Colour3>& weights) {
  std::vector<double> row = storedRow(t.error ? r.stdError[int(t.c)] : r.value[int(t.c)], t.error, schema, weights);
  if (schema.storage.rounding == TableRounding::Noise) {
    if (t.error)
      roundErrorRow(row);
    else
      roundRowToNoise(row, storedRow(r.stdError[int(t.c)], true, schema, weights));
  }
  return row;
}

// The chunk at (a, b) of table `path` among `packed` if it was packed for this layout (chunks of
// c1 x c2, the tables' deflate level), else none.
const std::vector<unsigned char>* packedChunkFor(const std::vector<PackedChunk>* packed, const std::string& path,
                                                 hsize_t a, hsize_t b, hsize_t c1, hsize_t c2, int level) {
  if (!packed || level != kTableDeflateLevel) return nullptr;
  for (const PackedChunk& c : *packed)
    if (c.path == path && c.a == a && c.b == b && c.c1 == c1 && c.c2 == c2) return &c.bytes;
  return nullptr;
}

// Whether an open dataset stores IEEE binary16 (a float16 table).
bool storesHalf(hid_t d) {
  H5Datatype t(H5Dget_type(d), "H5Dget_type");
  return H5Tget_class(t) == H5T_FLOAT && H5Tget_size(t) == 2;
}

// The selection `file` of dataset d (n elements, laid out as `memory`) as T (double or float). A
// float16 table is read as its own bits and widened by Imath's table: HDF5 converts a half type it
// has no native match for bit by bit in software, which made reading a compact file 5 times slower.
template <typename T>
std::vector<T> readSelection(hid_t d, hid_t memory, hid_t file, size_t n, const std::string& path) {
  std::vector<T> v(n);
  if (storesHalf(d)) {
    std::vector<uint16_t> bits(n);
    const H5Datatype t = halfType();
    h5check(H5Dread(d, t, memory, file, H5P_DEFAULT, bits.data()), "read " + path);
    for (size_t k = 0; k < n; ++k) v[k] = T(float(Imath::half(Imath::half::FromBits, bits[k])));
    return v;
  }
  h5check(
      H5Dread(d, std::is_same_v<T, float> ? H5T_NATIVE_FLOAT : H5T_NATIVE_DOUBLE, memory, file, H5P_DEFAULT, v.data()),
      "read " + path);
  return v;
}

// Row `i` of an open dataset, as doubles.
std::vector<double> readRowFrom(hid_t d, const std::string& path, int i) {
  const RowSelection s = selectRow(d, path, i);
  return readSelection<double>(d, s.memory, s.file, s.n, path);
}

std::vector<double> readRowImpl(hid_t file, const std::string& path, int i) {
  H5Dataset d(H5Dopen2(file, path.c_str(), H5P_DEFAULT), "open " + path);
  return readRowFrom(d, path, i);
}

template <class T>
std::vector<T> read1D(hid_t file, const std::string& path, hid_t type) {
  H5Dataset d(H5Dopen2(file, path.c_str(), H5P_DEFAULT), "open " + path);
  H5Dataspace fs(H5Dget_space(d), "H5Dget_space");
  hssize_t n = H5Sget_simple_extent_npoints(fs);
  std::vector<T> v(size_t(std::max<hssize_t>(0, n)));
  if (n > 0) h5check(H5Dread(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), "read " + path);
  return v;
}

// Every dataset that holds one row per incidence slice.
std::vector<std::string> rowDatasets(const OutputSchema& schema, FileStage stage = FileStage::Running) {
  std::vector<std::string> v;
  for (const TableRef& t : tablesOf(schema, stage)) {
    v.push_back(t.path);
    if (schema.storage.values == TableValues::Float16) v.push_back(scalePathOf(t.path));
  }
  for (Component c : schema.components.list()) {
    std::string n = componentName(c);
    for (const char* g : {"/stats/energy_reflected/", "/stats/energy_transmitted/", "/stats/energy_reflected_stderr/",
                          "/stats/energy_transmitted_stderr/", "/stats/rel_error/"})
      v.push_back(g + n);
  }
  for (const char* n :
       {"/stats/truncated", "/stats/leaked", "/stats/missed", "/stats/samples", "/stats/wave_samples", "/stats/rays",
        "/stats/seconds", "/stats/sampling_stop", "/stats/paths_albedo_stderr", "/stats/paths_rel_error",
        "/stats/energy_balance", "/stats/energy_balance_stderr", "/stats/nonphysical", "/bsdf/done"})
    v.push_back(n);
  if (schema.guarded.has(Component::Multiple))
    for (const char* n : {"/stats/multiple_check", "/stats/multiple_reenabled"}) v.push_back(n);
  if (schema.guarded.has(Component::Incoherent))
    for (const char* n : {"/stats/diffraction_check", "/stats/diffraction_reenabled"}) v.push_back(n);
  return v;
}

// Exit-bin block of the reciprocity fill: the fill holds a block of columns of every row for four
// datasets (incoherent and coherent, value and error) as doubles within this budget. The datasets it
// reads are chunked by the same block, so each chunk is decompressed once per fill.
constexpr double kFillBudgetBytes = 256.0 * 1024 * 1024;
hsize_t fillBlock(int nInc, int nL, int nB) {
  const double perColumn = double(nInc) * nL * 4 * sizeof(double);
  return hsize_t(std::clamp(kFillBudgetBytes / perColumn, 1.0, double(nB)));
}

// Columns [c0, c0 + w) of every row of a (nInc, nλ, nBins) dataset: (nInc, nλ, w), as doubles.
std::vector<double> readColumns(hid_t file, const std::string& path, hsize_t c0, hsize_t w) {
  H5Dataset d(H5Dopen2(file, path.c_str(), H5P_DEFAULT), "open " + path);
  H5Dataspace fs(H5Dget_space(d), "H5Dget_space");
  hsize_t dims[3] = {0, 0, 0};
  H5Sget_simple_extent_dims(fs, dims, nullptr);
  hsize_t start[3] = {0, 0, c0}, count[3] = {dims[0], dims[1], w};
  h5check(H5Sselect_hyperslab(fs, H5S_SELECT_SET, start, nullptr, count, nullptr), "select " + path);
  H5Dataspace ms(H5Screate_simple(3, count, nullptr), "H5Screate_simple");  // the selection's shape
  return readSelection<double>(d, ms, fs, count[0] * count[1] * count[2], path);
}

}  // namespace

double measureWriteSecondsPerSlice(const OutputSchema& schema, const DirectionGrid& grid, int slicesPerCommit) {
  const std::string scratch =
      (std::filesystem::temp_directory_path() / ("microbsdf-plan-" + std::to_string(::getpid()) + ".h5")).string();
  const int nL = int(schema.lambda_nm.size()), nB = grid.binCount();
  TileResult dummy;
  dummy.nLambda = nL;
  dummy.nBins = nB;
  for (Component c : schema.components.list()) {
    dummy.value[int(c)].assign(size_t(nL) * nB, 0.0);
    dummy.stdError[int(c)].assign(size_t(nL) * nB, 0.0);
  }
  dummy.truncated = dummy.leaked = dummy.missed = std::vector<double>(size_t(nL), 0.0);
  // As the run writes them: the slices of a computed tile (it and those symmetry maps it to) are
  // written, then committed as one (flushes, syncs, the journal), so a commit's cost is shared by
  // the tile's slices; one commit per slice counted 40 times what rank 0 spends on an isotropic job
  // of 60 slices per tile. Up to three commits of at most 64 slices in all (beyond, a commit is
  // taken to grow with its slices).
  const int nInc = int(schema.incidence.size());
  const int perCommit = std::clamp(slicesPerCommit, 1, 64);
  double seconds = 0;
  int written = 0;
  {
    BsdfFileWriter w(scratch, schema, grid);
    const int commits = std::clamp(64 / perCommit, 1, 3);
    for (int c = 0; c < commits && written < nInc; ++c) {
      std::vector<int> slices;
      const auto t0 = std::chrono::steady_clock::now();
      for (int k = 0; k < perCommit && written < nInc; ++k, ++written) {
        dummy.tile = dummy.incidenceIndex = written;
        w.writeSlice(dummy);
        slices.push_back(written);
      }
      w.commitSlices(slices);
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
  }
  seconds /= std::max(1, written);
  for (const char* ext : {"", ".partial", ".journal"}) std::filesystem::remove(scratch + ext);
  return seconds;
}

namespace {

std::string readStringAttr(hid_t obj, const std::string& name) {
  H5Attribute a(H5Aopen(obj, name.c_str(), H5P_DEFAULT), "open attribute " + name);
  H5Datatype t(H5Aget_type(a), "H5Aget_type");
  // A number (seed, paths_per_slice, …) as text: read in its class, not as bytes of a string.
  if (H5Tget_class(t) == H5T_INTEGER) {
    int64_t v = 0;
    h5check(H5Aread(a, H5T_NATIVE_INT64, &v), "read attribute " + name);
    return std::to_string(v);
  }
  if (H5Tget_class(t) == H5T_FLOAT) {
    double v = 0;
    h5check(H5Aread(a, H5T_NATIVE_DOUBLE, &v), "read attribute " + name);
    return fmt::format("{}", v);
  }
  std::string text(H5Tget_size(t), '\0');
  h5check(H5Aread(a, t, text.data()), "read attribute " + name);
  while (!text.empty() && text.back() == '\0') text.pop_back();
  return text;
}

std::vector<std::string> linesOf(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

// The text without comments and white space (a '#' outside a string starts a comment in TOML).
std::string tomlSkeleton(const std::string& text) {
  std::string out;
  for (const auto& line : linesOf(text)) {
    char quote = 0;
    for (char ch : line) {
      if (quote) {
        if (ch == quote) quote = 0;
      } else if (ch == '"' || ch == '\'') {
        quote = ch;
      } else if (ch == '#') {
        break;
      }
      if (!std::isspace(static_cast<unsigned char>(ch))) out += ch;
    }
    if (!out.empty() && out.back() != '\n') out += '\n';  // blank and comment lines leave nothing
  }
  return out;
}

// What differs between the job text stored in a partial file and the job's text ("" if nothing).
std::string jobTextDifference(const std::string& stored, const std::string& now) {
  if (stored == now) return "";
  const auto a = linesOf(stored), b = linesOf(now);
  size_t i = 0;
  while (i < a.size() && i < b.size() && a[i] == b[i]) ++i;
  auto show = [](const std::vector<std::string>& v, size_t k) {
    return k < v.size() ? "'" + v[k] + "'" : std::string("(end of file)");
  };
  std::string what =
      "the job text differs from line " + std::to_string(i + 1) + ": was " + show(a, i) + ", is now " + show(b, i);
  if (tomlSkeleton(stored) == tomlSkeleton(now)) what += " (only comments or white space differ)";
  return what;
}

// What differs between the input files recorded in a partial file and the job's ("" if nothing).
std::string inputFilesDifference(const std::string& storedJson, const std::vector<InputFile>& now) {
  std::map<std::string, std::pair<std::string, std::string>> stored;
  if (!storedJson.empty())
    for (const auto& e : nlohmann::json::parse(storedJson))
      stored[e.at("key").get<std::string>()] = {e.at("path").get<std::string>(), e.at("sha256").get<std::string>()};
  std::string what;
  auto add = [&](const std::string& s) { what += (what.empty() ? "" : "; ") + s; };
  for (const auto& f : now) {
    auto it = stored.find(f.key);
    if (it == stored.end())
      add(f.key + " " + f.path + " was not an input of the partial file");
    else if (it->second.first != f.path)
      add(f.key + " was " + it->second.first + ", is now " + f.path);
    else if (it->second.second != f.sha256)
      add(f.path + " (" + f.key + ") changed since the partial file was written: SHA-256 was " +
          it->second.second.substr(0, 16) + "..., is now " + f.sha256.substr(0, 16) + "...");
    if (it != stored.end()) stored.erase(it);
  }
  for (const auto& [key, v] : stored) add(key + " " + v.first + " is no longer an input");
  return what;
}

std::string inputFilesJson(const std::vector<InputFile>& files) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& f : files) j.push_back({{"key", f.key}, {"path", f.path}, {"sha256", f.sha256}});
  return j.dump();
}

// fsync of the HDF5 file's descriptor (sec2 driver): the slice is on the disk, not only in the page
// cache, before the journal says so.
void syncHdf5File(hid_t file, const std::string& name) {
  void* handle = nullptr;
  h5check(H5Fget_vfd_handle(file, H5P_DEFAULT, &handle), "get the file descriptor of " + name);
  if (handle && ::fsync(*static_cast<int*>(handle)) != 0) throw WriteError(osErrorMessage("fsync", name, errno));
}

void renameChecked(const std::string& from, const std::string& to) {
  if (std::rename(from.c_str(), to.c_str()) != 0) throw WriteError(osErrorMessage("rename to " + to, from, errno));
}

// How the file a run wrote differs from what `schema` would write — identity, not only text: the job
// text, every input file's content and the geometry built; "" when it is the same job.
std::string identityDifference(hid_t file, const OutputSchema& schema) {
  std::string differs = jobTextDifference(readStringAttr(file, "job_text"), schema.jobText);
  const std::string inputs = H5Aexists(file, "input_files") > 0 ? readStringAttr(file, "input_files") : "";
  if (differs.empty()) differs = inputFilesDifference(inputs, schema.inputFiles);
  const std::string storedHash = readStringAttr(file, "geometry_hash");
  if (differs.empty() && storedHash != schema.geometryHash)
    differs = "the microgeometry built from the job differs (geometry hash " + storedHash + ", now " +
              schema.geometryHash + ")";
  return differs;
}

// What a resume reads from the old partial file: an HDF5 failure there is a damaged file (truncated,
// overwritten), which the user must remove, not a failure of this run.
template <typename Read>
auto readingPartial(const std::string& partial, const std::string& journal, Read read) {
  try {
    return read();
  } catch (const InputError&) {
    throw;
  } catch (const WriteError&) {
    throw;
  } catch (const std::runtime_error& e) {
    throw InputError("cannot resume " + partial + ": it is damaged or not a partial table of this program (" +
                     e.what() + "). Remove " + partial + " and " + journal +
                     " (or run without --resume) to start over");
  }
}

// Slice t of the old partial file into `rows`, verified: every chunk read passes HDF5's checksum
// (Adler-32 inside each deflated table chunk, Fletcher-32 on the statistics), the energies are
// finite (a done flag over rows never written is forged or damaged) and no table holds a value the
// program cannot have written. A fault says which, and the slice is computed again.
std::optional<RecomputedSlice> readKeptSlice(hid_t old, const OutputSchema& schema, int t,
                                             std::map<std::string, std::vector<double>>& rows) {
  const UnfilledHalf unfilled = schema.halvesWaveByReciprocity ? UnfilledHalf::Allowed : UnfilledHalf::Refused;
  for (const auto& d : rowDatasets(schema)) {
    // (a partial file of an older version lacks some statistics)
    if (H5Lexists(old, d.substr(0, d.rfind('/')).c_str(), H5P_DEFAULT) <= 0 ||
        H5Lexists(old, d.c_str(), H5P_DEFAULT) <= 0)
      continue;
    try {
      rows[d] = readRowImpl(old, d, t);
    } catch (const std::runtime_error&) {
      return RecomputedSlice{t, KeptSliceFault::Unreadable, d};
    }
    const std::vector<double>& v = rows[d];
    if (d.rfind("/stats/energy_", 0) == 0 &&
        !std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); }))
      return RecomputedSlice{t, KeptSliceFault::EnergiesNotFinite, ""};
    const bool table = (d.rfind("/bsdf/", 0) == 0 && d != "/bsdf/done") || d.rfind("/bsdf_stderr/", 0) == 0;
    if (table && damagedValueOf(d, v, unfilled)) return RecomputedSlice{t, KeptSliceFault::ValuesDamaged, d};
  }
  return std::nullopt;
}

}  // namespace

std::optional<DamagedValue> damagedValueOf(const std::string& path, const std::vector<double>& v,
                                           UnfilledHalf unfilled) {
  // Path tallies (coherent, multiple, geo_masked) and every standard error are sums of
  // non-negative terms; incoherent and lost are differences and may be negative. Only the
  // incoherent tables wait for the reciprocity fill.
  const bool nonNegative = path.rfind("/bsdf_stderr/", 0) == 0 || path == "/bsdf/coherent" ||
                           path == "/bsdf/multiple" || path == "/bsdf/geo_masked";
  const bool mayWait =
      unfilled == UnfilledHalf::Allowed && path.size() >= 11 && path.compare(path.size() - 11, 11, "/incoherent") == 0;
  for (size_t k = 0; k < v.size(); ++k) {
    if (std::isnan(v[k]) && mayWait) continue;
    if (!std::isfinite(v[k]) || (nonNegative && v[k] < 0)) return DamagedValue{k, v[k]};
  }
  return std::nullopt;
}

bool isFinishedOutputOf(const std::string& path, const OutputSchema& schema) {
  if (!std::filesystem::is_regular_file(path) || H5Fis_hdf5(path.c_str()) <= 0) return false;
  try {
    H5File f(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), "open " + path);
    if (H5Aexists(f, "job_text") <= 0 || H5Aexists(f, "geometry_hash") <= 0 || !identityDifference(f, schema).empty() ||
        H5Lexists(f, "/bsdf/done", H5P_DEFAULT) <= 0)
      return false;
    const std::vector<uint8_t> done = read1D<uint8_t>(f, "/bsdf/done", H5T_NATIVE_UINT8);
    return done.size() == schema.incidence.size() && std::all_of(done.begin(), done.end(), [](uint8_t d) { return d; });
  } catch (const std::exception&) {
    return false;  // not a table this program can read: the run makes it anew
  }
}

BsdfFileWriter::BsdfFileWriter(const std::string& path, OutputSchema outputSchema, const DirectionGrid& grid,
                               bool resume)
    : path_(path),
      partial_(path + ".partial"),
      journal_(path + ".journal"),
      schema_(std::move(outputSchema)),
      grid_(grid) {
  const OutputSchema& schema = schema_;
  if (auto dir = std::filesystem::path(path).parent_path(); !dir.empty()) std::filesystem::create_directories(dir);
  std::set<int> journaled;
  if (resume && std::filesystem::exists(partial_) && std::filesystem::exists(journal_)) {
    std::ifstream j(journal_);
    std::string word;
    int t;
    while (j >> word >> t)
      if (word == "tile") journaled.insert(t);
  }
  if (journaled.empty()) {
    std::filesystem::remove(journal_);
    create(partial_);
    return;
  }
  // Resume: copy the finished slices of the old partial file (opened as a SWMR reader: readable
  // even if its writer was killed) into a new one.
  const std::string fresh = partial_ + ".new";
  auto fromOld = [&](auto read) { return readingPartial(partial_, journal_, read); };
  {
    H5File old = fromOld([&] {
      // One read of each piece of metadata: a SWMR reader retries a checksum failure (its writer
      // may be mid-write) for minutes, but this file's writer is gone (the lock was taken), so a
      // failure is damage.
      H5Plist fapl(H5Pcreate(H5P_FILE_ACCESS), "H5Pcreate");
      h5check(H5Pset_metadata_read_attempts(fapl, 1), "H5Pset_metadata_read_attempts");
      return H5File(H5Fopen(partial_.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, fapl),
                    "open " + partial_ + " to resume");
    });
    const std::string differs = fromOld([&] { return identityDifference(old, schema); });
    if (!differs.empty())
      throw InputError("cannot resume " + partial_ + ": " + differs + ". Restore what changed, or remove " + partial_ +
                       " and " + journal_ + " (or run without --resume) to start over");
    const std::vector<uint8_t> done = fromOld([&] { return read1D<uint8_t>(old, "/bsdf/done", H5T_NATIVE_UINT8); });
    create(fresh);
    for (int t : journaled) {
      if (t < 0 || t >= int(done.size()) || !done[t]) continue;
      std::map<std::string, std::vector<double>> kept;
      if (std::optional<RecomputedSlice> fault = readKeptSlice(old, schema, t, kept)) {
        recomputed_.push_back(*fault);
        continue;
      }
      for (const auto& [d, row] : kept) writeRow(file_, d, t, row, H5T_NATIVE_DOUBLE);
      resumed_.push_back(t);
    }
    h5check(H5Fflush(file_, H5F_SCOPE_GLOBAL), "flush " + fresh);
    syncHdf5File(file_, fresh);
  }
  renameChecked(fresh, partial_);
  // Rewrite the journal with what was kept (atomically).
  {
    const std::string next = journal_ + ".new";
    std::string text;
    for (int t : resumed_) text += "tile " + std::to_string(t) + "\n";
    const int fd = ::open(next.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) throw WriteError(osErrorMessage("create", next, errno));
    const bool ok = ::write(fd, text.data(), text.size()) == ssize_t(text.size()) && ::fsync(fd) == 0;
    const int err = errno;
    ::close(fd);
    if (!ok) throw WriteError(osErrorMessage("write", next, err));
  }
  renameChecked(journal_ + ".new", journal_);
}

// The root attributes: provenance, the identity a resume checks, how the run computed the slices.
static void writeProvenance(hid_t f, const OutputSchema& schema) {
  setStringAttr(f, "Conventions", "microbsdf-" + std::to_string(kSchemaVersion));
  setScalarAttr<int64_t>(f, "schema_version", H5T_NATIVE_INT64, kSchemaVersion);
  setStringAttr(f, "program_version", MICROBSDF_VERSION);
  setStringAttr(f, "job_text", schema.jobText);
  setStringAttr(f, "job_file", schema.jobFile);
  setScalarAttr<uint64_t>(f, "seed", H5T_NATIVE_UINT64, schema.seed);
  setStringAttr(f, "geometry_hash", schema.geometryHash);
  setStringAttr(f, "input_files", inputFilesJson(schema.inputFiles));
  setStringAttr(f, "geometry_kind", schema.geometryKind);
  setStringAttr(f, "material", schema.material);
  setScalarAttr<uint64_t>(f, "paths_per_slice", H5T_NATIVE_UINT64, schema.pathsPerSlice);
  if (!schema.slicePaths.empty())
    setStringAttr(f, "path_allocation",
                  "equal-error: paths_per_slice is the largest slice's; each slice's paths are in /stats/samples, "
                  "chosen so that with its pairs stored once every slice has about the error of the one the fold "
                  "helps least");
  setScalarAttr<int64_t>(f, "max_depth", H5T_NATIVE_INT64, schema.maxDepth);
  setStringAttr(f, "title", "Tabulated BSDF of a surface microgeometry (microbsdf)");
  setStringAttr(f, "incidence_sampling", schema.exactIncidence ? "exact" : "bin");
  if (!schema.effectsPlan.empty()) setStringAttr(f, "effects_plan", schema.effectsPlan);
  if (!schema.waveEstimator.empty()) setStringAttr(f, "wave_estimator", schema.waveEstimator);
  if (schema.waveErrorsCaveat) setStringAttr(f, "wave_errors", *schema.waveErrorsCaveat);
  if (schema.scalarModelCaveat) setStringAttr(f, "scalar_model", *schema.scalarModelCaveat);
  setStringAttr(f, "symmetry", schema.symmetry);
  std::string storage = schema.storage.name() + ": " +
                        (schema.storage.values == TableValues::Float16
                             ? "float16 tables, each slice and row (wavelength or colour channel) multiplied by its "
                               "/bsdf_scale (or /bsdf_stderr_scale) power of two"
                             : "float32 tables");
  storage += schema.storage.spectral() ? "; spectral tables (a row per wavelength)"
             : schema.storage.colour == TableColour::Xyz
                 ? "; tables in CIE XYZ (rows X, Y, Z; /colour/weights from the wavelengths)"
                 : "; tables in linear sRGB (rows R, G, B; /colour/weights from the wavelengths)";
  bool someBinErrors = false;
  for (Component c : schema.components.list()) someBinErrors = someBinErrors || schema.storesBinErrors(c);
  storage += schema.storage.errors == TableErrors::PerBin ? "; standard errors per bin in /bsdf_stderr"
             : someBinErrors ? "; standard errors per slice in /stats, and per bin in /bsdf_stderr for incoherent "
                               "and coherent only (the reciprocity fill's)"
                             : "; standard errors per slice in /stats";
  setStringAttr(f, "storage_profile", storage);
  const bool halved = schema.halvesWaveByReciprocity;
  setStringAttr(f, "reciprocity",
                halved ? "wave term computed once per pair of incidence bins on the same side; the other half of "
                         "/bsdf/incoherent is f_ws(o->i) - coherent(i->o) (docs/physics.md section 8)"
                       : "not used: " + schema.reciprocityOffReason);
}

// The axes: /spectrum, /grid (bins with their solid angles) and /incidence.
static void writeAxes(hid_t f, const OutputSchema& schema, const DirectionGrid& grid) {
  const int nB = grid.binCount();
  {
    H5Group g(H5Gcreate2(f, "spectrum", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /spectrum");
    write1D(g, "wavelength_nm", H5T_NATIVE_DOUBLE, schema.lambda_nm, "nm", "vacuum wavelength");
  }
  if (!schema.storage.spectral()) {
    // The tables' channels and the conversion that made them from the computed spectrum.
    const bool xyz = schema.storage.colour == TableColour::Xyz;
    H5Group g(H5Gcreate2(f, "colour", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /colour");
    setStringAttr(g, "space",
                  xyz ? "CIE 1931 XYZ (2 degree observer)"
                      : "linear sRGB (D65 white; from CIE 1931 XYZ with a Bradford adaptation E -> D65)");
    setStringAttr(g, "channels", xyz ? "X,Y,Z" : "R,G,B");
    const std::vector<Colour3> w = channelWeights(schema);
    std::vector<double> flat;
    for (const Colour3& c : w) flat.insert(flat.end(), c.begin(), c.end());
    hsize_t dims[2] = {w.size(), 3};
    H5Dataspace sp(H5Screate_simple(2, dims, nullptr), "H5Screate_simple");
    H5Dataset d(H5Dcreate2(g, "weights", H5T_NATIVE_DOUBLE, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                "create /colour/weights");
    h5check(H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, flat.data()), "write /colour/weights");
    describe(d, "1",
             "channel c of every table = sum over the wavelengths l of weights[l][c] * f(l) (each wavelength standing "
             "for its band, Y = 1 for a spectrum of 1); a table of standard errors sums |weights[l][c]| * stderr(l)");
  }
  {
    H5Group g(H5Gcreate2(f, "grid", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /grid");
    setStringAttr(g, "kind", grid.kind());
    if (auto* tp = std::get_if<ThetaPhiGrid>(&grid.layout())) {
      setScalarAttr<int64_t>(g, "n_theta", H5T_NATIVE_INT64, tp->nTheta);
      setScalarAttr<int64_t>(g, "n_phi", H5T_NATIVE_INT64, tp->nPhi);
    } else if (auto* dk = std::get_if<DiskGrid>(&grid.layout())) {
      setScalarAttr<int64_t>(g, "width", H5T_NATIVE_INT64, dk->width);
      setScalarAttr<int64_t>(g, "height", H5T_NATIVE_INT64, dk->height);
    }
    setStringAttr(g, "bin_order", "hemisphere-major (upper z>=0 first), then local index");
    std::vector<double> th(nB), ph(nB), om(nB), op(nB);
    for (int b = 0; b < nB; ++b) {
      Vec3 c = grid.centre(b);
      th[b] = degrees(sphericalTheta(c));
      ph[b] = degrees(sphericalPhi(c));
      om[b] = grid.solidAngle(b);
      op[b] = grid.projectedSolidAngle(b);
    }
    H5Dataset bt = write1D(g, "theta_deg", H5T_NATIVE_DOUBLE, th, "degree", "polar angle of the bin centre from +z");
    write1D(g, "phi_deg", H5T_NATIVE_DOUBLE, ph, "degree", "azimuth of the bin centre from +x");
    write1D(g, "solid_angle", H5T_NATIVE_DOUBLE, om, "sr", "solid angle of the bin");
    write1D(g, "projected_solid_angle", H5T_NATIVE_DOUBLE, op, "sr", "projected solid angle of the bin");
  }
  {
    H5Group g(H5Gcreate2(f, "incidence", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /incidence");
    std::vector<int32_t> bin;
    std::vector<double> th, ph;
    for (auto& i : schema.incidence) {
      bin.push_back(i.bin);
      th.push_back(i.theta_deg);
      ph.push_back(i.phi_deg);
    }
    write1D(g, "bin", H5T_NATIVE_INT32, bin, "1", "sphere bin of the incidence direction");
    write1D(g, "theta_deg", H5T_NATIVE_DOUBLE, th, "degree", "requested incidence polar angle");
    write1D(g, "phi_deg", H5T_NATIVE_DOUBLE, ph, "degree", "requested incidence azimuth");
  }
}

// /bsdf, /bsdf_stderr and /stats, every slice not yet written (NaN, done = 0).
// pairLayout: the final file of a run that stores pairs once (BsdfFileWriter::foldPairs): the folded
// tables in square blocks, the others as during the run.
static void createTables(hid_t f, const OutputSchema& schema, const DirectionGrid& grid, bool pairLayout = false) {
  const int nB = grid.binCount(), nL = int(schema.lambda_nm.size()), nI = int(schema.incidence.size()),
            nC = channelCount(schema);
  const bool halved = schema.halvesWaveByReciprocity;
  {
    H5Group b(H5Gcreate2(f, "bsdf", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /bsdf");
    const std::vector<TableRef> tables = tablesOf(schema, pairLayout ? FileStage::Final : FileStage::Running);
    const bool binErrors = std::any_of(tables.begin(), tables.end(), [](const TableRef& t) { return t.error; });
    std::optional<H5Group> e;
    if (binErrors)
      e.emplace(H5Gcreate2(f, "bsdf_stderr", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /bsdf_stderr");
    H5Group s(H5Gcreate2(f, "stats", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /stats");
    H5Group er(H5Gcreate2(s, "energy_reflected", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create group");
    H5Group et(H5Gcreate2(s, "energy_transmitted", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create group");
    H5Group re(H5Gcreate2(s, "rel_error", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create group");
    H5Group ser(H5Gcreate2(s, "energy_reflected_stderr", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create group");
    H5Group set(H5Gcreate2(s, "energy_transmitted_stderr", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create group");
    H5Dataset wl(H5Dopen2(f, "/spectrum/wavelength_nm", H5P_DEFAULT), "open wavelength");
    H5Dataset ib(H5Dopen2(f, "/incidence/bin", H5P_DEFAULT), "open incidence bin");
    H5Dataset gt(H5Dopen2(f, "/grid/theta_deg", H5P_DEFAULT), "open grid theta");
    h5check(H5DSset_scale(wl, "wavelength_nm"), "H5DSset_scale");
    h5check(H5DSset_scale(ib, "incidence_bin"), "H5DSset_scale");
    h5check(H5DSset_scale(gt, "exit_bin_theta_deg"), "H5DSset_scale");
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const bool half = schema.storage.values == TableValues::Float16;
    const H5Datatype halfT = halfType();
    std::optional<H5Group> bScale, eScale;  // the half tables' scales
    if (half) {
      bScale.emplace(H5Gcreate2(f, "bsdf_scale", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), "create /bsdf_scale");
      if (binErrors)
        eScale.emplace(H5Gcreate2(f, "bsdf_stderr_scale", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                       "create /bsdf_stderr_scale");
    }
    for (const TableRef& t : tables) {
      const std::string name = componentName(t.c);
      const bool blocked = halved && (t.c == Component::Incoherent || t.c == Component::Coherent);
      const bool folded = pairLayout && schema.foldsPairs(t.c);
      H5Dataset d = create3D(t.error ? e->get() : b.get(), name, half ? halfT.get() : H5T_NATIVE_FLOAT, nI, nC, nB, nan,
                             true, blocked ? fillBlock(nI, nC, nB) : 0, folded);
      if (folded)
        setStringAttr(d, "pairs",
                      "stored once: entry (i, o) with o the bin of incidence j on i's side holds the mean of f(i -> o) "
                      "and f(j -> bin of i) where j >= i (weighted by the projected solid angles of o and of the "
                      "bin of i" +
                          std::string(schema.slicePaths.empty() ? "" : ", each times its slice's paths") +
                          ") and NaN where j < i (read (j, bin of i) there)");
      const std::string what = t.error ? "standard error of BSDF component " : "bin-averaged BSDF component ";
      describe(d, "1/sr", what + name + (half ? ", divided by " + scalePathOf(t.path) + " (float16)" : ""));
      h5check(H5DSattach_scale(d, ib, 0), "attach scale");
      if (schema.storage.spectral()) h5check(H5DSattach_scale(d, wl, 1), "attach scale");
      h5check(H5DSattach_scale(d, gt, 2), "attach scale");
      if (half) {
        H5Dataset sc =
            create3D(t.error ? eScale->get() : bScale->get(), name, H5T_NATIVE_DOUBLE, nI, nC, 1, nan, false);
        describe(sc, "1/sr",
                 "the power of two by which each slice and row (wavelength or colour channel) of " + t.path +
                     " is multiplied: f = stored * scale (the row's peak stored in [2^14, 2^15))");
      }
    }
    for (Component c : schema.components.list()) {
      std::string name = componentName(c);
      for (hid_t grp : {er.get(), et.get()}) {
        H5Dataset d = create3D(grp, name, H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
        describe(d, "1", "hemispherical integral sum(f * projected_solid_angle) of " + name);
      }
      for (hid_t grp : {ser.get(), set.get()}) {
        H5Dataset d = create3D(grp, name, H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
        describe(d, "1",
                 "standard error of that hemispherical integral of " + name +
                     " (path-traced: from the per-path "
                     "energies; otherwise from the per-bin errors, see docs/output.md)");
      }
      {
        H5Dataset d = create3D(re, name, H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
        describe(d, "1",
                 "estimated relative standard error of the slice: sqrt(sum (stderr * projected_solid_angle)^2) / "
                 "sum |f| * projected_solid_angle, of " +
                     name);
      }
    }
    {
      std::vector<uint8_t> zeros(nI, 0);
      writeRows1D(b, "done", H5T_NATIVE_UINT8, zeros, "1", "1 when the incidence slice is complete");
    }
    writeRows1D(s, "samples", H5T_NATIVE_UINT64, std::vector<uint64_t>(nI, 0), "1", "paths per wavelength");
    writeRows1D(s, "wave_samples", H5T_NATIVE_UINT64, std::vector<uint64_t>(nI, 0), "1",
                "Kirchhoff samples (point x exit direction) per wavelength");
    writeRows1D(s, "rays", H5T_NATIVE_UINT64, std::vector<uint64_t>(nI, 0), "1",
                "ray casts through the scene (paths, facet sums, the wave term's visibility): the tile's work, "
                "independent of the machine");
    writeRows1D(s, "seconds", H5T_NATIVE_DOUBLE, std::vector<double>(nI, nan), "s", "wall time of the tile");
    writeRows1D(s, "sampling_stop", H5T_NATIVE_UINT8, std::vector<uint8_t>(nI, 0), "1",
                "0: fixed budget; 1: target_rel_error reached; 2: max_paths_per_slice spent first");
    if (schema.guarded.has(Component::Multiple)) {
      writeRows1D(s, "multiple_check", H5T_NATIVE_DOUBLE, std::vector<double>(nI, nan), "1",
                  "multiple scattering the effects planner skipped, verified on the slice: its energy + 3 standard "
                  "errors (largest over wavelengths; by a few thousand full-depth paths where single scattering came "
                  "from the facet sum)");
      writeRows1D(
          s, "multiple_reenabled", H5T_NATIVE_UINT8, std::vector<uint8_t>(nI, 0), "1",
          "1 when multiple_check exceeded [scene] tolerance: the slice holds multiple scattering after all "
          "(elsewhere /bsdf/multiple is the traced value, or 0 where the facet sum computed single scattering)");
    }
    if (schema.guarded.has(Component::Incoherent)) {
      writeRows1D(s, "diffraction_check", H5T_NATIVE_DOUBLE, std::vector<double>(nI, nan), "1",
                  "diffraction the effects planner skipped, verified on the slice: the upper estimate beyond noise of "
                  "sum over the renderer's cells of |sum (f_ws - f_coherent) * projected_solid_angle| (largest over "
                  "wavelengths), from the pilot that ran this slice as the job does or from the slice's own wave term");
      writeRows1D(s, "diffraction_reenabled", H5T_NATIVE_UINT8, std::vector<uint8_t>(nI, 0), "1",
                  "1 when diffraction_check exceeded [scene] tolerance: the slice holds its diffraction after all "
                  "(/bsdf/incoherent is the computed wave term wherever the slice computed it, 0 where a pilot "
                  "confirmed the skip)");
    }
    {
      H5Dataset d = create3D(s, "energy_balance", H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
      describe(d, "1",
               schema.lossless
                   ? "reflected + transmitted + truncated + leaked + missed - 1 of the components but lost: "
                     "the model's energy error (the material absorbs nothing)"
                   : "the excess of reflected + transmitted + truncated + leaked + missed over 1 (the "
                     "material absorbs: a deficit is absorption, an excess the model's error)");
      H5Dataset e = create3D(s, "energy_balance_stderr", H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
      describe(e, "1", "standard error of energy_balance");
      H5Dataset n = create3D(s, "nonphysical", H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
      describe(n, "1",
               "bits of what makes the slice non-physical at this wavelength (0: none): 1 its energy (the "
               "components but lost, both sides) below 0 and 2 above 1, each beyond 3 standard errors and 1e-3; 4 "
               "|energy_balance| beyond [scene] tolerance + 3 standard errors; 8 truncated + leaked + missed beyond "
               "the tolerance");
    }
    {
      H5Dataset d = create3D(s, "paths_albedo_stderr", H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
      describe(d, "1",
               "standard error of the summed energy (both hemispheres) of the path-traced components but "
               "lost, from the per-path energies (0 without path-traced components)");
      H5Dataset r = create3D(s, "paths_rel_error", H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
      describe(r, "1",
               "estimated relative error of the slice of the path-traced table (the sum of the path-traced "
               "components but lost): sqrt(sum_b sum_c (stderr * projected solid angle)^2) / sum_b |sum_c f| "
               "projected solid angle; what target_rel_error aims at (0 without paths)");
    }
    for (const char* n : {"truncated", "leaked", "missed"}) {
      H5Dataset d = create3D(s, n, H5T_NATIVE_DOUBLE, nI, nL, 1, nan, false);
      describe(d, "1", std::string("fraction of incident power ") + n);
    }
  }
}

void BsdfFileWriter::create(const std::string& filename) {
  H5Plist fapl(H5Pcreate(H5P_FILE_ACCESS), "H5Pcreate");
  h5check(H5Pset_libver_bounds(fapl, H5F_LIBVER_LATEST, H5F_LIBVER_LATEST), "H5Pset_libver_bounds");
  file_ = H5File(H5Fcreate(filename.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl), "create " + filename);
  const hid_t f = file_.get();
  writeProvenance(f, schema_);
  writeAxes(f, schema_, grid_);
  createTables(f, schema_, grid_, false);
  // From here on only dataset writes: the file stays readable if the writer dies.
  h5check(H5Fstart_swmr_write(f), "H5Fstart_swmr_write");
}

void BsdfFileWriter::appendJournal(const std::vector<int>& tiles) {
  // O_APPEND + fsync: the lines are on disk before the next tile is written.
  int fd = ::open(journal_.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  if (fd < 0) throw WriteError(osErrorMessage("open", journal_, errno));
  std::string line;
  for (int tile : tiles) line += "tile " + std::to_string(tile) + "\n";
  const ssize_t n = ::write(fd, line.data(), line.size());
  const bool ok = n == ssize_t(line.size()) && ::fsync(fd) == 0;
  const int err = n >= 0 && n != ssize_t(line.size()) ? ENOSPC : errno;
  ::close(fd);
  if (!ok) throw WriteError(osErrorMessage("write", journal_, err));
}

void BsdfFileWriter::close() {
  flushPending();
  closeDatasets();
  file_.close("close " + partial_);
}

BsdfFileWriter::~BsdfFileWriter() {
  if (!finished_) {
    datasets_.clear();
    file_.reset();  // leave the .partial file for inspection; the final path stays untouched
  }
}

BsdfFileWriter::EnergyBalance BsdfFileWriter::writeTile(const TileResult& r) {
  const EnergyBalance b = writeSlice(r);
  commitSlices({r.incidenceIndex});
  return b;
}

void BsdfFileWriter::commitSlices(const std::vector<int>& indices) {
  // The slices on disk (flushed and synced), then their done flags (flushed and synced), then the
  // journal: a slice marked done, or journaled, is complete on disk. One sync per commit, not per
  // slice: a kill before the journal's sync loses the commit's slices, which a resume recomputes.
  const hid_t f = file_.get();
  flushPending();
  h5check(H5Fflush(f, H5F_SCOPE_GLOBAL), "flush " + partial_);
  syncHdf5File(f, partial_);
  for (int i : indices) putRow("/bsdf/done", i, {1.0});
  flushPending();
  h5check(H5Fflush(f, H5F_SCOPE_GLOBAL), "flush " + partial_);
  syncHdf5File(f, partial_);
  appendJournal(indices);
}

BsdfFileWriter::OpenDataset& BsdfFileWriter::dataset(const std::string& path) {
  auto it = datasets_.find(path);
  if (it == datasets_.end()) {
    OpenDataset o;
    o.d = H5Dataset(H5Dopen2(file_.get(), path.c_str(), H5P_DEFAULT), "open " + path);
    H5Datatype t(H5Dget_type(o.d), "type of " + path);
    o.elemSize = H5Tget_size(t);
    o.half = H5Tget_class(t) == H5T_FLOAT && o.elemSize == 2;
    const bool isFloat = H5Tget_class(t) == H5T_FLOAT && (o.half || o.elemSize == sizeof(float));
    // The filters create3D sets (shuffle, then deflate): only then are the chunks ours to make.
    H5Plist dcpl(H5Dget_create_plist(o.d), "creation properties of " + path);
    H5Dataspace s(H5Dget_space(o.d), "H5Dget_space");
    if (isFloat && H5Pget_layout(dcpl) == H5D_CHUNKED && H5Sget_simple_extent_ndims(s) == 3 &&
        H5Pget_nfilters(dcpl) == 2) {
      unsigned flags = 0, cd[4] = {0, 0, 0, 0};
      size_t ncd = 4;
      const H5Z_filter_t first = H5Pget_filter2(dcpl, 0, &flags, &ncd, cd, 0, nullptr, nullptr);
      ncd = 4;
      const H5Z_filter_t second = H5Pget_filter2(dcpl, 1, &flags, &ncd, cd, 0, nullptr, nullptr);
      if (first == H5Z_FILTER_SHUFFLE && second == H5Z_FILTER_DEFLATE && ncd >= 1) {
        o.direct = true;
        o.deflateLevel = int(cd[0]);
        H5Sget_simple_extent_dims(s, o.dims, nullptr);
        h5check(H5Pget_chunk(dcpl, 3, o.chunk), "chunk shape of " + path);
      }
    }
    it = datasets_.emplace(path, std::move(o)).first;
  }
  return it->second;
}

void BsdfFileWriter::putTableRows(const std::vector<std::pair<std::string, const std::vector<double>*>>& rows, int i,
                                  const std::vector<PackedChunk>* packed) {
  struct Chunk {
    hid_t d;
    std::string path;
    hsize_t offset[3];
    std::vector<unsigned char> values;
    size_t elemSize;
    int level;
    const std::vector<unsigned char>* ready;  // packed by the rank that computed the tile
    std::vector<unsigned char> packed;
  };
  std::vector<Chunk> chunks;
  std::vector<ScaledRow> scaled;  // the half tables' rows, scaled
  scaled.reserve(rows.size());
  for (const auto& [path, v] : rows) {
    OpenDataset& o = dataset(path);
    if (!o.direct) {
      putTable(path, i, *v);
      continue;
    }
    const hsize_t n1 = o.dims[1], n2 = o.dims[2], c1 = o.chunk[1], c2 = o.chunk[2];
    if (v && v->size() != n1 * n2) throw std::runtime_error("HDF5: row size mismatch for " + path);
    const std::vector<double>* values = v;
    if (v && o.half) {
      scaled.push_back(scaleForHalf(*v, size_t(n1)));
      putRow(scalePathOf(path), i, scaled.back().scales);
      values = &scaled.back().values;
    }
    for (hsize_t a = 0; a < n1; a += c1)
      for (hsize_t b = 0; b < n2; b += c2) {
        const std::vector<unsigned char>* ready = packedChunkFor(packed, path, a, b, c1, c2, o.deflateLevel);
        if (!ready && !v) throw std::logic_error("putTableRows: no values and no packed chunk for " + path);
        chunks.push_back({o.d.get(),
                          path,
                          {hsize_t(i), a, b},
                          ready ? std::vector<unsigned char>{} : chunkBytes(*values, n1, n2, a, b, c1, c2, o.elemSize),
                          o.elemSize,
                          o.deflateLevel,
                          ready,
                          {}});
      }
  }
  tbb::parallel_for(size_t(0), chunks.size(), [&](size_t k) {
    if (!chunks[k].ready) chunks[k].packed = shuffleDeflate(chunks[k].values, chunks[k].elemSize, chunks[k].level);
  });
  for (const Chunk& c : chunks) {
    const std::vector<unsigned char>& bytes = c.ready ? *c.ready : c.packed;
    h5check(H5Dwrite_chunk(c.d, H5P_DEFAULT, 0, c.offset, bytes.size(), bytes.data()), "write " + c.path);
  }
}

void BsdfFileWriter::putTable(const std::string& path, int i, const std::vector<double>& v) {
  if (!dataset(path).half) return putRow(path, i, v);
  ScaledRow s = scaleForHalf(v, size_t(channelCount(schema_)));
  putRow(scalePathOf(path), i, s.scales);
  putRow(path, i, s.values);
}

std::vector<double> BsdfFileWriter::getTable(const std::string& path, int i) {
  std::vector<double> v = getRow(path, i);
  if (!dataset(path).half) return v;
  const std::vector<double> scales = getRow(scalePathOf(path), i);
  const size_t nB = v.size() / std::max<size_t>(1, scales.size());
  for (size_t k = 0; k < v.size(); ++k) v[k] *= scales[k / nB];
  return v;
}

void BsdfFileWriter::putRow(const std::string& path, int i, const std::vector<double>& v) {
  pending_[path][i] = v;
}

std::vector<double> BsdfFileWriter::getRow(const std::string& path, int i) {
  if (const auto p = pending_.find(path); p != pending_.end())
    if (const auto row = p->second.find(i); row != p->second.end()) return row->second;
  return readRowFrom(dataset(path).d.get(), path, i);
}

void BsdfFileWriter::flushPending() {
  for (auto& [path, rows] : pending_) {
    const hid_t d = dataset(path).d.get();
    H5Dataspace file(H5Dget_space(d), "H5Dget_space");
    const int rank = H5Sget_simple_extent_ndims(file);
    hsize_t dims[3] = {0, 1, 1};
    H5Sget_simple_extent_dims(file, dims, nullptr);
    const size_t rowSize = size_t(rank > 1 ? dims[1] : 1) * size_t(rank > 2 ? dims[2] : 1);
    // Consecutive rows in one write: a tile's slices, or a ring of slices symmetry maps it to.
    for (auto run = rows.begin(); run != rows.end();) {
      auto end = std::next(run);
      while (end != rows.end() && end->first == std::prev(end)->first + 1) ++end;
      std::vector<double> values;
      for (auto r = run; r != end; ++r) {
        if (r->second.size() != rowSize) throw std::runtime_error("HDF5: row size mismatch for " + path);
        values.insert(values.end(), r->second.begin(), r->second.end());
      }
      hsize_t start[3] = {hsize_t(run->first), 0, 0}, count[3] = {hsize_t(std::distance(run, end)), dims[1], dims[2]};
      h5check(H5Sselect_hyperslab(file, H5S_SELECT_SET, start, nullptr, count, nullptr), "select " + path);
      H5Dataspace memory(H5Screate_simple(rank, count, nullptr), "H5Screate_simple");
      writeValues(d, memory, file, values, dataset(path).half, path);
      run = end;
    }
  }
  pending_.clear();
}

void BsdfFileWriter::closeDatasets() {
  // Checked: closing writes what the chunk caches still hold.
  for (auto& [path, o] : datasets_) o.d.close("write " + path);
  datasets_.clear();
}

namespace {

using Rows = std::map<std::string, std::vector<double>>;

// /stats/energy_reflected, energy_transmitted (and their standard errors) and rel_error of
// component c of r's slice.
void componentRows(const TileResult& r, Component c, const DirectionGrid& grid, Rows& rows) {
  const std::string name = componentName(c);
  std::vector<double> refl(size_t(r.nLambda), 0.0), trans(size_t(r.nLambda), 0.0);
  for (int l = 0; l < r.nLambda; ++l)
    for (int b = 0; b < r.nBins; ++b) {
      double e = r.at(c, l, b) * grid.projectedSolidAngle(b);
      (grid.isUpper(b) ? refl : trans)[size_t(l)] += e;
    }
  rows["/stats/energy_reflected/" + name] = refl;
  rows["/stats/energy_transmitted/" + name] = trans;
  rows["/stats/energy_reflected_stderr/" + name] = energyStdError(r, c, 0, grid);
  rows["/stats/energy_transmitted_stderr/" + name] = energyStdError(r, c, 1, grid);
  rows["/stats/rel_error/" + name] = relativeError(r, {c}, grid);
}

// The energy balance of a slice from its rows (row(path)): reflected + transmitted + truncated +
// leaked + missed − 1 over the components but lost (BsdfFileWriter::writeEnergyBalance).
EnergyBalance energyBalanceOf(const OutputSchema& schema,
                              const std::function<std::vector<double>(const std::string&)>& row) {
  const int nL = int(schema.lambda_nm.size());
  EnergyBalance b;
  b.value.assign(size_t(nL), -1.0);
  std::vector<double> var(size_t(nL), 0.0);
  const std::vector<double> paths = row("/stats/paths_albedo_stderr");
  const bool traced = row("/stats/samples")[0] > 0;
  for (int l = 0; l < nL; ++l) var[size_t(l)] = paths[size_t(l)] * paths[size_t(l)];
  for (Component c : schema.components.list()) {
    if (c == Component::Lost || c == Component::GeoMasked) continue;
    const std::string n = componentName(c);
    const bool fromPaths = traced && (c == Component::Coherent || c == Component::Multiple);
    for (const char* side : {"reflected", "transmitted"}) {
      const std::vector<double> e = row(std::string("/stats/energy_") + side + "/" + n);
      const std::vector<double> se = row(std::string("/stats/energy_") + side + "_stderr/" + n);
      for (int l = 0; l < nL; ++l) {
        b.value[size_t(l)] += e[size_t(l)];
        if (!fromPaths) var[size_t(l)] += se[size_t(l)] * se[size_t(l)];
      }
    }
  }
  b.pathsLost.assign(size_t(nL), 0.0);
  for (const char* lost : {"/stats/truncated", "/stats/leaked", "/stats/missed"}) {
    const std::vector<double> v = row(lost);
    for (int l = 0; l < nL; ++l) {
      b.value[size_t(l)] += v[size_t(l)];
      b.pathsLost[size_t(l)] += v[size_t(l)];
    }
  }
  b.stdError.resize(size_t(nL));
  b.energy.resize(size_t(nL));
  b.flags.assign(size_t(nL), 0.0);
  for (int l = 0; l < nL; ++l) {
    b.energy[size_t(l)] = b.value[size_t(l)] + 1 - b.pathsLost[size_t(l)];
    if (!schema.lossless) b.value[size_t(l)] = std::max(0.0, b.value[size_t(l)]);
    b.stdError[size_t(l)] = std::sqrt(var[size_t(l)]);
    const double se = b.stdError[size_t(l)], e = b.energy[size_t(l)];
    unsigned f = 0;
    if (e < -(3 * se + 1e-3)) f |= unsigned(SliceFlag::NegativeEnergy);
    if (e - 1 > 3 * se + 1e-3) f |= unsigned(SliceFlag::ExcessEnergy);
    if (std::abs(b.value[size_t(l)]) > schema.tolerance + 3 * se) f |= unsigned(SliceFlag::Unbalanced);
    if (b.pathsLost[size_t(l)] > schema.tolerance) f |= unsigned(SliceFlag::PathsLost);
    b.flags[size_t(l)] = double(f);
  }
  return b;
}

// Every row of slice r but its tables, as the writer stores them.
Rows sliceRows(const TileResult& r, const OutputSchema& schema, const DirectionGrid& grid) {
  Rows rows;
  for (Component c : schema.components.list()) {
    if (!r.has(c)) throw std::runtime_error(std::string("tile lacks component ") + componentName(c));
    componentRows(r, c, grid, rows);
  }
  rows["/stats/truncated"] = r.truncated;
  rows["/stats/leaked"] = r.leaked;
  rows["/stats/missed"] = r.missed;
  rows["/stats/samples"] = {double(r.samples)};
  rows["/stats/wave_samples"] = {double(r.waveSamples)};
  rows["/stats/rays"] = {double(r.rays)};
  rows["/stats/seconds"] = {r.seconds};
  rows["/stats/sampling_stop"] = {double(int(r.samplingStop))};
  if (schema.guarded.has(Component::Multiple)) {
    rows["/stats/multiple_check"] = {r.multipleCheck};
    rows["/stats/multiple_reenabled"] = {r.multipleReenabled ? 1.0 : 0.0};
  }
  if (schema.guarded.has(Component::Incoherent)) {
    rows["/stats/diffraction_check"] = {r.diffractionCheck};
    rows["/stats/diffraction_reenabled"] = {r.diffractionReenabled ? 1.0 : 0.0};
  }
  std::vector<Component> traced;
  for (Component c : schema.components.list())
    if (c != Component::Lost && c != Component::GeoMasked && !r.pathMoments[int(c)].empty()) traced.push_back(c);
  std::vector<double> se = r.pathEnergyStdError(traced, -1);
  if (traced.empty()) se.assign(size_t(r.nLambda), 0.0);
  rows["/stats/paths_albedo_stderr"] = se;
  std::vector<double> rel = relativeError(r, traced, grid);
  if (r.samples == 0) rel.assign(size_t(r.nLambda), 0.0);  // the facet sum: no paths
  rows["/stats/paths_rel_error"] = rel;
  const EnergyBalance b = energyBalanceOf(schema, [&](const std::string& path) { return rows.at(path); });
  rows["/stats/energy_balance"] = b.value;
  rows["/stats/energy_balance_stderr"] = b.stdError;
  rows["/stats/nonphysical"] = b.flags;
  return rows;
}

// The slice's table chunks packed as createTables lays the tables out; a half table's scales go
// to `rows`.
std::vector<PackedChunk> packSlice(const TileResult& r, const OutputSchema& schema, const DirectionGrid& grid,
                                   Rows& rows) {
  const int nI = int(schema.incidence.size()), nL = channelCount(schema), nB = grid.binCount();
  const size_t elemSize = tableElementSize(schema);
  const std::vector<Colour3> weights = schema.storage.spectral() ? std::vector<Colour3>{} : channelWeights(schema);
  struct Work {
    PackedChunk chunk;
    const std::vector<double>* row;
  };
  std::vector<Work> work;
  std::vector<ScaledRow> scaled;
  scaled.reserve(2 * kComponentCount);
  for (const TableRef& t : tablesOf(schema)) {
    if (!r.has(t.c)) throw std::runtime_error(std::string("tile lacks component ") + componentName(t.c));
    const bool blocked = schema.halvesWaveByReciprocity && (t.c == Component::Incoherent || t.c == Component::Coherent);
    const auto [c1, c2] = sliceChunkShape(hsize_t(nL), hsize_t(nB), elemSize, blocked ? fillBlock(nI, nL, nB) : 0);
    // Each table's row as stored (its colour, its scaled half values) kept until it is packed.
    scaled.push_back({storedTableRow(r, t, schema, weights), {}});
    if (elemSize == 2) {
      scaled.back() = scaleForHalf(scaled.back().values, size_t(nL));
      rows[scalePathOf(t.path)] = scaled.back().scales;
    }
    const std::vector<double>* row = &scaled.back().values;
    for (hsize_t a = 0; a < hsize_t(nL); a += c1)
      for (hsize_t b = 0; b < hsize_t(nB); b += c2) work.push_back({{t.path, a, b, c1, c2, {}}, row});
  }
  tbb::parallel_for(size_t(0), work.size(), [&](size_t k) {
    const PackedChunk& c = work[k].chunk;
    work[k].chunk.bytes =
        shuffleDeflate(chunkBytes(*work[k].row, hsize_t(nL), hsize_t(nB), c.a, c.b, c.c1, c.c2, elemSize), elemSize,
                       kTableDeflateLevel);
  });
  std::vector<PackedChunk> out;
  for (Work& w : work) out.push_back(std::move(w.chunk));
  return out;
}

}  // namespace

PreparedSlice prepareSlice(const TileResult& r, const OutputSchema& schema, const DirectionGrid& grid) {
  PreparedSlice p{r.incidenceIndex, sliceRows(r, schema, grid), {}};
  p.chunks = packSlice(r, schema, grid, p.rows);
  return p;
}

namespace {

// A pilot tile's component c as the job's `paths` will fill it: a compressed table's size follows
// which bins hold a value (zeros cost next to nothing, and the pattern of zeros and values costs
// more than the values' count says), and a pilot leaves many bins empty that the job fills.
// A bin's hits are (f / σ)² (one hit of weight w gives f = w / (N Ω⊥), σ = f); a seen bin with
// c hits is filled at the job's budget with probability 1 − exp(−c N / N_pilot). The bins no pilot
// path reached are estimated from the bins hit once, twice, … (f1..f4) by the improved Chao1 lower
// bound of the unseen count (Chiu, Wang, Walther & Chao 2014, eq. 7) and filled at N as Shen, Chao
// & Lin (2003, eq. 5) extrapolate; at most the empty bins of the hemispheres the row reaches. The
// expected number of new bins is filled, in empty bins of those hemispheres chosen by a hash of
// the bin (the same for every wavelength: the paths are shared), each with what one hit of the
// job leaves there — one of the pilot's one-hit weights w, picked by a hash of the bin, as w / (N Ω⊥),
// σ = f: varied as the job's values are (one value repeated would compress better than they do) —
// so that the table is packed as the job's will be; a wave residual over c (`residual`) loses the new value and gains
// its variance. Bins with a value and no error are deterministic (the facet sum, `exact`): kept as they are.
struct ResidualRows {  // a wave residual's rows (incoherent = WS − coherent, lost = P_msk − geo_masked)
  std::vector<double>& value;
  std::vector<double>& error;
};
void fillExpectedBins(TileResult& r, Component c, const DirectionGrid& grid, double paths,
                      std::optional<ResidualRows> residual) {
  const double pilotPaths = double(r.samples);
  if (pilotPaths <= 0 || paths <= pilotPaths) return;
  auto& value = r.value[int(c)];
  auto& error = r.stdError[int(c)];
  if (error.size() != value.size()) return;
  // Empty bins in a fixed pseudo-random order (splitmix64 of the bin index).
  std::vector<std::pair<uint64_t, int>> order;
  for (int b = 0; b < r.nBins; ++b) {
    uint64_t z = uint64_t(b) + 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    order.emplace_back(z ^ (z >> 31), b);
  }
  std::sort(order.begin(), order.end());
  for (int l = 0; l < r.nLambda; ++l) {
    const size_t row = size_t(l) * size_t(r.nBins);
    double f[5] = {0, 0, 0, 0, 0}, expected = 0, seen = 0, empty[2] = {0, 0};
    bool reaches[2] = {false, false};
    std::vector<double> oneHitWeights;
    for (int b = 0; b < r.nBins; ++b) {
      const double v = value[row + size_t(b)], se = error[row + size_t(b)];
      const int side = grid.isUpper(b) ? 0 : 1;
      if (v == 0) {
        empty[side] += 1;
        continue;
      }
      if (!std::isfinite(v) || !(se > 0)) continue;  // deterministic (or not computed): as it is
      reaches[side] = true;
      seen += 1;
      const double hits = std::max(1.0, std::round((v / se) * (v / se)));
      if (hits <= 4) f[int(hits)] += 1;
      if (hits == 1) oneHitWeights.push_back(std::abs(v) * grid.projectedSolidAngle(b));
      expected += 1 - std::exp(-hits * paths / pilotPaths);
    }
    if (seen == 0 || oneHitWeights.empty()) continue;
    double f0 = f[2] > 0 ? f[1] * f[1] / (2 * f[2]) : f[1] * (f[1] - 1) / 2;
    if (f[4] > 0) f0 += f[3] / (4 * f[4]) * std::max(0.0, f[1] - f[2] * f[3] / (2 * f[4]));
    f0 = std::min(f0, (reaches[0] ? empty[0] : 0) + (reaches[1] ? empty[1] : 0));
    if (f0 > 0 && f[1] > 0)
      expected += f0 * (1 - std::pow(std::max(0.0, 1 - f[1] / (pilotPaths * f0)), paths - pilotPaths));
    // Seen bins the job leaves empty are few (a seen bin has at least one hit of N_pilot): the
    // growth is the new bins.
    long fresh = std::lround(std::max(0.0, expected - seen));
    for (const auto& [hash, b] : order) {
      if (fresh <= 0) break;
      if (value[row + size_t(b)] != 0 || !reaches[grid.isUpper(b) ? 0 : 1]) continue;
      const double w = oneHitWeights[size_t(hash % oneHitWeights.size())] * pilotPaths / paths;
      value[row + size_t(b)] = w / grid.projectedSolidAngle(b);
      // One hit at the job's budget: σ = f there (toJobErrors scales the pilot's errors to it).
      error[row + size_t(b)] = value[row + size_t(b)] * std::sqrt(paths / pilotPaths);
      if (residual && residual->value.size() == value.size() &&
          residual->error.size() == value.size()) {  // WS − coherent: less the new value
        residual->value[row + size_t(b)] -= value[row + size_t(b)];
        residual->error[row + size_t(b)] = std::hypot(residual->error[row + size_t(b)], error[row + size_t(b)]);
      }
      --fresh;
    }
  }
}

// The wave residual computed over a path-traced component (incoherent = WS − coherent, lost =
// P_msk − geo_masked: addWaveComponents), if any.
std::optional<Component> waveResidualOver(Component c) {
  if (c == Component::Coherent) return Component::Incoherent;
  if (c == Component::GeoMasked) return Component::Lost;
  return std::nullopt;
}

// A pilot tile's errors as the job's paths will leave them: rounded to the noise, a value keeps the
// bits its error leaves, and the pilot's path-traced errors are √(N / N_pilot) larger. The wave
// residual (incoherent = WS − coherent, its variance σ_WS² + σ_coh²) scales its coherent part; the
// wave term's own part is kept at the pilot's (its budget is the wave estimator's).
void toJobErrors(TileResult& r, double paths) {
  const double pilotPaths = double(r.samples);
  if (pilotPaths <= 0 || paths <= pilotPaths) return;
  const double k2 = pilotPaths / paths;
  for (Component under : {Component::Coherent, Component::GeoMasked}) {
    auto& se = r.stdError[int(*waveResidualOver(under))];
    const auto& part = r.stdError[int(under)];
    if (se.size() != part.size() || r.pathMoments[int(under)].empty()) continue;
    for (size_t k = 0; k < se.size(); ++k)
      se[k] = std::sqrt(std::max(0.0, se[k] * se[k] - (1 - k2) * part[k] * part[k]));
  }
  for (int c = 0; c < kComponentCount; ++c)
    if (!r.pathMoments[size_t(c)].empty())
      for (double& se : r.stdError[size_t(c)]) se *= std::sqrt(k2);
}

}  // namespace

double storedBytesPerSlice(const OutputSchema& schema, const DirectionGrid& grid,
                           const std::vector<TileResult>& tiles) {
  double bytes = 0;
  const std::vector<TableRef> tables = tablesOf(schema, FileStage::Final);
  for (TileResult r : tiles) {
    for (Component c : schema.components.list())
      if (!r.has(c)) {
        r.value[int(c)].assign(size_t(r.nLambda) * size_t(r.nBins), 0.0);
        r.stdError[int(c)].assign(size_t(r.nLambda) * size_t(r.nBins), 0.0);
      }
    // The bins the job's paths will fill.
    for (Component c : schema.components.list()) {
      if (r.pathMoments[int(c)].empty()) continue;
      const std::optional<Component> over = waveResidualOver(c);
      std::optional<ResidualRows> residual;
      if (over && schema.components.has(*over))
        residual.emplace(ResidualRows{r.value[int(*over)], r.stdError[int(*over)]});
      fillExpectedBins(r, c, grid, double(schema.pathsFor(r.incidenceIndex)), residual);
    }
    // Pairs stored once: a slice keeps half of its entries at the other incidence bins of its side
    // (the mirrored half is NaN, which compresses to next to nothing).
    std::vector<char> incidenceBin(size_t(r.nBins), 0);
    for (const IncidenceDirection& d : schema.incidence) incidenceBin[size_t(d.bin)] = 1;
    const int own = schema.incidence[size_t(r.incidenceIndex)].bin;
    std::map<std::string, double> kept;  // table path (in the final file) -> the share of its entries stored
    for (const TableRef& t : tables) {
      double all = 0, paired = 0;
      if (schema.foldsPairs(t.c))
        for (int l = 0; l < r.nLambda; ++l)
          for (int b = 0; b < r.nBins; ++b)
            if (r.at(t.c, l, b) != 0) {
              all += 1;
              paired += incidenceBin[size_t(b)] && b != own && grid.isUpper(b) == grid.isUpper(own);
            }
      kept[t.path] = all > 0 ? 1 - 0.5 * paired / all : 1;
    }
    if (schema.storage.rounding == TableRounding::Noise) toJobErrors(r, double(schema.pathsFor(r.incidenceIndex)));
    const PreparedSlice p = prepareSlice(r, schema, grid);
    for (const PackedChunk& c : p.chunks)
      if (kept.count(c.path)) bytes += double(c.bytes.size()) * kept.at(c.path);  // (the run's own errors: not)
    for (const auto& entry : p.rows) {  // (a structured binding is not captured by clang 14)
      const std::string& path = entry.first;
      const bool runningOnly = path.rfind("/bsdf_stderr_scale/", 0) == 0 &&
                               std::none_of(tables.begin(), tables.end(),
                                            [&](const TableRef& t) { return t.error && path == scalePathOf(t.path); });
      if (!runningOnly) bytes += double(entry.second.size()) * sizeof(double);
    }
  }
  return tiles.empty() ? 0.0 : bytes / double(tiles.size());
}

PreparedSlice BsdfFileWriter::prepare(const TileResult& r) const {
  return prepareSlice(r, schema_, grid_);
}

EnergyBalance BsdfFileWriter::writeSlice(const TileResult& r) {
  return writePrepared(prepare(r), [&] { return r; });
}

EnergyBalance BsdfFileWriter::writePrepared(const PreparedSlice& p, const std::function<TileResult()>& raw) {
  const int i = p.index;
  // The tables from the packed chunks; from the raw slice where the file's layout is not the one
  // they were packed for (a resumed file of another layout).
  bool packedFits = true;
  for (const TableRef& t : tablesOf(schema_)) {
    const OpenDataset& o = dataset(t.path);
    packedFits = packedFits && o.direct && (o.half == (tableElementSize(schema_) == 2));
    for (hsize_t a = 0; packedFits && a < o.dims[1]; a += o.chunk[1])
      for (hsize_t b = 0; packedFits && b < o.dims[2]; b += o.chunk[2])
        packedFits = packedChunkFor(&p.chunks, t.path, a, b, o.chunk[1], o.chunk[2], o.deflateLevel) != nullptr;
  }
  const std::optional<TileResult> slice = packedFits ? std::nullopt : std::optional<TileResult>(raw());
  const std::vector<TableRef> refs = tablesOf(schema_);
  std::vector<std::vector<double>> stored;  // the raw slice's rows as stored (its colour)
  if (slice) {
    const std::vector<Colour3> weights = schema_.storage.spectral() ? std::vector<Colour3>{} : channelWeights(schema_);
    for (const TableRef& t : refs) stored.push_back(storedTableRow(*slice, t, schema_, weights));
  }
  std::vector<std::pair<std::string, const std::vector<double>*>> tables;
  for (size_t k = 0; k < refs.size(); ++k) tables.emplace_back(refs[k].path, slice ? &stored[k] : nullptr);
  // The rows first: where the tables are compressed here, their scales replace the packed ones.
  for (const auto& [path, row] : p.rows) putRow(path, i, row);
  putTableRows(tables, i, slice ? nullptr : &p.chunks);
  return energyBalanceOf(schema_, [&](const std::string& path) { return p.rows.at(path); });
}

EnergyBalance BsdfFileWriter::writeEnergyBalance(int i) {
  const EnergyBalance b = energyBalanceOf(schema_, [&](const std::string& path) { return getRow(path, i); });
  putRow("/stats/energy_balance", i, b.value);
  putRow("/stats/energy_balance_stderr", i, b.stdError);
  putRow("/stats/nonphysical", i, b.flags);
  return b;
}

void BsdfFileWriter::writeSliceStats(const TileResult& r, Component c) {
  Rows rows;
  componentRows(r, c, grid_, rows);
  for (const auto& [path, row] : rows) putRow(path, r.incidenceIndex, row);
}

double BsdfFileWriter::completeReciprocal(const ReciprocalPairs& pairs) {
  hid_t f = file_.get();
  const int nI = int(schema_.incidence.size()), nL = int(schema_.lambda_nm.size()), nB = grid_.binCount();
  if (pairs.incidenceCount() != nI) throw std::logic_error("completeReciprocal: pairs do not match the job");
  if (!schema_.storage.spectral()) throw std::logic_error("completeReciprocal: a colour file is not halved");
  const std::vector<uint8_t> done = read1D<uint8_t>(f, "/bsdf/done", H5T_NATIVE_UINT8);
  if (std::count(done.begin(), done.end(), 0) != 0)
    throw std::logic_error("completeReciprocal: not every slice is done");
  const std::string inc = "/bsdf/incoherent", incE = "/bsdf_stderr/incoherent", coh = "/bsdf/coherent",
                    cohE = "/bsdf_stderr/coherent";
  const int block = int(fillBlock(nI, nL, nB));
  double energy = 0;
  for (int a = 0; a < nI;) {
    // Incidence indices [a, e) whose bins span at most `block` columns.
    const int c0 = pairs.incidenceBin(a);
    int e = a + 1;
    while (e < nI && pairs.incidenceBin(e) - c0 < block) ++e;
    const hsize_t w = hsize_t(pairs.incidenceBin(e - 1) - c0 + 1);
    // f_ws(j -> bin(i)) = incoherent + coherent of row j, with its variance se_inc² − se_coh²
    // (the two were combined in quadrature, docs/physics.md §3).
    auto columns = [&](const std::string& path) {
      std::vector<double> v = readColumns(f, path, hsize_t(c0), w);
      if (dataset(path).half) {  // (nI, nλ, w) stored / scale (nI, nλ)
        const std::vector<double> scale = readColumns(f, scalePathOf(path), 0, 1);
        for (size_t k = 0; k < v.size(); ++k) v[k] *= scale[k / w];
      }
      return v;
    };
    const std::vector<double> cInc = columns(inc), cIncE = columns(incE), cCoh = columns(coh), cCohE = columns(cohE);
    auto col = [&](int j, int l, int bin) { return (size_t(j) * nL + l) * w + size_t(bin - c0); };
    for (int i = a; i < e; ++i) {
      TileResult row;
      row.incidenceIndex = i;
      row.nLambda = nL;
      row.nBins = nB;
      auto& v = row.value[int(Component::Incoherent)];
      auto& se = row.stdError[int(Component::Incoherent)];
      v = getTable(inc, i);
      se = getTable(incE, i);
      const std::vector<double> ch = getTable(coh, i), chE = getTable(cohE, i);
      const int bi = pairs.incidenceBin(i);
      for (int o = 0; o < nB; ++o) {
        if (pairs.computes(i, o)) continue;
        const int j = pairs.incidenceOf(o);
        for (int l = 0; l < nL; ++l) {
          const size_t k = col(j, l, bi), x = size_t(l) * nB + o;
          const double fws = cInc[k] + cCoh[k];
          const double varWs = std::max(0.0, cIncE[k] * cIncE[k] - cCohE[k] * cCohE[k]);
          v[x] = fws - ch[x];  // reflection: f(i -> o) = f(o -> i), docs/physics.md §8
          se[x] = std::sqrt(varWs + chE[x] * chE[x]);
          if (schema_.storage.rounding == TableRounding::Noise) roundEstimate(v[x], se[x]);  // as computed bins are
          if (!std::isfinite(v[x]) || !std::isfinite(se[x]))
            throw std::runtime_error("reciprocity fill: slice " + std::to_string(j) + " has no finite value at bin " +
                                     std::to_string(bi));
        }
      }
      putTable(inc, i, v);
      putTable(incE, i, se);
      writeSliceStats(row, Component::Incoherent);
      writeEnergyBalance(i);
      for (int l = 0; l < nL; ++l)
        for (int b = 0; b < nB; ++b) energy += v[size_t(l) * nB + b] * grid_.projectedSolidAngle(b);
    }
    flushPending();
    h5check(H5Fflush(f, H5F_SCOPE_GLOBAL), "flush");
    a = e;
  }
  return energy / std::max(1, nI * nL);
}

namespace {

// A dataset copied from one file to another of the same layout: whole when small, else row by row
// (a table of the paper's size is tens of gigabytes as doubles).
void copyDataset(hid_t from, hid_t to, const std::string& path) {
  H5Dataset a(H5Dopen2(from, path.c_str(), H5P_DEFAULT), "open " + path);
  H5Dataset b(H5Dopen2(to, path.c_str(), H5P_DEFAULT), "open " + path);
  H5Dataspace s(H5Dget_space(a), "H5Dget_space");
  const hssize_t n = H5Sget_simple_extent_npoints(s);
  if (n <= (1 << 22) || H5Sget_simple_extent_ndims(s) < 2) {
    std::vector<double> v(size_t(std::max<hssize_t>(n, 0)));
    if (n > 0) h5check(H5Dread(a, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), "read " + path);
    if (n > 0) h5check(H5Dwrite(b, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), "write " + path);
  } else {
    hsize_t dims[3] = {0, 0, 0};
    H5Sget_simple_extent_dims(s, dims, nullptr);
    for (hsize_t i = 0; i < dims[0]; ++i) writeRowTo(b, path, int(i), readRowFrom(a, path, int(i)), H5T_NATIVE_DOUBLE);
  }
  b.close("write " + path);
}

// Rows [a, a + n) of a (nInc, rows, cols) float dataset: (n, rows, cols) as floats; or columns
// [a, a + n) of every row: (nInc, rows, n).
std::vector<float> readBlock(hid_t d, const std::string& path, hsize_t a, hsize_t n, bool columns) {
  H5Dataspace fs(H5Dget_space(d), "H5Dget_space");
  hsize_t dims[3] = {0, 0, 0};
  H5Sget_simple_extent_dims(fs, dims, nullptr);
  hsize_t start[3] = {columns ? 0 : a, 0, columns ? a : 0};
  hsize_t count[3] = {columns ? dims[0] : n, dims[1], columns ? n : dims[2]};
  h5check(H5Sselect_hyperslab(fs, H5S_SELECT_SET, start, nullptr, count, nullptr), "select " + path);
  H5Dataspace ms(H5Screate_simple(3, count, nullptr), "H5Screate_simple");
  return readSelection<float>(d, ms, fs, count[0] * count[1] * count[2], path);
}

// Rows [a, a + n) of a (nInc, rows, cols) dataset from doubles (n x rows x cols): a table's values
// (writeValues: float32, or float16 with `half`), or its scales.
void writeBlock(hid_t d, const std::string& path, hsize_t a, const std::vector<double>& v, hsize_t rows, hsize_t cols,
                bool half) {
  H5Dataspace fs(H5Dget_space(d), "H5Dget_space");
  const hsize_t n = v.size() / (rows * cols);
  hsize_t start[3] = {a, 0, 0}, count[3] = {n, rows, cols};
  h5check(H5Sselect_hyperslab(fs, H5S_SELECT_SET, start, nullptr, count, nullptr), "select " + path);
  H5Dataspace ms(H5Screate_simple(3, count, nullptr), "H5Screate_simple");
  writeValues(d, ms, fs, v, half, path);
}

// What the fold found, per component: the reciprocity test of every pair of independent estimates.
struct PairCheck {
  uint64_t pairs = 0, tested = 0;
  double sumZ2 = 0, maxZ = 0, diffL1 = 0, sumL1 = 0;
};

}  // namespace

nlohmann::json BsdfFileWriter::foldPairs(const std::string& target) {
  const OutputSchema& schema = schema_;
  const int nI = int(schema.incidence.size()), nC = channelCount(schema), nB = grid_.binCount();
  const bool half = schema.storage.values == TableValues::Float16;
  // Both files closed with every object in them (a close after a failed write, a full disk, must
  // not leave HDF5 a half-open file to flush when the process exits).
  H5Plist fapl(H5Pcreate(H5P_FILE_ACCESS), "H5Pcreate");
  h5check(H5Pset_libver_bounds(fapl, H5F_LIBVER_LATEST, H5F_LIBVER_LATEST), "H5Pset_libver_bounds");
  h5check(H5Pset_fclose_degree(fapl, H5F_CLOSE_STRONG), "H5Pset_fclose_degree");
  H5File out(H5Fcreate(target.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl), "create " + target);
  writeProvenance(out, schema);
  writeAxes(out, schema, grid_);
  createTables(out, schema, grid_, true);
  std::set<std::string> folded;
  for (const TableRef& t : tablesOf(schema, FileStage::Final))
    if (schema.foldsPairs(t.c)) folded.insert({t.path, scalePathOf(t.path)});
  for (const std::string& d : rowDatasets(schema, FileStage::Final))
    if (!folded.count(d)) copyDataset(file_.get(), out.get(), d);
  std::vector<int> incOf(size_t(nB), -1);
  for (int i = 0; i < nI; ++i) incOf[size_t(schema.incidence[size_t(i)].bin)] = i;
  auto upper = [&](int i) { return grid_.isUpper(schema.incidence[size_t(i)].bin); };
  const std::string scratchPath = target + ".scratch";
  nlohmann::json report = nlohmann::json::object();
  for (Component c : schema.components.list()) {
    if (!schema.foldsPairs(c)) continue;
    const std::string name = componentName(c), v = "/bsdf/" + name, e = "/bsdf_stderr/" + name;
    // The run's per-bin errors (read), and whether the final file keeps them (written).
    const bool errors = schema.keepsBinErrorsWhileRunning(c), writeErrors = schema.storesBinErrors(c);
    // Two estimates of a pair are independent unless one tile made both (symmetry) or one is the
    // other mirrored (the wave term halved by reciprocity): then their mean's error is at most the
    // mean of their errors.
    auto independent = [&](int i, int j) {
      return schema.sourceTile[size_t(i)] != schema.sourceTile[size_t(j)] &&
             !(c == Component::Incoherent && schema.halvesWaveByReciprocity);
    };
    // Phase 1: the pair matrix P[i][row][j] = f(i -> bin of j) in square blocks (a scratch file), so
    // that phase 2 reads f(j -> bin of i) for a block of i as one column of blocks.
    {
      H5File scratch(H5Fcreate(scratchPath.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl), "create " + scratchPath);
      for (const std::string& p : errors ? std::vector<std::string>{v, e} : std::vector<std::string>{v}) {
        H5Dataset d = create3D(scratch, p == v ? "v" : "e", H5T_NATIVE_FLOAT, hsize_t(nI), hsize_t(nC), hsize_t(nI),
                               0.0, true, 0, true);
        for (int a = 0; a < nI; a += int(kPairBlock)) {
          const int n = std::min(int(kPairBlock), nI - a);
          std::vector<double> band(size_t(n) * nC * nI);
          for (int i = a; i < a + n; ++i) {
            const std::vector<double> row = getTable(p, i);
            for (int ch = 0; ch < nC; ++ch)
              for (int j = 0; j < nI; ++j)
                band[(size_t(i - a) * nC + ch) * nI + j] = row[size_t(ch) * nB + schema.incidence[size_t(j)].bin];
          }
          writeBlock(d, scratchPath, hsize_t(a), band, hsize_t(nC), hsize_t(nI), false);
        }
        d.close("write " + scratchPath);
      }
      scratch.close("close " + scratchPath);
    }
    // Phase 2: per block of incidences, the (weighted) mean of f(i -> o) and f(j -> bin of i) where j >= i.
    H5File scratch(H5Fopen(scratchPath.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), "open " + scratchPath);
    H5Dataset sv(H5Dopen2(scratch, "v", H5P_DEFAULT), "open scratch"), se;
    if (errors) se = H5Dataset(H5Dopen2(scratch, "e", H5P_DEFAULT), "open scratch");
    H5Dataset ov(H5Dopen2(out, v.c_str(), H5P_DEFAULT), "open " + v), oe, svOut, seOut;
    if (writeErrors) oe = H5Dataset(H5Dopen2(out, e.c_str(), H5P_DEFAULT), "open " + e);
    if (half) svOut = H5Dataset(H5Dopen2(out, scalePathOf(v).c_str(), H5P_DEFAULT), "open " + scalePathOf(v));
    if (half && writeErrors)
      seOut = H5Dataset(H5Dopen2(out, scalePathOf(e).c_str(), H5P_DEFAULT), "open " + scalePathOf(e));
    PairCheck check;
    for (int a = 0; a < nI; a += int(kPairBlock)) {
      const int n = std::min(int(kPairBlock), nI - a);
      const std::vector<float> colV = readBlock(sv, scratchPath, hsize_t(a), hsize_t(n), true);
      const std::vector<float> colE = errors ? readBlock(se, scratchPath, hsize_t(a), hsize_t(n), true) : colV;
      std::vector<double> bandV, bandE, scalesV, scalesE;  // the band's rows and, for float16, their scales
      for (int i = a; i < a + n; ++i) {
        std::vector<double> row = getTable(v, i), err = errors ? getTable(e, i) : std::vector<double>{};
        for (int j = 0; j < nI; ++j) {
          if (j == i || upper(j) != upper(i)) continue;
          const size_t o = size_t(schema.incidence[size_t(j)].bin);
          for (int ch = 0; ch < nC; ++ch) {
            const size_t x = size_t(ch) * nB + o, y = (size_t(j) * nC + ch) * n + size_t(i - a);
            if (j < i) {  // stored at (j, bin of i)
              row[x] = std::nan("");
              if (errors) err[x] = std::nan("");
              continue;
            }
            const double f1 = row[x], f2 = colV[y];
            // Weighted by the projected solid angles of the bins each estimate was tallied in
            // (reciprocalPairWeight: the mean of least variance of the path-traced tables; equal
            // weights made a pole or horizon slice, whose own bin is small, up to 3 times noisier
            // than unfolded). `incoherent` (the wave term less `coherent`) takes the same weights,
            // so that WS = coherent + incoherent stays the weighted mean of the wave term's two
            // values, with no path noise.
            // Slices with paths of their own (path_allocation = "equal-error") weigh by them too.
            const double pathsRatio =
                schema.slicePaths.empty() ? 1.0 : double(schema.pathsFor(j)) / double(schema.pathsFor(i));
            const double w1 = reciprocalPairWeight(grid_, int(o), schema.incidence[size_t(i)].bin, pathsRatio),
                         w2 = 1 - w1;
            row[x] = w1 * f1 + w2 * f2;
            ++check.pairs;
            check.diffL1 += std::abs(f1 - f2);
            check.sumL1 += std::abs(f1) + std::abs(f2);
            if (!errors) continue;
            const double s1 = err[x], s2 = colE[y];
            if (independent(i, j)) {
              err[x] = std::sqrt(w1 * w1 * s1 * s1 + w2 * w2 * s2 * s2);
              if (s1 * s1 + s2 * s2 > 0) {
                const double z = (f1 - f2) / std::sqrt(s1 * s1 + s2 * s2);
                ++check.tested;
                check.sumZ2 += z * z;
                check.maxZ = std::max(check.maxZ, std::abs(z));
              }
            } else {
              err[x] = w1 * s1 + w2 * s2;
            }
            if (schema.storage.rounding == TableRounding::Noise) roundEstimate(row[x], err[x]);  // to its own noise
          }
        }
        if (!writeErrors) err.clear();  // (kept per slice in the final file)
        if (half) {
          for (const auto& [r, scales] :
               {std::pair<std::vector<double>*, std::vector<double>*>{&row, &scalesV}, {&err, &scalesE}}) {
            if (r->empty()) continue;
            ScaledRow s = scaleForHalf(*r, size_t(nC));
            scales->insert(scales->end(), s.scales.begin(), s.scales.end());
            *r = std::move(s.values);
          }
        }
        bandV.insert(bandV.end(), row.begin(), row.end());
        bandE.insert(bandE.end(), err.begin(), err.end());
      }
      writeBlock(ov, v, hsize_t(a), bandV, hsize_t(nC), hsize_t(nB), half);
      if (writeErrors) writeBlock(oe, e, hsize_t(a), bandE, hsize_t(nC), hsize_t(nB), half);
      if (half) writeBlock(svOut, scalePathOf(v), hsize_t(a), scalesV, hsize_t(nC), 1, false);
      if (half && writeErrors) writeBlock(seOut, scalePathOf(e), hsize_t(a), scalesE, hsize_t(nC), 1, false);
    }
    if (half) svOut.close("write " + scalePathOf(v));
    if (half && writeErrors) seOut.close("write " + scalePathOf(e));
    ov.close("write " + v);
    if (writeErrors) oe.close("write " + e);
    report[name] = {{"pairs", check.pairs},
                    {"relative_l1_difference", check.sumL1 > 0 ? check.diffL1 / check.sumL1 : 0.0},
                    {"tested_pairs", check.tested},
                    {"mean_z2", check.tested ? check.sumZ2 / double(check.tested) : 0.0},
                    {"max_abs_z", check.maxZ}};
  }
  std::filesystem::remove(scratchPath);
  setStringAttr(
      out, "pairs",
      "stored once for " + std::string(report.empty() ? "no component" : "the components below") +
          ": same-side pairs of incidence bins hold the mean of f(i -> o) and f(o -> i), weighted by "
          "the projected solid angles of the bins each was tallied in" +
          std::string(schema.slicePaths.empty() ? ""
                                                : " times the paths of the slice that tallied it (path_allocation = "
                                                  "\"equal-error\": /stats/samples)") +
          " (the reciprocity check of each: " + report.dump() + ")");
  out.close("close " + target);
  return report;
}

void BsdfFileWriter::finish() {
  // Every byte on disk before the rename: a failure here leaves the partial file and its journal
  // (resumable) and the old output, if any, untouched.
  flushPending();
  if (schema_.storage.pairs == TablePairs::Once) {
    // The final file is written anew with each pair stored once; the partial file stays until it
    // has its name (a kill during the fold is resumed by folding again).
    const std::string folded = path_ + ".pairs";
    try {
      pairsReport_ = foldPairs(folded);
    } catch (...) {
      std::error_code ec;
      std::filesystem::remove(folded, ec);
      std::filesystem::remove(folded + ".scratch", ec);
      throw;
    }
    syncPath(folded);
    closeDatasets();
    file_.close("close " + partial_);
    renameChecked(folded, path_);
    std::error_code ec;
    std::filesystem::remove(partial_, ec);
  } else {
    closeDatasets();
    file_.close("close " + partial_);
    syncPath(partial_);
    renameChecked(partial_, path_);
  }
  // The output has its name and the partial file is gone: the journal goes with it before the
  // folder is synced, and a failure of that sync is reported as what it is (the output in place,
  // its rename not yet durable), not as a run whose partial file is still there.
  inPlace_ = true;
  std::error_code ec;
  std::filesystem::remove(journal_, ec);
  std::filesystem::path dir = std::filesystem::path(path_).parent_path();
  syncPath(dir.empty() ? "." : dir.string());
  finished_ = true;
}

BsdfFileReader::BsdfFileReader(const std::string& path) {
  if (!std::filesystem::exists(path)) {
    if (std::filesystem::exists(path + ".partial"))
      throw InputError(path + ": no such file; " + path +
                       ".partial holds the slices of a run that has not "
                       "finished (being written, stopped or killed): open that to look at them");
    throw InputError(path + ": no such file");
  }
  // A SWMR reader opens a partial file while its run writes it, or after the run was killed (the
  // file still says it is open for writing); complete files open the same way.
  hid_t id = H5Fopen(path.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, H5P_DEFAULT);
  if (id < 0) {
    H5Eclear2(H5E_DEFAULT);
    id = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  }
  if (id < 0) {
    H5Eclear2(H5E_DEFAULT);
    throw InputError(path + ": cannot be opened as HDF5 (not a microbsdf output file, or no permission to read it)");
  }
  file_ = H5File(id, "open " + path);
  path_ = path;
  // A foreign HDF5 file, or one damaged, is refused with what it lacks (exit 2), not with the HDF5
  // library's error stack.
  for (const char* required : {"/spectrum", "/spectrum/wavelength_nm", "/incidence", "/incidence/bin",
                               "/incidence/theta_deg", "/incidence/phi_deg", "/bsdf", "/bsdf/done", "/grid"})
    if (H5Lexists(file_, required, H5P_DEFAULT) <= 0) {
      H5Eclear2(H5E_DEFAULT);
      throw InputError(path + ": not a microbsdf output file (it has no " + required + ")");
    }
  try {
    readStructure(path);
  } catch (const InputError&) {
    throw;
  } catch (const std::runtime_error& e) {
    throw InputError(path + ": a damaged microbsdf output file (" + e.what() + ")");
  }
}

void BsdfFileReader::readStructure(const std::string& path) {
  lambda_nm_ = read1D<double>(file_, "/spectrum/wavelength_nm", H5T_NATIVE_DOUBLE);
  incBin_ = read1D<int>(file_, "/incidence/bin", H5T_NATIVE_INT);
  incTheta_ = read1D<double>(file_, "/incidence/theta_deg", H5T_NATIVE_DOUBLE);
  incPhi_ = read1D<double>(file_, "/incidence/phi_deg", H5T_NATIVE_DOUBLE);
  done_ = read1D<uint8_t>(file_, "/bsdf/done", H5T_NATIVE_UINT8);
  if (H5Lexists(file_, "/colour", H5P_DEFAULT) > 0) {
    H5Group c(H5Gopen2(file_, "/colour", H5P_DEFAULT), "open /colour");
    colourSpace_ = readStringAttr(c, "space");
    std::stringstream names(readStringAttr(c, "channels"));
    for (std::string n; std::getline(names, n, ',');) channels_.push_back(n);
    if (channels_.size() != 3)
      throw std::runtime_error(path + ": /colour names " + std::to_string(channels_.size()) + " channels, not 3");
  } else {
    for (double l : lambda_nm_) channels_.push_back(fmt::format("{:g}nm", l));
  }
  H5Group g(H5Gopen2(file_, "/grid", H5P_DEFAULT), "open /grid");
  auto intAttr = [&](const char* name) {
    int64_t v = 0;
    H5Attribute a(H5Aopen(g, name, H5P_DEFAULT), std::string("open attribute ") + name);
    h5check(H5Aread(a, H5T_NATIVE_INT64, &v), "read attribute");
    return int(v);
  };
  if (H5Aexists(g, "n_theta") > 0)
    grid_ = std::make_unique<DirectionGrid>(ThetaPhiGrid{intAttr("n_theta"), intAttr("n_phi")});
  else
    grid_ = std::make_unique<DirectionGrid>(DiskGrid{intAttr("width"), intAttr("height")});
  if (incBin_.size() != done_.size() || incTheta_.size() != done_.size() || incPhi_.size() != done_.size() ||
      lambda_nm_.empty())
    throw InputError(path +
                     ": a damaged microbsdf output file (its incidence and done lists differ in length, or it "
                     "has no wavelength)");
}

SpectrumToColour BsdfFileReader::toColour() const {
  if (spectral()) return SpectrumToColour(lambda_nm_);
  std::vector<Colour3> perChannel(3);
  for (int c = 0; c < 3; ++c) {
    Colour3 unit{0, 0, 0};
    unit[size_t(c)] = 1;
    perChannel[size_t(c)] = colourSpace_.rfind("CIE 1931 XYZ", 0) == 0 ? unit : linearSrgbToXyz(unit);
  }
  return SpectrumToColour::fromChannels(perChannel);
}

int BsdfFileReader::doneCount() const {
  return int(std::count_if(done_.begin(), done_.end(), [](uint8_t d) { return d != 0; }));
}

std::vector<std::string> BsdfFileReader::components() const {
  std::vector<std::string> out;
  for (int c = 0; c < kComponentCount; ++c) {
    std::string p = std::string("/bsdf/") + kComponentNames[c];
    if (H5Lexists(file_, p.c_str(), H5P_DEFAULT) > 0) out.push_back(kComponentNames[c]);
  }
  return out;
}

std::vector<double> BsdfFileReader::readRow(const std::string& dataset, int incidence) const {
  return readRowImpl(file_, dataset, incidence);
}

const BsdfFileReader::OpenTable& BsdfFileReader::table(const std::string& path) const {
  auto it = tables_.find(path);
  if (it != tables_.end()) return it->second;
  // A chunk cache that holds a row and a column of square blocks (pairs stored once), so that
  // reading the slices in order decompresses each block about once.
  H5Plist dapl(H5Pcreate(H5P_DATASET_ACCESS), "H5Pcreate");
  h5check(H5Pset_chunk_cache(dapl, 12421, 64u << 20, 1.0), "H5Pset_chunk_cache");
  OpenTable t;
  t.d = H5Dataset(H5Dopen2(file_, path.c_str(), dapl), "open " + path);
  t.folded = H5Aexists(t.d, "pairs") > 0;
  const std::string scalePath = scalePathOf(path);
  if (H5Lexists(file_, scalePath.substr(0, scalePath.rfind('/')).c_str(), H5P_DEFAULT) > 0) {
    t.scale = H5Dataset(H5Dopen2(file_, scalePath.c_str(), H5P_DEFAULT), "open " + scalePath);
    if (t.folded) {  // a finished file (the fold writes the final one): its scales do not change
      H5Dataspace fs(H5Dget_space(t.scale), "H5Dget_space");
      t.scales.resize(size_t(H5Sget_simple_extent_npoints(fs)));
      h5check(H5Dread(t.scale, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, t.scales.data()), "read " + scalePath);
    }
  }
  return tables_.emplace(path, std::move(t)).first->second;
}

// A finished table holds finite values only (every mirrored half filled, every skipped component
// 0): a NaN or an infinity there is damage, which a reader must not pass on as a figure. A partial
// file may hold NaN in the half of a pair still to be mirrored, and is read as it is.
std::vector<double> BsdfFileReader::readTable(const std::string& path, int incidence) const {
  std::vector<double> v = readTableValues(path, incidence);
  if (doneCount() != incidenceCount()) return v;
  if (const std::optional<DamagedValue> bad = damagedValueOf(path, v, UnfilledHalf::Refused))
    throw InputError(fmt::format("{}: {} of slice {} holds {} at value {}{}: the table is damaged; compute it again",
                                 path_, path, incidence, bad->value, bad->at,
                                 std::isfinite(bad->value) ? ", which a sum of non-negative terms cannot" : ""));
  return v;
}

std::vector<double> BsdfFileReader::readTableValues(const std::string& path, int incidence) const {
  const OpenTable& t = table(path);
  std::vector<double> v = readRowFrom(t.d, path, incidence);
  const size_t nB = size_t(grid_->binCount()), nC = v.size() / nB, nI = incBin_.size();
  if (t.scale.valid()) {
    // Read with the row: a partial file's slices get their scales as they are written.
    const std::vector<double> scales = readRowFrom(t.scale, scalePathOf(path), incidence);
    for (size_t k = 0; k < v.size(); ++k) v[k] *= scales[k / nB];
  }
  if (!t.folded) return v;
  // Pairs stored once: the same-side entries of incidences j < i are at (j, bin of i), one column
  // of the table.
  const int bi = incBin_[size_t(incidence)];
  H5Dataspace fs(H5Dget_space(t.d), "H5Dget_space");
  hsize_t start[3] = {0, 0, hsize_t(bi)}, count[3] = {hsize_t(nI), hsize_t(nC), 1};
  h5check(H5Sselect_hyperslab(fs, H5S_SELECT_SET, start, nullptr, count, nullptr), "select " + path);
  H5Dataspace ms(H5Screate_simple(3, count, nullptr), "H5Screate_simple");
  const std::vector<double> col = readSelection<double>(t.d, ms, fs, nI * nC, path);
  const bool upper = grid_->isUpper(bi);
  for (size_t j = 0; j < size_t(incidence); ++j) {
    if (grid_->isUpper(incBin_[j]) != upper) continue;
    for (size_t c = 0; c < nC; ++c)
      v[c * nB + size_t(incBin_[j])] = col[j * nC + c] * (t.scales.empty() ? 1.0 : t.scales[j * nC + c]);
  }
  return v;
}

std::vector<double> BsdfFileReader::slice(const std::string& component, int incidence) const {
  return readTable("/bsdf/" + component, incidence);
}
bool BsdfFileReader::hasBinErrors(const std::string& component) const {
  const std::string p = "/bsdf_stderr/" + component;
  return H5Lexists(file_, "/bsdf_stderr", H5P_DEFAULT) > 0 && H5Lexists(file_, p.c_str(), H5P_DEFAULT) > 0;
}
std::vector<double> BsdfFileReader::sliceStdError(const std::string& component, int incidence) const {
  if (!hasBinErrors(component))
    throw std::runtime_error("the file stores the standard errors of '" + component +
                             "' per slice only (its storage profile: attribute storage_profile), not per bin");
  return readTable("/bsdf_stderr/" + component, incidence);
}
std::string BsdfFileReader::storageProfile() const {
  return hasAttribute("storage_profile") ? attribute("storage_profile")
                                         : "full: float32 tables; standard errors per bin";
}

SliceStats BsdfFileReader::stats(int incidence) const {
  SliceStats s;
  s.samples = uint64_t(readRow("/stats/samples", incidence)[0]);
  s.seconds = readRow("/stats/seconds", incidence)[0];
  if (H5Lexists(file_, "/stats/wave_samples", H5P_DEFAULT) > 0)
    s.waveSamples = uint64_t(readRow("/stats/wave_samples", incidence)[0]);
  if (H5Lexists(file_, "/stats/sampling_stop", H5P_DEFAULT) > 0)
    s.samplingStop = int(readRow("/stats/sampling_stop", incidence)[0]);
  if (H5Lexists(file_, "/stats/multiple_check", H5P_DEFAULT) > 0) {
    s.multipleCheck = readRow("/stats/multiple_check", incidence)[0];
    s.multipleReenabled = readRow("/stats/multiple_reenabled", incidence)[0] != 0;
  }
  if (H5Lexists(file_, "/stats/diffraction_check", H5P_DEFAULT) > 0) {
    s.diffractionCheck = readRow("/stats/diffraction_check", incidence)[0];
    s.diffractionReenabled = readRow("/stats/diffraction_reenabled", incidence)[0] != 0;
  }
  s.truncated = readRow("/stats/truncated", incidence);
  s.leaked = readRow("/stats/leaked", incidence);
  s.missed = readRow("/stats/missed", incidence);
  const bool energyErrors = H5Lexists(file_, "/stats/energy_reflected_stderr", H5P_DEFAULT) > 0;
  if (energyErrors) s.pathsAlbedoStdError = readRow("/stats/paths_albedo_stderr", incidence);
  if (H5Lexists(file_, "/stats/paths_rel_error", H5P_DEFAULT) > 0)
    s.pathsRelError = readRow("/stats/paths_rel_error", incidence);
  if (H5Lexists(file_, "/stats/energy_balance", H5P_DEFAULT) > 0) {
    s.energyBalance = readRow("/stats/energy_balance", incidence);
    s.energyBalanceStdError = readRow("/stats/energy_balance_stderr", incidence);
  }
  if (H5Lexists(file_, "/stats/nonphysical", H5P_DEFAULT) > 0) s.nonphysical = readRow("/stats/nonphysical", incidence);
  for (const auto& c : components()) {
    s.energyReflected[c] = readRow("/stats/energy_reflected/" + c, incidence);
    s.energyTransmitted[c] = readRow("/stats/energy_transmitted/" + c, incidence);
    if (energyErrors) {
      s.energyReflectedStdError[c] = readRow("/stats/energy_reflected_stderr/" + c, incidence);
      s.energyTransmittedStdError[c] = readRow("/stats/energy_transmitted_stderr/" + c, incidence);
    }
    std::string rel = "/stats/rel_error/" + c;
    if (H5Lexists(file_, "/stats/rel_error", H5P_DEFAULT) > 0 && H5Lexists(file_, rel.c_str(), H5P_DEFAULT) > 0)
      s.relError[c] = readRow(rel, incidence);
  }
  return s;
}

std::string BsdfFileReader::attribute(const std::string& name) const {
  return readStringAttr(file_, name);
}

bool BsdfFileReader::hasAttribute(const std::string& name) const {
  return H5Aexists(file_, name.c_str()) > 0;
}

int64_t BsdfFileReader::intAttribute(const std::string& name) const {
  int64_t v = 0;
  H5Attribute a(H5Aopen(file_, name.c_str(), H5P_DEFAULT), "open attribute " + name);
  h5check(H5Aread(a, H5T_NATIVE_INT64, &v), "read attribute " + name);
  return v;
}

int BsdfFileReader::nearestIncidence(double theta_deg, double phi_deg) const {
  Vec3 w = sphericalDirection(radians(theta_deg), radians(phi_deg));
  int best = 0;
  double bestDot = -2;
  for (int i = 0; i < incidenceCount(); ++i) {
    double d = dot(w, sphericalDirection(radians(incTheta_[i]), radians(incPhi_[i])));
    if (d > bestDot) {
      bestDot = d;
      best = i;
    }
  }
  return best;
}

namespace {

// Little-endian fields of a byte message between ranks.
struct ByteWriter {
  std::vector<unsigned char> out;
  void u64(uint64_t v) {
    for (int k = 0; k < 8; ++k) out.push_back(static_cast<unsigned char>(v >> (8 * k)));
  }
  void bytes(const unsigned char* p, size_t n) {
    u64(n);
    out.insert(out.end(), p, p + n);
  }
  void text(const std::string& s) { bytes(reinterpret_cast<const unsigned char*>(s.data()), s.size()); }
};
struct ByteReader {
  const std::vector<unsigned char>& in;
  size_t pos = 0;
  size_t take(size_t n) {
    if (n > in.size() - pos) throw std::runtime_error("prepared slice: message truncated");
    pos += n;
    return pos - n;
  }
  uint64_t u64() {
    const size_t at = take(8);
    uint64_t v = 0;
    for (int k = 0; k < 8; ++k) v |= uint64_t(in[at + size_t(k)]) << (8 * k);
    return v;
  }
  std::vector<unsigned char> bytes() {
    const size_t n = u64(), at = take(n);
    return {in.begin() + long(at), in.begin() + long(at + n)};
  }
  std::string text() {
    const std::vector<unsigned char> b = bytes();
    return {b.begin(), b.end()};
  }
};

}  // namespace

std::vector<unsigned char> serializePrepared(const PreparedSlice& p) {
  ByteWriter w;
  w.u64(uint64_t(p.index));
  w.u64(p.rows.size());
  for (const auto& [path, row] : p.rows) {
    w.text(path);
    w.bytes(reinterpret_cast<const unsigned char*>(row.data()), row.size() * sizeof(double));
  }
  w.u64(p.chunks.size());
  for (const PackedChunk& c : p.chunks) {
    w.text(c.path);
    for (uint64_t v : {c.a, c.b, c.c1, c.c2}) w.u64(v);
    w.bytes(c.bytes.data(), c.bytes.size());
  }
  return std::move(w.out);
}

PreparedSlice deserializePrepared(const std::vector<unsigned char>& bytes) {
  ByteReader r{bytes};
  PreparedSlice p;
  p.index = int(r.u64());
  for (uint64_t n = r.u64(), k = 0; k < n; ++k) {
    const std::string path = r.text();
    const std::vector<unsigned char> raw = r.bytes();
    if (raw.size() % sizeof(double)) throw std::runtime_error("prepared slice: a row of partial values");
    std::vector<double> row(raw.size() / sizeof(double));
    std::memcpy(row.data(), raw.data(), raw.size());
    p.rows.emplace(path, std::move(row));
  }
  p.chunks.resize(r.u64());
  for (PackedChunk& c : p.chunks) {
    c.path = r.text();
    c.a = r.u64(), c.b = r.u64(), c.c1 = r.u64(), c.c2 = r.u64();
    c.bytes = r.bytes();
  }
  if (r.pos != bytes.size()) throw std::runtime_error("prepared slice: trailing bytes");
  return p;
}

std::string describeSliceFlags(unsigned flags) {
  std::string out;
  const std::pair<SliceFlag, const char*> names[] = {{SliceFlag::NegativeEnergy, "energy below 0"},
                                                     {SliceFlag::ExcessEnergy, "energy above 1"},
                                                     {SliceFlag::Unbalanced, "energy balance beyond the tolerance"},
                                                     {SliceFlag::PathsLost, "paths lost beyond the tolerance"}};
  for (const auto& [bit, name] : names)
    if (flags & unsigned(bit)) out += (out.empty() ? "" : ", ") + std::string(name);
  return out;
}

}  // namespace mbsdf
