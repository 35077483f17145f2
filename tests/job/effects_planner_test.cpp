// The effects planner's renderer-facing keys (effects_planner.h): the angular resolution at which
// the diffraction decision compares WS with GS, and the incidence range it plans for.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>

#include "core/direction_grid.h"
#include "job/effects_planner.h"
#include "job/tile_computer.h"
#include "job/transport.h"
#include "scattering/coherence_window.h"

using namespace mbsdf;

// Cells of the renderer's resolution partition the bins: every bin with a solid angle in one cell;
// about 2π / res² cells per hemisphere (each about res across); resolution 0 keeps the bins.
TEST(EffectsPlanner, ResolutionCellsPartitionTheBins) {
  const DirectionGrid grid(ThetaPhiGrid{90, 180});
  const std::vector<int> bins = resolutionCells(grid, 0.0);
  EXPECT_EQ(std::set<int>(bins.begin(), bins.end()).size(), size_t(grid.binCount()));
  for (double res_deg : {5.0, 10.0, 30.0}) {
    const std::vector<int> cells = resolutionCells(grid, res_deg);
    const int n = *std::max_element(cells.begin(), cells.end()) + 1;
    std::vector<double> omega(size_t(n), 0.0);
    for (int b = 0; b < grid.binCount(); ++b) {
      ASSERT_GE(cells[size_t(b)], 0);
      omega[size_t(cells[size_t(b)])] += grid.solidAngle(b);
    }
    const double res = res_deg * kPi / 180, expected = 2 * 2 * kPi / (res * res);  // two hemispheres
    EXPECT_NEAR(n, expected, 0.1 * expected) << res_deg;
    // No cell is more than about twice or less than half the nominal res².
    for (double w : omega) {
      EXPECT_LT(w, 2.2 * res * res) << res_deg;
      EXPECT_GT(w, 0.45 * res * res) << res_deg;
    }
  }
}

// A flat aluminium patch under a 10 µm coherence length: the window blurs the specular peak over
// about 3° (λ/δc), more than the 1.4° rings of the grid, so at the grid's resolution WS and GS
// differ by nearly twice the reflected energy and diffraction is on; a renderer that resolves 30°
// sees the blurred peak inside the cap about the normal, and diffraction is off. Both from the
// flat interface's closed form, without a wave pilot.
TEST(EffectsPlanner, DiffractionJudgedAtTheRenderersResolution) {
  auto plan = [](double res_deg) {
    const Job job = loadJobFromString(
        "[geometry]\nkind = \"flat\"\nsize_um = [2.5, 2.5]\n[material]\nname = \"Al\"\n[spectrum]\nwavelengths_nm = "
        "[500.0]\n"
        "[directions]\nn_theta = 64\nn_phi = 16\nincidence = [[0.0, 0.0]]\n[scene]\ncoherence_length_um = 10.0\n"
        "tolerance = 0.05\nangular_resolution_deg = " +
            std::to_string(res_deg) + "\n[effects]\npilot_budget = 10.0\n[sampling]\npaths_per_slice = 20000\n",
        "t.toml", "");
    const EffectsPlan p = planEffects(job);
    EXPECT_EQ(p.components.has(Component::Incoherent), p.find(Effect::Incoherent)->on);
    return *p.find(Effect::Incoherent);
  };
  const EffectDecision fine = plan(0), coarse = plan(30);
  EXPECT_TRUE(fine.on) << fine.reason;
  EXPECT_GT(fine.evidence["closed_form_l1"].get<double>(), 1.0);
  EXPECT_FALSE(coarse.on) << coarse.reason;
  EXPECT_LT(coarse.evidence["closed_form_upper"].get<double>(), 0.05);
  EXPECT_NE(coarse.reason.find("pooled to the renderer's 30 deg"), std::string::npos);
  for (const EffectDecision& d : {fine, coarse}) EXPECT_EQ(d.evidence["decided_by"], "flat interface") << d.reason;
}

// [sampling] wave_estimator = "auto" under components = "auto": the planner keeps the static pick
// where it meets the tolerance or is deterministic, and otherwise takes the deterministic estimator
// with the smaller error, from one pilot tile run as the job runs it. A rough periodic heightfield
// (correlation 2 λ) under a 20 µm window on theta-phi bins: the static rule gives `area` (fft's
// direct sum is not chosen statically off a disk grid), whose error at 1024 samples per bin is
// hundreds of times fft's; the plan takes fft. The area pilot (about 1/8 of the bins, chosen from
// fft's table) predicts area's error: checked against a whole area tile's distance from fft's table.
TEST(EffectsPlanner, WaveEstimatorFromTheTolerance) {
  const std::string text =
      "[geometry]\nkind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.1\ncorrelation_um = 1.0\n[material]\nname = "
      "\"Al\"\n"
      "[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 8\nn_phi = 16\nincidence = [[20.0, 0.0]]\n"
      "[scene]\ncoherence_length_um = 20.0\ntolerance = 0.02\n[effects]\npilot_budget = "
      "10.0\n[sampling]\npaths_per_slice = 20000\n"
      "wave_samples_per_bin = 1024\nseed = 5\n";
  const Job job = loadJobFromString(text, "t.toml", "");
  ASSERT_EQ(job.resolvedWaveEstimator(), WaveEstimatorKind::Area);
  const EffectsPlan p = planEffects(job);
  ASSERT_NE(p.find(Effect::Estimator), nullptr) << p.toJson().dump();
  const nlohmann::json d = p.find(Effect::Estimator)->evidence;
  EXPECT_EQ(d["estimator"], "fft") << d.dump();
  EXPECT_EQ(p.waveEstimator, WaveEstimatorKind::Fft);
  double fftError = -1, areaError = -1;
  for (const auto& c : d["candidates"])
    (c["estimator"] == "fft" ? fftError : areaError) = c["predicted_error"].get<double>();
  ASSERT_GT(fftError, 0);
  EXPECT_LT(fftError * 10, areaError) << d.dump();

  // Whole tiles of both, as the job runs them: area's L1 distance from fft's table is its error
  // (fft's is 1/10 of it or less); the pilot's prediction from 1/8 of the bins is within 2× of it.
  const DirectionGrid grid(job.gridLayout);
  GeometricTransport transport(job, grid, 1000);
  auto table = [&](const std::string& name) {
    Job j = job;
    j.waveEstimator = waveEstimatorKind(name);
    return makeJobWaveEstimator(j, grid, *transport.scene(), waveSettingsOf(j))
        ->run(0, job.incidence[0].bin, std::nullopt);
  };
  const WaveTileResult fft = table("fft"), area = table("area");
  double l1 = 0;
  for (int b = 0; b < grid.binCount(); ++b)
    l1 += std::abs(area.fws[size_t(b)] - fft.fws[size_t(b)]) * grid.projectedSolidAngle(b);
  std::printf("fft predicted error %.4g; area predicted %.4g, its tile's L1 distance from fft's %.4g\n", fftError,
              areaError, l1);
  EXPECT_GT(areaError, 0.5 * l1) << l1;
  EXPECT_LT(areaError, 2.0 * l1) << l1;

  // A deterministic static pick (a small sine-grating cell under a wide window: exact) runs no pilot.
  const Job grating = loadJobFromString(
      "[geometry]\nkind = \"sine-grating\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.03\n[material]\n"
      "name = \"Al\"\n[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 8\nn_phi = 16\n"
      "incidence = [[20.0, 0.0]]\n[scene]\ncoherence_length_um = 50.0\ntolerance = 0.02\n[sampling]\n"
      "paths_per_slice = 20000\nwave_samples_per_bin = 1024\n",
      "g.toml", "");
  const EffectsPlan pg = planEffects(grating);
  ASSERT_NE(pg.find(Effect::Estimator), nullptr) << pg.toJson().dump();
  const EffectDecision& x = *pg.find(Effect::Estimator);
  EXPECT_EQ(x.evidence["estimator"], "exact");
  EXPECT_EQ(pg.waveEstimator, WaveEstimatorKind::Exact);
  EXPECT_FALSE(x.evidence.contains("candidates"));
  EXPECT_NE(x.reason.find("deterministic; no estimator pilot"), std::string::npos) << x.reason;
}

// Pilots are the job's own beams: a binary mirror grating (grooves along y) lit exactly along its
// grooves (φ = 90°, `incidence_sampling = "exact"`) reflects off ridge tops and groove floors within
// the plane of the grooves and never reaches a wall: nothing scatters twice and `multiple` is
// dropped. Piloted through the incidence bin's centre (φ = 67.5° on 8 φ bins) the light meets the
// walls; the same job with bin-averaged incidence, whose slices do average over such directions,
// keeps `multiple`.
TEST(EffectsPlanner, PilotsFollowTheJobsExactDirections) {
  auto multiple = [](const std::string& sampling) {
    const Job job = loadJobFromString(
        "[geometry]\nkind = \"binary-grating\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\ndepth_um = 1.0\nduty = 0.5\n"
        "[material]\nname = \"mirror\"\n[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 9\nn_phi = 8\n"
        "incidence = [[40.0, 90.0]]\nincidence_sampling = \"" +
            sampling +
            "\"\n[scene]\ncoherence_length_um = 0.0\n"
            "[effects]\npilot_budget = 10.0\n[sampling]\npaths_per_slice = 20000\n",
        "t.toml", "");
    return *planEffects(job).find(Effect::Multiple);
  };
  const EffectDecision exact = multiple("exact"), averaged = multiple("bin");
  EXPECT_FALSE(exact.on) << exact.reason;
  EXPECT_TRUE(averaged.on) << averaged.reason;
}

namespace {

Job vGrooveJob(double apex_deg, const std::string& material, const std::string& incidence) {
  return loadJobFromString("[geometry]\nkind = \"ridged\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\napex_angle_deg = " +
                               std::to_string(apex_deg) + "\n[material]\n" + material +
                               "\n[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 9\nn_phi = 8\n"
                               "incidence = " +
                               incidence +
                               "\nincidence_sampling = \"exact\"\n[scene]\n"
                               "coherence_length_um = 0.0\n[effects]\ncomponents = [\"coherent\", \"multiple\"]\n"
                               "[sampling]\npaths_per_slice = 20000\nseed = 9\n",
                           "t.toml", "");
}

double multipleEnergy(const Job& job, int t) {
  const DirectionGrid grid(job.gridLayout);
  GeometricTransport transport(job, grid, job.pathsPerSlice);
  const auto& inc = job.incidence[size_t(t)];
  const TileResult r = transport.run(t, t, inc.bin, sphericalDirection(radians(inc.theta_deg), radians(inc.phi_deg)));
  double e = 0;
  for (int b = 0; b < grid.binCount(); ++b) e += r.at(Component::Multiple, 0, b) * grid.projectedSolidAngle(b);
  return e;
}

}  // namespace

// The geometry's single-bounce bound against the path tracer, which knows nothing of it: V-grooves
// of walls θs = (180° − apex)/2 from 5° to 27.5°, mirror and glass (n = 1.5); past 30° (apex 110°:
// 35°) there is none. Below the bound (0.5°
// under it, across the grooves, diagonally and along them) no path meets the surface twice; across
// the grooves the bound is tight for the mirror (light reflected from one wall leaves at θi + 2θs
// and meets the other wall once that exceeds 90° − θs), so 3° above it some paths do.
TEST(EffectsPlanner, SingleBounceBoundHoldsForThePathTracer) {
  EXPECT_FALSE(singleBounceLimit_deg(vGrooveJob(110.0, "name = \"mirror\"", "[[0.0, 0.0]]")).has_value());
  for (double apex : {170.0, 160.0, 150.0, 140.0, 130.0, 125.0}) {
    const double thetaS = (180 - apex) / 2;
    for (const std::string material : {"name = \"mirror\"", "kind = \"dielectric\"\nior = 1.5"}) {
      const bool glass = material.find("dielectric") != std::string::npos;
      double expected = 90 - 3 * thetaS;
      if (glass && 1.5 * std::cos(radians(2 * thetaS)) < 1)
        expected = std::min(expected, degrees(std::asin(1.5 * std::cos(radians(2 * thetaS)))) - thetaS);
      const Job probe = vGrooveJob(apex, material, "[[0.0, 0.0]]");
      const std::optional<double> limit = singleBounceLimit_deg(probe);
      ASSERT_TRUE(limit.has_value()) << "apex " << apex;
      EXPECT_NEAR(*limit, expected, 1e-6) << "apex " << apex << ", " << material;
      ASSERT_NEAR(*steepestFacet_deg(probe), thetaS, 1e-6);
      const double below = *limit - 0.5, above = 90 - 3 * thetaS + 3;
      std::string list = "[[" + std::to_string(below) + ", 0.0], [" + std::to_string(below) + ", 45.0], [" +
                         std::to_string(below) + ", 90.0]";
      if (!glass && above < 89) list += ", [" + std::to_string(above) + ", 0.0]";
      const Job job = vGrooveJob(apex, material, list + "]");
      const DirectionGrid grid(job.gridLayout);
      for (int t = 0; t < 3; ++t) {
        EXPECT_TRUE(scattersOnce(job, grid, t, limit));
        EXPECT_EQ(multipleEnergy(job, t), 0.0) << "apex " << apex << ", " << material << ", incidence " << t;
      }
      if (job.incidence.size() == 4) {
        EXPECT_FALSE(scattersOnce(job, grid, 3, limit));
        EXPECT_GT(multipleEnergy(job, 3), 0.0) << "apex " << apex << " at " << above << " deg";
      }
    }
  }
}

// No bound where the surface is not a graph (vertical walls) or the light comes from inside.
TEST(EffectsPlanner, SingleBounceBoundOnlyForGraphs) {
  const Job walls = loadJobFromString(
      "[geometry]\nkind = \"binary-grating\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\ndepth_um = 1.0\nduty = 0.5\n"
      "[material]\nname = \"mirror\"\n[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 9\nn_phi = 8\n"
      "incidence = [[10.0, 0.0]]\n[scene]\ncoherence_length_um = 0.0\n",
      "t.toml", "");
  EXPECT_FALSE(singleBounceLimit_deg(walls).has_value());
  const Job inside = vGrooveJob(150.0, "kind = \"dielectric\"\nior = 1.5", "[[170.0, 0.0]]");
  const DirectionGrid grid(inside.gridLayout);
  EXPECT_FALSE(scattersOnce(inside, grid, 0, singleBounceLimit_deg(inside)));
}

// Every listed incidence when there are few; otherwise kMaxPilots spread over the set: the most
// grazing first, then the closest to normal, and azimuths as well as polar angles.
TEST(EffectsPlanner, PilotsSpreadOverTheIncidences) {
  auto job = [](const std::string& incidence) {
    return loadJobFromString(
        "[geometry]\nkind = \"flat\"\nsize_um = [2.0, 2.0]\n[material]\nname = \"Al\"\n"
        "[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 8\nn_phi = 16\n"
        "incidence = " +
            incidence + "\nsymmetry = \"none\"\n[scene]\ncoherence_length_um = 0.0\n",
        "t.toml", "");
  };
  const Job few = job("[[10.0, 0.0], [50.0, 90.0], [30.0, 0.0], [0.0, 0.0]]");
  EXPECT_EQ(pilotIncidences(few), (std::vector<int>{1, 3, 2, 0}));
  const Job all = job("\"all\"");
  const std::vector<int> p = pilotIncidences(all);
  ASSERT_EQ(p.size(), size_t(kMaxPilots));
  EXPECT_EQ(std::set<int>(p.begin(), p.end()).size(), p.size());
  double maxTheta = 0, minTheta = 90;
  for (const auto& inc : all.incidence)
    maxTheta = std::max(maxTheta, inc.theta_deg), minTheta = std::min(minTheta, inc.theta_deg);
  EXPECT_EQ(all.incidence[size_t(p[0])].theta_deg, maxTheta);
  EXPECT_EQ(all.incidence[size_t(p[1])].theta_deg, minTheta);
  std::set<int> quadrants;
  for (int i : p)
    if (all.incidence[size_t(i)].theta_deg > 20)
      quadrants.insert(int(std::floor(all.incidence[size_t(i)].phi_deg / 90.0)) % 4);
  EXPECT_GE(quadrants.size(), size_t(3)) << "pilots cover the azimuths";
}

// The pilots' work never exceeds [effects] pilot_budget x the computed tiles (in tiles' paths and
// wave terms), and what the budget cannot judge is kept: a rough Al heightfield with three listed
// incidences. At the default 0.5 no wave pilot fits (one would cost a whole tile's wave term
// against 1.5): diffraction is kept on, saying why.
TEST(EffectsPlanner, PilotBudgetBoundsThePilots) {
  for (double budget : {0.1, 0.5, 2.0, 10.0}) {
    const Job job = loadJobFromString(
        "[geometry]\nkind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.3\ncorrelation_um = 2.0\n[material]\nname "
        "= \"Al\"\n"
        "[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 8\nn_phi = 16\n"
        "incidence = [[0.0, 0.0], [40.0, 0.0], [70.0, 30.0]]\n[scene]\ncoherence_length_um = 20.0\ntolerance = 0.02\n"
        "[effects]\npilot_budget = " +
            std::to_string(budget) +
            "\n[sampling]\npaths_per_slice = 50000\n"
            "wave_samples_per_bin = 256\nseed = 5\n",
        "t.toml", "");
    const EffectsPlan p = planEffects(job);
    ASSERT_TRUE(p.pilotBudget);
    EXPECT_EQ(p.pilotBudget->fraction, budget);
    EXPECT_EQ(p.pilotBudget->computedTiles, 3);
    EXPECT_LE(p.pilotBudget->pathTilesSpent, budget * 3 + 1e-9) << p.toJson().dump();
    EXPECT_LE(p.pilotBudget->waveTilesSpent, budget * 3 + 1e-9) << p.toJson().dump();
    EXPECT_LE(p.pilots.size(), p.pilotsPlanned.size());
    if (budget == 0.5) {
      const EffectDecision& d = *p.find(Effect::Incoherent);
      EXPECT_TRUE(d.on);
      EXPECT_TRUE(p.components.has(Component::Incoherent));
      EXPECT_NE(d.reason.find("pilot budget"), std::string::npos) << d.reason;
    }
  }
}

// The plan's JSON form (what the file records and every rank receives) reads back to the same plan,
// field by field, and a malformed one is refused naming what is wrong.
TEST(EffectsPlan, JsonRoundTrip) {
  EffectsPlan p;
  p.components.add(Component::Coherent);
  p.components.add(Component::Incoherent);
  p.decisions.push_back({Effect::Multiple, false, "below the tolerance", {{"pilot_energy", 0.001}}});
  p.decisions.push_back({Effect::Wavelengths, true, "colour", {}});
  p.tolerance = 0.02;
  p.coherenceLength_um = 50;
  p.coherenceSource = "coherence_length_um";
  p.pilots = {3, 0};
  p.pilotsPlanned = {3, 0, 7};
  p.pilotBudget = PilotBudgetUse{0.5, 9, 4.5, 1.2, 2.0};
  p.pilotPaths = 20000;
  p.pilotTilesKept = true;
  p.pilotSeconds = 1.5;
  p.waveTransmission = false;
  p.lambda_nm = std::vector<double>{450, 550, 650};
  p.waveEstimator = WaveEstimatorKind::Exact;
  const EffectsPlan q = EffectsPlan::fromJson(nlohmann::json::parse(p.toJson().dump()));
  EXPECT_EQ(q.components.list(), p.components.list());
  ASSERT_EQ(q.decisions.size(), 2u);
  EXPECT_EQ(q.decisions[0].effect, Effect::Multiple);
  EXPECT_FALSE(q.decisions[0].on);
  EXPECT_EQ(q.decisions[0].reason, "below the tolerance");
  EXPECT_EQ(q.decisions[0].evidence["pilot_energy"].get<double>(), 0.001);
  EXPECT_EQ(q.find(Effect::Wavelengths), &q.decisions[1]);
  EXPECT_EQ(q.find(Effect::Btdf), nullptr);
  EXPECT_EQ(q.pilots, p.pilots);
  EXPECT_EQ(q.pilotsPlanned, p.pilotsPlanned);
  ASSERT_TRUE(q.pilotBudget);
  EXPECT_EQ(q.pilotBudget->computedTiles, 9);
  EXPECT_EQ(q.pilotBudget->waveTilesSpent, 2.0);
  EXPECT_EQ(q.pilotPaths, 20000u);
  EXPECT_TRUE(q.pilotTilesKept);
  EXPECT_EQ(q.waveTransmission, false);
  EXPECT_EQ(q.lambda_nm, p.lambda_nm);
  EXPECT_EQ(q.waveEstimator, WaveEstimatorKind::Exact);
  EXPECT_EQ(q.toJson(), p.toJson());

  nlohmann::json bad = p.toJson();
  bad["decisions"][0]["effect"] = "shimmer";
  EXPECT_THROW(EffectsPlan::fromJson(bad), std::invalid_argument);
  bad = p.toJson();
  bad.erase("tolerance");
  EXPECT_THROW(EffectsPlan::fromJson(bad), std::invalid_argument);
}

// Diffraction from physics on a random rough surface: the Kirchhoff ensemble (jobEnsemble,
// scattering/kirchhoff_ensemble.h) against the deterministic `fft` evaluator on a realisation, as
// the job computes its tiles (its incoherent component, fft's WS minus the facet sum's GS). Gold
// with 1 nm Gaussian ground noise (correlation 0.2 µm) on a 5 µm patch under a 2 mm coherence
// length, collimated at bins' centres. At 5.6° the specular lands in a narrow wedge of the pole
// ring, across whose edges geometric optics spreads it over the noise's 0.5° slopes and the wave
// term does not: both distances are far beyond the tolerance and agree within 15 %. At 39°–62° the
// lobes stay inside their bins: the realisation's distance is below the ensemble's upper bound,
// which is below the tolerance. The planner decides on and off from it without a wave pilot.
TEST(EffectsPlanner, KirchhoffEnsembleAgreesWithTheFftEvaluator) {
  auto job = [](const std::string& incidence, const std::string& components) {
    return loadJobFromString(
        "[geometry]\nkind = \"flat\"\nsize_um = [5.0, 5.0]\nground_noise_rms_nm = 1.0\n[material]\nname = \"Au\"\n"
        "[spectrum]\nwavelengths_nm = [500.0, 600.0]\n[directions]\nn_theta = 8\nn_phi = 16\nincidence = " +
            incidence +
            "\nincidence_sampling = \"exact\"\n[scene]\ncoherence_length_um = 2000.0\ntolerance = 0.02\n[effects]\n"
            "components = " +
            components + "\n[sampling]\npaths_per_slice = 20000\nwave_estimator = \"fft\"\nseed = 5\n",
        "t.toml", "");
  };
  const std::string pole = "[[5.625, 11.25]]", inside = "[[39.375, 11.25], [50.625, 101.25], [61.875, 191.25]]";
  for (const std::string& incidence : {pole, inside}) {
    const Job full = job(incidence, "[\"coherent\", \"incoherent\"]");
    const DirectionGrid grid(full.gridLayout);
    const std::optional<KirchhoffEnsemble> ensemble = jobEnsemble(full);
    ASSERT_TRUE(ensemble);
    const std::vector<int> cells = resolutionCells(grid, 0.0);
    const TileComputer computer(full, grid);
    double paths = 0, wave = 0;
    for (int t = 0; t < int(full.incidence.size()); ++t) {
      const TileResult r = computer.compute(t, {}, &paths, &wave);
      for (int l = 0; l < 2; ++l) {
        double realisation = 0;
        for (int b = 0; b < grid.binCount(); ++b)
          realisation += std::abs(r.at(Component::Incoherent, l, b)) * grid.projectedSolidAngle(b);
        const EnsembleSlice s = ensembleSlice(full, *ensemble, grid, t, full.lambda_nm[size_t(l)], cells);
        std::printf("theta_i %.3g, %g nm: realisation (fft - facet sum) %.4f, ensemble %.4f (bound %.4f)\n",
                    full.incidence[size_t(t)].theta_deg, full.lambda_nm[size_t(l)], realisation, s.l1(),
                    s.upperBound());
        if (incidence == pole) {
          EXPECT_GT(realisation, 5 * full.scene.tolerance);
          EXPECT_NEAR(s.l1() / realisation, 1.0, 0.15);
        } else {
          EXPECT_LT(realisation, s.upperBound());
          EXPECT_LT(s.upperBound(), full.scene.tolerance);
        }
      }
    }
    const EffectsPlan plan = planEffects(job(incidence, "[\"auto\"]"));
    const EffectDecision& d = *plan.find(Effect::Incoherent);
    EXPECT_EQ(d.on, incidence == pole) << d.reason;
    EXPECT_EQ(d.evidence["decided_by"], "kirchhoff ensemble") << d.reason;
    EXPECT_EQ(plan.pilotBudget->waveTilesSpent, 0.0);
  }
}

// Diffraction from physics on a flat interface: the closed form (flatInterfaceSliceOf,
// scattering/flat_interface.h) against the `exact` evaluator, as the job computes its tiles (its
// incoherent component, WS minus the facet sum's GS), on a gold mirror and on glass (n 1.5) lit
// from above and from inside, under a 10 µm coherence length (a spot of sd 0.85° at 550 nm).
// Collimated beams whose specular beam lies at a bin's centre, 1.4° from an edge, on an edge, and
// inside the glass beyond the critical angle (total reflection): the distances agree within 0.01
// (measured in the test's output). The planner decides from it without a wave pilot: off where
// every beam stays inside its bin, on elsewhere.
TEST(EffectsPlanner, FlatInterfaceAgreesWithTheExactEvaluator) {
  auto job = [](const std::string& material, const std::string& incidence, const std::string& components) {
    return loadJobFromString("[geometry]\nkind = \"flat\"\nsize_um = [5.0, 5.0]\n[material]\n" + material +
                                 "\n[spectrum]\nwavelengths_nm = [550.0]\n[directions]\nn_theta = 8\nn_phi = 16\n"
                                 "incidence = " +
                                 incidence +
                                 "\nincidence_sampling = \"exact\"\n[scene]\ncoherence_length_um = 100.0\n"
                                 "tolerance = 0.02\n[effects]\ncomponents = " +
                                 components + "\n[sampling]\npaths_per_slice = 20000\nwave_estimator = \"exact\"\n",
                             "t.toml", "");
  };
  const std::string gold = "name = \"Au\"", glass = "kind = \"dielectric\"\nior = 1.5";
  const std::string centres = "[[39.375, 11.25], [61.875, 101.25]]", edge = "[[39.375, 0.5]]",
                    onEdge = "[[39.375, 0.0]]", inside = "[[129.375, 11.25], [118.125, 33.75]]";
  struct Case {
    std::string material, incidence;
    bool on;
  };
  for (const Case& c : {Case{gold, centres, false}, Case{gold, edge, true}, Case{gold, onEdge, true},
                        Case{glass, centres, false}, Case{glass, edge, true}, Case{glass, inside, false}}) {
    const Job full = job(c.material, c.incidence, "[\"coherent\", \"incoherent\"]");
    ASSERT_TRUE(jobFlatInterface(full));
    const DirectionGrid grid(full.gridLayout);
    const std::vector<int> cells = resolutionCells(grid, 0.0);
    const TileComputer computer(full, grid);
    double paths = 0, wave = 0;
    for (int t = 0; t < int(full.incidence.size()); ++t) {
      const TileResult r = computer.compute(t, {}, &paths, &wave);
      double realisation = 0;
      for (int b = 0; b < grid.binCount(); ++b)
        realisation += std::abs(r.at(Component::Incoherent, 0, b)) * grid.projectedSolidAngle(b);
      const EnsembleSlice s = flatInterfaceSliceOf(full, grid, t, 550.0, cells);
      std::printf("%s theta_i %.5g phi_i %.4g: exact - facet sum %.4f, closed form %.4f\n",
                  c.material.substr(0, 12).c_str(), full.incidence[size_t(t)].theta_deg,
                  full.incidence[size_t(t)].phi_deg, realisation, s.l1());
      EXPECT_NEAR(s.l1(), realisation, 1e-3) << c.incidence;
      EXPECT_EQ(s.l1(), s.upperBound());
    }
    const EffectsPlan plan = planEffects(job(c.material, c.incidence, "[\"auto\"]"));
    const EffectDecision& d = *plan.find(Effect::Incoherent);
    EXPECT_EQ(d.on, c.on) << d.reason;
    EXPECT_EQ(d.evidence["decided_by"], "flat interface") << d.reason;
    EXPECT_EQ(plan.pilotBudget->waveTilesSpent, 0.0);
  }
}

// The same over incidence bins, on a perfect mirror. Both tables spread the incidence bin over its
// mirror image; the wave model's beams spill across the image's edges by the window's spot (sd s in
// the plane of direction cosines), so the L1 distance is twice the spill, P s / (√(2π) A) to first
// order for an image of area A and perimeter P in that plane. Under a 50 µm coherence length the
// closed form's 8 × 8 rule is within 3 % of that (measured 0.1329 against 0.1329 at 30° and 0.162
// against 0.160 at 61.9°), and `exact` within its own summed errors (0.117 ± 0.053 and
// 0.143 ± 0.052: its M × M sub-directions resolve a spill 0.4° wide coarsely). Diffraction on; under
// a 2 mm coherence length (L1 0.003), off, both without a wave pilot.
TEST(EffectsPlanner, FlatInterfaceOverAnIncidenceBin) {
  auto job = [](double coherence_um, const std::string& components) {
    return loadJobFromString(
        "[geometry]\nkind = \"flat\"\nsize_um = [10.0, 10.0]\n[material]\nname = \"mirror\"\n[spectrum]\n"
        "wavelengths_nm = [550.0]\n[directions]\nn_theta = 8\nn_phi = 16\nincidence = [[30.0, 0.0], [61.9, 0.0]]\n"
        "[scene]\ncoherence_length_um = " +
            std::to_string(coherence_um) + "\ntolerance = 0.02\n[effects]\ncomponents = " + components +
            "\n[sampling]\npaths_per_slice = 20000\nwave_estimator = \"exact\"\n",
        "t.toml", "");
  };
  const Job full = job(50.0, "[\"coherent\", \"incoherent\"]");
  const DirectionGrid grid(full.gridLayout);
  const std::vector<int> cells = resolutionCells(grid, 0.0);
  const TileComputer computer(full, grid);
  const double s = 1 / (std::sqrt(2.0) * (50.0 / kCoherenceLengthPerSigma) * 2 * kPi / 0.55);
  double paths = 0, wave = 0;
  for (int t = 0; t < 2; ++t) {
    // The image of the incidence bin: a sector of the annulus sin θ in [r1, r2], 22.5° wide.
    const int ring = full.incidence[size_t(t)].bin / 16;
    const double r1 = std::sin(radians(ring * 11.25)), r2 = std::sin(radians((ring + 1) * 11.25)), dphi = radians(22.5);
    const double area = 0.5 * dphi * (r2 * r2 - r1 * r1), perimeter = 2 * (r2 - r1) + dphi * (r1 + r2);
    const double firstOrder = 2 * perimeter * s / (std::sqrt(2 * kPi) * area);
    const TileResult r = computer.compute(t, {}, &paths, &wave);
    double realisation = 0, errors = 0;
    for (int b = 0; b < grid.binCount(); ++b) {
      realisation += std::abs(r.at(Component::Incoherent, 0, b)) * grid.projectedSolidAngle(b);
      errors += r.stdError[int(Component::Incoherent)][size_t(b)] * grid.projectedSolidAngle(b);
    }
    const double closed = flatInterfaceSliceOf(full, grid, t, 550.0, cells).l1();
    std::printf("theta_i %.3g: closed form %.4f, first order %.4f, exact - facet sum %.4f +- %.4f\n",
                full.incidence[size_t(t)].theta_deg, closed, firstOrder, realisation, errors);
    EXPECT_NEAR(closed / firstOrder, 1.0, 0.03);
    EXPECT_NEAR(closed, realisation, errors);
  }
  for (double coherence_um : {50.0, 2000.0}) {
    const EffectsPlan plan = planEffects(job(coherence_um, "[\"auto\"]"));
    const EffectDecision& d = *plan.find(Effect::Incoherent);
    EXPECT_EQ(d.on, coherence_um < 100) << d.reason;
    EXPECT_EQ(d.evidence["decided_by"], "flat interface") << d.reason;
    EXPECT_EQ(plan.pilotBudget->waveTilesSpent, 0.0);
  }
}

// The same on a rough surface of intermediate Rayleigh roughness (Gaussian heights, rms 50 nm,
// correlation 0.8 µm, 10 µm patch; g = 0.3–4 at 500 nm) under a 20 µm coherence length, where the
// realisation adds speckle the ensemble does not have: at 5.6°, 39° and 73° both distances exceed
// the tolerance many times and agree within a factor 1.5 (measured 0.41/0.47, 0.54/0.55,
// 0.72/0.69).
TEST(EffectsPlanner, KirchhoffEnsembleAgreesWithTheFftEvaluatorOnARoughSurface) {
  const Job job = loadJobFromString(
      "[geometry]\nkind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.05\ncorrelation_um = 0.8\n[material]\n"
      "name = \"Al\"\n[spectrum]\nwavelengths_nm = [500.0]\n[directions]\nn_theta = 8\nn_phi = 16\n"
      "incidence = [[5.625, 11.25], [39.375, 11.25], [73.125, 101.25]]\nincidence_sampling = \"exact\"\n[scene]\n"
      "coherence_length_um = 20.0\ntolerance = 0.02\n[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n"
      "[sampling]\npaths_per_slice = 20000\nwave_estimator = \"fft\"\nseed = 5\n",
      "t.toml", "");
  const DirectionGrid grid(job.gridLayout);
  const std::optional<KirchhoffEnsemble> ensemble = jobEnsemble(job);
  ASSERT_TRUE(ensemble);
  const TileComputer computer(job, grid);
  double paths = 0, wave = 0;
  for (int t = 0; t < int(job.incidence.size()); ++t) {
    const TileResult r = computer.compute(t, {}, &paths, &wave);
    double realisation = 0;
    for (int b = 0; b < grid.binCount(); ++b)
      realisation += std::abs(r.at(Component::Incoherent, 0, b)) * grid.projectedSolidAngle(b);
    const double ens = ensembleSlice(job, *ensemble, grid, t, 500.0, resolutionCells(grid, 0.0)).l1();
    std::printf("theta_i %.3g: realisation (fft - facet sum) %.4f, ensemble %.4f\n", job.incidence[size_t(t)].theta_deg,
                realisation, ens);
    EXPECT_GT(ens, 5 * job.scene.tolerance);
    EXPECT_GT(realisation, 5 * job.scene.tolerance);
    EXPECT_LT(ens / realisation, 1.5);
    EXPECT_GT(ens / realisation, 1 / 1.5);
  }
}

// The log names who chose the wave estimator: a job that names none and runs under `auto` gets the
// planner's choice, said to be the planner's, with the static rule's reason where it kept it; one
// that names it keeps "named by the job".
TEST(EffectsPlanner, WaveEstimatorChoiceNamesTheChooser) {
  auto load = [](const std::string& sampling) {
    return loadJobFromString(
        "[geometry]\nkind = \"flat\"\nsize_um = [10.0, 10.0]\n[material]\nname = \"mirror\"\n[spectrum]\n"
        "wavelengths_nm = [550.0]\n[directions]\nn_theta = 8\nn_phi = 16\nincidence = [[30.0, 0.0]]\n[sampling]\n"
        "paths_per_slice = 20000\n" +
            sampling,
        "t.toml", "");
  };
  Job job = load("");
  applyEffectsPlan(job, planEffects(job));
  EXPECT_EQ(job.waveEstimatorChoice().rfind("chosen by the effects planner: ", 0), 0u) << job.waveEstimatorChoice();
  EXPECT_NE(job.waveEstimatorChoice().find("chosen as deterministic"), std::string::npos) << job.waveEstimatorChoice();
  Job named = load("wave_estimator = \"exact\"\n");
  applyEffectsPlan(named, planEffects(named));
  EXPECT_EQ(named.waveEstimatorChoice(), "named by the job");
}

// The flat interface's closed form only where it holds: a closed periodic patch in one plane under
// a window. Not without a window (one copy of the patch, whose aperture diffracts), not on a patch
// that does not repeat, nor with ground noise (the Kirchhoff ensemble's case).
TEST(EffectsPlanner, FlatInterfaceOnlyWhereItsClosedFormHolds) {
  auto flat = [](const std::string& geometry, const std::string& scene, const std::string& material,
                 const std::string& incidence) {
    return jobFlatInterface(loadJobFromString(
        "[geometry]\nkind = \"flat\"\nsize_um = [10.0, 10.0]\n" + geometry + "[material]\n" + material +
            "\n[spectrum]\nwavelengths_nm = [550.0]\n[directions]\nn_theta = 8\nn_phi = 16\nincidence = " + incidence +
            "\n[scene]\n" + scene + "[sampling]\npaths_per_slice = 20000\n",
        "t.toml", ""));
  };
  const std::string mirror = "name = \"mirror\"", glass = "kind = \"dielectric\"\nior = 1.5";
  EXPECT_TRUE(flat("", "", mirror, "[[30.0, 0.0]]"));
  EXPECT_TRUE(flat("", "", glass, "[[30.0, 0.0], [150.0, 0.0]]"));
  EXPECT_FALSE(flat("", "coherence_length_um = 0.0\n", mirror, "[[30.0, 0.0]]"));
  EXPECT_FALSE(flat("periodic = false\n", "", mirror, "[[30.0, 0.0]]"));
  EXPECT_FALSE(flat("ground_noise_rms_nm = 1.0\n", "", mirror, "[[30.0, 0.0]]"));
}
