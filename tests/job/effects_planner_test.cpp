// The effects planner's renderer-facing keys (effects_planner.h): the angular resolution at which
// the diffraction decision compares WS with GS, and the incidence range it plans for.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "core/direction_grid.h"
#include "job/effects_planner.h"

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
// sees the blurred peak inside the cap about the normal, and diffraction is off.
TEST(EffectsPlanner, DiffractionJudgedAtTheRenderersResolution) {
  auto plan = [](double res_deg) {
    const Job job = loadJobFromString(
        "[geometry]\nkind = \"flat\"\nsize_um = [2.5, 2.5]\n[material]\nname = \"Al\"\n[spectrum]\nwavelengths_nm = [500.0]\n"
        "[directions]\nn_theta = 64\nn_phi = 16\nincidence = [[0.0, 0.0]]\n[scene]\ncoherence_length_um = 10.0\n"
        "tolerance = 0.05\nangular_resolution_deg = " + std::to_string(res_deg) + "\n[sampling]\npaths_per_slice = 20000\n",
        "t.toml", "");
    const nlohmann::json p = planEffects(job);
    for (const auto& d : p["decisions"])
      if (d["effect"] == "incoherent") return d;
    return nlohmann::json{};
  };
  const nlohmann::json fine = plan(0), coarse = plan(30);
  EXPECT_TRUE(fine["on"].get<bool>()) << fine.dump();
  EXPECT_GT(fine["pilot_lower"].get<double>(), 1.0);
  EXPECT_FALSE(coarse["on"].get<bool>()) << coarse.dump();
  EXPECT_LT(coarse["pilot_upper"].get<double>(), 0.05);
  EXPECT_NE(coarse["reason"].get<std::string>().find("pooled to the renderer's 30 deg"), std::string::npos);
}
