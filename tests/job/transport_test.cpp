// The geometric transport's choice of the facet sum (job/transport.h): only where no path of depth
// >= 2 is wanted, per tile by counted work (never by timing), or as [sampling] single_scattering
// forces (its errors: job_test.cpp).
#include "job/transport.h"

#include <gtest/gtest.h>

using namespace mbsdf;

namespace {
const std::string kGrating =
    "[geometry]\nkind = \"sine-grating\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.03\n"
    "[material]\nname = \"Al\"\n[directions]\nn_theta = 8\nn_phi = 16\nincidence = [[20.0, 0.0], [75.0, 0.0]]\n"
    "[scene]\ncoherence_length_um = 50.0\n";
}  // namespace

TEST(Transport, FacetSumWhereNothingScattersTwiceAndItCostsLess) {
  // The transport keeps references to the job's geometry and the grid: they live beside it.
  struct Setup {
    Job job;
    DirectionGrid grid;
    std::unique_ptr<GeometricTransport> t;
    explicit Setup(const std::string& text)
        : job(loadJobFromString(text, "t.toml", "")),
          grid(job.gridLayout),
          t(std::make_unique<GeometricTransport>(job, grid, job.pathsPerSlice)) {}
  };
  auto transport = [](const std::string& text) {
    auto s = std::make_shared<Setup>(text);
    return std::make_pair(std::cref(s->job), std::shared_ptr<GeometricTransport>(s, s->t.get()));
  };
  const std::string ws = "[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n";
  {
    auto [job, t] = transport(kGrating + ws + "[sampling]\npaths_per_slice = 50000\n");
    ASSERT_TRUE(t->mayUseFacetSum());
    // 20°: every direction above the steepest slope (5.4°): 1280 x 64 orientations, no ray.
    EXPECT_TRUE(t->facetSum(job.incidence[0].bin, std::nullopt));
    const TileResult r = t->run(0, 0, job.incidence[0].bin, std::nullopt);
    EXPECT_EQ(r.samples, 0u);
    EXPECT_EQ(r.rays, 0u);
    EXPECT_TRUE(r.has(Component::Coherent));
  }
  {
    // Few paths: the grazing bin's visibility rays cost more than 2 x 1000 rays.
    auto [job, t] = transport(kGrating + ws + "[sampling]\npaths_per_slice = 1000\n");
    EXPECT_FALSE(t->facetSum(job.incidence[1].bin, std::nullopt));
    EXPECT_GT(t->run(1, 1, job.incidence[1].bin, std::nullopt).samples, 0u);
  }
  {
    auto [job, t] = transport(kGrating + ws + "[sampling]\nsingle_scattering = \"paths\"\n");
    EXPECT_FALSE(t->mayUseFacetSum());
  }
  {
    auto [job, t] = transport(kGrating + ws + "[sampling]\nsingle_scattering = \"facets\"\npaths_per_slice = 1000\n");
    EXPECT_TRUE(t->facetSum(job.incidence[1].bin, std::nullopt));
  }
  {
    // multiple (paths of depth >= 2) or lost (their geo_masked tally) need the path tracer.
    auto [job, t] = transport(kGrating + "[effects]\ncomponents = [\"coherent\", \"incoherent\", \"multiple\"]\n");
    EXPECT_FALSE(t->mayUseFacetSum());
    auto [job2, t2] = transport(kGrating + "[effects]\ncomponents = [\"coherent\", \"incoherent\", \"lost\"]\n");
    EXPECT_FALSE(t2->mayUseFacetSum());
  }
  {
    // A mesh (not a heightfield): every pair by rays, far more than the paths' at the default budget.
    auto [job, t] = transport("[geometry]\nkind = \"hemispheres\"\n[directions]\nincidence = [[20.0, 0.0]]\n" + ws);
    ASSERT_TRUE(t->mayUseFacetSum());
    EXPECT_FALSE(t->facetSum(job.incidence[0].bin, std::nullopt));
  }
}
