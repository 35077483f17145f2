#include "job/geometry_factory.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <stdexcept>

#include "core/error.h"
#include "geometry/fabrication_defects.h"
#include "geometry/generators.h"
#include "geometry/mesh_loader.h"
#include "geometry/topography.h"
#include "geometry/topography_stats.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace mbsdf {

std::string resolvePath(const std::string& base, const std::string& file) {
  std::filesystem::path p(file);
  if (p.is_absolute() || base.empty()) return file;
  return (std::filesystem::path(base) / p).string();
}

namespace {

double gMaxGeneratedTriangles = 1e7;
// The [geometry] table of a job, read kind by kind; every check fails naming the key.
struct GeometryReader {
  const ParamDict& geo;
  const std::string& baseDir;
  uint64_t seed;
  double groundRms_um, groundCorr;
  TopographyReport* topographyOut;
  double maxTriangles = maxGeneratedTriangles();

  std::vector<double> size2(const std::vector<double>& def) const {
    std::vector<double> s = geo.getDoubles("size_um", def);
    if (s.size() == 1) s.push_back(s[0]);
    if (s.size() != 2) geo.fail("size_um", "expected [x, y] in micrometres");
    if (!(s[0] > 0 && s[1] > 0)) geo.fail("size_um", "the patch size must be positive");
    return s;
  }
  std::vector<double> pair2(const std::string& key, double def) const {
    std::vector<double> s = geo.getDoubles(key, {def, def});
    if (s.size() == 1) s.push_back(s[0]);
    if (s.size() != 2 || !(s[0] > 0 && s[1] > 0)) geo.fail(key, "expected one or two positive numbers");
    return s;
  }
  // Texels per side of a generated heightfield: at most 2048 (the cell limit), an error naming the
  // key rather than a silently coarser texel.
  int texels(double size, double texel) const {
    if (std::ceil(size / texel) > 2048)
      geo.fail("texel_um", fmt::format("{} µm / {} µm = {} texels per side; at most 2048 (use a larger texel_um or a "
                                       "smaller size_um)",
                                       size, texel, std::ceil(size / texel)));
    return gridSizeFor(size, texel);
  }
  // Generators throw std::invalid_argument for inconsistent shapes; report them against the key
  // most likely responsible.
  template <typename Fn>
  Microgeometry guard(const std::string& key, Fn&& fn) const {
    try {
      return fn();
    } catch (const std::invalid_argument& e) {
      geo.fail(key, e.what());
    }
  }
  // Impossible sizes fail here, before anything is allocated (found by fuzz_job: a tiny
  // resolution_um made a hemispheres patch of billions of triangles).
  void budget(const std::string& key, double triangles) const {
    if (!(triangles <= maxTriangles))
      geo.fail(key, fmt::format("would generate about {:.3g} triangles (limit {:.3g}); use a coarser resolution or "
                                "a smaller patch",
                                triangles, maxTriangles));
  }
  static double rings(double length, double res) { return std::max(2.0, std::ceil(length / res)); }

  Microgeometry flat() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double res = geo.getDouble("resolution_um", groundRms_um > 0 ? groundCorr / 2 : 0.0);
    if (res < 0) geo.fail("resolution_um", "must be >= 0");
    if (res > 0) budget("resolution_um", 2 * rings(s[0], res) * rings(s[1], res));
    g = makeFlat(s[0], s[1], res);
    return g;
  }
  Microgeometry sineGrating() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double period = geo.positive("period_um", 5.0), amp = geo.nonNegative("amplitude_um", 0.05);
    int64_t spp = geo.positiveInt("samples_per_period", 64);
    double res = geo.getDouble("resolution_um", groundRms_um > 0 ? groundCorr / 2 : 0.0);
    if (res < 0) geo.fail("resolution_um", "must be >= 0");
    budget("samples_per_period", 2.0 * double(spp) * std::ceil(s[0] / period) * (res > 0 ? rings(s[1], res) : 1));
    g = guard("period_um", [&] { return makeSineGrating(s[0], s[1], period, amp, spp, res); });
    return g;
  }
  Microgeometry binaryGrating() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double period = geo.positive("period_um", 2.0), depth = geo.positive("depth_um", 0.1);
    double duty = geo.getDouble("duty", 0.5);
    if (!(duty > 0 && duty < 1)) geo.fail("duty", "must be in (0, 1)");
    double res = geo.getDouble("resolution_um", groundRms_um > 0 ? groundCorr / 2 : 0.0);
    if (res < 0) geo.fail("resolution_um", "must be >= 0");
    budget("period_um",
           10.0 * std::ceil(s[0] / period) * (res > 0 ? rings(s[1], res) * rings(period + 2 * depth, res) : 1));
    g = guard("period_um", [&] { return makeBinaryGrating(s[0], s[1], period, depth, duty, res); });
    return g;
  }
  Microgeometry ridged() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double period = geo.positive("period_um", 2.0);
    double apex = geo.getDouble("apex_angle_deg", 90.0);
    if (!(apex > 0 && apex < 180)) geo.fail("apex_angle_deg", "must be in (0, 180)");
    double res = geo.getDouble("resolution_um", groundRms_um > 0 ? groundCorr / 2 : 0.0);
    if (res < 0) geo.fail("resolution_um", "must be >= 0");
    budget("period_um", 4.0 * std::ceil(s[0] / period) *
                            (res > 0 ? rings(s[1], res) * rings(period / std::sin(radians(apex / 2)), res) : 1));
    g = guard("period_um", [&] { return makeRidged(s[0], s[1], period, apex, res); });
    return g;
  }
  Microgeometry gaussian() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double rms = geo.positive("rms_um", 0.1), corr = geo.positive("correlation_um", 1.0);
    double texel = geo.positive("texel_um", corr / 8);
    g = makeGaussian(s[0], s[1], rms, corr, texels(s[0], texel), texels(s[1], texel), seed);
    return g;
  }
  Microgeometry noise() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double rms = geo.positive("rms_um", 0.132), feature = geo.positive("feature_um", 5.0);
    double density = geo.positive("density", 3.0), texel = geo.positive("texel_um", feature / 16);
    if (!(density * s[0] * s[1] / (kPi * feature * feature) <= 1e7))
      geo.fail("density", "would place more than 1e7 noise impulses on the patch");
    g = makeNoise({.size_um = {s[0], s[1]},
                   .rms_um = rms,
                   .feature_radius_um = feature,
                   .density_per_um2 = density,
                   .texels = {texels(s[0], texel), texels(s[1], texel)},
                   .seed = seed});
    return g;
  }
  Microgeometry hemispheres() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double r = geo.positive("radius_um", 2.0);
    auto sp = pair2("spacing_um", 5.0);
    double res = geo.positive("resolution_um", r / 16);
    budget("resolution_um", 2 * std::ceil(s[0] / sp[0]) * std::ceil(s[1] / sp[1]) * rings(2 * kPi * r, res) *
                                (rings(std::max(sp[0], sp[1]), res) + rings(0.5 * kPi * r, res)));
    g = guard("spacing_um", [&] {
      return makeDomeLattice(
          {.size_um = {s[0], s[1]}, .spacing_um = {sp[0], sp[1]}, .radii_um = {r, r, r}, .resolution_um = res});
    });
    return g;
  }
  Microgeometry axicon() const {
    Microgeometry g;
    auto s = size2({10.0, 10.0});
    std::vector<double> radii = geo.getDoubles("radii_um", {0.4, 0.45, 0.3});
    if (radii.size() != 3 || !(radii[0] > 0 && radii[1] > 0 && radii[2] > 0))
      geo.fail("radii_um", "expected three positive radii [rx, ry, height]");
    auto sp = pair2("spacing_um", 1.0);
    double res = geo.positive("resolution_um", std::min(radii[0], radii[1]) / 16);
    const double rmax = std::max({radii[0], radii[1], radii[2]});
    budget("resolution_um", 2 * std::ceil(s[0] / sp[0]) * std::ceil(s[1] / sp[1]) * rings(2 * kPi * rmax, res) *
                                (rings(std::max(sp[0], sp[1]), res) + rings(0.5 * kPi * rmax, res)));
    g = guard("spacing_um", [&] {
      return makeDomeLattice({.size_um = {s[0], s[1]},
                              .spacing_um = {sp[0], sp[1]},
                              .radii_um = {radii[0], radii[1], radii[2]},
                              .resolution_um = res});
    });
    return g;
  }
  Microgeometry overhang() const {
    Microgeometry g;
    auto s = size2({20.0, 20.0});
    double sp = geo.positive("spacing_um", 5.0);
    double stemR = geo.positive("stem_radius_um", 0.8), stemH = geo.positive("stem_height_um", 1.5);
    double capR = geo.positive("cap_radius_um", 2.0), capH = geo.positive("cap_height_um", 1.0);
    double res = geo.positive("resolution_um", capR / 16);
    budget("resolution_um",
           2 * std::ceil(s[0] / sp) * std::ceil(s[1] / sp) * rings(2 * kPi * capR, res) *
               (rings(sp, res) + rings(stemH, res) + rings(capR, res) + rings(0.5 * kPi * std::max(capR, capH), res)));
    g = guard("cap_radius_um", [&] {
      return makeOverhang({.size_um = {s[0], s[1]},
                           .spacing_um = sp,
                           .stem_radius_um = stemR,
                           .stem_height_um = stemH,
                           .cap_radius_um = capR,
                           .cap_height_um = capH,
                           .resolution_um = res});
    });
    return g;
  }
  Microgeometry mesh() const {
    Microgeometry g;
    std::string file = geo.getString("file", "");
    if (file.empty()) geo.fail("file", "a mesh geometry needs file = \"patch.obj\" or \"patch.ply\"");
    double scale = unitToMicrometres(geo.getString("units", "um"), geo.where("units"));
    g = loadMesh(resolvePath(baseDir, file), scale);
    // The footprint of the vertices the triangles use (a stray vertex must not enlarge it).
    double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
    for (const auto& tri : g.triangles)
      for (uint32_t i : tri) {
        const Vec3& v = g.vertices[i];
        x0 = std::min(x0, v.x);
        x1 = std::max(x1, v.x);
        y0 = std::min(y0, v.y);
        y1 = std::max(y1, v.y);
      }
    if (g.triangles.empty()) geo.fail("file", "the mesh " + file + " has no faces");
    auto s = size2({g.sizeX, g.sizeY});
    // Centre the footprint on the origin (float precision in Embree).
    Vec3 c{(x0 + x1) / 2, (y0 + y1) / 2, 0};
    for (auto& v : g.vertices) v = v - c;
    g.sizeX = s[0];
    g.sizeY = s[1];
    g.description = "mesh " + file;
    return g;
  }
  Microgeometry heightfield() const {
    std::string file = geo.getString("file", "");
    if (file.empty()) geo.fail("file", "a heightfield geometry needs file = \"height.exr\" (or .x3p, .sdf, .gsf)");
    const std::string path = resolvePath(baseDir, file);
    const bool measured = isTopographyFile(path);
    Topography t;
    if (measured) {
      if (geo.has("texel_um")) geo.fail("texel_um", "the texel of " + file + " is in the file; remove texel_um");
      t = loadTopography(path);
      for (const std::string& w : t.warnings) spdlog::warn("{}", w);
    } else {
      if (!geo.has("texel_um")) geo.fail("texel_um", "a heightfield needs its texel size in micrometres");
      t = loadTopographyExr(path, geo.positive("texel_um", 1.0));
    }
    const double scale = geo.getDouble("height_scale", 1.0);
    for (double& z : t.z_um) z *= scale;
    TopographyConditioning c;
    if (geo.has("crop_texels")) {
      const std::vector<double> v = geo.getDoubles("crop_texels", {});
      if (v.size() != 4 ||
          std::any_of(v.begin(), v.end(), [](double x) { return x != std::floor(x) || std::abs(x) > 1e9; }))
        geo.fail("crop_texels", "expected [first column, first row, columns, rows] as whole numbers");
      c.crop = std::array<int, 4>{int(v[0]), int(v[1]), int(v[2]), int(v[3])};
    }
    // Measured maps are levelled by default, as metrology software does before any analysis; an EXR
    // is taken as the heights it holds.
    c.level = parseLevelling(geo.getString("level", measured ? "plane" : "none"), geo.where("level"));
    c.levelOrder = int(geo.getInt("level_order", 2));
    c.edges = parseEdgeTreatment(geo.getString("edges", "wrap"), geo.where("edges"));
    c.windowFraction = geo.getDouble("window_fraction", 0.1);
    TopographyReport report;
    t = conditionTopography(std::move(t), c, geo.where("file"), &report.conditioning);
    if (report.conditioning.filled)
      spdlog::info("{}: {} of {} points were not measured; filled by Laplace interpolation", file,
                   report.conditioning.filled, t.size());
    if (const TopographyStats stats = topographyStats(t, false); c.edges == EdgeTreatment::Wrap && stats.seamStands())
      spdlog::warn(
          "{}: the patch's opposite edges do not meet (steps across the wrap {:.3g} x and {:.3g} x the "
          "inside ones in x and y); they scatter as a ridge. [geometry] edges = \"mirror\" or \"window\" "
          "makes the patch continuous",
          file, stats.seamRatioX, stats.seamRatioY);
    Microgeometry g = heightfieldMesh(t.z_um, t.nx, t.ny, t.dx_um * t.nx, t.dy_um * t.ny);
    g.description = "heightfield " + file;
    if (topographyOut) {
      report.heights = std::make_shared<const Topography>(std::move(t));
      *topographyOut = std::move(report);
    }
    return g;
  }
};

// [geometry.defects]: the surface as produced (geometry/fabrication_defects.h).
Microgeometry withDefects(const Microgeometry& designed, const ParamDict& d, uint64_t seed,
                          TopographyReport* topographyOut) {
  FabricationDefects f;
  f.texel_um = d.nonNegative("texel_um", 0.0);
  f.depthScale = d.positive("depth_scale", 1.0);
  f.lateralRms_um = d.nonNegative("lateral_rms_nm", 0.0) * 1e-3;
  f.lateralCorrelation_um = d.positive("lateral_correlation_um", 0.5);
  f.sidewallAngle_deg = d.getDouble("sidewall_angle_deg", 90.0);
  if (!(f.sidewallAngle_deg > 0 && f.sidewallAngle_deg <= 90)) d.fail("sidewall_angle_deg", "must be in (0, 90]");
  f.edgeRadius_um = d.nonNegative("edge_radius_um", 0.0);
  f.seed = seed;
  // The raster is meshed: it obeys the generators' triangle limit.
  if (f.texel_um > 0) {
    const double triangles = 2 * std::round(designed.sizeX / f.texel_um) * std::round(designed.sizeY / f.texel_um);
    if (triangles > maxGeneratedTriangles())
      d.fail("texel_um", fmt::format("a raster of {} µm on the {} x {} µm patch makes {:.3g} triangles; at most {:.3g}",
                                     f.texel_um, designed.sizeX, designed.sizeY, triangles, maxGeneratedTriangles()));
  }
  Topography t = rasteriseHeights(designed, f.texel_um, d.where("texel_um"));
  f.texel_um = std::min(t.dx_um, t.dy_um);
  applyFabricationDefects(t, f, d.file() + ": [geometry.defects]");
  Microgeometry g = heightfieldMesh(t.z_um, t.nx, t.ny, t.dx_um * t.nx, t.dy_um * t.ny);
  g.description = designed.description + ", as produced: " + f.describe();
  spdlog::info("{}: [geometry.defects] {}", d.file(), f.describe());
  if (topographyOut) topographyOut->heights = std::make_shared<const Topography>(std::move(t));
  return g;
}

}  // namespace

double maxGeneratedTriangles() {
  return gMaxGeneratedTriangles;
}
void setMaxGeneratedTriangles(double n) {
  gMaxGeneratedTriangles = n;
}

Microgeometry buildMicrogeometry(const ParamDict& geo, const std::string& baseDir, std::string* kindOut,
                                 TopographyReport* topographyOut) {
  const std::string kind = geo.getString("kind", "flat");
  *kindOut = kind;
  const uint64_t seed = uint64_t(geo.getInt("seed", 1));
  const bool periodic = geo.getBool("periodic", true);
  const double groundRms_um = geo.nonNegative("ground_noise_rms_nm", 0.0) * 1e-3;
  const double groundCorr = groundRms_um > 0 ? geo.positive("ground_noise_correlation_um", 0.2) : 0.2;
  const GeometryReader reader{geo, baseDir, seed, groundRms_um, groundCorr, topographyOut};
  using Kind = Microgeometry (GeometryReader::*)() const;
  static const std::map<std::string, Kind> kinds = {
      {"flat", &GeometryReader::flat},
      {"sine-grating", &GeometryReader::sineGrating},
      {"binary-grating", &GeometryReader::binaryGrating},
      {"ridged", &GeometryReader::ridged},
      {"gaussian", &GeometryReader::gaussian},
      {"noise", &GeometryReader::noise},
      {"hemispheres", &GeometryReader::hemispheres},
      {"axicon", &GeometryReader::axicon},
      {"overhang", &GeometryReader::overhang},
      {"mesh", &GeometryReader::mesh},
      {"heightfield", &GeometryReader::heightfield},
  };
  const auto it = kinds.find(kind);
  if (it == kinds.end())
    geo.fail("kind", "unknown geometry kind '" + kind +
                         "' (flat, sine-grating, binary-grating, ridged, gaussian, noise, hemispheres, axicon, "
                         "overhang, mesh, heightfield)");
  Microgeometry g = (reader.*(it->second))();
  if (geo.has("defects")) g = withDefects(g, geo.table("defects"), seed, topographyOut);
  g.periodic = periodic;
  if (groundRms_um > 0) {
    addGroundNoise(g, groundRms_um, groundCorr, seed);
    // The heights reported (and written by `check --heights`) are the ones meshed, noise included.
    if (topographyOut && topographyOut->heights)
      if (const auto grid = heightGridOf(g)) {
        auto t = std::make_shared<Topography>(*topographyOut->heights);
        t->z_um = grid->h;
        topographyOut->heights = t;
      }
  }
  if (size_t removed = g.removeDegenerate())
    spdlog::warn("{}: removed {} degenerate (zero-area) triangles", geo.where("kind"), removed);
  if (size_t removed = g.removeDuplicates())
    spdlog::warn(
        "{}: removed {} repeated triangles (the same three corners as an earlier one), which would "
        "scatter twice",
        geo.where("kind"), removed);
  g.validate(geo.file() + ": [geometry]");
  return g;
}

}  // namespace mbsdf
