// A tile as the run computes it (tile_computer.h): the effects planner's geometric pilots are the
// first paths of their tiles, a diffraction pilot along the job's own collimated direction is the
// tile's wave term, and a tile is the same whether the rank computing it holds the pilot's result
// or computes it again.
#include <gtest/gtest.h>

#include <functional>
#include <map>
#include <string>

#include "core/direction_grid.h"
#include "job/effects_planner.h"
#include "job/job.h"
#include "job/tile_computer.h"

using namespace mbsdf;

namespace {

Job autoJob(const std::string& geometry, const std::string& material, const std::string& incidence,
            const std::string& sampling = "") {
  return loadJobFromString("[geometry]\n" + geometry + "\n[material]\n" + material +
                               "\n[spectrum]\nwavelengths_nm = [500.0, 600.0]\n[directions]\nn_theta = 8\nn_phi = 16\n"
                               "incidence = " +
                               incidence +
                               "\n[scene]\ncoherence_length_um = 50.0\ntolerance = 0.02\n[effects]\n"
                               "components = [\"auto\"]\n[sampling]\npaths_per_slice = 50000\nseed = 5\n" +
                               sampling,
                           "t.toml", "");
}

// Every pilot tile computed by a computer that holds the pilots and by one that does not.
void expectPilotTilesKept(Job job) {
  PilotResults pilots;
  const EffectsPlan plan = planEffects(job, {}, &pilots);
  applyEffectsPlan(job, plan);
  ASSERT_TRUE(plan.pilotTilesKept) << formatEffects(plan);
  ASSERT_FALSE(plan.pilots.empty());
  ASSERT_LT(plan.pilotPaths, job.pathsPerSlice) << "the test wants a tile of two rounds";
  const DirectionGrid grid(job.gridLayout);
  const TileComputer holding(job, grid, pilots), tracing(job, grid);
  double paths = 0, wave = 0;
  for (int t : plan.pilots) {
    EXPECT_TRUE(holding.holdsPilot(t));
    EXPECT_FALSE(tracing.holdsPilot(t));
    const TileResult a = holding.compute(t, {}, &paths, &wave), b = tracing.compute(t, {}, &paths, &wave);
    EXPECT_EQ(a.samples, job.pathsPerSlice);
    std::vector<double> sa = a.serialize(), sb = b.serialize();
    // The seconds spent differ; everything else is the table's.
    ASSERT_EQ(sa.size(), sb.size());
    EXPECT_EQ(TileResult::deserialize(sa).value, TileResult::deserialize(sb).value) << "tile " << t;
    EXPECT_EQ(TileResult::deserialize(sa).stdError, TileResult::deserialize(sb).stdError) << "tile " << t;
    EXPECT_EQ(a.rays, b.rays);
  }
}

// One Al tile at 30° on 8 × 16 bins, 500 nm, with the components and sampling given.
Job oneTileJob(const std::string& geometry, const std::string& sceneAndComponents, const std::string& sampling) {
  return loadJobFromString("[geometry]\n" + geometry +
                               "\n[material]\nname = \"Al\"\n[spectrum]\nwavelengths_nm = [500.0]\n[directions]\n"
                               "n_theta = 8\nn_phi = 16\nincidence = [[30.0, 0.0]]\n" +
                               sceneAndComponents + "\n[sampling]\n" + sampling,
                           "t.toml", "");
}

// Tile 0 of `job`, its paths' progress and its wave term's given apart.
TileResult computeTile(const Job& job, const std::function<void(uint64_t)>& progress,
                       const std::function<void(uint64_t)>& waveProgress = {}) {
  const DirectionGrid grid(job.gridLayout);
  const TileComputer computer(job, grid);
  double paths = 0, wave = 0;
  return computer.compute(0, progress, &paths, &wave, waveProgress);
}

}  // namespace

TEST(TileComputer, KeptPilotTilesAreTheJobsOwn) {
  // Explicit geometry averaged over the incidence bins (a V-groove mirror: multiple scattering on).
  expectPilotTilesKept(autoJob("kind = \"ridged\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\napex_angle_deg = 125.0",
                               "name = \"mirror\"", "[[0.0, 0.0], [20.0, 0.0], [25.0, 90.0], [30.0, 90.0]]"));
  // A statistical surface (microflake walk), collimated incidence.
  Job flakes = autoJob("kind = \"statistical\"\nndf = \"ggx\"\nalpha = 0.5", "name = \"Au\"",
                       "[[10.0, 0.0], [60.0, 0.0]]\nincidence_sampling = \"exact\"");
  expectPilotTilesKept(flakes);
}

// A result that is not the job's first round (another path count) is not kept: the tile is traced.
TEST(TileComputer, ForeignPilotResultIsNotKept) {
  Job job = autoJob("kind = \"ridged\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\napex_angle_deg = 125.0",
                    "name = \"mirror\"", "[[0.0, 0.0], [20.0, 0.0]]");
  PilotResults pilots;
  const EffectsPlan plan = planEffects(job, {}, &pilots);
  applyEffectsPlan(job, plan);
  for (auto& [t, r] : pilots.tiles) r.samples += 1;
  const DirectionGrid grid(job.gridLayout);
  const TileComputer computer(job, grid, pilots);
  for (int t : plan.pilots) EXPECT_FALSE(computer.holdsPilot(t));
}

// A diffraction pilot along the job's own collimated direction, with the job's estimator (`exact`
// for this grating: 8 x 128 facets within the 1024 samples per bin), is the tile's wave term: the
// rank that ran it keeps it, and the tile equals one whose wave term is computed again. With a
// Monte Carlo estimator at fewer samples than the pilot's it is not the job's, and is not kept.
TEST(TileComputer, KeptWavePilotIsTheTilesOwnWaveTerm) {
  const std::string grating = "kind = \"sine-grating\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.1";
  const std::string incidence = "[[10.0, 0.0], [35.0, 0.0], [60.0, 90.0]]\nincidence_sampling = \"exact\"";
  Job job = autoJob(grating, "name = \"Al\"", incidence, "wave_samples_per_bin = 1024\n");
  PilotResults pilots;
  const EffectsPlan plan = planEffects(job, {}, &pilots);
  applyEffectsPlan(job, plan);
  ASSERT_TRUE(job.components.has(Component::Incoherent) && !job.guarded.has(Component::Incoherent))
      << formatEffects(plan);
  ASSERT_FALSE(pilots.waveTerms.empty()) << formatEffects(plan);
  const DirectionGrid grid(job.gridLayout);
  const TileComputer holding(job, grid, pilots), computing(job, grid);
  double paths = 0, wave = 0;
  for (const auto& [t, w] : pilots.waveTerms) {
    EXPECT_TRUE(holding.holdsPilot(t));
    const TileResult a = holding.compute(t, {}, &paths, &wave), b = computing.compute(t, {}, &paths, &wave);
    EXPECT_EQ(a.value, b.value) << "tile " << t;
    EXPECT_EQ(a.stdError, b.stdError) << "tile " << t;
    EXPECT_EQ(a.rays, b.rays) << "the kept wave term's rays are the tile's work, counted once";
  }

  // The kept wave term is what the tile uses: one changed by hand shows in the tile.
  PilotResults tampered = pilots;
  const int t0 = tampered.waveTerms.begin()->first;
  for (double& v : tampered.waveTerms.begin()->second.fws) v += 1;
  const TileComputer fooled(job, grid, tampered);
  EXPECT_NE(fooled.compute(t0, {}, &paths, &wave).value, computing.compute(t0, {}, &paths, &wave).value);

  Job orders = autoJob(grating, "name = \"Al\"", incidence, "wave_samples_per_bin = 64\nwave_estimator = \"orders\"\n");
  PilotResults other;
  const EffectsPlan p2 = planEffects(orders, {}, &other);
  applyEffectsPlan(orders, p2);
  ASSERT_FALSE(other.waveTerms.empty()) << formatEffects(p2);
  ASSERT_FALSE(orders.guarded.has(Component::Incoherent)) << formatEffects(p2);
  for (auto& [t, w] : other.waveTerms)
    for (double& v : w.fws) v += 1;  // would show in the tile if it were kept
  const TileComputer notKept(orders, grid, other), own(orders, grid);
  for (const auto& [t, w] : other.waveTerms)
    EXPECT_EQ(notKept.compute(t, {}, &paths, &wave).value, own.compute(t, {}, &paths, &wave).value) << "tile " << t;
}

// A tile's progress is told in paths by the paths and in its own work by the wave term, each to its
// own callback: the paths' count never runs past the tile's paths (the run's reporter showed
// "4352/1000 (435.2 %)" while it counted the wave term's facet sums as paths).
TEST(TileComputer, WaveTermReportsItsProgressApart) {
  const Job job =
      oneTileJob("kind = \"sine-grating\"\nsize_um = [4.0, 4.0]\nperiod_um = 2.0\namplitude_um = 0.1",
                 "[scene]\ncoherence_length_um = 50.0\n[effects]\ncomponents = [\"coherent\", \"incoherent\"]",
                 "paths_per_slice = 1000\nwave_estimator = \"exact\"\n");
  uint64_t mostPaths = 0, waveCalls = 0;
  computeTile(
      job, [&](uint64_t n) { mostPaths = std::max(mostPaths, n); }, [&](uint64_t) { ++waveCalls; });
  EXPECT_LE(mostPaths, job.pathsPerSlice);
  EXPECT_GT(waveCalls, 0u);
}

// Progressive sampling's rounds continue the tile's count of paths (each round used to count from 0
// again): the count never falls and ends at the paths the tile took.
TEST(TileComputer, ProgressiveRoundsCountOn) {
  const Job job = oneTileJob("kind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.3\ncorrelation_um = 2.0",
                             "[effects]\ncomponents = [\"coherent\", \"multiple\"]",
                             "paths_per_slice = 2000\ntarget_rel_error = 0.0001\nmax_paths_per_slice = 8000\n");
  std::vector<uint64_t> counts;
  const TileResult r = computeTile(job, [&](uint64_t n) { counts.push_back(n); });
  ASSERT_EQ(r.samples, 8000u);  // the target is out of reach: four rounds
  ASSERT_FALSE(counts.empty());
  for (size_t i = 1; i < counts.size(); ++i) EXPECT_GE(counts[i], counts[i - 1]) << i;
  EXPECT_EQ(counts.back(), r.samples);
}
