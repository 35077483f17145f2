#include "job/job.h"

#include "core/colour.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/file_digest.h"
#include "geometry/lattice_cell.h"
#include "job/geometry_factory.h"
#include "job/params.h"
#include "job/symmetry.h"
#include "scattering/coherence_window.h"
#include "scattering/fft_estimator.h"
#include "scattering/path_allocation.h"
#include "scattering/visibility_table.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
namespace {

Material parseMaterial(const ParamDict& m, std::string* nameOut) {
  Material mat;
  std::string kind = m.getString("kind", "conductor");
  if (kind != "conductor" && kind != "dielectric") m.fail("kind", "must be \"conductor\" or \"dielectric\"");
  // Default material: aluminium for a conductor, BK7 for a dielectric (unless an index is given).
  std::string name =
      m.getString("name", m.has("eta") || m.has("k") || m.has("ior") ? "" : (kind == "conductor" ? "Al" : "BK7"));
  if (!name.empty()) {
    if (!builtinMaterial(name, &mat)) {
      std::string list;
      for (auto& n : builtinMaterialNames()) list += (list.empty() ? "" : ", ") + n;
      m.fail("name", "unknown material '" + name + "' (built in: " + list + ")");
    }
    if ((kind == "conductor") != mat.isConductor())
      m.fail("kind", "material '" + name + "' is a " + (mat.isConductor() ? "conductor" : "dielectric"));
    if (m.has("ior") || m.has("eta") || m.has("k")) m.fail("name", "give either name or ior/eta/k, not both");
    *nameOut = name;
  } else if (kind == "dielectric") {
    if (!m.has("ior")) m.fail("ior", "a dielectric needs name = \"BK7\" or ior = <index>");
    double n = m.positive("ior", 1.5);
    mat.model = Dielectric{ConstantIndex{n, 0.0}};
    *nameOut = "ior " + std::to_string(n);
  } else {
    if (!m.has("eta") || !m.has("k"))
      m.fail(m.has("eta") ? "k" : "eta", "a conductor needs name = \"Al\" (or Ag, Au, Cu, mirror) or both eta and k");
    double eta = m.positive("eta", 1.0), k = m.nonNegative("k", 0.0);
    mat.model = Conductor{ConstantIndex{eta, k}};
    *nameOut = "eta " + std::to_string(eta) + " k " + std::to_string(k);
  }
  mat.outsideIor = m.positive("outside_ior", 1.0);
  return mat;
}

std::vector<double> parseWavelengths(const ParamDict& s) {
  std::vector<double> l;
  const toml::node* n = s.node("wavelengths_nm");
  if (!n) {
    for (int i = 0; i < 8; ++i) l.push_back(400.0 + (i + 0.5) * 300.0 / 8);  // 8 bands over 400–700 nm
    return l;
  }
  if (n->is_table()) {
    ParamDict t = s.table("wavelengths_nm");
    double lo = t.positive("min", 400), hi = t.positive("max", 700);
    int64_t count = t.positiveInt("count", 8);
    if (count > 100000) t.fail("count", "must be at most 100000");
    if (hi < lo) t.fail("max", "must be >= min");
    for (int64_t i = 0; i < count; ++i) l.push_back(lo + (i + 0.5) * (hi - lo) / double(count));
    return l;
  }
  l = s.getDoubles("wavelengths_nm", {});
  if (l.empty()) s.fail("wavelengths_nm", "needs at least one wavelength");
  if (l.size() > 100000) s.fail("wavelengths_nm", "at most 100000 wavelengths");
  for (double v : l)
    if (!(v > 0)) s.fail("wavelengths_nm", "wavelengths must be positive (nm)");
  // Each wavelength once: a repeated one would be a second column of the same spectrum (and the
  // colour conversion integrates over distinct samples).
  std::vector<double> sorted = l;
  std::sort(sorted.begin(), sorted.end());
  if (auto d = std::adjacent_find(sorted.begin(), sorted.end()); d != sorted.end())
    s.fail("wavelengths_nm", fmt::format("{} nm is listed twice; each wavelength once", *d));
  return l;
}

// An isotropic NDF table: one "theta_deg, D" pair per line (comma or whitespace separated; '#'
// comments), θ from the normal, any range in [0, 180], D in any scale (normalised by Eq. 17).
TabulatedNdf loadNdfTable(const ParamDict& geo, const std::string& baseDir) {
  const std::string name = geo.getString("ndf_file", "");
  if (name.empty()) geo.fail("ndf_file", "ndf = \"tabulated\" needs ndf_file = <table of theta_deg, D>");
  std::filesystem::path path(name);
  if (!path.is_absolute() && !baseDir.empty()) path = std::filesystem::path(baseDir) / path;
  std::ifstream in(path);
  if (!in) geo.fail("ndf_file", "cannot read '" + path.string() + "'");
  std::vector<std::pair<double, double>> rows;
  std::string line;
  for (int lineNo = 1; std::getline(in, line); ++lineNo) {
    if (auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream ls(line);
    double th, d;
    if (!(ls >> th)) continue;  // blank or comment
    std::string rest;
    if (!(ls >> d) || (ls >> rest) || !(th >= 0 && th <= 180) || !(d >= 0) || !std::isfinite(d))
      throw InputError(path.string() + ":" + std::to_string(lineNo) +
                       ": expected 'theta_deg, D' with theta in [0, 180] and D >= 0");
    if (!rows.empty() && !(th > rows.back().first))
      throw InputError(path.string() + ":" + std::to_string(lineNo) + ": theta must increase from line to line");
    rows.push_back({th, d});
  }
  if (rows.size() < 2) throw InputError(path.string() + ": an NDF table needs at least two rows");
  TabulatedNdf t;
  for (auto it = rows.rbegin(); it != rows.rend(); ++it) {  // increasing cos θ
    t.cosTheta.push_back(std::cos(radians(it->first)));
    t.value.push_back(it->second);
  }
  try {
    normaliseNdfTable(t);  // normals above the horizon
  } catch (const std::invalid_argument& e) {
    throw InputError(path.string() + ": " + e.what());
  }
  return t;
}

StatisticalSurface parseStatistical(const ParamDict& geo, const std::string& baseDir) {
  StatisticalSurface st;
  const std::string ndf = geo.getString("ndf", "beckmann");
  auto alphas = [&]() {
    std::vector<double> a = geo.getDoubles("alpha", {0.3});
    if (a.size() == 1) a.push_back(a[0]);
    if (a.size() != 2 || !(a[0] > 0 && a[1] > 0 && a[0] <= 100 && a[1] <= 100))
      geo.fail("alpha", "expected one or two roughnesses in (0, 100] ([alpha_x, alpha_y])");
    return a;
  };
  if (ndf == "beckmann") {
    auto a = alphas();
    st.ndf = BeckmannNdf{a[0], a[1]};
  } else if (ndf == "ggx") {
    auto a = alphas();
    st.ndf = GgxNdf{a[0], a[1]};
  } else if (ndf == "vmf") {
    if (geo.has("alpha") == geo.has("kappa"))
      geo.fail("kappa", "the vmf NDF needs either kappa or alpha (kappa = 2/alpha²)");
    double kappa = geo.has("kappa") ? geo.nonNegative("kappa", 0.0) : 2.0 / std::pow(geo.positive("alpha", 1.0), 2);
    if (!(kappa <= 1e4)) geo.fail(geo.has("kappa") ? "kappa" : "alpha", "kappa must be at most 1e4 (alpha >= 0.0142)");
    st.ndf = VonMisesFisherNdf{kappa};
  } else if (ndf == "sphere") {
    st.ndf = VonMisesFisherNdf{0.0};
  } else if (ndf == "tabulated") {
    st.ndf = loadNdfTable(geo, baseDir);
  } else {
    geo.fail("ndf", "must be \"beckmann\", \"ggx\", \"vmf\", \"sphere\" (constant full-sphere NDF) or \"tabulated\"");
  }
  const std::string flakes = geo.getString("flakes", "specular");
  if (flakes == "specular")
    st.flakes = FlakeKind::Specular;
  else if (flakes == "diffuse")
    st.flakes = FlakeKind::Diffuse;
  else
    geo.fail("flakes", "must be \"specular\" (the material's interface) or \"diffuse\" (Lambertian)");
  st.flakeAlbedo = geo.nonNegative("flake_albedo", 1.0);
  if (st.flakeAlbedo > 1) geo.fail("flake_albedo", "must be in [0, 1]");
  return st;
}

// [directions]: the grid, the incidences and how they are sampled.
void parseDirections(const ParamDict& dirs, Job& job) {
  std::string gridKind = dirs.getString("grid", "theta-phi");
  // Bins per hemisphere at most 2.5e7 (the paper's resolution is 22,500): beyond that the tables do
  // not fit in memory, and the products would overflow (found by fuzz_job).
  constexpr int64_t kMaxBins = 25000000;
  if (gridKind == "theta-phi") {
    int64_t nt = dirs.positiveInt("n_theta", 75), np = dirs.positiveInt("n_phi", 300);
    if (nt > kMaxBins || np > kMaxBins || nt * np > kMaxBins)
      dirs.fail(nt > np ? "n_theta" : "n_phi", "n_theta x n_phi must be at most 2.5e7 bins per hemisphere");
    job.gridLayout = ThetaPhiGrid{int(nt), int(np)};
  } else if (gridKind == "disk") {
    int64_t w = dirs.positiveInt("width", 64), h = dirs.positiveInt("height", 64);
    if (w > kMaxBins || h > kMaxBins || w * h > kMaxBins)
      dirs.fail(w > h ? "width" : "height", "width x height must be at most 2.5e7 pixels per hemisphere");
    job.gridLayout = DiskGrid{int(w), int(h)};
  } else {
    dirs.fail("grid", "must be \"theta-phi\" or \"disk\"");
  }
  DirectionGrid grid(job.gridLayout);
  const toml::node* inc = dirs.node("incidence");
  const bool dielectric = !job.material.isConductor();
  if (!inc || (inc->is_string() && *inc->value<std::string>() == "all")) {
    job.incidenceAll = true;
    int nb = dielectric ? grid.binCount() : grid.binsPerHemisphere();
    for (int b = 0; b < nb; ++b) {
      if (grid.projectedSolidAngle(b) <= 0) continue;
      Vec3 c = grid.centre(b);
      job.incidence.push_back({degrees(sphericalTheta(c)), degrees(sphericalPhi(c)), b});
    }
  } else if (const toml::array* a = inc->as_array()) {
    for (const auto& e : *a) {
      const toml::array* pair = e.as_array();
      if (!pair || pair->size() != 2 || !(*pair)[0].value<double>() || !(*pair)[1].value<double>())
        dirs.fail("incidence", "expected \"all\" or a list of [theta_deg, phi_deg] pairs");
      double th = *(*pair)[0].value<double>(), ph = *(*pair)[1].value<double>();
      double maxTheta = dielectric ? 180.0 : 90.0;
      if (!(th >= 0 && th <= maxTheta) || !std::isfinite(ph))
        dirs.fail("incidence",
                  "theta_deg must be in [0, " + std::to_string(int(maxTheta)) + "] (" +
                      (dielectric ? "> 90 is light from inside the material" : "light from above a conductor") + ")");
      job.incidence.push_back({th, ph, grid.binOfAngles(th, ph)});
    }
    if (job.incidence.empty()) dirs.fail("incidence", "needs at least one direction");
  } else {
    dirs.fail("incidence", "expected \"all\" or a list of [theta_deg, phi_deg] pairs");
  }

  std::string incSampling = dirs.getString("incidence_sampling", "bin");
  if (incSampling != "bin" && incSampling != "exact") dirs.fail("incidence_sampling", "must be \"bin\" or \"exact\"");
  job.exactIncidence = incSampling == "exact";
}

// [scene]: what the renderer needs (coherence, BRDF/BTDF, tolerance, resolution, colour, the
// incidences it looks up).
void parseScene(const ParamDict& scene, Job& job) {
  job.scene.coherenceLength_um = scene.nonNegative("coherence_length_um", 50.0);
  if (scene.has("light") || scene.has("source_angular_diameter_deg")) {
    // A disk source -> coherence length at the mean wavelength (van Cittert–Zernike, coherence_window.h).
    for (const char* k : {"coherence_length_um", "source_angular_diameter_deg"})
      if (scene.has("light") && scene.has(k)) scene.fail(k, "give the light source or its coherence, not both");
    if (scene.has("coherence_length_um"))
      scene.fail("coherence_length_um", "give either coherence_length_um or source_angular_diameter_deg");
    double diameter = 0;
    if (scene.has("light")) {
      const std::string light = scene.getString("light", "");
      if (light != "sun")
        scene.fail("light", "unknown light '" + light + "' (built in: \"sun\"; or give source_angular_diameter_deg)");
      diameter = kSunAngularDiameter_deg;
      job.scene.coherenceSource = "light = \"sun\"";
    } else {
      diameter = scene.positive("source_angular_diameter_deg", 1.0);
      if (!(diameter < 180)) scene.fail("source_angular_diameter_deg", "must be below 180");
      job.scene.coherenceSource = "source_angular_diameter_deg";
    }
    job.scene.sourceAngularDiameter_deg = diameter;
    job.scene.coherenceLength_um = coherenceLengthOfDiskSource(radians(diameter), job.meanLambda_um());
  }
  job.scene.needs = scene.getStrings("needs", {"brdf", "btdf"});
  for (auto& n : job.scene.needs)
    if (n != "brdf" && n != "btdf") scene.fail("needs", "entries must be \"brdf\" or \"btdf\"");
  job.scene.tolerance = scene.positive("tolerance", 0.01);
  job.scene.angularResolution_deg = scene.nonNegative("angular_resolution_deg", 0.0);
  const std::string colour = scene.getString("colour", "spectral");
  if (colour != "spectral" && colour != "rgb") scene.fail("colour", "must be \"spectral\" or \"rgb\"");
  job.scene.colour = colour == "rgb" ? SceneNeeds::Colour::Rgb : SceneNeeds::Colour::Spectral;
  if (!(job.scene.angularResolution_deg <= 90)) scene.fail("angular_resolution_deg", "must be in [0, 90]");
  // The incidences the renderer will look up: with incidence = "all", bins farther than this from
  // the normal on their side (light from above: θ; from inside a dielectric: 180° − θ) are not
  // computed. Whole θ rings go, so symmetry and reciprocity still apply (an exit bin that is no
  // longer an incidence bin is computed by the tile itself, reciprocity.h).
  job.scene.incidenceMax_deg = scene.positive("incidence_max_deg", 90.0);
  if (!(job.scene.incidenceMax_deg <= 90)) scene.fail("incidence_max_deg", "must be in (0, 90]");
  {
    auto fromNormal = [](double theta_deg) { return theta_deg <= 90 ? theta_deg : 180 - theta_deg; };
    if (job.incidenceAll) {
      std::erase_if(job.incidence,
                    [&](const IncidenceDirection& d) { return fromNormal(d.theta_deg) > job.scene.incidenceMax_deg; });
      if (job.incidence.empty())
        scene.fail("incidence_max_deg", "leaves no incidence bin (the bin centres nearest the normal lie farther out)");
    } else {
      for (const auto& d : job.incidence)
        if (fromNormal(d.theta_deg) > job.scene.incidenceMax_deg + 1e-9)
          scene.fail("incidence_max_deg", "the listed incidence theta_deg = " + fmt::format("{:g}", d.theta_deg) +
                                              " lies beyond it (remove one or the other)");
    }
  }
}

// [effects]: the components asked for ("auto": the effects planner decides), reciprocity, the pilot budget.
void parseEffects(const ParamDict& eff, Job& job) {
  job.requestedComponents = eff.getStrings("components", {"auto"});
  for (const auto& c : job.requestedComponents) {
    if (c == "auto") {
      // The effects planner decides before the run (effects_planner.h); until then the candidates
      // are the paper's full model WM.
      job.autoComponents = true;
      job.components.add(Component::Coherent);
      job.components.add(Component::Incoherent);
      job.components.add(Component::Multiple);
      continue;
    }
    auto comp = componentFromName(c);
    if (!comp || *comp == Component::GeoMasked)
      eff.fail("components", "unknown component '" + c + "' (auto, coherent, incoherent, multiple, lost)");
    job.components.add(*comp);
  }

  job.reciprocity = eff.getBool("reciprocity", true);
  job.pilotBudget = eff.positive("pilot_budget", 0.5);
}

// [output] profile, values, rounding, errors, pairs, colour: how the tables are stored
// (core/storage_profile.h); the profile names a preset, the other keys override it.
void parseStorageProfile(const ParamDict& out, Job& job) {
  // The value of `key` among `names` (its index), `fallback` when absent; another value is an error
  // naming the key and listing the names.
  auto choice = [&out](const char* key, std::initializer_list<const char*> names, int fallback) {
    if (!out.has(key)) return fallback;
    const std::string v = out.getString(key, "");
    int k = 0;
    for (const char* n : names) {
      if (v == n) return k;
      ++k;
    }
    std::string list;
    for (const char* n : names) list += (list.empty() ? "\"" : ", \"") + std::string(n) + "\"";
    out.fail(key, "must be one of " + list);
  };
  job.storage = choice("profile", {"full", "compact"}, 0) == 1 ? StorageProfile::compact() : StorageProfile::full();
  StorageProfile& s = job.storage;
  s.values = TableValues(choice("values", {"float32", "float16"}, int(s.values)));
  s.rounding = TableRounding(choice("rounding", {"noise", "none"}, int(s.rounding)));
  s.errors = TableErrors(choice("errors", {"per-bin", "per-slice"}, int(s.errors)));
  s.pairs = TablePairs(choice("pairs", {"both", "once"}, int(s.pairs)));
  s.colour = TableColour(choice("colour", {"spectral", "xyz", "linear-srgb"}, int(s.colour)));
}

// The colour of the tables, once the job is known: a colour needs visible wavelengths (an explicit
// one is an error without them). The compact profile's XYZ is kept only where it pays and costs
// nothing: more than three wavelengths, and no wave term that reciprocity would halve (the
// mirrored half needs spectral tables); otherwise that profile stores the spectrum.
void resolveStorageColour(const ParamDict& out, Job& job) {
  // Pairs of incidence bins exist with every bin of a side as an incidence (incidence = "all") and
  // bin-averaged incidence (a bin-centre beam is not reciprocal bin to bin).
  if (job.storage.pairs == TablePairs::Once && (!job.incidenceAll || job.exactIncidence)) {
    if (out.has("pairs"))
      out.fail("pairs", job.exactIncidence ? "\"once\" needs bin-averaged incidence (incidence_sampling = \"exact\" "
                                             "is not reciprocal bin to bin)"
                                           : "\"once\" needs incidence = \"all\" (pairs of incidence bins)");
    job.storage.pairs = TablePairs::Both;
  }
  if (job.storage.spectral()) return;
  bool visible = true;
  try {
    SpectrumToColour check(job.lambda_nm);
  } catch (const std::invalid_argument&) {
    visible = false;
  }
  if (out.has("colour")) {
    if (!visible) out.fail("colour", "the job's wavelengths hold no visible light: there is no colour to store");
    return;
  }
  if (!visible || job.lambda_nm.size() <= 3) {
    job.storage.colour = TableColour::Spectral;
    return;
  }
  job.storage.colour = TableColour::Spectral;
  const bool halves = job.halvesWaveByReciprocity();
  if (!halves) job.storage.colour = TableColour::Xyz;
}

// [sampling]: budgets, seeds and estimators.
void parseSampling(const ParamDict& samp, Job& job) {
  job.pathsPerSlice = uint64_t(samp.positiveInt("paths_per_slice", 1000000));
  const std::string allocation = samp.getString("path_allocation", "uniform");
  if (allocation != "uniform" && allocation != "equal-error")
    samp.fail("path_allocation", "must be \"uniform\" or \"equal-error\"");
  job.pathAllocation = allocation == "equal-error" ? Job::PathAllocation::EqualError : Job::PathAllocation::Uniform;
  job.targetRelError = samp.nonNegative("target_rel_error", 0.0);
  if (!(job.targetRelError < 1)) samp.fail("target_rel_error", "must be a fraction in (0, 1), or 0 for a fixed budget");
  {
    const int64_t maxPaths =
        samp.positiveInt("max_paths_per_slice", int64_t(std::min<uint64_t>(job.pathsPerSlice * 16, uint64_t(1) << 50)));
    if (uint64_t(maxPaths) < job.pathsPerSlice) samp.fail("max_paths_per_slice", "must be >= paths_per_slice");
    if (job.targetRelError == 0 && samp.has("max_paths_per_slice"))
      samp.fail("max_paths_per_slice", "is the budget of progressive sampling: set target_rel_error too");
    job.maxPathsPerSlice = uint64_t(maxPaths);
  }
  auto bounded = [&](const std::string& key, int64_t def, int64_t max) {
    int64_t v = samp.positiveInt(key, def);
    if (v > max) samp.fail(key, "must be at most " + std::to_string(max));
    return v;
  };
  job.maxDepth = int(bounded("max_depth", 100, 1000000));
  job.seed = uint64_t(samp.getInt("seed", 1));
  if (const std::string e = samp.getString("wave_estimator", "auto"); e != "auto") {
    job.waveEstimator = parseWaveEstimator(e);
    if (!job.waveEstimator)
      samp.fail("wave_estimator", "must be \"auto\", \"area\", \"orders\", \"exact\", \"fft\" or \"paper\"");
  }
  job.waveSamplesPerBin = bounded("wave_samples_per_bin", 256, 1000000000);
  job.wavePointsPerDirection = bounded("wave_points_per_direction", 64, 1000000000);
  if (job.wavePointsPerDirection < 2) samp.fail("wave_points_per_direction", "must be >= 2 (pairwise estimator)");
  job.waveIncidenceDirections = bounded("wave_incidence_directions", 4, 1000000);
  job.wavePoleHorizonIncidenceDirections =
      bounded("wave_incidence_directions_pole_horizon", job.waveIncidenceDirections, 1000000);
  job.waveSubdirections = bounded("wave_subdirections", kDefaultSubdirections, kMaxSubdirections);
  if (job.waveSubdirections < kMinSubdirections || !std::has_single_bit(uint64_t(job.waveSubdirections)))
    samp.fail("wave_subdirections", "must be a power of two from " + std::to_string(kMinSubdirections) + " to " +
                                        std::to_string(kMaxSubdirections));
  const std::string single = samp.getString("single_scattering", "auto");
  if (single != "auto" && single != "paths" && single != "facets")
    samp.fail("single_scattering", "must be \"auto\", \"paths\" or \"facets\"");
  job.singleScattering = single == "paths"    ? Job::SingleScatteringMode::Paths
                         : single == "facets" ? Job::SingleScatteringMode::Facets
                                              : Job::SingleScatteringMode::Auto;
  const std::string table = samp.getString("visibility_table", "auto");
  if (table != "auto" && table != "on" && table != "off")
    samp.fail("visibility_table", "must be \"auto\", \"on\" or \"off\"");
  job.visibilityTable = table == "on"    ? Job::VisibilityTableMode::On
                        : table == "off" ? Job::VisibilityTableMode::Off
                                         : Job::VisibilityTableMode::Auto;
}

// Every vertex within 1e6 µm (1 m) of the origin. Embree traces in single precision and asserts on
// bounds it cannot represent (heights of 5e28 µm, a finite EXR of 1e30 × height_scale 0.05, abort
// it); a surface patch of that size is a unit or scale error.
void checkCoordinates(const ParamDict& geo, const char* shapeKey, const Microgeometry& g) {
  constexpr double kMaxCoordinate_um = 1e6;
  for (size_t i = 0; i < g.vertices.size(); ++i) {
    const Vec3& v = g.vertices[i];
    const double m = std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
    if (!(m <= kMaxCoordinate_um))
      geo.fail(shapeKey, fmt::format("vertex {} lies at ({:.4g}, {:.4g}, {:.4g}) µm, beyond the 1e6 µm (1 m) a surface "
                                     "patch can span: check the file's units, height_scale or size_um",
                                     i, v.x, v.y, v.z));
  }
}

// [geometry]: a statistical surface (its NDF) or explicit microgeometry, and the input files it reads.
void parseGeometry(const ParamDict& geo, const ParamDict& eff, const std::string& baseDir,
                   const std::string& sourceName, Job& job) {
  if (geo.getString("kind", "flat") == "statistical") {
    job.geometryKind = "statistical";
    job.statistical = parseStatistical(geo, baseDir);
    if (!job.material.isConductor() && job.statistical->flakes == FlakeKind::Specular &&
        !isHeightfieldNdf(job.statistical->ndf))
      geo.fail("ndf",
               "dielectric flakes need a heightfield NDF (beckmann or ggx): the walk continues on the "
               "other side of the surface");
    for (const auto& c : job.requestedComponents)
      if (c == "incoherent" || c == "lost")
        eff.fail("components",
                 "a statistical surface has no explicit geometry for scalar diffraction: use "
                 "coherent (single scattering) and multiple");
    // "auto" is GM here (no explicit geometry for diffraction); explicit requests are already parsed.
    if (std::find(job.requestedComponents.begin(), job.requestedComponents.end(), "auto") !=
        job.requestedComponents.end()) {
      job.components = ComponentSet{};
      job.components.add(Component::Coherent);
      job.components.add(Component::Multiple);
    }
    if (std::holds_alternative<TabulatedNdf>(job.statistical->ndf)) {
      const std::string path = resolvePath(baseDir, geo.getString("ndf_file", ""));
      job.inputFiles.push_back({"geometry.ndf_file", path, sha256OfFile(path)});
    }
  } else {
    TopographyReport topography;
    job.geometry = buildMicrogeometry(geo, baseDir, &job.geometryKind, &topography);
    if (topography.heights) job.topography = std::move(topography);
    const char* shapeKey = geo.has("file") ? "file" : "kind";
    checkCoordinates(geo, shapeKey, job.geometry);
    job.closure = surfaceClosureOf(job.geometry);
    // A face wound the other way faces the other medium: it would take the upper medium's light as
    // the lower's (a flat square with one face turned reflected 0.38 instead of 0.92).
    if (job.closure.windingEdges)
      geo.fail(shapeKey, "the triangles are not wound consistently: " + job.closure.describe() +
                             "; turn the faces that face the other way");
    // One interface between two media projects onto its footprint once; more is a second sheet
    // (a copy of the surface, overlapping parts), whose light the model would count twice.
    if (job.closure.coveredMoreThanOnce())
      geo.fail(shapeKey,
               fmt::format("the triangles cover the footprint {:.4g} times (their signed projected area over the "
                           "footprint's): overlapping or repeated sheets, where one surface between two media "
                           "covers it once",
                           1 - job.closure.uncoveredFraction));
    if (!job.closure.closed() || job.closure.unusedVertices)
      spdlog::warn("{}: [geometry] {}: {}{}", sourceName, job.geometryKind, job.closure.describe(),
                   job.closure.closed() ? "" : "; light through the holes is counted as missed, not scattered");
    if (job.geometryKind == "mesh" || job.geometryKind == "heightfield") {
      const std::string path = resolvePath(baseDir, geo.getString("file", ""));
      job.inputFiles.push_back({"geometry.file", path, sha256OfFile(path)});
    }
  }
}

// single_scattering = "facets" needs a closed periodic patch and no paths to trace.
void checkSingleScattering(const ParamDict& samp, const Job& job) {
  if (job.singleScattering == Job::SingleScatteringMode::Facets) {
    const bool autoComponents = std::find(job.requestedComponents.begin(), job.requestedComponents.end(), "auto") !=
                                job.requestedComponents.end();
    if (job.statistical || !job.geometry.periodic)
      samp.fail("single_scattering", "\"facets\" needs explicit periodic geometry");
    if (!job.closure.closed())
      samp.fail("single_scattering", "\"facets\" needs a closed surface; the patch has " + job.closure.describe());
    if (!autoComponents && (job.components.has(Component::Multiple) || job.components.has(Component::Lost)))
      samp.fail("single_scattering", "\"facets\" computes single scattering only: multiple and lost need paths");
  }
}

// [directions] symmetry: declared or detected, and why it is (not) used.
void decideSymmetry(const ParamDict& dirs, const std::string& symmetry, Job& job) {
  // Azimuthal symmetry (symmetry.h): declared, or detected for a statistical surface whose NDF is
  // isotropic; it needs a theta-phi grid and incidence = "all" to have rings to reduce.
  {
    const bool isotropicNdf =
        job.statistical && std::visit(
                               [](const auto& n) {
                                 using T = std::decay_t<decltype(n)>;
                                 if constexpr (std::is_same_v<T, BeckmannNdf> || std::is_same_v<T, GgxNdf>)
                                   return n.alphaX == n.alphaY;
                                 else
                                   return true;  // von Mises–Fisher and tabulated D(cos θm) are isotropic
                               },
                               job.statistical->ndf);
    const bool wanted = symmetry == "isotropic" || (symmetry == "auto" && isotropicNdf);
    if (symmetry == "isotropic" && job.statistical && !isotropicNdf)
      dirs.fail("symmetry", "the surface's NDF is anisotropic (alpha_x != alpha_y)");
    // Explicit geometry: detect rotation (4- or 2-fold) and mirror symmetry of the patch (symmetry.h),
    // only where the job could use it (the check maps every facet and may build an Embree scene).
    const auto* tp = std::get_if<ThetaPhiGrid>(&job.gridLayout);
    const bool reducible = tp && job.incidenceAll;
    const PatchSymmetry ps =
        symmetry == "auto" && !job.statistical && reducible ? patchSymmetryOf(job.geometry) : PatchSymmetry{};
    const int order = ps.rotationOrder;
    const bool found = order > 1 || ps.mirror;
    // The table is isotropic whether or not the run can use it: say so first (the exporters write
    // one incidence azimuth for a `symmetry` that starts with "isotropic").
    if (wanted && !tp)
      job.symmetryReason =
          "isotropic surface; the reduction is not used: needs a theta-phi grid (its rings map onto themselves "
          "under rotation)";
    else if (wanted && !job.incidenceAll)
      job.symmetryReason = "isotropic surface; the reduction is not used: needs incidence = \"all\"";
    else if (symmetry == "auto" && !job.statistical && !reducible)
      job.symmetryReason = "not checked: needs a theta-phi grid and incidence = \"all\"";
    else if (wanted)
      job.isotropic = true, job.symmetryReason = symmetry == "isotropic" ? "declared isotropic ([directions] symmetry)"
                                                                         : "detected: the surface's NDF is isotropic";
    else if (found) {
      std::string what;
      if (order > 1 && tp->nPhi % order == 0) {
        job.rotationOrder = order;
        what = "rotation by " + std::to_string(360 / order) + " degrees";
      } else if (order > 1) {
        what = "(rotation by " + std::to_string(360 / order) + " degrees unused: n_phi = " + std::to_string(tp->nPhi) +
               " is not a multiple of " + std::to_string(order) + ")";
      }
      if (ps.mirror) {
        job.mirrorSymmetric = true;
        what += std::string(what.empty() ? "" : " and ") + "the mirror y -> -y";
      }
      job.symmetryReason = (job.symmetryReduced() ? "detected: the patch is invariant under " : "not used: ") + what;
    } else
      job.symmetryReason = symmetry == "none" ? "none ([directions] symmetry = \"none\")" : "none declared or detected";
  }
}

// [sampling] path_allocation = "equal-error": the paths per slice, once the pairs' storage is known.
void allocateSlicePaths(const ParamDict& samp, Job& job) {
  if (job.pathAllocation != Job::PathAllocation::EqualError) return;
  // It trades the paths of the slices the fold helps for an equal error: without the fold there is
  // nothing to trade, and progressive sampling decides each slice's paths itself.
  if (job.storage.pairs != TablePairs::Once)
    samp.fail("path_allocation",
              "\"equal-error\" needs [output] pairs = \"once\" (it shares the paths by what the fold of each pair "
              "gives a slice; storing both ways, every slice has the error of its own paths)");
  if (job.targetRelError > 0)
    samp.fail("path_allocation", "\"equal-error\" and target_rel_error both decide the paths per slice: set one");
  job.slicePaths = job.equalErrorSlicePaths();
}

// The lattice cell a windowed wave term uses, and whether a named wave estimator applies.
void checkWaveTerm(const ParamDict& samp, Job& job) {
  // The lattice cell, where a windowed wave term could use it (it maps every facet a few times).
  if (!job.statistical && job.geometry.periodic && job.scene.coherenceLength_um > 0 &&
      (job.needsWave() || job.autoComponents)) {
    const LatticeCell cell = latticeCellOf(job.geometry);
    job.cellNx = cell.nx;
    job.cellNy = cell.ny;
  }
  using enum WaveEstimatorKind;
  const std::optional<WaveEstimatorKind> named = job.waveEstimator;
  if ((named == Orders || named == Exact || named == Fft) && !job.statistical &&
      !(job.geometry.periodic && job.scene.coherenceLength_um > 0))
    samp.fail("wave_estimator", "\"" + waveEstimatorName(*named) +
                                    "\" needs a periodic patch and a coherence window (scene.coherence_length_um > 0)");
  if (named == Fft && !job.statistical) {
    const std::string why =
        fftUnsuitable(job.geometry, job.material, job.lambda_um(), windowSigma(job.scene.coherenceLength_um),
                      job.components.has(Component::Lost));
    if (!why.empty()) samp.fail("wave_estimator", "\"fft\" " + why);
  }
}

}  // namespace

Material loadMaterialFromString(const std::string& text, const std::string& sourceName) {
  const ParamDict root = ParamDict::parseString(text, sourceName);
  // A job's text holds at least one key (loadJobFromString): an empty one is damaged or foreign,
  // and the defaults would pass for its material.
  if (root.empty()) throw InputError(sourceName + ": holds no job text, so the table's material is unknown");
  std::string name;
  return parseMaterial(root.table("material"), &name);
}

Job loadJobFromString(const std::string& text, const std::string& sourceName, const std::string& baseDir) {
  ParamDict root = ParamDict::parseString(text, sourceName);
  // Every key has a default, so an empty file would be a whole job (a flat mirror over 22,500
  // incidences); a file with no key at all is far more often a truncated copy or the wrong file.
  if (root.empty())
    throw InputError(sourceName + ": the job file holds no key; a job needs at least one (e.g. [geometry] kind)");
  Job job;
  job.file = sourceName;
  job.text = text;

  ParamDict mat = root.table("material");
  job.material = parseMaterial(mat, &job.materialName);

  ParamDict spec = root.table("spectrum");
  job.lambda_nm = parseWavelengths(spec);
  auto [lo, hi] = job.material.validRange_nm();
  for (double l : job.lambda_nm)
    if (l < lo || l > hi)
      spec.fail("wavelengths_nm", fmt::format("wavelength {:g} nm is outside the table of material {} ({:g}–{:g} nm)",
                                              l, job.material.describe(), lo, hi));

  // The sections in the order their checks depend on each other (the incidences need the material;
  // the scene, the wavelengths and incidences; the geometry's checks, the components).
  ParamDict dirs = root.table("directions");
  parseDirections(dirs, job);
  const std::string symmetry = dirs.getString("symmetry", "auto");
  if (symmetry != "auto" && symmetry != "none" && symmetry != "isotropic")
    dirs.fail("symmetry", "must be \"auto\", \"none\" or \"isotropic\"");
  ParamDict scene = root.table("scene");
  parseScene(scene, job);
  ParamDict eff = root.table("effects");
  parseEffects(eff, job);
  ParamDict samp = root.table("sampling");
  parseSampling(samp, job);

  ParamDict out = root.table("output");
  job.outputPath = out.getString("path", "out.h5");
  if (job.outputPath.empty()) out.fail("path", "must not be empty");
  job.previews = out.getBool("previews", false);
  parseStorageProfile(out, job);

  ParamDict geo = root.table("geometry");
  parseGeometry(geo, eff, baseDir, sourceName, job);
  checkSingleScattering(samp, job);
  decideSymmetry(dirs, symmetry, job);
  checkWaveTerm(samp, job);
  resolveStorageColour(out, job);
  allocateSlicePaths(samp, job);

  root.reportUnused();
  return job;
}

WaveEstimatorKind Job::resolvedWaveEstimator() const {
  return waveEstimator ? *waveEstimator : staticWaveEstimator();
}

WaveEstimatorKind Job::staticWaveEstimator() const {
  const double sigma = windowSigma(scene.coherenceLength_um);
  if (geometry.periodic && orderLobesSeparate(sigma, cellSizeX(), cellSizeY())) {
    // The deterministic `exact` has no sampling error, and costs about as much as 8–12 points of
    // `orders` per facet of the cell (its first-level visibility points, the split pieces and the
    // facet integral; measured in the accuracy study: the 5 µm sine grating's 128 facets as about
    // 2^9.5 points, the hemisphere cell's 1 624 as about 2^14): chosen where it costs no more than
    // `orders` at the job's own budget (wave_samples_per_bin points).
    return 8 * facetsPerCell() <= double(waveSamplesPerBin) ? WaveEstimatorKind::Exact : WaveEstimatorKind::Orders;
  }
  // Overlapping lobes on a small cell (a flat or few-facet surface): `exact` sums every order a bin
  // holds, 8 points per facet and order in the unit above. Chosen where that costs at most 16 times
  // the Monte Carlo budget, which buys a Monte Carlo estimator only a quarter of its error (1/√N):
  // a flat mirror's Kirchhoff integral is then exact, where 256 samples per bin of `area` give ten
  // units of noise on a unit albedo.
  if (geometry.periodic && scene.coherenceLength_um > 0 &&
      8 * facetsPerCell() * std::max(1.0, exactOrdersPerBin()) <= 16 * double(waveSamplesPerBin))
    return WaveEstimatorKind::Exact;
  // Overlapping lobes (speckle) on a heightfield with a disk grid: the deterministic Fourier-domain
  // evaluator (no masked field, size within its limit), whose separable evaluation there is fast;
  // Monte Carlo over such speckle needs far more samples (docs/accuracy.md). On
  // other grids its direct sum over the orders in the window's reach can cost more than the Monte
  // Carlo budget (large bins against a small speckle), so it is chosen explicitly there.
  if (std::holds_alternative<DiskGrid>(gridLayout) &&
      fftUnsuitable(geometry, material, lambda_um(), sigma, components.has(Component::Lost)).empty())
    return WaveEstimatorKind::Fft;
  return WaveEstimatorKind::Area;
}

double Job::exactOrdersPerBin() const {
  // Propagating orders are A_cell / λ² per unit of projected solid angle (the reciprocal lattice in
  // direction cosines); a bin holds π / (bins per hemisphere) of it. The shortest wavelength has most.
  const std::vector<double> lambdas = lambda_um();
  const double lambda = *std::min_element(lambdas.begin(), lambdas.end());
  const int bins = DirectionGrid(gridLayout).binsPerHemisphere();
  return kPi / std::max(1, bins) * cellSizeX() * cellSizeY() / (lambda * lambda);
}

std::string Job::waveEstimatorChoice() const {
  if (waveEstimatorPlanned) {
    // The planner keeps the static pick where it meets the tolerance: then say why it was picked.
    const std::string planned = "chosen by the effects planner: " + *waveEstimatorPlanned;
    return staticWaveEstimator() == *waveEstimator ? planned + "; " + staticWaveEstimatorReason() : planned;
  }
  if (waveEstimator) return "named by the job";
  return staticWaveEstimatorReason();
}

std::string Job::staticWaveEstimatorReason() const {
  const WaveEstimatorKind e = staticWaveEstimator();
  if (deterministicEstimator(e))
    return fmt::format("chosen as deterministic: {:.3g} facets per cell, {:.3g} orders per bin", facetsPerCell(),
                       exactOrdersPerBin());
  if (!geometry.periodic || !(scene.coherenceLength_um > 0))
    return "chosen as Monte Carlo: the deterministic estimators need a periodic patch and a coherence window";
  return fmt::format(
      "chosen as Monte Carlo: `exact` would cost {:.3g} points per bin ({:.3g} facets per cell x {:.3g} orders), "
      "against {} samples; its errors are its own estimate",
      8 * facetsPerCell() * std::max(1.0, exactOrdersPerBin()), facetsPerCell(), exactOrdersPerBin(),
      waveSamplesPerBin);
}

std::optional<std::string> Job::waveErrorsCaveat() const {
  if (!needsWave()) return std::nullopt;
  const WaveEstimatorKind e = resolvedWaveEstimator();
  if (deterministicEstimator(e)) return std::nullopt;
  if (e == WaveEstimatorKind::Paper)
    return std::string(
        "the `paper` estimator stores its bias estimate (Var/P) as the error, not a standard error of f_ws");
  // Elsewhere the Monte Carlo estimators' errors hold, under a collimated beam and over incidence
  // bins alike (WaveHonesty: mean z² against `exact` 0.58-2.3 on flat interfaces, a sine grating
  // and a dome lattice).
  return std::nullopt;
}

int Job::incidenceRuleNodesAt(const DirectionGrid& grid, int bin, int extraOrders) const {
  // The estimators' own choice of rule (incidenceDirectionsOf), from the job's two keys.
  WaveSettings ws;
  ws.incidenceDirections = int(waveIncidenceDirections);
  ws.poleHorizonIncidenceDirections = int(wavePoleHorizonIncidenceDirections);
  return incidenceRuleNodes(incidenceRuleOrder(incidenceDirectionsOf(ws, grid, bin)) + extraOrders);
}

double Job::meanIncidenceRuleNodes(const DirectionGrid& grid, int extraOrders) const {
  if (incidence.empty()) return 0;
  double sum = 0;
  for (const IncidenceDirection& inc : incidence) sum += incidenceRuleNodesAt(grid, inc.bin, extraOrders);
  return sum / double(incidence.size());
}

int Job::visibilityTableResolution() const {
  constexpr int M = 128;
  if (visibilityTable == VisibilityTableMode::Off || statistical || resolvedWaveEstimator() != WaveEstimatorKind::Exact)
    return 0;
  if (visibilityTable == VisibilityTableMode::On) return M;
  const double hemispheres = material.isConductor() ? 1 : 2;
  if (VisibilityTable::bytesFor(size_t(facetsPerCell()), M, !material.isConductor()) > 1e9) return 0;
  const double nodes = exactIncidence ? 1.0 : meanIncidenceRuleNodes(DirectionGrid(gridLayout));
  double orders = 0;
  for (double l : lambda_um()) orders += kPi * cellSizeX() * cellSizeY() / (l * l);
  // Measured on the paper's HEMISPHERES (one 5 µm cell, 550 nm): the table answers about 3/4 of
  // the first-level masking queries and a tile's time falls by about 20 %; the break-even is near
  // twice the ray ratio.
  const double saved = double(incidence.size()) * nodes * orders, cost = 2 * (M + 1.0) * (M + 1.0) * hemispheres;
  return saved >= cost ? M : 0;
}

std::string Job::reciprocityOffReason() const {
  if (!components.has(Component::Incoherent)) return "no wave term";
  if (!reciprocity) return "[effects] reciprocity = false";
  if (guarded.has(Component::Incoherent))
    return "diffraction was skipped and is verified slice by slice (a slice's check cannot come from its "
           "reciprocal partner)";
  if (symmetryReduced()) return "symmetry reduction: part of each ring is computed, the other slices are rotations";
  if (!incidenceAll) return "incidence is a list of directions, not \"all\"";
  if (exactIncidence) return "incidence_sampling = \"exact\" (bin-centre beams are not reciprocal bin to bin)";
  if (components.has(Component::Lost)) return "the lost component needs the masked power of every exit bin";
  if (const WaveEstimatorKind e = resolvedWaveEstimator();
      e != WaveEstimatorKind::Area && e != WaveEstimatorKind::Paper)
    return "the " + waveEstimatorName(e) + " estimator's cost is per incidence sample, not per exit bin";
  if (!storage.spectral())
    return "[output] colour: the mirrored half's per-wavelength energies need the spectral tables, which a colour "
           "file does not keep";
  return "";
}

std::vector<uint64_t> Job::equalErrorSlicePaths() const {
  return mbsdf::equalErrorSlicePaths(DirectionGrid(gridLayout), incidenceBins(), !material.isConductor(),
                                     pathsPerSlice);
}

double Job::meanSlicePaths() const {
  if (slicePaths.empty()) return double(pathsPerSlice);
  double sum = 0;
  for (uint64_t n : slicePaths) sum += double(n);
  return sum / double(slicePaths.size());
}

std::string Job::describePaths() const {
  if (slicePaths.empty()) return std::to_string(pathsPerSlice) + " paths per slice";
  const auto [lo, hi] = std::minmax_element(slicePaths.begin(), slicePaths.end());
  return fmt::format("{} to {} paths per slice (mean {:.0f}; path_allocation = \"equal-error\")", *lo, *hi,
                     meanSlicePaths());
}

Job loadJob(const std::string& path) {
  ParamDict probe = ParamDict::parseFile(path);  // reads the file (errors name it)
  std::string base = std::filesystem::path(path).parent_path().string();
  return loadJobFromString(probe.sourceText(), path, base);
}

}  // namespace mbsdf
