// The scalar model's validity from the geometry: a periodic patch placed on the FDTD map of
// docs/validation.md, on its unsafe side, at the job's worst wavelength.
#include "job/scalar_validity.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <tuple>

#include <nlohmann/json.hpp>

#include "job/job.h"

using namespace mbsdf;

namespace {
Job gratingJob(double period_um, double depth_um, const std::string& wavelengths = "[500.0]",
               const std::string& scene = "coherence_length_um = 50.0", const std::string& incidence = "[[0.0, 0.0]]",
               const std::string& material = "kind = \"dielectric\"\nior = 1.5",
               const std::string& components = "\"coherent\", \"incoherent\"") {
  std::ostringstream t;
  t << "[geometry]\nkind = \"binary-grating\"\nsize_um = [" << period_um << ", 0.2]\nperiod_um = " << period_um
    << "\ndepth_um = " << depth_um << "\nduty = 0.5\n[material]\n"
    << material << "\n[spectrum]\n"
    << "wavelengths_nm = " << wavelengths << "\n[directions]\nincidence = " << incidence << "\n[scene]\n"
    << scene << "\n[effects]\ncomponents = [" << components << "]\n";
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

// Between validated cases the figure is interpolated: at 7 λ and 0.6 λ it lies between those of the
// four cases around it; on a validated case it is that case's.
TEST(ScalarValidity, BetweenCasesInterpolated) {
  const ScalarValidity between = scalarValidity(gratingJob(3.5, 0.3));
  ASSERT_TRUE(between.maxOrderError.has_value());
  double lo = 1, hi = 0;
  for (double p : {5.0, 10.0})
    for (double d : {0.5, 1.0}) {
      const double e = *validatedError(ValidityMaterial::Dielectric, ValiditySide::Outside, 0.0, p, d, ScalarModel::Ws);
      lo = std::min(lo, e), hi = std::max(hi, e);
    }
  EXPECT_GE(*between.maxOrderError, lo);
  EXPECT_LE(*between.maxOrderError, hi);
  for (const ValidatedCase& c : validatedCases())
    EXPECT_DOUBLE_EQ(
        *validatedError(c.material, c.side, c.theta_deg, c.periodOverLambda, c.depthOverLambda, ScalarModel::Wm),
        c.maxDeltaWm);
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
  EXPECT_NE(subWavelength.note.find("outside the rigorously validated cases"), std::string::npos);
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

// Oblique light is placed by its angle: 40° between the 30° and 50° cases; a beam from inside the
// glass (θ > 90°) on the map of that side; past the last validated angle nothing is vouched for.
TEST(ScalarValidity, ObliqueLightByAngleAndSide) {
  const ScalarValidity normal = scalarValidity(gratingJob(5.0, 0.25));
  const ScalarValidity at40 =
      scalarValidity(gratingJob(5.0, 0.25, "[500.0]", "coherence_length_um = 50.0", "[[40.0, 0.0]]"));
  ASSERT_TRUE(normal.maxOrderError && at40.maxOrderError);
  EXPECT_NEAR(at40.theta_deg, 40.0, 1e-9);
  const auto at = [](double theta) {
    return *validatedError(ValidityMaterial::Dielectric, ValiditySide::Outside, theta, 10.0, 0.5, ScalarModel::Ws);
  };
  EXPECT_NEAR(*at40.maxOrderError, 0.5 * (at(30.0) + at(50.0)), 1e-12);
  EXPECT_GT(*at40.maxOrderError, *normal.maxOrderError);
  // Several incidences: the worst decides and is named.
  const ScalarValidity both =
      scalarValidity(gratingJob(5.0, 0.25, "[500.0]", "coherence_length_um = 50.0", "[[0.0, 0.0], [40.0, 0.0]]"));
  EXPECT_NEAR(both.theta_deg, 40.0, 1e-9);
  const ScalarValidity inside =
      scalarValidity(gratingJob(5.0, 0.25, "[500.0]", "coherence_length_um = 50.0", "[[150.0, 0.0]]"));
  EXPECT_EQ(inside.side, ValiditySide::Inside);
  EXPECT_NEAR(inside.theta_deg, 30.0, 1e-9);
  EXPECT_NE(inside.note.find("lit from inside"), std::string::npos) << inside.note;
  const ScalarValidity grazing =
      scalarValidity(gratingJob(5.0, 0.25, "[500.0]", "coherence_length_um = 50.0", "[[80.0, 0.0]]"));
  EXPECT_FALSE(grazing.maxOrderError.has_value());
  EXPECT_TRUE(grazing.beyondTolerance);
}

// A metal is placed on the conductors' map, not the glass one; WM's figure is used when the job
// computes multiple scattering.
TEST(ScalarValidity, ConductorsHaveTheirOwnMap) {
  const std::string al = "name = \"Al\"";
  const ScalarValidity metal =
      scalarValidity(gratingJob(2.5, 0.05, "[500.0]", "coherence_length_um = 50.0", "[[30.0, 0.0]]", al));
  ASSERT_TRUE(metal.maxOrderError.has_value());
  EXPECT_EQ(metal.material, ValidityMaterial::Conductor);
  EXPECT_DOUBLE_EQ(*metal.maxOrderError, *validatedError(ValidityMaterial::Conductor, ValiditySide::Outside, 30.0, 5.0,
                                                         0.1, ScalarModel::Ws));
  EXPECT_NE(metal.note.find("conductor"), std::string::npos) << metal.note;
  const ScalarValidity wm =
      scalarValidity(gratingJob(2.5, 0.05, "[500.0]", "coherence_length_um = 50.0", "[[30.0, 0.0]]", al,
                                "\"coherent\", \"incoherent\", \"multiple\""));
  ASSERT_TRUE(wm.maxOrderError.has_value());
  EXPECT_EQ(wm.model, ScalarModel::Wm);
  EXPECT_DOUBLE_EQ(*wm.maxOrderError, *validatedError(ValidityMaterial::Conductor, ValiditySide::Outside, 30.0, 5.0,
                                                      0.1, ScalarModel::Wm));
  // Deeper than any validated metal grating: not vouched for.
  EXPECT_FALSE(scalarValidity(gratingJob(2.5, 0.5, "[500.0]", "coherence_length_um = 50.0", "[[0.0, 0.0]]", al))
                   .maxOrderError.has_value());
}

// The map in the code is the one `scripts/validate-fdtd` measured: per validated case, the largest
// |Δ| of its orders (WS and WM) in docs/validation/fdtd.json (rounded to 1e-4), and every binary,
// oblique and metal case of the data is in the map.
TEST(ScalarValidity, MapMatchesTheValidationData) {
  std::ifstream in(std::string(MICROBSDF_SOURCE_DIR) + "/docs/validation/fdtd.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json rows = nlohmann::json::parse(in);
  int matched = 0;
  for (const ValidatedCase& c : validatedCases()) {
    double ws = -1, wm = -1;
    for (const auto& row : rows) {
      const std::string set = row.value("set", "binary");
      if (set != "binary" && set != "oblique" && set != "metal") continue;
      const ValidityMaterial material = set == "metal" ? ValidityMaterial::Conductor : ValidityMaterial::Dielectric;
      const ValiditySide side = row["from"] == "glass" ? ValiditySide::Inside : ValiditySide::Outside;
      const double p = row["period_um"].get<double>() / 0.5, d = row["depth_um"].get<double>() / 0.5;
      if (material != c.material || side != c.side || std::abs(row.value("theta_deg", 0.0) - c.theta_deg) > 1e-9 ||
          std::abs(p - c.periodOverLambda) > 1e-9 || std::abs(d - c.depthOverLambda) > 1e-9)
        continue;
      const double fdtd = row["fdtd"].get<double>();
      ws = std::max(ws, std::abs(row.value("microbsdf_ws", row["microbsdf"].get<double>()) - fdtd));
      wm = std::max(wm, std::abs(row["delta"].get<double>()));
    }
    ASSERT_GE(wm, 0) << "no validation data for θ " << c.theta_deg << "°, period " << c.periodOverLambda << " λ, depth "
                     << c.depthOverLambda << " λ";
    EXPECT_NEAR(c.maxDeltaWs, ws, 6e-5) << c.theta_deg << "°, " << c.periodOverLambda << " λ, " << c.depthOverLambda;
    EXPECT_NEAR(c.maxDeltaWm, wm, 6e-5) << c.theta_deg << "°, " << c.periodOverLambda << " λ, " << c.depthOverLambda;
    ++matched;
  }
  std::set<std::tuple<std::string, std::string, double, double, double>> inData;
  for (const auto& row : rows) {
    const std::string set = row.value("set", "binary");
    if (set == "binary" || set == "oblique" || set == "metal")
      inData.insert({set == "metal" ? "metal" : "glass", row["from"].get<std::string>(), row.value("theta_deg", 0.0),
                     row["period_um"].get<double>(), row["depth_um"].get<double>()});
  }
  EXPECT_EQ(size_t(matched), inData.size());
}
