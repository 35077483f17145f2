// A tile as the run computes it (tile_computer.h): the effects planner's geometric pilots are the
// first paths of their tiles, and a tile is the same whether the rank computing it holds the
// pilot's result or traces those paths again.
#include <gtest/gtest.h>

#include <map>
#include <string>

#include "core/direction_grid.h"
#include "job/effects_planner.h"
#include "job/job.h"
#include "job/tile_computer.h"

using namespace mbsdf;

namespace {

Job autoJob(const std::string& geometry, const std::string& material, const std::string& incidence) {
  return loadJobFromString("[geometry]\n" + geometry + "\n[material]\n" + material +
                               "\n[spectrum]\nwavelengths_nm = [500.0, 600.0]\n[directions]\nn_theta = 8\nn_phi = 16\n"
                               "incidence = " +
                               incidence +
                               "\n[scene]\ncoherence_length_um = 50.0\ntolerance = 0.02\n[effects]\n"
                               "components = [\"auto\"]\n[sampling]\npaths_per_slice = 50000\nseed = 5\n",
                           "t.toml", "");
}

// Every pilot tile computed by a computer that holds the pilots and by one that does not.
void expectPilotTilesKept(Job job) {
  std::map<int, TileResult> pilots;
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
  std::map<int, TileResult> pilots;
  const EffectsPlan plan = planEffects(job, {}, &pilots);
  applyEffectsPlan(job, plan);
  for (auto& [t, r] : pilots) r.samples += 1;
  const DirectionGrid grid(job.gridLayout);
  const TileComputer computer(job, grid, pilots);
  for (int t : plan.pilots) EXPECT_FALSE(computer.holdsPilot(t));
}
