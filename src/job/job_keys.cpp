#include "job/job_keys.h"

#include <fmt/format.h>

#include <algorithm>

namespace mbsdf {

const std::vector<JobKey>& jobKeys() {
  using enum KeyType;
  static const std::vector<JobKey> keys = {
      {"geometry", Table, "", "", "the surface: a generated one, a mesh, a heightfield, or a statistical surface"},
      {"geometry.kind", String, "\"flat\"",
       "flat, sine-grating, binary-grating, ridged, gaussian, noise, hemispheres, axicon, overhang, mesh, heightfield, "
       "statistical",
       "which surface"},
      {"geometry.size_um", Numbers, "[20.0, 20.0]", "> 0", "patch footprint [x, y] in µm (one number: square)"},
      {"geometry.periodic", Boolean, "true", "", "rays leaving a side re-enter from the opposite side"},
      {"geometry.seed", Integer, "1", "", "seed of the random surfaces and of the ground noise"},
      {"geometry.ground_noise_rms_nm", Number, "0.0", ">= 0",
       "rms of a Gaussian displacement in z added to every vertex"},
      {"geometry.ground_noise_correlation_um", Number, "0.2", "> 0", "its correlation length"},
      {"geometry.resolution_um", Number, "kind-dependent", "> 0 (flat: >= 0)", "target mesh edge length"},
      {"geometry.period_um", Number, "5.0 (sine-grating), 2.0 (binary-grating, ridged)", "> 0", "grating period"},
      {"geometry.amplitude_um", Number, "0.05", ">= 0", "sine-grating: amplitude a of z = a sin(2πx/Λ)"},
      {"geometry.samples_per_period", Integer, "64", "> 0", "sine-grating: profile samples per period"},
      {"geometry.depth_um", Number, "0.1", "> 0", "binary-grating: ridge height"},
      {"geometry.duty", Number, "0.5", "(0, 1)", "binary-grating: ridge width over the period"},
      {"geometry.apex_angle_deg", Number, "90.0", "(0, 180)", "ridged: apex angle of the V-grooves' ridges"},
      {"geometry.rms_um", Number, "0.1 (gaussian), 0.132 (noise)", "> 0", "rms height"},
      {"geometry.correlation_um", Number, "1.0", "> 0", "gaussian: correlation length"},
      {"geometry.texel_um", Number,
       "correlation/8 (gaussian), feature/16 (noise); required for an EXR heightfield (X3P, SDF, GSF: from the file)",
       "> 0", "heightfield texel size"},
      {"geometry.feature_um", Number, "5.0", "> 0", "noise: feature size"},
      {"geometry.density", Number, "3.0", "> 0", "noise: impulses per feature area"},
      {"geometry.radius_um", Number, "2.0", "> 0", "hemispheres: radius"},
      {"geometry.spacing_um", Numbers, "5.0 (hemispheres, overhang), 1.0 (axicon)", "> 0",
       "lattice spacing (one or [x, y])"},
      {"geometry.radii_um", Numbers, "[0.4, 0.45, 0.3]", "> 0", "axicon: half-ellipsoid radii (x, y, height)"},
      {"geometry.stem_radius_um", Number, "0.8", "> 0", "overhang: stem radius"},
      {"geometry.stem_height_um", Number, "1.5", "> 0", "overhang: stem height"},
      {"geometry.cap_radius_um", Number, "2.0", "> 0", "overhang: cap radius"},
      {"geometry.cap_height_um", Number, "1.0", "> 0", "overhang: cap height"},
      {"geometry.file", String, "— (required for mesh, heightfield)", "",
       "mesh (OBJ, PLY) or heightfield file: float EXR, or a measured topography in ISO 25178-72 X3P, Surfstand SDF "
       "(text or binary) or Gwyddion GSF"},
      {"geometry.units", String, "\"um\"", "nm, um, mm, m", "mesh: length unit of the file"},
      {"geometry.height_scale", Number, "1.0", "",
       "heightfield: pixel value × scale = height in µm (X3P, SDF, GSF: "
       "height in µm × scale)"},
      {"geometry.crop_texels", Numbers, "— (the whole grid)", "inside the grid, >= 2 x 2",
       "heightfield: [first column, first row, columns, rows] of the grid to use"},
      {"geometry.level", String, "\"plane\" (X3P, SDF, GSF), \"none\" (EXR)", "none, plane, polynomial",
       "heightfield: least-squares form removed from the measured points (the stage's tilt, the sample's form)"},
      {"geometry.level_order", Integer, "2", "1 to 6", "heightfield, level = \"polynomial\": its total degree"},
      {"geometry.edges", String, "\"wrap\"", "wrap, mirror, window",
       "heightfield: how the patch repeats — as it is, mirrored into a 2(n−1)² patch, or with a border tapered to "
       "the mean height"},
      {"geometry.window_fraction", Number, "0.1", "(0, 0.5]",
       "heightfield, edges = \"window\": the taper's width "
       "on each side, as a fraction of the side"},
      {"geometry.defects", Table, "", "",
       "fabrication defects applied to the surface (any kind but statistical and overhangs): the produced "
       "variant of a designed surface, see docs/topography.md"},
      {"geometry.defects.texel_um", Number, "the heightfield's own grid", "> 0",
       "the raster the defects act on (required unless the surface is a heightfield)"},
      {"geometry.defects.depth_scale", Number, "1.0", "> 0",
       "heights scaled about the lowest point (0.95: depth −5 %)"},
      {"geometry.defects.lateral_rms_nm", Number, "0.0", ">= 0",
       "rms of a smooth random in-plane displacement (line-edge roughness)"},
      {"geometry.defects.lateral_correlation_um", Number, "0.5", "> 0", "its correlation length"},
      {"geometry.defects.sidewall_angle_deg", Number, "90.0", "(0, 90]",
       "walls at most this steep from horizontal (morphological opening by a cone)"},
      {"geometry.defects.edge_radius_um", Number, "0.0", ">= 0",
       "convex edges and concave corners rounded to this radius (opening and closing by a ball)"},
      {"geometry.ndf", String, "\"beckmann\"", "beckmann, ggx, vmf, sphere, tabulated",
       "statistical: the microflake NDF"},
      {"geometry.ndf_file", String, "—", "", "statistical, tabulated: lines theta_deg, D"},
      {"geometry.alpha", Numbers, "0.3", "(0, 100]",
       "statistical: roughness (one or [alpha_x, alpha_y]; vmf: kappa = 2/alpha²)"},
      {"geometry.kappa", Number, "—", "[0, 1e4]", "statistical, vmf: concentration"},
      {"geometry.flakes", String, "\"specular\"", "specular, diffuse", "statistical: what a flake does to light"},
      {"geometry.flake_albedo", Number, "1.0", "[0, 1]", "statistical: the flakes' albedo"},

      {"material", Table, "", "", "the lower medium; the upper one is `outside_ior`"},
      {"material.kind", String, "\"conductor\"", "conductor, dielectric", "the lower medium's kind"},
      {"material.name", String, "\"Al\" (conductor), \"BK7\" (dielectric)", "Al, Ag, Au, Cu, BK7, mirror",
       "a built-in material, unless eta/k/ior is given"},
      {"material.eta", Number, "—", "> 0", "a conductor's constant real index"},
      {"material.k", Number, "—", ">= 0", "a conductor's constant extinction coefficient"},
      {"material.ior", Number, "—", "> 0", "a dielectric's constant real index"},
      {"material.outside_ior", Number, "1.0", "> 0", "index of the upper medium"},

      {"spectrum", Table, "", "", "the wavelengths"},
      {"spectrum.wavelengths_nm", NumbersOrTable, "8 band centres over 400–700 nm", "> 0",
       "a list, or { min, max, count } (band centres)"},
      {"spectrum.wavelengths_nm.min", Number, "400", "> 0", "shortest band edge"},
      {"spectrum.wavelengths_nm.max", Number, "700", "> min", "longest band edge"},
      {"spectrum.wavelengths_nm.count", Integer, "8", "> 0", "number of bands"},

      {"directions", Table, "", "", "the direction grid and the incidences"},
      {"directions.grid", String, "\"theta-phi\"", "theta-phi, disk", "the direction grid"},
      {"directions.n_theta", Integer, "75", "> 0", "theta-phi: θ bins per hemisphere"},
      {"directions.n_phi", Integer, "300", "> 0", "theta-phi: φ bins"},
      {"directions.width", Integer, "64", "> 0", "disk: pixels across"},
      {"directions.height", Integer, "64", "> 0", "disk: pixels down"},
      {"directions.incidence", StringOrNumbers, "\"all\"", "\"all\" or [[theta_deg, phi_deg], …]", "the incidences"},
      {"directions.incidence_sampling", String, "\"bin\"", "bin, exact",
       "spread over the incidence bin, or a collimated beam"},
      {"directions.symmetry", String, "\"auto\"", "auto, none, isotropic",
       "compute part of each θ ring and rotate the rest"},

      {"scene", Table, "", "", "what the renderer needs: the light, the colour, the accuracy"},
      {"scene.coherence_length_um", Number, "50.0", ">= 0", "coherence length δc of the light"},
      {"scene.light", String, "—", "sun", "a built-in source (δc from its angular size)"},
      {"scene.source_angular_diameter_deg", Number, "—", "> 0", "a uniform disk source of this angular diameter"},
      {"scene.needs", Strings, "[\"brdf\", \"btdf\"]", "brdf, btdf", "what the renderer needs"},
      {"scene.colour", String, "\"spectral\"", "spectral, rgb", "what the renderer is fed"},
      {"scene.angular_resolution_deg", Number, "0", ">= 0", "the angular detail the renderer resolves (0: the bins)"},
      {"scene.incidence_max_deg", Number, "90", "> 0", "the largest incidence angle the renderer looks up"},
      {"scene.tolerance", Number, "0.01", "> 0", "accuracy target of components = \"auto\""},

      {"effects", Table, "", "", "which components the job computes"},
      {"effects.components", Strings, "\"auto\"", "auto, coherent, incoherent, multiple, lost",
       "\"auto\" (the effects planner decides) or a list"},
      {"effects.pilot_budget", Number, "0.5", "> 0",
       "the pilots' work at most, as a fraction of the job's computed tiles"},
      {"effects.reciprocity", Boolean, "true", "", "halve the wave term by reciprocity where the job allows it"},

      {"sampling", Table, "", "", "budgets, seeds and estimators"},
      {"sampling.paths_per_slice", Integer, "1000000", "> 0", "paths per incidence slice"},
      {"sampling.path_allocation", String, "\"uniform\"", "uniform, equal-error",
       "equal-error (pairs stored once): each slice the paths for the error of the one the fold helps least"},
      {"sampling.target_rel_error", Number, "0", "[0, 1)", "progressive sampling's target (0: a fixed budget)"},
      {"sampling.max_paths_per_slice", Integer, "16 × paths_per_slice", ">= paths_per_slice",
       "progressive sampling's budget"},
      {"sampling.max_depth", Integer, "100", "[1, 1e6]", "bounces before a path is cut"},
      {"sampling.seed", Integer, "1", "", "seed of the path tracer's and wave estimators' random numbers"},
      {"sampling.wave_estimator", String, "\"auto\"", "auto, area, orders, exact, fft, paper", "the wave estimator"},
      {"sampling.wave_samples_per_bin", Integer, "256", "[1, 1e9]", "Kirchhoff samples per exit bin"},
      {"sampling.wave_points_per_direction", Integer, "64", "[2, 1e9]", "area: surface points per exit direction"},
      {"sampling.visibility_table", String, "\"auto\"", "auto, on, off",
       "exact: the shared table of first-level masking rays"},
      {"sampling.single_scattering", String, "\"auto\"", "auto, paths, facets",
       "how single scattering is computed without deeper paths"},
      {"sampling.wave_incidence_directions", Integer, "4", "[1, 1e6]",
       "bin-averaged: n x n Gauss-Legendre incidence nodes per bin, n^2 >= this"},
      {"sampling.wave_incidence_directions_pole_horizon", Integer, "wave_incidence_directions", "[1, 1e6]",
       "the same for the incidence bins that reach normal incidence or the horizon (a theta-phi grid's first "
       "and last rings, a disk grid's centre pixels and those its rim cuts), where the bin's average "
       "converges slowest"},
      {"sampling.wave_subdirections", Integer, "16", "16, 32, …, 512",
       "exact, fft, bin-averaged: sub-directions per axis of the incidence bin"},

      {"output", Table, "", "", "the output file"},
      {"output.path", String, "\"out.h5\"", "", "output HDF5 file (-o overrides it)"},
      {"output.previews", Boolean, "false", "", "validated; previews come from `microbsdf slice`"},
      {"output.profile", String, "\"full\"", "full, compact",
       "how the tables are stored: full (float32, per-bin errors, spectral, pairs both ways) or compact "
       "(float16, errors per slice, XYZ colour, pairs once); both round values to their noise"},
      {"output.values", String, "the profile's", "float32, float16",
       "table values: float32, or float16 scaled per slice and wavelength"},
      {"output.rounding", String, "\"noise\"", "noise, none",
       "noise: each value keeps the binary digits above 1/16 of its standard error and each error 8 "
       "significant bits (the quickstart's tables: 0.37 of their size); none: every bit"},
      {"output.colour", String, "the profile's", "spectral, xyz, linear-srgb",
       "tables per wavelength, or their colour (CIE 1931 XYZ or linear sRGB; the conversion is in the file)"},
      {"output.pairs", String, "the profile's", "once, both",
       "incidence = \"all\": each same-side bin pair stored once, the mean of both estimates, or both ways"},
      {"output.errors", String, "the profile's", "per-bin, per-slice",
       "standard errors: a table per component, or only the per-slice statistics"},
  };
  return keys;
}

const JobKey* findJobKey(std::string_view path) {
  for (const JobKey& k : jobKeys())
    if (k.path == path) return &k;
  return nullptr;
}

namespace {
size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

std::string_view sectionOf(std::string_view path) {
  const size_t dot = path.rfind('.');
  return dot == std::string_view::npos ? std::string_view() : path.substr(0, dot);
}
}  // namespace

std::string nearestJobKey(std::string_view path) {
  std::string_view best;
  size_t bestDistance = std::max<size_t>(2, path.size() / 3) + 1;  // a typo, not another word
  for (const JobKey& k : jobKeys()) {
    if (sectionOf(k.path) != sectionOf(path)) continue;
    const size_t d = editDistance(k.path, path);
    if (d < bestDistance) bestDistance = d, best = k.path;
  }
  return std::string(best);
}

std::string_view keyTypeName(KeyType t) {
  switch (t) {
    case KeyType::Table:
      return "table";
    case KeyType::String:
      return "string";
    case KeyType::Strings:
      return "string or [strings]";
    case KeyType::Number:
      return "number";
    case KeyType::Numbers:
      return "number or [numbers]";
    case KeyType::Integer:
      return "integer";
    case KeyType::Boolean:
      return "boolean";
    case KeyType::StringOrNumbers:
      return "string or [[numbers]]";
    case KeyType::NumbersOrTable:
      return "[numbers] or table";
  }
  return "?";
}

std::string jobKeysMarkdown() {
  std::string out = "| key | type | default | accepted | meaning |\n|---|---|---|---|---|\n";
  for (const JobKey& k : jobKeys()) {
    if (k.type == KeyType::Table) continue;
    out += fmt::format("| `{}` | {} | {} | {} | {} |\n", k.path, keyTypeName(k.type),
                       k.defaultText.empty() ? "—" : k.defaultText, k.range.empty() ? "any" : k.range, k.meaning);
  }
  return out;
}

std::string jobKeysText() {
  std::string out;
  for (const JobKey& k : jobKeys()) {
    if (k.type == KeyType::Table) {
      out += fmt::format("[{}]  {}\n", k.path, k.meaning);
      continue;
    }
    out += fmt::format("  {:<36} {:<22} default {}{}\n      {}\n", k.path, keyTypeName(k.type),
                       k.defaultText.empty() ? "—" : k.defaultText,
                       k.range.empty() ? "" : "; accepted: " + std::string(k.range), k.meaning);
  }
  return out;
}

}  // namespace mbsdf
