// `plan`'s accuracy figures: the relative error per slice it predicts for the job's budget, from
// pilots at a fraction of it, against the error of tiles computed at the job's budget.
#include "job/plan.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "core/direction_grid.h"
#include "io/bsdf_file.h"
#include "job/effects_planner.h"
#include "job/job.h"
#include "job/transport.h"
#include "scattering/wave_estimator.h"

using namespace mbsdf;

namespace {

Job sceneJob(const std::string& geometry, const std::string& material, uint64_t paths) {
  return loadJobFromString(
      "[geometry]\n" + geometry + "\n[material]\n" + material +
          "\n[spectrum]\nwavelengths_nm = [500.0, 650.0]\n[directions]\nn_theta = 12\nn_phi = 24\n"
          "incidence = [[0.0, 0.0], [35.0, 20.0], [70.0, 200.0]]\n[scene]\ncoherence_length_um = 0.0\n"
          "[effects]\ncomponents = [\"coherent\", \"multiple\"]\n[sampling]\npaths_per_slice = " +
          std::to_string(paths) + "\nseed = 3\n",
      "t.toml", "");
}

// The largest relativeError of the path-traced table over the pilot incidences, measured on
// tiles computed with the job's own budget.
double measuredError(const Job& job) {
  const DirectionGrid grid(job.gridLayout);
  GeometricTransport transport(job, grid, job.pathsPerSlice);
  double worst = 0;
  for (int t : pilotIncidences(job)) {
    const TileResult r = transport.run(t, t, job.incidence[size_t(t)].bin, std::nullopt);
    for (double e : relativeError(r, {Component::Coherent, Component::Multiple}, grid)) worst = std::max(worst, e);
  }
  return worst;
}

}  // namespace

// Four scenes, pilots at 20 000 paths, jobs at 320 000: the predicted error (the pilots' scaled by
// 1/√16) within a factor of 1.5 of the measured one.
TEST(Plan, PredictedErrorMatchesTheJobsOwn) {
  const std::vector<std::pair<const char*, Job>> scenes = {
      {"mirror hemispheres",
       sceneJob("kind = \"hemispheres\"\nsize_um = [10.0, 10.0]\nradius_um = 2.0\nspacing_um = 5.0\n"
                "resolution_um = 0.25",
                "name = \"mirror\"", 320000)},
      {"rough aluminium", sceneJob("kind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.5\ncorrelation_um = 1.5",
                                   "name = \"Al\"", 320000)},
      {"glass sine grating",
       sceneJob("kind = \"sine-grating\"\nsize_um = [4.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.4",
                "kind = \"dielectric\"\nior = 1.5", 320000)},
      {"gold V-grooves", sceneJob("kind = \"ridged\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\napex_angle_deg = 90.0",
                                  "name = \"Au\"", 320000)},
  };
  PlanOptions options;
  options.pilotPaths = 20000;
  for (const auto& [name, job] : scenes) {
    const nlohmann::json p = planJob(job, options);
    const double predicted = p["accuracy"]["paths"]["rel_error"].get<double>();
    const double measured = measuredError(job);
    std::printf("%-20s predicted %.4f, measured %.4f (ratio %.2f)\n", name, predicted, measured, predicted / measured);
    ASSERT_GT(measured, 0) << name;
    EXPECT_LT(predicted / measured, 1.5) << name;
    EXPECT_GT(predicted / measured, 1 / 1.5) << name;
    // The budget that buys 1 % is the job's scaled by (error / 1 %)².
    for (const auto& t : p["accuracy"]["targets"]) {
      if (std::abs(t["rel_error"].get<double>() - 0.01) > 1e-12) continue;
      EXPECT_NEAR(double(t["paths_per_slice"].get<uint64_t>()),
                  std::max(1000.0, 320000 * std::pow(predicted / 0.01, 2)), 1.0)
          << name;
    }
  }
}

namespace {

// The error a table actually has: √Σ_b (Δf_b Ω⊥_b)² / Σ_b |f_ref,b| Ω⊥_b against a reference at 16× the
// budget with another seed, largest over wavelengths. Its expectation² is the run's predicted error²
// plus the reference's (1/16 of it), which is divided out.
double distanceToReference(const std::vector<double>& f, const std::vector<double>& ref, int nL,
                           const DirectionGrid& grid) {
  const int nB = grid.binCount();
  double worst = 0;
  for (int l = 0; l < nL; ++l) {
    double d2 = 0, mass = 0;
    for (int b = 0; b < nB; ++b) {
      const size_t i = size_t(l) * size_t(nB) + size_t(b);
      d2 += std::pow((f[i] - ref[i]) * grid.projectedSolidAngle(b), 2);
      mass += std::abs(ref[i]) * grid.projectedSolidAngle(b);
    }
    if (mass > 0) worst = std::max(worst, std::sqrt(d2) / mass);
  }
  return worst / std::sqrt(1 + 1 / 16.0);
}

std::vector<double> pathTable(const TileResult& r) {
  std::vector<double> f(r.value[int(Component::Coherent)]);
  if (r.has(Component::Multiple))
    for (size_t i = 0; i < f.size(); ++i) f[i] += r.value[int(Component::Multiple)][i];
  return f;
}

Job withSeed(Job job, uint64_t seed, uint64_t paths, int64_t samples) {
  job.seed = seed;
  job.pathsPerSlice = paths;
  job.waveSamplesPerBin = samples;
  return job;
}

// Per pilot incidence: the predicted error (plan --json's per_pilot) and the measured distance of
// the job's tile from the reference; the ratio √(Σ measured² / Σ predicted²) over the pilots.
double checkScene(const char* name, const Job& job, bool wave) {
  PlanOptions options;
  options.pilotPaths = 20000;
  const nlohmann::json p = planJob(job, options);
  const nlohmann::json& perPilot = p["accuracy"][wave ? "wave" : "paths"]["per_pilot"];
  const DirectionGrid grid(job.gridLayout);
  const Job run = job, ref = withSeed(job, job.seed + 101, 16 * job.pathsPerSlice, 16 * job.waveSamplesPerBin);
  GeometricTransport runPaths(run, grid, run.pathsPerSlice), refPaths(ref, grid, ref.pathsPerSlice);
  double measured2 = 0, predicted2 = 0;
  for (const auto& pilot : perPilot) {
    const int t = pilot["incidence"].get<int>();
    const int bin = job.incidence[size_t(t)].bin;
    double measured;
    if (wave) {
      auto est = makeJobWaveEstimator(run, grid, *runPaths.scene(), waveSettingsOf(run));
      auto estRef = makeJobWaveEstimator(ref, grid, *refPaths.scene(), waveSettingsOf(ref));
      const WaveTileResult a = est->run(t, bin, std::nullopt, {}), b = estRef->run(t, bin, std::nullopt, {});
      measured = distanceToReference(a.fws, b.fws, a.nLambda, grid);
    } else {
      const TileResult a = runPaths.run(t, t, bin, std::nullopt), b = refPaths.run(t, t, bin, std::nullopt);
      measured = distanceToReference(pathTable(a), pathTable(b), a.nLambda, grid);
    }
    const double predicted = pilot["rel_error"].get<double>();
    std::printf("%-28s theta_i %5.1f: predicted %.4f, measured %.4f\n", name, pilot["theta_deg"].get<double>(),
                predicted, measured);
    measured2 += measured * measured;
    predicted2 += predicted * predicted;
  }
  EXPECT_GT(predicted2, 0) << name;
  return std::sqrt(measured2 / predicted2);
}

Job waveJob(const std::string& geometry, const std::string& estimator, int samples) {
  return loadJobFromString(
      "[geometry]\n" + geometry +
          "\n[material]\nname = \"Al\"\n[spectrum]\nwavelengths_nm = [500.0]\n[directions]\n"
          "n_theta = 12\nn_phi = 24\nincidence = [[0.0, 0.0], [35.0, 20.0], [60.0, 200.0]]\n"
          "[scene]\ncoherence_length_um = 20.0\n[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n"
          "[sampling]\npaths_per_slice = 20000\nwave_estimator = \"" +
          estimator + "\"\nwave_samples_per_bin = " + std::to_string(samples) + "\nseed = 3\n",
      "t.toml", "");
}

}  // namespace

// What `plan` predicts against what the job gets: on five scenes (four path-traced tables, one
// Monte Carlo wave term) the predicted relative error of each pilot slice at the job's budget
// (plan --json: accuracy.*.per_pilot), from pilots at a fraction of it, against the distance of the
// job's own tile from a reference at 16× the budget with another seed — within a factor of 1.5 (as
// √(Σ measured² / Σ predicted²) over the pilot slices: one slice's distance is itself a random
// number).
TEST(Plan, PredictedErrorMatchesALongReference) {
  const std::vector<std::pair<const char*, Job>> pathScenes = {
      {"mirror hemispheres",
       sceneJob("kind = \"hemispheres\"\nsize_um = [10.0, 10.0]\nradius_um = 2.0\nspacing_um = 5.0\n"
                "resolution_um = 0.25",
                "name = \"mirror\"", 80000)},
      {"rough aluminium", sceneJob("kind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.5\ncorrelation_um = 1.5",
                                   "name = \"Al\"", 80000)},
      {"glass sine grating (R + T)",
       sceneJob("kind = \"sine-grating\"\nsize_um = [4.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.4",
                "kind = \"dielectric\"\nior = 1.5", 80000)},
      {"gold V-grooves", sceneJob("kind = \"ridged\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\napex_angle_deg = 90.0",
                                  "name = \"Au\"", 80000)},
  };
  for (const auto& [name, job] : pathScenes) {
    const double ratio = checkScene(name, job, false);
    std::printf("%-28s measured / predicted %.2f\n", name, ratio);
    EXPECT_LT(ratio, 1.5) << name;
    EXPECT_GT(ratio, 1 / 1.5) << name;
  }
  const Job wave =
      waveJob("kind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.3\ncorrelation_um = 2.0", "orders", 256);
  const double ratio = checkScene("rough Al, orders wave term", wave, true);
  std::printf("%-28s measured / predicted %.2f\n", "rough Al, orders wave term", ratio);
  EXPECT_LT(ratio, 1.5);
  EXPECT_GT(ratio, 1 / 1.5);
}
