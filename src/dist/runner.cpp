#include "dist/runner.h"

#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <chrono>
#include <deque>
#include <memory>
#include <optional>

#include "core/log.h"
#include "geometry/embree_scene.h"
#include "io/bsdf_file.h"
#include "scattering/path_tracer.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
namespace {
constexpr int kTagResult = 12;
}

RunSummary runJob(const Job& job, const MpiSession& mpi, const RunOptions& options) {
  auto t0 = std::chrono::steady_clock::now();
  std::optional<tbb::global_control> threads;
  if (options.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, size_t(options.threads));

  const std::string outPath = options.outputPath.empty() ? job.outputPath : options.outputPath;
  DirectionGrid grid(job.gridLayout);
  PeriodicScene scene(job.geometry);
  PathTracerSettings settings;
  settings.paths = job.pathsPerSlice;
  settings.maxDepth = job.maxDepth;
  settings.seed = job.seed;
  settings.tallyGeoMasked = job.components.has(Component::Lost);
  PathTracer tracer(scene, job.material, job.lambda_um(), grid, settings);
  std::unique_ptr<WaveEstimator> wave;
  if (job.needsWave()) {
    WaveSettings ws;
    ws.estimator = job.resolvedWaveEstimator();
    ws.samplesPerBin = int(job.waveSamplesPerBin);
    ws.pointsPerDirection = int(job.wavePointsPerDirection);
    ws.incidenceDirections = int(job.waveIncidenceDirections);
    ws.seed = job.seed;
    ws.computeMasked = job.components.has(Component::Lost);
    wave = makeWaveEstimator(WaveContext{job.geometry, scene, job.material, job.lambda_um(), grid,
                                         CoherenceWindow::fromCoherenceLength(job.scene.coherenceLength_um,
                                                                              job.geometry.sizeX, job.geometry.sizeY,
                                                                              job.geometry.periodic),
                                         ws});
    if (mpi.rank() == 0)
      spdlog::info("scalar diffraction: {} estimator, {} samples per bin, coherence length {} µm{}", wave->name(),
                   job.waveSamplesPerBin, job.scene.coherenceLength_um,
                   job.scene.coherenceLength_um > 0 ? "" : " (no window: one copy of the patch)");
  }

  const int nTiles = int(job.incidence.size());
  if (mpi.rank() == 0)
    spdlog::info("job {}: {} ({} triangles, {:.3g} x {:.3g} µm{}), {}, {} wavelengths, grid {} ({} bins), {} tiles "
                 "on {} ranks, {} paths per slice",
                 job.file, job.geometryKind, job.geometry.triangles.size(), job.geometry.sizeX, job.geometry.sizeY,
                 job.geometry.periodic ? ", periodic" : "", job.material.describe(), job.lambda_nm.size(), grid.kind(),
                 grid.binCount(), nTiles, mpi.size(), job.pathsPerSlice);

  std::unique_ptr<BsdfFileWriter> writer;
  if (mpi.rank() == 0) writer = std::make_unique<BsdfFileWriter>(outPath, job, grid);

  ProgressReporter progress("tiles", uint64_t(nTiles));
  int written = 0;
  auto writeResult = [&](const TileResult& r) {
    writer->writeTile(r);
    ++written;
    progress.update(uint64_t(written));
  };
  auto receiveOne = [&](bool blocking) {
    int flag = 0;
    MPI_Status st;
    if (blocking) MPI_Probe(MPI_ANY_SOURCE, kTagResult, MPI_COMM_WORLD, &st), flag = 1;
    else MPI_Iprobe(MPI_ANY_SOURCE, kTagResult, MPI_COMM_WORLD, &flag, &st);
    if (!flag) return false;
    int count = 0;
    MPI_Get_count(&st, MPI_DOUBLE, &count);
    std::vector<double> buf(static_cast<size_t>(count));
    MPI_Recv(buf.data(), count, MPI_DOUBLE, st.MPI_SOURCE, kTagResult, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    writeResult(TileResult::deserialize(buf));
    return true;
  };

  std::deque<std::vector<double>> sendBuffers;
  std::vector<MPI_Request> requests;
  uint64_t paths = 0;
  for (int t = mpi.rank(); t < nTiles; t += mpi.size()) {
    const auto& inc = job.incidence[t];
    spdlog::debug("tile {}: incidence theta {:.3f} phi {:.3f} (bin {})", t, inc.theta_deg, inc.phi_deg, inc.bin);
    ProgressReporter pathProgress("tile " + std::to_string(t) + " paths",
                                  job.pathsPerSlice * (job.material.directionsIndependentOfLambda() ? 1 : job.lambda_nm.size()),
                                  30.0, false);
    std::optional<Vec3> exact;
    if (job.exactIncidence) exact = sphericalDirection(radians(inc.theta_deg), radians(inc.phi_deg));
    TileResult r = tracer.run(t, t, inc.bin, exact, [&](uint64_t done) {
      pathProgress.update(done);
      if (mpi.rank() == 0)
        while (receiveOne(false)) {}
    });
    if (wave) {
      WaveTileResult w = wave->run(t, inc.bin, exact);
      addWaveComponents(r, w, job.components.has(Component::Incoherent), job.components.has(Component::Lost));
      r.seconds += w.seconds;
      r.rays += w.rays;
    }
    paths += r.samples;
    if (mpi.rank() == 0) {
      writeResult(r);
      while (receiveOne(false)) {}
    } else {
      sendBuffers.push_back(r.serialize());
      requests.emplace_back();
      MPI_Isend(sendBuffers.back().data(), int(sendBuffers.back().size()), MPI_DOUBLE, 0, kTagResult, MPI_COMM_WORLD,
                &requests.back());
    }
  }
  if (mpi.rank() == 0) {
    while (written < nTiles) receiveOne(true);
    writer->finish();
  } else if (!requests.empty()) {
    MPI_Waitall(int(requests.size()), requests.data(), MPI_STATUSES_IGNORE);
  }
  RunSummary s;
  s.tiles = nTiles;
  s.paths = paths;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return s;
}

}  // namespace mbsdf
