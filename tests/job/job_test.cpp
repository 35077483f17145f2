// Job files: defaults, errors that name file, line and key, unknown keys.
#include "job/job.h"
#include "job/symmetry.h"

#include <gtest/gtest.h>

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

TEST(Job, AFileWithNoKeyIsRefused) {
  // Every key has a default: without this check an empty (truncated, mistaken) file would run a
  // whole default job.
  for (const char* text : {"", "\n\n", "# only a comment\n", "  \t\n# two\n# comments\n"}) {
    const std::string e = errorOf(text);
    EXPECT_NE(e.find("test.toml"), std::string::npos) << e;
    EXPECT_NE(e.find("holds no key"), std::string::npos) << e;
  }
  EXPECT_EQ(errorOf("[geometry]\nkind = \"flat\"\n"), "");
}

// A mesh file whose face is repeated loads as the mesh without the repeat (the same triangles,
// hence the same tables); one with a second sheet over the first, or with a face wound the other way
// round, is refused, naming the file's key.
TEST(Job, RepeatedFacesAreDroppedASecondSheetAndATurnedFaceRefused) {
  const auto dir = std::filesystem::temp_directory_path() / "microbsdf_job_repeated_faces";
  std::filesystem::create_directories(dir);
  const std::string square = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";
  std::ofstream(dir / "square.obj") << square;
  std::ofstream(dir / "repeated.obj") << square << "f 1 2 3\nv 1 1 0\nf 2 5 3\n";
  std::ofstream(dir / "sheets.obj") << square << "v 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\nf 5 6 7\nf 6 8 7\n";
  std::ofstream(dir / "turned.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 3 4\n";
  auto job = [&](const char* file) {
    return "[geometry]\nkind = \"mesh\"\nfile = \"" + (dir / file).string() + "\"\n";
  };
  const Job single = loadJobFromString(job("square.obj"), "test.toml", "");
  const Job repeated = loadJobFromString(job("repeated.obj"), "test.toml", "");
  EXPECT_EQ(repeated.geometry.triangles, single.geometry.triangles);
  EXPECT_TRUE(repeated.closure.closed()) << repeated.closure.describe();
  const std::string e = errorOf(job("sheets.obj"));
  EXPECT_NE(e.find("test.toml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("geometry.file"), std::string::npos) << e;
  EXPECT_NE(e.find("cover the footprint 2 times"), std::string::npos) << e;
  // A face wound the other way round: refused, not run as a patch with a hole.
  const std::string turned = errorOf(job("turned.obj"));
  EXPECT_NE(turned.find("geometry.file"), std::string::npos) << turned;
  EXPECT_NE(turned.find("not wound consistently"), std::string::npos) << turned;
  std::filesystem::remove_all(dir);
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
  // Extreme values are printed as numbers a reader can read, not as 300 digits or "0.000000".
  e = errorOf("[material]\nname = \"Al\"\n[spectrum]\nwavelengths_nm = [1e300]\n");
  EXPECT_NE(e.find("wavelength 1e+300 nm"), std::string::npos) << e;
  e = errorOf("[geometry]\nkind = \"sine-grating\"\nperiod_um = -1e-300\n");
  EXPECT_NE(e.find("(got -1e-300)"), std::string::npos) << e;
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

// Inputs found by fuzz_job (scripts/fuzz): each must be accepted or rejected with an InputError.
// Some used to run for minutes; the test's CTest time-out catches that without a wall-clock bound
// here (a loaded machine must not fail a test).
TEST(Job, FuzzRegressions) {
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(MICROBSDF_SOURCE_DIR) + "/tests/fuzz/regressions/job")) {
    std::ifstream in(entry.path(), std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    try {
      loadJobFromString(text, "fuzz.toml", "/nonexistent");
    } catch (const InputError&) {
    }
  }
}

TEST(Job, StatisticalSurface) {
  Job j = loadJobFromString(
      "[geometry]\nkind = \"statistical\"\nndf = \"ggx\"\nalpha = [0.2, 0.4]\n[directions]\nincidence = [[0.0, 0.0]]\n",
      "t.toml", "");
  ASSERT_TRUE(j.statistical.has_value());
  EXPECT_EQ(j.geometryKind, "statistical");
  const auto* g = std::get_if<GgxNdf>(&j.statistical->ndf);
  ASSERT_NE(g, nullptr);
  EXPECT_DOUBLE_EQ(g->alphaX, 0.2);
  EXPECT_DOUBLE_EQ(g->alphaY, 0.4);
  // "auto" is single + multiple scattering (no explicit geometry for diffraction).
  EXPECT_TRUE(j.components.has(Component::Coherent));
  EXPECT_TRUE(j.components.has(Component::Multiple));
  EXPECT_FALSE(j.components.has(Component::Incoherent));
  Job v = loadJobFromString("[geometry]\nkind = \"statistical\"\nndf = \"vmf\"\nalpha = 0.2\n", "t.toml", "");
  EXPECT_NEAR(std::get<VonMisesFisherNdf>(v.statistical->ndf).kappa, 50.0, 1e-9);
  Job s = loadJobFromString("[geometry]\nkind = \"statistical\"\nndf = \"sphere\"\nflake_albedo = 0.5\n", "t.toml", "");
  EXPECT_EQ(std::get<VonMisesFisherNdf>(s.statistical->ndf).kappa, 0.0);
  EXPECT_EQ(s.statistical->flakeAlbedo, 0.5);

  EXPECT_NE(errorOf("[geometry]\nkind = \"statistical\"\nndf = \"cauchy\"\n").find("geometry.ndf"), std::string::npos);
  EXPECT_NE(errorOf("[geometry]\nkind = \"statistical\"\nalpha = -1.0\n").find("geometry.alpha"), std::string::npos);
  EXPECT_NE(errorOf("[geometry]\nkind = \"statistical\"\nflake_albedo = 1.5\n").find("geometry.flake_albedo"),
            std::string::npos);
  EXPECT_NE(errorOf("[geometry]\nkind = \"statistical\"\nndf = \"vmf\"\n").find("geometry.kappa"), std::string::npos);
  EXPECT_NE(errorOf("[geometry]\nkind = \"statistical\"\n[effects]\ncomponents = [\"incoherent\"]\n")
                .find("effects.components"),
            std::string::npos);
  EXPECT_NE(errorOf("[geometry]\nkind = \"statistical\"\nndf = \"sphere\"\n[material]\nkind = \"dielectric\"\n")
                .find("geometry.ndf"),
            std::string::npos);
  // Keys of explicit geometry are unused (reported) for a statistical surface.
  EXPECT_NE(errorOf("[geometry]\nkind = \"statistical\"\nradius_um = 2.0\n").find("geometry.radius_um"),
            std::string::npos);
}

TEST(Job, TabulatedNdfFile) {
  auto dir = std::filesystem::temp_directory_path() / "microbsdf_ndf_test";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "good.csv") << "# theta_deg, D\n0, 2.0\n45, 1.0\n90, 0.0\n";
  std::ofstream(dir / "bad.csv") << "0, 1.0\n10, -3\n";
  std::ofstream(dir / "order.csv") << "0, 1.0\n20 1.0\n10 1.0\n";
  Job j = loadJobFromString("[geometry]\nkind = \"statistical\"\nndf = \"tabulated\"\nndf_file = \"good.csv\"\n",
                            "t.toml", dir.string());
  const auto& t = std::get<TabulatedNdf>(j.statistical->ndf);
  ASSERT_EQ(t.cosTheta.size(), 3u);
  EXPECT_NEAR(t.cosTheta.back(), 1.0, 1e-15);
  auto err = [&](const std::string& file) {
    try {
      loadJobFromString("[geometry]\nkind = \"statistical\"\nndf = \"tabulated\"\nndf_file = \"" + file + "\"\n",
                        "t.toml", dir.string());
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(err("bad.csv").find("bad.csv:2"), std::string::npos) << err("bad.csv");
  EXPECT_NE(err("order.csv").find("order.csv:3"), std::string::npos) << err("order.csv");
  EXPECT_NE(err("missing.csv").find("geometry.ndf_file"), std::string::npos) << err("missing.csv");
}

// [scene] light source -> coherence length; conflicting or unknown sources name the key.
TEST(Job, SceneLightSource) {
  Job sun = loadJobFromString("[spectrum]\nwavelengths_nm = [550.0]\n[scene]\nlight = \"sun\"\n", "t.toml", "");
  EXPECT_NEAR(sun.scene.coherenceLength_um, 159.7, 0.1);
  EXPECT_EQ(sun.scene.coherenceSource, "light = \"sun\"");
  Job disk = loadJobFromString(
      "[spectrum]\nwavelengths_nm = [500.0, 600.0]\n[scene]\nsource_angular_diameter_deg = 1.066\n", "t.toml", "");
  EXPECT_NEAR(disk.scene.coherenceLength_um, 159.7 / 2, 0.1);  // twice the sun's diameter, same mean λ
  EXPECT_NE(errorOf("[scene]\nlight = \"moon\"\n").find("scene.light"), std::string::npos);
  EXPECT_NE(errorOf("[scene]\nlight = \"sun\"\ncoherence_length_um = 50.0\n").find("scene.coherence_length_um"),
            std::string::npos);
  EXPECT_NE(errorOf("[scene]\nsource_angular_diameter_deg = -1.0\n").find("scene.source_angular_diameter_deg"),
            std::string::npos);
  EXPECT_TRUE(loadJobFromString("[directions]\nincidence = [[0.0, 0.0]]\n", "t.toml", "").autoComponents);
  EXPECT_FALSE(loadJobFromString("[effects]\ncomponents = [\"coherent\"]\n", "t.toml", "").autoComponents);
}

// [scene] incidence_max_deg: incidence = "all" keeps whole rings within the angle on each side;
// a listed direction beyond it, or a range with no bin, is an error naming the key.
TEST(Job, SceneIncidenceRange) {
  const std::string dirs = "[directions]\nn_theta = 6\nn_phi = 4\n";  // ring centres 7.5, 22.5, ... 82.5 deg
  Job al = loadJobFromString(dirs + "[scene]\nincidence_max_deg = 50.0\n", "t.toml", "");
  EXPECT_EQ(al.incidence.size(), 3u * 4u);
  for (const auto& d : al.incidence) EXPECT_LE(d.theta_deg, 50.0);
  EXPECT_TRUE(al.incidenceAll);
  Job glass = loadJobFromString(
      "[material]\nkind = \"dielectric\"\nior = 1.5\n" + dirs + "[scene]\nincidence_max_deg = 30.0\n", "t.toml", "");
  ASSERT_EQ(glass.incidence.size(), 2u * 2u * 4u);  // two rings above, two inside
  for (const auto& d : glass.incidence) EXPECT_LE(std::min(d.theta_deg, 180 - d.theta_deg), 30.0);
  EXPECT_EQ(loadJobFromString(dirs, "t.toml", "").incidence.size(), 6u * 4u);
  EXPECT_NE(errorOf(dirs + "[scene]\nincidence_max_deg = 5.0\n").find("scene.incidence_max_deg"), std::string::npos);
  EXPECT_NE(errorOf(dirs + "[scene]\nincidence_max_deg = 95.0\n").find("scene.incidence_max_deg"), std::string::npos);
  EXPECT_NE(errorOf("[directions]\nincidence = [[70.0, 0.0]]\n[scene]\nincidence_max_deg = 60.0\n")
                .find("scene.incidence_max_deg"),
            std::string::npos);
  // Whole rings go, so an isotropic surface still computes one azimuth per remaining ring.
  Job iso = loadJobFromString(
      "[geometry]\nkind = \"statistical\"\nndf = \"ggx\"\nalpha = 0.3\n" + dirs + "[scene]\nincidence_max_deg = 50.0\n",
      "t.toml", "");
  ASSERT_TRUE(iso.symmetryReduced()) << iso.symmetryReason;
  const DirectionGrid grid(iso.gridLayout);
  EXPECT_EQ(AzimuthalSymmetry(iso, grid).representativeCount(), 3);
}

// [directions] symmetry: detected for isotropic NDFs, refused for anisotropic ones, unused (with the
// reason) without rings to reduce.
TEST(Job, SymmetryDetectedOrDeclared) {
  const std::string stat = "[geometry]\nkind = \"statistical\"\nndf = \"ggx\"\n";
  Job iso = loadJobFromString(stat + "alpha = 0.3\n[directions]\nn_theta = 3\nn_phi = 4\n", "t.toml", "");
  EXPECT_TRUE(iso.isotropic) << iso.symmetryReason;
  Job aniso = loadJobFromString(stat + "alpha = [0.3, 0.5]\n[directions]\nn_theta = 3\nn_phi = 4\n", "t.toml", "");
  EXPECT_FALSE(aniso.isotropic);
  EXPECT_NE(errorOf(stat + "alpha = [0.3, 0.5]\n[directions]\nsymmetry = \"isotropic\"\n").find("directions.symmetry"),
            std::string::npos);
  Job list = loadJobFromString(stat + "alpha = 0.3\n[directions]\nincidence = [[10.0, 0.0]]\n", "t.toml", "");
  EXPECT_FALSE(list.isotropic);
  EXPECT_NE(list.symmetryReason.find("incidence"), std::string::npos);
  Job declared = loadJobFromString(
      "[geometry]\nkind = \"gaussian\"\n[directions]\nn_theta = 3\nn_phi = 4\nsymmetry = \"isotropic\"\n", "t.toml",
      "");
  EXPECT_TRUE(declared.isotropic);
  EXPECT_FALSE(
      loadJobFromString("[geometry]\nkind = \"gaussian\"\n[directions]\nn_theta = 3\nn_phi = 4\n", "t.toml", "")
          .isotropic);
  EXPECT_NE(errorOf("[directions]\nsymmetry = \"mirror\"\n").find("directions.symmetry"), std::string::npos);
}

// wave_estimator = "fft": heightfields only; with a window narrower than 4 L / 2π no lost component;
// `auto` picks it for a heightfield under a narrow window on a disk grid and keeps `orders` for wide
// windows and `area` elsewhere.
TEST(Job, FftEstimatorConditions) {
  const std::string gauss =
      "[geometry]\nkind = \"gaussian\"\nsize_um = [10.0, 10.0]\nrms_um = 0.1\ncorrelation_um = 1.0\n";
  const std::string narrow = "[scene]\ncoherence_length_um = 15.0\n",
                    disk = "[directions]\ngrid = \"disk\"\nwidth = 16\nheight = 16\n";
  std::string e = errorOf("[geometry]\nkind = \"hemispheres\"\n[sampling]\nwave_estimator = \"fft\"\n");
  EXPECT_NE(e.find("sampling.wave_estimator"), std::string::npos) << e;
  EXPECT_NE(e.find("heightfield"), std::string::npos) << e;
  EXPECT_EQ(errorOf(gauss + narrow + "[sampling]\nwave_estimator = \"fft\"\n"), "");
  e = errorOf(
      gauss + narrow + disk +
      "[effects]\ncomponents = [\"coherent\", \"incoherent\", \"lost\"]\n[sampling]\nwave_estimator = \"fft\"\n");
  EXPECT_NE(e.find("lost"), std::string::npos) << e;
  EXPECT_EQ(errorOf(gauss + narrow + disk + "[sampling]\nwave_estimator = \"fft\"\n"), "");
  EXPECT_EQ(waveEstimatorName(loadJobFromString(gauss + narrow + disk, "t.toml", "").resolvedWaveEstimator()), "fft");
  EXPECT_EQ(waveEstimatorName(loadJobFromString(gauss + narrow, "t.toml", "").resolvedWaveEstimator()),
            "area");  // explicit on theta-phi
  EXPECT_EQ(
      waveEstimatorName(loadJobFromString(gauss + narrow + disk +
                                              "[effects]\ncomponents = [\"coherent\", \"incoherent\", \"lost\"]\n",
                                          "t.toml", "")
                            .resolvedWaveEstimator()),
      "area");
  EXPECT_EQ(waveEstimatorName(loadJobFromString(gauss + disk + "[scene]\ncoherence_length_um = 100.0\n", "t.toml", "")
                                  .resolvedWaveEstimator()),
            "orders");
  EXPECT_EQ(waveEstimatorName(loadJobFromString("[geometry]\nkind = \"hemispheres\"\n" + narrow + disk, "t.toml", "")
                                  .resolvedWaveEstimator()),
            "area");
}

// The lattice cell decides the grating-order regime: the paper's HEMISPHERES (20 µm, 4 x 4 cells
// of 5 µm) under δc = 50 µm resolve to `orders` (2πσ/L = 2.6 for the patch, 10.5 for the cell);
// `exact`'s visibility table is built when the job's tiles pay for it, on request, never for
// other estimators; a bad value names the key.
TEST(Job, LatticeCellAndVisibilityTable) {
  const std::string hemi =
      "[geometry]\nkind = \"hemispheres\"\n[scene]\ncoherence_length_um = 50.0\n"
      "[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n";
  const Job j = loadJobFromString(hemi, "t.toml", "");
  EXPECT_EQ(j.cellNx, 4);
  EXPECT_EQ(j.cellNy, 4);
  EXPECT_DOUBLE_EQ(j.cellSizeX(), 5.0);
  EXPECT_EQ(waveEstimatorName(j.resolvedWaveEstimator()), "orders");
  EXPECT_EQ(j.visibilityTableResolution(), 0);  // not exact
  // exact where it costs no more than orders at the job's budget: a 4 µm flat patch (2 facets), or
  // the hemisphere cell (6 136 facets) with 2^16 points.
  EXPECT_EQ(waveEstimatorName(loadJobFromString("[geometry]\nsize_um = [4.0, 4.0]\n[scene]\ncoherence_length_um = "
                                                "50.0\n[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n",
                                                "t.toml", "")
                                  .resolvedWaveEstimator()),
            "exact");
  EXPECT_EQ(
      waveEstimatorName(
          loadJobFromString(hemi + "[sampling]\nwave_samples_per_bin = 65536\n", "t.toml", "").resolvedWaveEstimator()),
      "exact");
  const std::string all = "[directions]\nn_theta = 15\nn_phi = 30\nincidence = \"all\"\n";
  const std::string one =
      "[directions]\nn_theta = 15\nn_phi = 30\nincidence = [[30.0, 0.0]]\nincidence_sampling = \"exact\"\n";
  EXPECT_EQ(loadJobFromString(hemi + all + "[sampling]\nwave_estimator = \"exact\"\n", "t.toml", "")
                .visibilityTableResolution(),
            128);
  EXPECT_EQ(loadJobFromString(hemi + one + "[sampling]\nwave_estimator = \"exact\"\n", "t.toml", "")
                .visibilityTableResolution(),
            0);
  EXPECT_EQ(loadJobFromString(hemi + one + "[sampling]\nwave_estimator = \"exact\"\nvisibility_table = \"on\"\n",
                              "t.toml", "")
                .visibilityTableResolution(),
            128);
  EXPECT_EQ(loadJobFromString(hemi + all + "[sampling]\nwave_estimator = \"exact\"\nvisibility_table = \"off\"\n",
                              "t.toml", "")
                .visibilityTableResolution(),
            0);
  const std::string e = errorOf(hemi + "[sampling]\nvisibility_table = \"maybe\"\n");
  EXPECT_NE(e.find("sampling.visibility_table"), std::string::npos) << e;
}

// [sampling] single_scattering (job/transport.h): bad values, "facets" beside components that need
// paths of depth >= 2, and on a statistical surface are errors naming the key.
TEST(Job, SingleScatteringKeyErrorsNameTheKey) {
  const std::string grating =
      "[geometry]\nkind = \"sine-grating\"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.03\n"
      "[material]\nname = \"Al\"\n[directions]\nn_theta = 8\nn_phi = 16\nincidence = [[20.0, 0.0], [75.0, 0.0]]\n"
      "[scene]\ncoherence_length_um = 50.0\n";
  for (const std::string& bad :
       {grating + "[sampling]\nsingle_scattering = \"maybe\"\n",
        grating + "[effects]\ncomponents = [\"coherent\", \"multiple\"]\n[sampling]\nsingle_scattering = \"facets\"\n",
        grating + "[effects]\ncomponents = [\"coherent\", \"lost\"]\n[sampling]\nsingle_scattering = \"facets\"\n",
        std::string("[geometry]\nkind = \"statistical\"\nndf = \"ggx\"\nalpha = 0.3\n[sampling]\nsingle_scattering = "
                    "\"facets\"\n")}) {
    const std::string e = errorOf(bad);
    EXPECT_NE(e.find("sampling.single_scattering"), std::string::npos) << bad << "\n" << e;
  }
  // With components = "auto" the planner decides multiple later: "facets" is accepted (paths are
  // used if multiple turns out to be needed).
  EXPECT_EQ(errorOf(grating + "[sampling]\nsingle_scattering = \"facets\"\n"), "");
}

TEST(Job, RepeatedWavelengthAndTexelLimitNameTheKey) {
  std::string e = errorOf("[spectrum]\nwavelengths_nm = [450.0, 550.0, 450.0]\n");
  EXPECT_NE(e.find("wavelengths_nm"), std::string::npos) << e;
  EXPECT_NE(e.find("450 nm is listed twice"), std::string::npos) << e;
  e = errorOf("[geometry]\nkind = \"gaussian\"\nsize_um = [300.0, 10.0]\ntexel_um = 0.1\n");
  EXPECT_NE(e.find("texel_um"), std::string::npos) << e;
  EXPECT_NE(e.find("at most 2048"), std::string::npos) << e;
  EXPECT_EQ(errorOf("[geometry]\nkind = \"gaussian\"\nsize_um = [204.8, 10.0]\ntexel_um = 0.1\n"), "");
}

// [output] profile, values, rounding, errors, colour: the compact profile stores XYZ where that pays and costs
// nothing (more than three visible wavelengths, no wave term halved by reciprocity), the spectrum
// otherwise; an explicit colour without visible light is an error naming the key, and an explicit
// colour turns the reciprocity halving off with the reason.
TEST(Job, StorageProfileAndItsColour) {
  const std::string eight = "[spectrum]\nwavelengths_nm = { min = 400.0, max = 700.0, count = 8 }\n";
  Job full = loadJobFromString(eight, "t.toml", "");
  EXPECT_EQ(full.storage, StorageProfile::full());
  Job compact = loadJobFromString(eight + "[output]\nprofile = \"compact\"\n", "t.toml", "");
  EXPECT_EQ(compact.storage, StorageProfile::compact());
  EXPECT_EQ(compact.storage.name(),
            "compact (values = float16, rounding = noise, errors = per-slice, colour = xyz, pairs = once)");
  Job three = loadJobFromString("[spectrum]\nwavelengths_nm = [450.0, 550.0, 650.0]\n[output]\nprofile = \"compact\"\n",
                                "t.toml", "");
  EXPECT_EQ(three.storage.colour, TableColour::Spectral);
  EXPECT_EQ(three.storage.values, TableValues::Float16);
  const std::string halved =
      eight +
      "[directions]\nn_theta = 4\nn_phi = 8\nincidence = \"all\"\n[geometry]\nkind = \"gaussian\"\nsize_um = 10.0\n"
      "rms_um = 0.3\ncorrelation_um = 1.0\n[effects]\ncomponents = [\"coherent\", \"incoherent\"]\n"
      "[sampling]\nwave_estimator = \"area\"\n";
  Job keeps = loadJobFromString(halved + "[output]\nprofile = \"compact\"\n", "t.toml", "");
  EXPECT_EQ(keeps.storage.colour, TableColour::Spectral);
  EXPECT_TRUE(keeps.halvesWaveByReciprocity());
  Job colour = loadJobFromString(halved + "[output]\nprofile = \"compact\"\ncolour = \"xyz\"\n", "t.toml", "");
  EXPECT_EQ(colour.storage.colour, TableColour::Xyz);
  EXPECT_FALSE(colour.halvesWaveByReciprocity());
  EXPECT_NE(colour.reciprocityOffReason().find("[output] colour"), std::string::npos);
  Job srgb = loadJobFromString(eight + "[output]\nvalues = \"float16\"\ncolour = \"linear-srgb\"\n", "t.toml", "");
  EXPECT_EQ(srgb.storage.name(),
            "full (values = float16, rounding = noise, errors = per-bin, colour = linear-srgb, pairs = both)");
  Job unrounded = loadJobFromString(eight + "[output]\nrounding = \"none\"\n", "t.toml", "");
  EXPECT_EQ(unrounded.storage.rounding, TableRounding::None);
  EXPECT_EQ(full.storage.rounding, TableRounding::Noise);
  const std::string infrared =
      "[material]\nkind = \"dielectric\"\nior = 1.5\n[spectrum]\nwavelengths_nm = [1000.0, 1100.0, 1200.0, 1300.0]\n";
  EXPECT_EQ(loadJobFromString(infrared + "[output]\nprofile = \"compact\"\n", "t.toml", "").storage.colour,
            TableColour::Spectral);
  EXPECT_NE(errorOf(infrared + "[output]\ncolour = \"xyz\"\n").find("output.colour"), std::string::npos);
  for (const char* bad : {"profile = \"small\"", "values = \"float64\"", "errors = \"none\"", "colour = \"rgb\"",
                          "rounding = \"lossless\""}) {
    const std::string e = errorOf(std::string("[output]\n") + bad + "\n");
    EXPECT_NE(e.find("test.toml:2"), std::string::npos) << bad << ": " << e;
  }
}

// [sampling] path_allocation: "equal-error" gives each slice of a job storing its pairs once the
// paths of scattering/path_allocation.h (the largest exactly paths_per_slice, the same in a ring);
// without pairs stored once, with progressive sampling, or an unknown value, an error names the key.
TEST(Job, PathAllocationNeedsPairsStoredOnce) {
  const std::string full =
      "[directions]\nn_theta = 6\nn_phi = 12\nincidence = \"all\"\n[sampling]\npaths_per_slice = 9000\n";
  Job uniform = loadJobFromString(full + "[output]\npairs = \"once\"\n", "t.toml", "");
  EXPECT_TRUE(uniform.slicePaths.empty());
  EXPECT_EQ(uniform.pathsFor(3), 9000u);
  Job equal = loadJobFromString(full + "path_allocation = \"equal-error\"\n[output]\npairs = \"once\"\n", "t.toml", "");
  ASSERT_EQ(equal.slicePaths.size(), equal.incidence.size());
  EXPECT_EQ(*std::max_element(equal.slicePaths.begin(), equal.slicePaths.end()), 9000u);
  EXPECT_LT(*std::min_element(equal.slicePaths.begin(), equal.slicePaths.end()), 9000u);
  for (size_t i = 0; i < equal.incidence.size(); ++i) EXPECT_EQ(equal.slicePaths[i], equal.slicePaths[i / 12 * 12]);
  EXPECT_NE(equal.describePaths().find("equal-error"), std::string::npos);
  for (const std::string& bad :
       {full + "path_allocation = \"equal-error\"\n",
        full + "path_allocation = \"equal-error\"\ntarget_rel_error = 0.05\n[output]\npairs = \"once\"\n",
        full + "path_allocation = \"by-ring\"\n[output]\npairs = \"once\"\n"}) {
    const std::string e = errorOf(bad);
    EXPECT_NE(e.find("sampling.path_allocation"), std::string::npos) << bad << "\n" << e;
    EXPECT_NE(e.find("test.toml:"), std::string::npos) << e;
  }
}

// [sampling] wave_incidence_directions_pole_horizon: the job's rule unless set; the mean incidence
// nodes per tile count each incidence at its bin's rule (an 8-ring theta-phi grid, all upper bins:
// 2 of 8 rings at n = 4, 25 nodes, and 6 at n = 2, 5 nodes); a bad value names the key.
TEST(Job, PoleAndHorizonIncidenceRule) {
  const std::string grid = "[directions]\nn_theta = 8\nn_phi = 4\nincidence = \"all\"\n";
  const Job plain = loadJobFromString(grid, "t.toml", "");
  EXPECT_EQ(plain.wavePoleHorizonIncidenceDirections, plain.waveIncidenceDirections);
  const DirectionGrid g(plain.gridLayout);
  EXPECT_DOUBLE_EQ(plain.meanIncidenceRuleNodes(g), 5.0);
  EXPECT_DOUBLE_EQ(plain.meanIncidenceRuleNodes(g, 1), 13.0);
  const Job edges = loadJobFromString(grid + "[sampling]\nwave_incidence_directions_pole_horizon = 16\n", "t.toml", "");
  EXPECT_EQ(edges.wavePoleHorizonIncidenceDirections, 16);
  EXPECT_EQ(edges.waveIncidenceDirections, 4);
  EXPECT_DOUBLE_EQ(edges.meanIncidenceRuleNodes(g), (2 * 25.0 + 6 * 5.0) / 8);
  EXPECT_DOUBLE_EQ(edges.meanIncidenceRuleNodes(g, 1), (2 * 41.0 + 6 * 13.0) / 8);
  const std::string e = errorOf("[sampling]\nwave_incidence_directions_pole_horizon = 0\n");
  EXPECT_NE(e.find("sampling.wave_incidence_directions_pole_horizon"), std::string::npos) << e;
}

// A table's material comes from the job text stored in its file: an empty text (a damaged or
// foreign file) is an error naming the source, not the default material.
TEST(Job, MaterialFromAnEmptyJobTextIsRefused) {
  EXPECT_TRUE(loadMaterialFromString("[material]\nname = \"Au\"\n", "t.h5 (job_text)").isConductor());
  try {
    loadMaterialFromString("", "t.h5 (job_text)");
    FAIL() << "an empty job text gave a material";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("t.h5 (job_text)"), std::string::npos) << e.what();
  }
}
