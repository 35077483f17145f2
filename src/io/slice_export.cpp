#include "io/slice_export.h"

#include "io/output_target.h"

#include <spdlog/fmt/fmt.h>

#include <optional>
#include <set>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <fstream>
#include <stdexcept>

#include "core/colour.h"
#include "core/error.h"
#include "io/colour_bar.h"
#include "io/exr_image.h"
#include "io/png_image.h"
#include "scattering/components.h"

namespace mbsdf {

Colour3 falseColour(double t) {
  // Viridis (van der Walt & Smith, matplotlib), 9 control points, linear in between.
  static const double kStops[9][3] = {{68, 1, 84},    {71, 44, 122}, {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
                                      {39, 173, 129}, {92, 200, 99}, {170, 220, 50}, {253, 231, 37}};
  t = std::clamp(t, 0.0, 1.0) * 8;
  int k = std::min(7, int(t));
  double u = t - k;
  Colour3 c;
  for (int i = 0; i < 3; ++i) c[i] = ((1 - u) * kStops[k][i] + u * kStops[k + 1][i]) / 255.0;
  return c;
}

double srgbEncode(double linear) {
  linear = std::clamp(linear, 0.0, 1.0);
  return linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1 / 2.4) - 0.055;
}

std::vector<double> modelSlice(const BsdfFileReader& file, const std::string& model, int incidence,
                               std::vector<double>* stdError) {
  auto comps = modelComponents(model);
  if (!comps) throw std::invalid_argument("unknown model '" + model + "' (GS, GM, WS, WM or a component name)");
  auto have = file.components();
  std::vector<double> sum, var;
  bool binErrors = stdError != nullptr;
  for (Component c : *comps) binErrors = binErrors && file.hasBinErrors(componentName(c));
  for (Component c : *comps) {
    std::string name = componentName(c);
    if (std::find(have.begin(), have.end(), name) == have.end())
      throw std::invalid_argument("model " + model + " needs component '" + name + "', which the file does not hold");
    auto v = file.slice(name, incidence);
    if (sum.empty()) {
      sum.assign(v.size(), 0.0);
      var.assign(v.size(), 0.0);
    }
    for (size_t i = 0; i < v.size(); ++i) sum[i] += v[i];
    if (!binErrors) continue;
    auto e = file.sliceStdError(name, incidence);
    for (size_t i = 0; i < v.size(); ++i) var[i] += e[i] * e[i];
  }
  if (stdError && !binErrors) {
    stdError->clear();  // the file keeps its errors per slice (its storage profile)
  } else if (stdError) {
    stdError->resize(var.size());
    for (size_t i = 0; i < var.size(); ++i) (*stdError)[i] = std::sqrt(var[i]);
  }
  return sum;
}

std::vector<std::string> availableModels(const BsdfFileReader& file) {
  const auto have = file.components();
  const std::set<std::string> comps(have.begin(), have.end());
  std::vector<std::string> models;
  for (const char* m : {"GS", "GM", "WS", "WM"}) {
    const std::vector<Component> need = *modelComponents(m);  // a named copy: no dangling temporary
    bool ok = true;
    for (Component c : need) ok = ok && comps.count(componentName(c));
    if (ok) models.push_back(m);
  }
  return models;
}

namespace {
// Per pixel of the disk projection (W x S, W = 2S with `both`): the spectrum of the bin it falls in
// (NaN outside the disk).
std::vector<double> diskSpectra(const BsdfFileReader& file, const std::vector<double>& f, const SliceRequest& req) {
  const DirectionGrid& grid = file.grid();
  const int nL = file.channelCount(), nB = grid.binCount();
  const int S = req.size, W = req.both ? 2 * S : S;
  std::vector<double> spec(size_t(W) * S * nL, std::nan(""));
  for (int j = 0; j < S; ++j)
    for (int i = 0; i < W; ++i) {
      const bool trans = req.both ? i >= S : req.transmission;
      const int ii = i % S;
      double x = -1 + 2.0 * (ii + 0.5) / S, y = 1 - 2.0 * (j + 0.5) / S;
      double r2 = x * x + y * y;
      if (r2 > 1) continue;
      double z = std::sqrt(1 - r2);
      int b = grid.binOf({x, y, trans ? -z : z});
      for (int l = 0; l < nL; ++l) spec[(size_t(j) * W + i) * nL + l] = f[size_t(l) * nB + b];
    }
  return spec;
}

// The PNG picture of a model table f (nλ x nBins) of the file.
RgbImage sliceImage(const BsdfFileReader& file, const std::vector<double>& f, const SliceRequest& req) {
  const int nL = file.channelCount();
  const int S = req.size, W = req.both ? 2 * S : S;
  // True colour needs visible wavelengths; false colour (log2 of the spectral mean, or of Y for a
  // table stored in colour) works for any.
  std::optional<SpectrumToColour> colour;
  if (req.style != "false" || !file.spectral()) colour.emplace(file.toColour());
  checkFalseColourRange(req);
  const std::vector<double> spec = diskSpectra(file, f, req);
  const int bar = req.style == "false" ? colourBarHeight(S) : 0;
  RgbImage img;
  img.width = W;
  img.height = S + bar;
  img.rgb.assign(size_t(img.width) * img.height * 3, 0);
  auto put = [&](int i, int j, const Colour3& c) {
    for (int k = 0; k < 3; ++k)
      img.rgb[(size_t(j) * W + i) * 3 + k] = uint8_t(std::lround(std::clamp(c[k], 0.0, 1.0) * 255));
  };
  for (int j = 0; j < S; ++j)
    for (int i = 0; i < W; ++i) {
      const double* v = &spec[(size_t(j) * W + i) * nL];
      if (std::isnan(v[0])) continue;
      if (req.style == "false") {
        double mean = 0;
        for (int l = 0; l < nL; ++l) mean += v[l] / nL;
        if (!file.spectral()) mean = colour->xyz(v)[1];
        double t = mean > 0 ? (std::log2(mean) - req.log2Min) / (req.log2Max - req.log2Min) : 0.0;
        put(i, j, falseColour(t));
      } else {
        Colour3 rgb = colour->linearSrgb(v);
        for (double& c : rgb) c = srgbEncode(c * req.exposure);
        put(i, j, rgb);
      }
    }
  if (bar > 0) drawColourBar(img, S, S, req.log2Min, req.log2Max);
  return img;
}
}  // namespace

void checkFalseColourRange(const SliceRequest& req) {
  if (req.style == "false" && !(req.log2Max > req.log2Min && std::isfinite(req.log2Max - req.log2Min)))
    throw InputError(fmt::format("--log2-min {:g} and --log2-max {:g}: the false-colour scale needs min < max",
                                 req.log2Min, req.log2Max));
}

RgbImage renderSliceImage(const BsdfFileReader& file, const SliceRequest& req, int inc) {
  return sliceImage(file, modelSlice(file, req.model, inc), req);
}

int exportSlice(const BsdfFileReader& file, const SliceRequest& req, const std::string& outPath) {
  int inc = file.nearestIncidence(req.theta_deg, req.phi_deg);
  if (!file.done(inc)) {
    int done = 0;
    for (int i = 0; i < file.incidenceCount(); ++i) done += file.done(i) ? 1 : 0;
    throw InputError(fmt::format(
        "the slice nearest to theta_i = {:g}, phi_i = {:g} (theta {:g}, phi {:g}) is not computed "
        "yet: incomplete: {} of {} slices",
        req.theta_deg, req.phi_deg, file.incidenceTheta(inc), file.incidencePhi(inc), done, file.incidenceCount()));
  }
  std::vector<double> err;
  std::vector<double> f = modelSlice(file, req.model, inc, &err);
  const DirectionGrid& grid = file.grid();
  const int nL = file.channelCount(), nB = grid.binCount();
  const std::vector<std::string>& rowNames = file.channelNames();  // "450nm", … or "X", "Y", "Z"
  std::string ext = std::filesystem::path(outPath).extension().string();
  if (ext == ".png") {
    writePng(outPath, sliceImage(file, f, req));
  } else if (ext == ".exr") {
    const int S = req.size, W = req.both ? 2 * S : S;
    // R, G, B and Y channels only when some wavelength is visible (an 850 nm job has none).
    std::optional<SpectrumToColour> colour;
    try {
      colour.emplace(file.toColour());
    } catch (const std::invalid_argument&) {
    }
    const std::vector<double> spec = diskSpectra(file, f, req);
    std::vector<ExrChannel> ch;
    for (int l = 0; l < nL; ++l) {
      char name[32];
      // A colour table's own rows as "stored.X" (its R, G, B, Y follow, computed as for a spectrum).
      if (file.spectral())
        std::snprintf(name, sizeof name, "%.1fnm", file.wavelengths_nm()[size_t(l)]);
      else
        std::snprintf(name, sizeof name, "stored.%s", rowNames[size_t(l)].c_str());
      ch.push_back({name, std::vector<float>(size_t(W) * S, 0.f)});
    }
    ch.push_back({"mean", std::vector<float>(size_t(W) * S, 0.f)});
    if (colour)
      for (const char* n : {"R", "G", "B", "Y"}) ch.push_back({n, std::vector<float>(size_t(W) * S, 0.f)});
    for (size_t p = 0; p < size_t(W) * S; ++p) {
      const double* v = &spec[p * nL];
      if (std::isnan(v[0])) continue;
      double mean = 0;
      for (int l = 0; l < nL; ++l) {
        ch[l].pixels[p] = float(v[l]);
        mean += v[l] / nL;
      }
      ch[nL].pixels[p] = float(mean);
      if (!colour) continue;
      Colour3 rgb = colour->linearSrgb(v), xyz = colour->xyz(v);
      for (int c = 0; c < 3; ++c) ch[nL + 1 + c].pixels[p] = float(rgb[c]);
      ch[nL + 4].pixels[p] = float(xyz[1]);
    }
    writeExr(outPath, W, S, ch);
  } else if (ext == ".csv") {
    std::ostringstream o;
    o << "# microbsdf slice: model " << req.model << ", incidence theta " << file.incidenceTheta(inc) << " deg, phi "
      << file.incidencePhi(inc) << " deg; f in 1/sr (bin average), "
      << (err.empty() ? "no per-bin standard errors (the file keeps them per slice: microbsdf info)"
                      : "stderr = standard error")
      << "\n";
    // The colour a renderer fed with RGB uses, when some wavelength is visible: CIE 1931 XYZ (each
    // sample standing for its band, core/colour.h) and linear sRGB.
    std::optional<SpectrumToColour> colour;
    try {
      colour.emplace(file.toColour());
    } catch (const std::invalid_argument&) {
    }
    o << "bin,hemisphere,theta_deg,phi_deg,solid_angle_sr,projected_solid_angle_sr";
    for (const std::string& n : rowNames) o << ",f_" << n;
    const bool binErrors = !err.empty();
    if (binErrors)
      for (const std::string& n : rowNames) o << ",stderr_" << n;
    if (colour) o << ",X,Y,Z,R_linear,G_linear,B_linear" << (binErrors ? ",stderr_X,stderr_Y,stderr_Z" : "");
    o << "\n";
    o.precision(9);
    for (int b = 0; b < nB; ++b) {
      if (grid.projectedSolidAngle(b) <= 0) continue;
      Vec3 c = grid.centre(b);
      o << b << "," << (grid.isUpper(b) ? "reflection" : "transmission") << "," << degrees(sphericalTheta(c)) << ","
        << degrees(sphericalPhi(c)) << "," << grid.solidAngle(b) << "," << grid.projectedSolidAngle(b);
      for (int l = 0; l < nL; ++l) o << "," << f[size_t(l) * nB + b];
      if (binErrors)
        for (int l = 0; l < nL; ++l) o << "," << err[size_t(l) * nB + b];
      if (colour) {
        std::vector<double> v(static_cast<size_t>(nL));
        for (int l = 0; l < nL; ++l) v[size_t(l)] = f[size_t(l) * nB + b];
        const Colour3 xyz = colour->xyz(v.data()), rgb = xyzToLinearSrgb(xyz);
        for (double x : xyz) o << "," << x;
        for (double x : rgb) o << "," << x;
        if (!binErrors) {
          o << "\n";
          continue;
        }
        // Σ_λ w_λ se_λ: the standard error of X, Y, Z whatever the correlation between wavelengths
        // (they share paths; the weights are non-negative), an upper bound.
        for (int c = 0; c < 3; ++c) {
          double se = 0;
          for (int l = 0; l < nL; ++l) se += colour->weights()[size_t(l)][size_t(c)] * err[size_t(l) * nB + b];
          o << "," << se;
        }
      }
      o << "\n";
    }
    writeFileAtomically(outPath, o.str());  // an existing file is replaced whole or left as it was
  } else {
    throw std::invalid_argument("unknown slice format '" + ext + "' (use .exr, .png or .csv)");
  }
  return inc;
}

}  // namespace mbsdf
