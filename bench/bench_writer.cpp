// Rank 0's writer fed finished tiles as fast as it takes them (no physics): paper-resolution slices
// (75 x 300 bins per hemisphere, 8 wavelengths, coherent, incoherent and multiple with their
// standard errors: 8.6 MB of float32 per slice) written and committed one by one, as a job without
// symmetry writes them, and in commits of 60 (a symmetric surface's ring), and one by one with their
// statistics and chunks prepared by the ranks that computed them (as rank 0 receives a worker's). The baseline,
// measured in the same run: the same bytes written raw to a file and synced. Printed: slices per second of each and the
// writer's rate against the raw one.
#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "core/direction_grid.h"
#include "io/bsdf_file.h"
#include "io/output_schema.h"
#include "scattering/tile_result.h"

namespace mbsdf {
namespace {

constexpr int kLambda = 8;

struct WriterFixture {
  DirectionGrid grid{ThetaPhiGrid{75, 300}};
  OutputSchema schema;
  std::vector<TileResult> slices;  // distinct contents, reused round robin
  WriterFixture(int nIncidence) {
    schema.jobText = "# writer benchmark";
    schema.jobFile = "bench.toml";
    schema.geometryKind = "none";
    schema.material = "none";
    schema.seed = 1;
    schema.pathsPerSlice = 1000000;
    for (int l = 0; l < kLambda; ++l) schema.lambda_nm.push_back(400.0 + 40.0 * l);
    for (int i = 0; i < nIncidence; ++i) schema.incidence.push_back({45.0, 0.0, i % grid.binsPerHemisphere()});
    for (Component c : {Component::Coherent, Component::Incoherent, Component::Multiple}) schema.components.add(c);
    for (int k = 0; k < 4; ++k) slices.push_back(slice(k));
  }
  // A rough lobe with Monte Carlo noise in its low digits: what the deflate filter sees in a real table.
  TileResult slice(int k) const {
    TileResult r;
    r.nLambda = kLambda;
    r.nBins = grid.binCount();
    r.samples = 1000000;
    r.truncated = r.leaked = r.missed = std::vector<double>(kLambda, 0.0);
    uint64_t state = 0x9E3779B97F4A7C15ull * uint64_t(k + 1);
    auto noise = [&] {
      state ^= state << 13, state ^= state >> 7, state ^= state << 17;
      return double(state >> 11) * 0x1.0p-53 - 0.5;
    };
    for (Component c : {Component::Coherent, Component::Incoherent, Component::Multiple}) {
      auto& v = r.value[int(c)];
      auto& e = r.stdError[int(c)];
      v.resize(size_t(kLambda) * r.nBins);
      e.resize(v.size());
      for (int l = 0; l < kLambda; ++l)
        for (int b = 0; b < r.nBins; ++b) {
          const Vec3 d = grid.centre(b);
          const double lobe = d.z > 0 ? std::exp(-(1 - d.z) * 8.0) : 0.0;
          v[size_t(l) * r.nBins + b] = lobe * (1 + 0.05 * noise());
          e[size_t(l) * r.nBins + b] = 0.05 * lobe * (1 + 0.1 * noise());
        }
      r.pathMoments[int(c)] = std::vector<double>(kLambda, 0.5);
    }
    return r;
  }
  size_t rawBytes() const { return size_t(6) * kLambda * size_t(grid.binCount()) * sizeof(float); }
};

double gWriterOne = 0, gWriterRing = 0, gWriterPacked = 0, gRaw = 0;

// Slices per second through BsdfFileWriter, committed in groups of `commit`; with `packed`, the
// slices come prepared (statistics and compressed table chunks), as the ranks that computed them
// send them (prepareSlice, not timed: the other ranks' work).
void BM_WriterSlices(benchmark::State& state) {
  const int n = int(state.range(0)), commit = int(state.range(1));
  const bool packed = state.range(2) != 0;
  WriterFixture f(n);
  std::vector<PreparedSlice> prepared;
  for (int i = 0; packed && i < n; ++i) {
    TileResult r = f.slices[size_t(i) % f.slices.size()];
    r.incidenceIndex = i;
    prepared.push_back(prepareSlice(r, f.schema, f.grid));
  }
  const std::string path = (std::filesystem::temp_directory_path() / "microbsdf_bench_writer.h5").string();
  double seconds = 0;
  for (auto _ : state) {
    for (const char* ext : {"", ".partial", ".journal"}) std::filesystem::remove(path + ext);
    BsdfFileWriter writer(path, f.schema, f.grid);
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<int> pending;
    for (int i = 0; i < n; ++i) {
      TileResult r = f.slices[size_t(i) % f.slices.size()];
      r.incidenceIndex = i;
      if (packed)
        writer.writePrepared(prepared[size_t(i)], [&] { return r; });
      else
        writer.writeSlice(r);
      pending.push_back(i);
      if (int(pending.size()) == commit || i == n - 1) {
        writer.commitSlices(pending);
        pending.clear();
      }
    }
    writer.finish();
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  std::filesystem::remove(path);
  const double rate = double(n) * double(state.iterations()) / seconds;
  state.counters["slices_per_s"] = rate;
  (packed ? gWriterPacked : commit == 1 ? gWriterOne : gWriterRing) = rate;
}
BENCHMARK(BM_WriterSlices)
    ->Args({60, 1, 0})
    ->Args({60, 60, 0})
    ->Args({60, 1, 1})
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

// The same bytes (float32) written raw and synced once per slice.
void BM_RawSliceWrites(benchmark::State& state) {
  const int n = int(state.range(0));
  WriterFixture f(1);
  std::vector<float> bytes(f.rawBytes() / sizeof(float));
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = float(f.slices[0].value[0][i % f.slices[0].value[0].size()]);
  const std::string path = (std::filesystem::temp_directory_path() / "microbsdf_bench_raw.bin").string();
  double seconds = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    for (int i = 0; i < n; ++i) {
      const ssize_t w = ::write(fd, bytes.data(), f.rawBytes());
      if (w != ssize_t(f.rawBytes()) || ::fsync(fd) != 0) state.SkipWithError("raw write failed");
    }
    ::close(fd);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  std::filesystem::remove(path);
  gRaw = double(n) * double(state.iterations()) / seconds;
  state.counters["slices_per_s"] = gRaw;
}
BENCHMARK(BM_RawSliceWrites)->Arg(60)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

// Reading a table whose pairs are stored once (square blocks; every slice read with its mirrored
// half) against the same table stored both ways (one slice per chunk row), as `slice`, `export` and
// `render` read them: one slice, and the whole table in order. A full-sphere job's table: 16 x 64 bins
// per hemisphere, every upper bin an incidence (1024 slices), 8 wavelengths stored as XYZ in float16,
// three components. Also the fold's own time at the end of the run.
struct ReadFixture {
  DirectionGrid grid{ThetaPhiGrid{16, 64}};
  std::string once, both;
  double foldSeconds = 0;
  ReadFixture() {
    WriterFixture w(1);
    OutputSchema schema = w.schema;
    schema.incidence.clear();
    for (int b = 0; b < grid.binsPerHemisphere(); ++b) schema.incidence.push_back({45.0, 0.0, b});
    for (int b = 0; b < grid.binsPerHemisphere(); ++b) schema.sourceTile.push_back(b);
    schema.storage = StorageProfile::compact();
    const WriterFixture lobes(1);
    for (const auto& [path, pairs] :
         {std::pair<std::string*, TablePairs>{&once, TablePairs::Once}, {&both, TablePairs::Both}}) {
      *path = (std::filesystem::temp_directory_path() /
               (std::string("microbsdf_bench_read_") + (pairs == TablePairs::Once ? "once" : "both") + ".h5"))
                  .string();
      schema.storage.pairs = pairs;
      for (const char* ext : {"", ".partial", ".journal"}) std::filesystem::remove(*path + ext);
      BsdfFileWriter writer(*path, schema, grid);
      for (int i = 0; i < int(schema.incidence.size()); ++i) {
        TileResult r = sliceOn(i);
        writer.writeTile(r);
      }
      const auto t0 = std::chrono::steady_clock::now();
      writer.finish();
      if (pairs == TablePairs::Once)
        foldSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
  }
  // A noisy lobe about the mirror direction of incidence i.
  TileResult sliceOn(int i) const {
    TileResult r;
    r.incidenceIndex = i;
    r.nLambda = kLambda;
    r.nBins = grid.binCount();
    r.samples = 1000000;
    r.truncated = r.leaked = r.missed = std::vector<double>(kLambda, 0.0);
    const Vec3 wi = grid.centre(i), m{-wi.x, -wi.y, wi.z};
    uint64_t state = 0x9E3779B97F4A7C15ull * uint64_t(i + 1);
    for (Component c : {Component::Coherent, Component::Incoherent, Component::Multiple}) {
      auto& v = r.value[int(c)];
      v.resize(size_t(kLambda) * r.nBins);
      r.stdError[int(c)].assign(v.size(), 0.0);
      for (int l = 0; l < kLambda; ++l)
        for (int b = 0; b < r.nBins; ++b) {
          state ^= state << 13, state ^= state >> 7, state ^= state << 17;
          const Vec3 d = grid.centre(b);
          const double lobe = d.z > 0 ? std::exp(-(1 - dot(d, m)) * 8.0) : 0.0;
          v[size_t(l) * r.nBins + b] = lobe * (1 + 0.05 * (double(state >> 11) * 0x1.0p-53 - 0.5));
        }
      r.pathMoments[int(c)] = std::vector<double>(kLambda, 0.5);
    }
    return r;
  }
};
const ReadFixture& readFixture() {
  static const ReadFixture f;
  return f;
}

double gReadOnce[2] = {0, 0}, gReadBoth[2] = {0, 0};  // [one slice, whole table] seconds

void BM_ReadTable(benchmark::State& state) {
  const bool folded = state.range(0) != 0, whole = state.range(1) != 0;
  const ReadFixture& f = readFixture();
  double seconds = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    BsdfFileReader r(folded ? f.once : f.both);  // opened anew: no chunk cached from the last pass
    const int n = whole ? r.incidenceCount() : 1;
    for (int i = 0; i < n; ++i)
      for (const char* c : {"coherent", "incoherent", "multiple"})
        benchmark::DoNotOptimize(r.slice(c, whole ? i : 500));
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  (folded ? gReadOnce : gReadBoth)[whole ? 1 : 0] = seconds / double(state.iterations());
  state.counters["seconds"] = seconds / double(state.iterations());
}
BENCHMARK(BM_ReadTable)
    ->Args({0, 0})
    ->Args({1, 0})
    ->Args({0, 1})
    ->Args({1, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);

}  // namespace

void printReadSummary() {
  if (gReadBoth[0] <= 0 || gReadOnce[1] <= 0) return;
  const ReadFixture& f = readFixture();
  std::printf(
      "reading a full-sphere table (1024 slices of 16x64 bins per hemisphere, XYZ float16, 3 components): one slice "
      "%.2f ms with pairs stored once, %.2f ms stored both ways (ratio %.2f); the whole table %.2f s and %.2f s "
      "(ratio %.2f); file %.2f MB and %.2f MB; the fold at the end of the run %.2f s\n",
      1e3 * gReadOnce[0], 1e3 * gReadBoth[0], gReadOnce[0] / gReadBoth[0], gReadOnce[1], gReadBoth[1],
      gReadOnce[1] / gReadBoth[1], double(std::filesystem::file_size(f.once)) / 1e6,
      double(std::filesystem::file_size(f.both)) / 1e6, f.foldSeconds);
}

void printWriterSummary() {
  if (gRaw <= 0) return;
  std::printf(
      "writer, paper-resolution slices (75x300 bins, 8 wavelengths, 3 components + errors): %.1f slices/s committed "
      "one by one, %.1f in rings of 60, %.1f one by one prepared by the computing ranks; raw writes of the same bytes "
      "%.1f slices/s; ratio %.2f, %.2f and %.2f\n",
      gWriterOne, gWriterRing, gWriterPacked, gRaw, gWriterOne / gRaw, gWriterRing / gRaw, gWriterPacked / gRaw);
}

}  // namespace mbsdf
