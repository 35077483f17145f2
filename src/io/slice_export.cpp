#include "io/slice_export.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "io/exr_image.h"
#include "scattering/components.h"

namespace mbsdf {

std::vector<double> modelSlice(const BsdfFileReader& file, const std::string& model, int incidence,
                               std::vector<double>* stdError) {
  auto comps = modelComponents(model);
  if (!comps) throw std::invalid_argument("unknown model '" + model + "' (GS, GM, WS, WM or a component name)");
  auto have = file.components();
  std::vector<double> sum, var;
  for (Component c : *comps) {
    std::string name = componentName(c);
    if (std::find(have.begin(), have.end(), name) == have.end())
      throw std::invalid_argument("model " + model + " needs component '" + name + "', which the file does not hold");
    auto v = file.slice(name, incidence);
    auto e = file.sliceStdError(name, incidence);
    if (sum.empty()) { sum.assign(v.size(), 0.0); var.assign(v.size(), 0.0); }
    for (size_t i = 0; i < v.size(); ++i) {
      sum[i] += v[i];
      var[i] += e[i] * e[i];
    }
  }
  if (stdError) {
    stdError->resize(var.size());
    for (size_t i = 0; i < var.size(); ++i) (*stdError)[i] = std::sqrt(var[i]);
  }
  return sum;
}

int exportSlice(const BsdfFileReader& file, const SliceRequest& req, const std::string& outPath) {
  int inc = file.nearestIncidence(req.theta_deg, req.phi_deg);
  if (!file.done(inc)) throw std::runtime_error("the slice nearest to the requested incidence is not computed yet");
  std::vector<double> err;
  std::vector<double> f = modelSlice(file, req.model, inc, &err);
  const DirectionGrid& grid = file.grid();
  const auto& lambda = file.wavelengths_nm();
  const int nL = int(lambda.size()), nB = grid.binCount();
  std::string ext = std::filesystem::path(outPath).extension().string();
  if (ext == ".exr") {
    const int S = req.size;
    std::vector<ExrChannel> ch;
    for (int l = 0; l < nL; ++l) {
      char name[32];
      std::snprintf(name, sizeof name, "%.1fnm", lambda[l]);
      ch.push_back({name, std::vector<float>(size_t(S) * S, 0.f)});
    }
    ch.push_back({"mean", std::vector<float>(size_t(S) * S, 0.f)});
    for (int j = 0; j < S; ++j)
      for (int i = 0; i < S; ++i) {
        double x = -1 + 2.0 * (i + 0.5) / S, y = 1 - 2.0 * (j + 0.5) / S;
        double r2 = x * x + y * y;
        if (r2 > 1) continue;
        double z = std::sqrt(1 - r2);
        int b = grid.binOf({x, y, req.transmission ? -z : z});
        double mean = 0;
        for (int l = 0; l < nL; ++l) {
          double v = f[size_t(l) * nB + b];
          ch[l].pixels[size_t(j) * S + i] = float(v);
          mean += v / nL;
        }
        ch.back().pixels[size_t(j) * S + i] = float(mean);
      }
    writeExr(outPath, S, S, ch);
  } else if (ext == ".csv") {
    std::ofstream o(outPath);
    if (!o) throw std::runtime_error("cannot write " + outPath);
    o << "# microbsdf slice: model " << req.model << ", incidence theta " << file.incidenceTheta(inc) << " deg, phi "
      << file.incidencePhi(inc) << " deg; f in 1/sr (bin average), stderr = standard error\n";
    o << "bin,hemisphere,theta_deg,phi_deg,solid_angle_sr,projected_solid_angle_sr";
    for (double l : lambda) o << ",f_" << l << "nm";
    for (double l : lambda) o << ",stderr_" << l << "nm";
    o << "\n";
    o.precision(9);
    for (int b = 0; b < nB; ++b) {
      if (grid.projectedSolidAngle(b) <= 0) continue;
      Vec3 c = grid.centre(b);
      o << b << "," << (grid.isUpper(b) ? "reflection" : "transmission") << "," << degrees(sphericalTheta(c)) << ","
        << degrees(sphericalPhi(c)) << "," << grid.solidAngle(b) << "," << grid.projectedSolidAngle(b);
      for (int l = 0; l < nL; ++l) o << "," << f[size_t(l) * nB + b];
      for (int l = 0; l < nL; ++l) o << "," << err[size_t(l) * nB + b];
      o << "\n";
    }
  } else {
    throw std::invalid_argument("unknown slice format '" + ext + "' (use .exr or .csv)");
  }
  return inc;
}

}  // namespace mbsdf
