// The scalar model's validity from the geometry: a periodic patch placed on the FDTD map of
// docs/validation.md, on its unsafe side, at the job's worst wavelength.
#include "job/scalar_validity.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "job/job.h"

using namespace mbsdf;

namespace {
Job gratingJob(double period_um, double depth_um, const std::string& wavelengths = "[500.0]",
               const std::string& scene = "coherence_length_um = 50.0") {
  std::ostringstream t;
  t << "[geometry]\nkind = \"binary-grating\"\nsize_um = [" << period_um << ", 0.2]\nperiod_um = " << period_um
    << "\ndepth_um = " << depth_um << "\nduty = 0.5\n[material]\nkind = \"dielectric\"\nior = 1.5\n[spectrum]\n"
    << "wavelengths_nm = " << wavelengths << "\n[directions]\nincidence = [[0.0, 0.0]]\n[scene]\n"
    << scene << "\n[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n";
  return loadJobFromString(t.str(), "t.toml", "");
}
}  // namespace

// A 1-D grating on a 0.2 µm wide patch: its period is along x (the patch's width along the
// invariant y is no period). 10 λ, depth λ/2: the map's 10 λ row, λ/2 column.
TEST(ScalarValidity, GratingPlacedOnTheMap) {
  const ScalarValidity v = scalarValidity(gratingJob(5.0, 0.25));
  ASSERT_TRUE(v.applies);
  EXPECT_NEAR(v.periodOverLambda, 10.0, 1e-9);
  EXPECT_NEAR(v.heightOverLambda, 0.5, 1e-9);
  ASSERT_TRUE(v.maxOrderError.has_value());
  EXPECT_LT(*v.maxOrderError, 0.01);
  EXPECT_FALSE(v.beyondTolerance) << v.note;
}

// Between validated cases the unsafe neighbour counts: 7 λ takes the 5 λ row, 0.6 λ the λ column.
TEST(ScalarValidity, BetweenCasesTheUnsafeNeighbour) {
  const ScalarValidity between = scalarValidity(gratingJob(3.5, 0.3));
  const ScalarValidity row5 = scalarValidity(gratingJob(2.5, 0.5));
  ASSERT_TRUE(between.maxOrderError && row5.maxOrderError);
  EXPECT_DOUBLE_EQ(*between.maxOrderError, *row5.maxOrderError);
}

// Short periods and deep ridges: beyond the tolerance, or outside the map altogether; the
// shortest wavelength of a spectral job decides when it is the worse.
TEST(ScalarValidity, WarnsWhereScalarDiffractionFails) {
  const ScalarValidity deep = scalarValidity(gratingJob(1.0, 0.5));
  ASSERT_TRUE(deep.maxOrderError.has_value());
  EXPECT_GT(*deep.maxOrderError, 0.05);
  EXPECT_TRUE(deep.beyondTolerance);
  EXPECT_NE(deep.note.find("beyond the tolerance"), std::string::npos) << deep.note;
  const ScalarValidity subWavelength = scalarValidity(gratingJob(0.4, 0.1));
  EXPECT_FALSE(subWavelength.maxOrderError.has_value());
  EXPECT_TRUE(subWavelength.beyondTolerance);
  EXPECT_NE(subWavelength.note.find("outside the rigorously validated range"), std::string::npos);
  // 5 µm, depth 1.2 µm: 2.4 λ deep at 500 nm (outside), 1.5 λ at 800 nm.
  const ScalarValidity spectral = scalarValidity(gratingJob(5.0, 1.2, "[500.0, 800.0]"));
  EXPECT_FALSE(spectral.maxOrderError.has_value());
  EXPECT_NEAR(spectral.heightOverLambda, 2.4, 1e-9);
}

// No diffraction orders to judge: no coherence window, a flat patch.
TEST(ScalarValidity, OnlyForPeriodicPatchesUnderAWindow) {
  EXPECT_FALSE(scalarValidity(gratingJob(5.0, 0.25, "[500.0]", "coherence_length_um = 0.0")).applies);
  const Job flat = loadJobFromString(
      "[geometry]\nkind = \"flat\"\nsize_um = [10.0, 10.0]\n[material]\nname = \"Al\"\n[directions]\nincidence = "
      "[[0.0, 0.0]]\n"
      "[scene]\ncoherence_length_um = 50.0\n[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n",
      "t.toml", "");
  EXPECT_FALSE(scalarValidity(flat).applies);
}

// The map in the code is the one `scripts/validate-fdtd` measured: per validated case, the largest
// |Δ| of the binary gratings at normal incidence in docs/validation/fdtd.json (rounded to 1e-4).
TEST(ScalarValidity, MapMatchesTheValidationData) {
  std::ifstream in(std::string(MICROBSDF_SOURCE_DIR) + "/docs/validation/fdtd.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json rows = nlohmann::json::parse(in);
  const ValidityMap& map = validityMap();
  int matched = 0;
  for (int r = 0; r < ValidityMap::kRows; ++r)
    for (int c = 0; c < ValidityMap::kCols; ++c) {
      double worst = -1;
      for (const auto& row : rows) {
        if (row.value("set", "binary") != "binary") continue;
        const double p = row["period_um"].get<double>() / 0.5, d = row["depth_um"].get<double>() / 0.5;
        if (std::abs(p - map.periodOverLambda[r]) < 1e-9 && std::abs(d - map.depthOverLambda[c]) < 1e-9)
          worst = std::max(worst, std::abs(row["delta"].get<double>()));
      }
      ASSERT_GE(worst, 0) << "no validation data for period " << map.periodOverLambda[r] << " λ, depth "
                          << map.depthOverLambda[c] << " λ";
      EXPECT_NEAR(map.maxDelta[r][c], worst, 6e-5)
          << map.periodOverLambda[r] << " λ, " << map.depthOverLambda[c] << " λ";
      ++matched;
    }
  EXPECT_EQ(matched, ValidityMap::kRows * ValidityMap::kCols);
}
