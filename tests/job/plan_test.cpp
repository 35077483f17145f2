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

using namespace mbsdf;

namespace {

Job sceneJob(const std::string& geometry, const std::string& material, uint64_t paths) {
  return loadJobFromString("[geometry]\n" + geometry + "\n[material]\n" + material +
                               "\n[spectrum]\nwavelengths_nm = [500.0, 650.0]\n[directions]\nn_theta = 12\nn_phi = 24\n"
                               "incidence = [[0.0, 0.0], [35.0, 20.0], [70.0, 200.0]]\n[scene]\ncoherence_length_um = 0.0\n"
                               "[effects]\ncomponents = [\"coherent\", \"multiple\"]\n[sampling]\npaths_per_slice = " +
                               std::to_string(paths) + "\nseed = 3\n",
                           "t.toml", "");
}

// The largest sliceRelativeError of coherent and multiple over the pilot incidences, measured on
// tiles computed with the job's own budget.
double measuredError(const Job& job) {
  const DirectionGrid grid(job.gridLayout);
  GeometricTransport transport(job, grid, job.pathsPerSlice);
  double worst = 0;
  for (int t : pilotIncidences(job)) {
    const TileResult r = transport.run(t, t, job.incidence[size_t(t)].bin, std::nullopt);
    for (Component c : {Component::Coherent, Component::Multiple})
      for (double e : sliceRelativeError(r, c, grid)) worst = std::max(worst, e);
  }
  return worst;
}

}  // namespace

// Four scenes, pilots at 20 000 paths, jobs at 320 000: the predicted error (the pilots' scaled by
// 1/√16) within a factor of 1.5 of the measured one.
TEST(Plan, PredictedErrorMatchesTheJobsOwn) {
  const std::vector<std::pair<const char*, Job>> scenes = {
      {"mirror hemispheres", sceneJob("kind = \"hemispheres\"\nsize_um = [10.0, 10.0]\nradius_um = 2.0\nspacing_um = 5.0\n"
                                      "resolution_um = 0.25",
                                      "name = \"mirror\"", 320000)},
      {"rough aluminium", sceneJob("kind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.5\ncorrelation_um = 1.5",
                                   "name = \"Al\"", 320000)},
      {"glass sine grating", sceneJob("kind = \"sine-grating\"\nsize_um = [4.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.4",
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
      EXPECT_NEAR(double(t["paths_per_slice"].get<uint64_t>()), std::max(1000.0, 320000 * std::pow(predicted / 0.01, 2)), 1.0)
          << name;
    }
  }
}
