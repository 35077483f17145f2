// Job files: defaults, errors that name file, line and key, unknown keys.
#include "job/job.h"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include "core/error.h"

using namespace mbsdf;

namespace {
std::string errorOf(const std::string& text) {
  try {
    loadJobFromString(text, "test.toml", "");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Job, DefaultsAreDocumentedValues) {
  Job j = loadJobFromString("[directions]\nincidence = [[0.0, 0.0]]\n", "t.toml", "");
  EXPECT_EQ(j.geometryKind, "flat");
  EXPECT_EQ(j.lambda_nm.size(), 8u);
  EXPECT_NEAR(j.lambda_nm.front(), 418.75, 1e-12);
  EXPECT_NEAR(j.lambda_nm.back(), 681.25, 1e-12);
  EXPECT_EQ(j.pathsPerSlice, 1000000u);
  EXPECT_EQ(j.maxDepth, 100);
  EXPECT_TRUE(j.material.isConductor());
  EXPECT_TRUE(j.components.has(Component::Coherent));
  EXPECT_TRUE(j.components.has(Component::Multiple));
  EXPECT_EQ(j.outputPath, "out.h5");
  EXPECT_DOUBLE_EQ(j.geometry.sizeX, 20.0);
}

TEST(Job, UnknownKeyNamesKeyAndLine) {
  std::string e = errorOf("[geometry]\nkind = \"flat\"\nradius_typo = 3\n");
  EXPECT_NE(e.find("test.toml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("geometry.radius_typo"), std::string::npos) << e;
  e = errorOf("[geometri]\nkind = \"flat\"\n");
  EXPECT_NE(e.find("test.toml:1"), std::string::npos) << e;
  EXPECT_NE(e.find("geometri"), std::string::npos) << e;
}

TEST(Job, MalformedTomlNamesLine) {
  std::string e = errorOf("[geometry]\nkind = \"flat\n");
  EXPECT_NE(e.find("test.toml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("malformed"), std::string::npos) << e;
}

TEST(Job, BadValuesNameTheKey) {
  EXPECT_NE(errorOf("[geometry]\nsize_um = [-1.0, 2.0]\n").find("geometry.size_um"), std::string::npos);
  EXPECT_NE(errorOf("[geometry]\nkind = \"sphere\"\n").find("geometry.kind"), std::string::npos);
  EXPECT_NE(errorOf("[material]\nname = \"Unobtainium\"\n").find("material.name"), std::string::npos);
  EXPECT_NE(errorOf("[material]\nkind = \"dielectric\"\nname = \"Al\"\n").find("material.kind"), std::string::npos);
  EXPECT_NE(errorOf("[sampling]\npaths_per_slice = 0\n").find("sampling.paths_per_slice"), std::string::npos);
  EXPECT_NE(errorOf("[sampling]\nmax_depth = \"deep\"\n").find("sampling.max_depth"), std::string::npos);
  EXPECT_NE(errorOf("[directions]\nincidence = [[95.0, 0.0]]\n").find("directions.incidence"), std::string::npos);
  EXPECT_NE(errorOf("[effects]\ncomponents = [\"shiny\"]\n").find("effects.components"), std::string::npos);
  // Wavelength outside the aluminium table (298–886 nm).
  std::string e = errorOf("[material]\nname = \"Al\"\n[spectrum]\nwavelengths_nm = [1500.0]\n");
  EXPECT_NE(e.find("spectrum.wavelengths_nm"), std::string::npos) << e;
  EXPECT_NE(e.find("test.toml:4"), std::string::npos) << e;
  // Patch not holding a whole number of periods.
  e = errorOf("[geometry]\nkind = \"ridged\"\nsize_um = [10.0, 10.0]\nperiod_um = 3.0\n");
  EXPECT_NE(e.find("geometry.period_um"), std::string::npos) << e;
}

TEST(Job, MissingMeshFileNamesFile) {
  std::string e = errorOf("[geometry]\nkind = \"mesh\"\nfile = \"nowhere.obj\"\n");
  EXPECT_NE(e.find("nowhere.obj"), std::string::npos) << e;
  EXPECT_NE(e.find("not found"), std::string::npos) << e;
}

TEST(Job, IncidenceAllCoversTheHemispheres) {
  Job c = loadJobFromString("[directions]\nn_theta = 3\nn_phi = 4\n", "t.toml", "");
  EXPECT_EQ(c.incidence.size(), 12u);  // conductor: upper hemisphere
  Job d = loadJobFromString("[material]\nkind = \"dielectric\"\nior = 1.5\n[directions]\nn_theta = 3\nn_phi = 4\n",
                            "t.toml", "");
  EXPECT_EQ(d.incidence.size(), 24u);  // dielectric: both
}

TEST(Job, WavelengthRangeTable) {
  Job j = loadJobFromString("[spectrum]\nwavelengths_nm = { min = 400.0, max = 700.0, count = 3 }\n", "t.toml", "");
  ASSERT_EQ(j.lambda_nm.size(), 3u);
  EXPECT_DOUBLE_EQ(j.lambda_nm[1], 550.0);
}

// Inputs found by fuzz_job (scripts/fuzz): each must be accepted or rejected with an InputError,
// quickly (they used to run for minutes).
TEST(Job, FuzzRegressions) {
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(MICROBSDF_SOURCE_DIR) + "/tests/fuzz/regressions/job")) {
    std::ifstream in(entry.path(), std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    auto t0 = std::chrono::steady_clock::now();
    try {
      loadJobFromString(text, "fuzz.toml", "/nonexistent");
    } catch (const InputError&) {
    }
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0) << entry.path();
  }
}
