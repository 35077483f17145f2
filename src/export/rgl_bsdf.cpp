#include "export/rgl_bsdf.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/colour.h"
#include "core/error.h"
#include "export/piecewise_bilinear_warp.h"
#include "export/tensor_file.h"

namespace mbsdf {
namespace {

// The format's unit coordinates of spherical angles (Dupuy & Jakob 2018, §6): u_θ = √(2θ/π) gives
// the grazing half vectors fewer nodes and the pole more; u_φ = (φ + π) / 2π.
double u2theta(double u) {
  return u * u * (0.5 * kPi);
}
double u2phi(double u) {
  return (2 * u - 1) * kPi;
}
double theta2u(double theta) {
  return std::sqrt(theta / (0.5 * kPi));
}
double phi2u(double phi) {
  return (phi + kPi) / (2 * kPi);
}
Vec3 directionOfU(double ux, double uy) {
  return sphericalDirection(u2theta(ux), u2phi(uy));
}

// Values on an nx × ny grid of the unit square in (u_θ, u_φ), stored and interpolated as a renderer
// reads them: float32, bilinear between nodes (x = column, fastest).
struct UGrid {
  int nx = 0, ny = 0;
  std::vector<float> v;
  double node(int i, int j) const { return v[size_t(j) * size_t(nx) + size_t(i)]; }
  double at(double x, double y) const {
    const double px = std::clamp(x, 0.0, 1.0) * (nx - 1), py = std::clamp(y, 0.0, 1.0) * (ny - 1);
    const int i = std::min(int(px), nx - 2), j = std::min(int(py), ny - 2);
    const double tx = px - i, ty = py - j;
    return (1 - ty) * ((1 - tx) * node(i, j) + tx * node(i + 1, j)) +
           ty * ((1 - tx) * node(i, j + 1) + tx * node(i + 1, j + 1));
  }
};

// The table's reflectance at the file's incidence nodes, through BsdfLookup (an isotropic table's
// nodes are its rings of incidences, exit directions relative to the incidence azimuth: the format's
// isotropic frame; an anisotropic table's nodes sit on a θ × φ grid between its incidence bins).
struct Reflectance {
  const BsdfLookup& lookup;
  std::vector<double> theta, phi;  // the nodes (radians)
  bool isotropic = true;

  Vec3 wi(int k, int l) const { return sphericalDirection(theta[size_t(k)], isotropic ? 0.0 : phi[size_t(l)]); }
  // The table's hemispherical integral of the reflected side at node (k, l).
  double integral(int k, int l, int lambda) const { return lookup.hemisphericalIntegral(wi(k, l), lambda, true); }
  // The mean of the table's two estimates of a reciprocal pair, f(ωi, ωo) and f(ωo, ωi): a renderer
  // reads f both ways (light and camera paths), a passive surface's BRDF is reciprocal (Helmholtz),
  // and the table's Monte Carlo noise would otherwise break that by its own few per cent.
  double f(int k, int l, const Vec3& wo, int lambda) const {
    const Vec3 w = wi(k, l);
    return 0.5 * (lookup.eval(w, wo, lambda) + lookup.eval(wo, w, lambda));
  }
};

Reflectance reflectanceNodes(const BsdfFileReader& file, const BsdfLookup& lookup) {
  Reflectance nodes{lookup, {}, {}, tableIsIsotropic(file)};
  for (int i = 0; i < file.incidenceCount(); ++i) {
    if (file.incidenceTheta(i) >= 90) continue;
    if (!file.done(i)) throw InputError(fmt::format("incidence {} is unfinished: finish the run first", i));
    const double t = radians(file.incidenceTheta(i));
    if (std::none_of(nodes.theta.begin(), nodes.theta.end(), [&](double x) { return std::abs(x - t) < 1e-9; }))
      nodes.theta.push_back(t);
  }
  if (nodes.theta.empty()) throw InputError("the table holds no incidence above the surface: nothing to reflect");
  std::sort(nodes.theta.begin(), nodes.theta.end());
  if (nodes.isotropic) {
    nodes.phi = {0.0};
    return nodes;
  }
  if (lookup.nearestOnly())
    throw InputError(
        "an anisotropic table goes to the RGL format only with every incidence bin (incidence = \"all\"): the "
        "format interpolates between incidence azimuths");
  const auto* g = std::get_if<ThetaPhiGrid>(&file.grid().layout());
  // Nodes at twice the table's incidence azimuths: between them the format interpolates in its warped
  // coordinates, which follow a lobe as it turns, where the table's own rule blends two lobes.
  const int nPhi = g ? g->nPhi : 24;
  for (int l = 0; l <= 2 * nPhi; ++l) nodes.phi.push_back(-kPi + kPi * l / nPhi);
  return nodes;
}

// D from the table: the largest f 4 cos θi cos θo at each half vector, floored and normalised.
UGrid ndfFromTable(const Reflectance& r, const std::vector<int>& lambdas, const RglExport& o) {
  UGrid d{o.nTheta_m, o.nPhi_m, std::vector<float>(size_t(o.nTheta_m) * size_t(o.nPhi_m), 0.0f)};
  double largest = 0;
  std::vector<double> raw(d.v.size(), 0.0);
  for (int j = 0; j < d.ny; ++j)
    for (int i = 0; i < d.nx; ++i) {
      const Vec3 m = directionOfU(double(i) / (d.nx - 1), double(j) / (d.ny - 1));
      double best = 0;
      for (size_t k = 0; k < r.theta.size(); ++k)
        for (size_t l = 0; l < r.phi.size(); ++l) {
          const Vec3 wi = r.wi(int(k), int(l));
          const double c = dot(wi, m);
          const Vec3 wo = m * (2 * c) - wi;
          if (c <= 0 || wo.z <= 1e-3) continue;
          for (int lambda : lambdas) best = std::max(best, r.f(int(k), int(l), wo, lambda) * 4 * wi.z * wo.z);
        }
      raw[size_t(j * d.nx + i)] = best;
      largest = std::max(largest, best);
    }
  if (!(largest > 0)) largest = 1;  // a black table: any D will do, take it uniform
  // ∫ D cos θm dωm by the midpoint rule on the bilinear patches (dω = 2π² u_θ sin θ du_θ du_φ).
  double integral = 0;
  for (size_t n = 0; n < raw.size(); ++n) d.v[n] = float(std::max(raw[n], o.ndfFloor * largest));
  for (int j = 0; j + 1 < d.ny; ++j)
    for (int i = 0; i + 1 < d.nx; ++i) {
      const double ux = (i + 0.5) / (d.nx - 1), uy = (j + 0.5) / (d.ny - 1);
      const double theta = u2theta(ux);
      integral += d.at(ux, uy) * std::cos(theta) * 2 * kPi * kPi * ux * std::sin(theta) / ((d.nx - 1) * (d.ny - 1));
    }
  for (float& x : d.v) x = float(x / integral);
  return d;
}

// σ(ωi) = ∫ D(ωm) max(0, ωi·ωm) dωm at the nodes of D's grid (isotropic: along θ, the same in φ).
UGrid sigmaOf(const UGrid& d, bool isotropic) {
  UGrid s{d.nx, d.ny, std::vector<float>(d.v.size())};
  auto sigma = [&](const Vec3& wi) {
    double sum = 0;
    for (int j = 0; j + 1 < d.ny; ++j)
      for (int i = 0; i + 1 < d.nx; ++i) {
        const double ux = (i + 0.5) / (d.nx - 1), uy = (j + 0.5) / (d.ny - 1);
        sum += d.at(ux, uy) * std::max(0.0, dot(wi, directionOfU(ux, uy))) * 2 * kPi * kPi * ux * std::sin(u2theta(ux));
      }
    return sum / ((d.nx - 1) * (d.ny - 1));
  };
  for (int i = 0; i < d.nx; ++i) {
    const double column = isotropic ? sigma(directionOfU(double(i) / (d.nx - 1), 0.5)) : 0.0;
    for (int j = 0; j < d.ny; ++j)
      s.v[size_t(j * d.nx + i)] =
          float(isotropic ? column : sigma(directionOfU(double(i) / (d.nx - 1), double(j) / (d.ny - 1))));
  }
  return s;
}

// The density in u of the half vector seen from wi: D max(0, wi·ωm) / σ(wi) times the Jacobian
// 2π² u_θ sin θm.
std::vector<float> vndfSlice(const UGrid& d, const Vec3& wi, double sigma) {
  std::vector<float> v(d.v.size());
  for (int j = 0; j < d.ny; ++j)
    for (int i = 0; i < d.nx; ++i) {
      const double ux = double(i) / (d.nx - 1), uy = double(j) / (d.ny - 1);
      const Vec3 m = directionOfU(ux, uy);
      v[size_t(j * d.nx + i)] =
          float(d.node(i, j) * std::max(0.0, dot(wi, m)) / sigma * 2 * kPi * kPi * ux * std::sin(u2theta(ux)));
    }
  return v;
}

TensorField floats(std::string name, std::vector<uint64_t> shape, std::vector<float> values) {
  TensorField f;
  f.name = std::move(name);
  f.shape = std::move(shape);
  f.floats = std::move(values);
  return f;
}

// Per incidence node: the table on the warp's n × n grid (values[λ][node]) — f cos θo 4σ / D at the
// half vector the node maps to, 0 where the reflected direction leaves the upper hemisphere. The
// readers' eval returns spectra D / (4σ) as f cos θo, the value their samplers divide by the pdf over
// ωo (rgl-epfl/brdf-loader powitacq.inl BRDF::eval and BRDF::sample; Mitsuba 3 `measured`).
std::vector<std::vector<double>> spectraSlice(const Reflectance& r, int k, int l, const UGrid& d, double sigma,
                                              const PiecewiseBilinearWarp& warp, const std::vector<int>& lambdas,
                                              int n) {
  const Vec3 wi = r.wi(k, l);
  std::vector<std::vector<double>> values(lambdas.size(), std::vector<double>(size_t(n) * size_t(n), 0.0));
  for (int b = 0; b < n; ++b)
    for (int a = 0; a < n; ++a) {
      const WarpSample p = warp.sample(double(a) / (n - 1), double(b) / (n - 1));
      const Vec3 m = directionOfU(p.x, p.y);
      const double c = dot(wi, m);
      const Vec3 wo = m * (2 * c) - wi;
      if (c <= 0 || wo.z <= 0) continue;
      const double scale = wo.z * 4 * sigma / d.at(p.x, p.y);
      for (size_t q = 0; q < lambdas.size(); ++q) values[q][size_t(b * n + a)] = r.f(k, l, wo, lambdas[q]) * scale;
    }
  return values;
}

// Scales one incidence's values (per wavelength) so that the file's albedo there — ∫ f cos θo dωo with
// f cos θo = spectra D / (4σ) as a renderer evaluates it, by the midpoint rule on the warp's unit
// square, where dωo = ds / pdf — is the
// table's hemispherical integral: sampling a lobe narrower than the table's bins at the nodes (a flat
// mirror's specular bin) would otherwise become light a renderer gains or loses. A mismatch beyond a
// factor 2 is not scaled away: the nodes do not resolve that lobe, and `out` lists it.
void conserveEnergy(std::vector<std::vector<double>>& values, const Reflectance& r, int k, int l, const UGrid& d,
                    double sigma, const PiecewiseBilinearWarp& warp, const std::vector<int>& lambdas,
                    const std::vector<std::string>& bands, int n, RglFile& out) {
  const Vec3 wi = r.wi(k, l);
  const int q = 2 * n;  // quadrature points per axis
  std::vector<double> albedo(lambdas.size(), 0.0);
  for (int b = 0; b < q; ++b)
    for (int a = 0; a < q; ++a) {
      const double sx = (a + 0.5) / q, sy = (b + 0.5) / q;
      const WarpSample p = warp.sample(sx, sy);
      const Vec3 m = directionOfU(p.x, p.y);
      const double c = dot(wi, m);
      const Vec3 wo = m * (2 * c) - wi;
      const double jacobian = 2 * kPi * kPi * p.x * std::sin(u2theta(p.x)) * 4 * c;  // dωo per unit u
      if (c <= 0 || wo.z <= 0 || !(p.pdf > 0) || !(jacobian > 1e-12)) continue;
      const double x = sx * (n - 1), y = sy * (n - 1);
      const int i = std::min(int(x), n - 2), j = std::min(int(y), n - 2);
      const double tx = x - i, ty = y - j;
      const double fScale = d.at(p.x, p.y) / (4 * sigma) * jacobian / p.pdf / (q * q);
      for (size_t w = 0; w < lambdas.size(); ++w) {
        const std::vector<double>& v = values[w];
        const double spec = (1 - ty) * ((1 - tx) * v[size_t(j * n + i)] + tx * v[size_t(j * n + i + 1)]) +
                            ty * ((1 - tx) * v[size_t((j + 1) * n + i)] + tx * v[size_t((j + 1) * n + i + 1)]);
        albedo[w] += spec * fScale;
      }
    }
  for (size_t w = 0; w < lambdas.size(); ++w) {
    const double target = r.integral(k, l, lambdas[w]);
    if (!(target > 1e-12)) continue;
    if (!(albedo[w] > 0) || target / albedo[w] < 0.5 || target / albedo[w] > 2) {
      out.unresolved.push_back(
          {degrees(r.theta[size_t(k)]), degrees(r.isotropic ? 0.0 : r.phi[size_t(l)]), bands[w], albedo[w], target});
      continue;
    }
    out.energyCorrection = std::max(out.energyCorrection, std::abs(target / albedo[w] - 1));
    for (double& x : values[w]) x *= target / albedo[w];
  }
}

}  // namespace

RglFile rglBsdfFile(const BsdfFileReader& file, const BsdfLookup& lookup, const RglExport& options,
                    const std::string& description) {
  const Reflectance r = reflectanceNodes(file, lookup);
  RglExport o = options;
  // An anisotropic file holds twice the table's incidence azimuths (see reflectanceNodes): a coarser
  // warped grid keeps its size in bounds at an error that the measurements (docs/export.md) show.
  if (o.nSample <= 0) o.nSample = r.isotropic ? 64 : 48;
  const std::vector<double>& table_nm = file.wavelengths_nm();
  std::vector<int> lambdas = o.wavelengths;
  if (lambdas.empty())
    for (size_t q = 0; q < table_nm.size(); ++q) lambdas.push_back(int(q));
  // A colour table (storage profile) holds channels, not wavelengths: the file holds its RGB.
  if (!file.spectral() && o.colour != RglExport::Colour::rgb)
    throw std::invalid_argument("the table is stored in colour (" + file.colourSpace() + "): export it as rgb");
  if (!file.spectral()) lambdas = {0, 1, 2};
  std::vector<double> nm;
  std::vector<std::string> bands;
  for (int q : lambdas) {
    nm.push_back(file.spectral() ? table_nm[size_t(q)] : std::nan(""));
    bands.push_back(file.spectral() ? fmt::format("{:g} nm", table_nm[size_t(q)]) : file.channelNames()[size_t(q)]);
  }
  const UGrid d = ndfFromTable(r, lambdas, o);
  const UGrid s = sigmaOf(d, r.isotropic);
  const SpectrumToColour colour = file.spectral() ? SpectrumToColour(nm) : file.toColour();
  // Luminance weights: CIE Y per wavelength; outside the visible, equal weights.
  std::vector<double> yWeight;
  double ySum = 0;
  for (const Colour3& w : colour.weights()) ySum += w[1];
  for (size_t q = 0; q < nm.size(); ++q) yWeight.push_back(ySum > 0 ? colour.weights()[q][1] / ySum : 1.0 / nm.size());
  const bool rgb = o.colour == RglExport::Colour::rgb;
  const size_t channels = rgb ? 3 : nm.size(), n2 = size_t(o.nSample) * size_t(o.nSample);
  const size_t nTheta = r.theta.size(), nPhi = r.phi.size();
  std::vector<float> vndf, values, luminance;
  RglFile out;
  for (size_t l = 0; l < nPhi; ++l)
    for (size_t k = 0; k < nTheta; ++k) {
      const Vec3 wi = r.wi(int(k), int(l));
      const double sigma = s.at(theta2u(std::acos(std::clamp(wi.z, -1.0, 1.0))), phi2u(r.phi[l]));
      const std::vector<float> slice = vndfSlice(d, wi, sigma);
      vndf.insert(vndf.end(), slice.begin(), slice.end());
      const PiecewiseBilinearWarp warp(slice, d.nx, d.ny);
      auto spectra = spectraSlice(r, int(k), int(l), d, sigma, warp, lambdas, o.nSample);
      conserveEnergy(spectra, r, int(k), int(l), d, sigma, warp, lambdas, bands, o.nSample, out);
      std::vector<double> lum(n2, 0.0);
      std::vector<std::vector<double>> stored(channels, std::vector<double>(n2));
      for (size_t node = 0; node < n2; ++node) {
        std::vector<double> spectrum(nm.size());
        for (size_t q = 0; q < nm.size(); ++q) spectrum[q] = spectra[q][node];
        if (rgb) {
          const Colour3 c = colour.linearSrgb(spectrum.data());
          for (size_t ch = 0; ch < 3; ++ch) stored[ch][node] = c[ch];
        } else {
          for (size_t q = 0; q < nm.size(); ++q) stored[q][node] = spectrum[q];
        }
        for (size_t q = 0; q < nm.size(); ++q) lum[node] += yWeight[q] * std::max(0.0, spectrum[q]);
      }
      for (const auto& channel : stored)
        for (double v : channel) {
          out.negativeClamped += v < 0;
          ++out.nodes;
          values.push_back(float(std::max(0.0, v)));
        }
      // A black slice would leave the renderer's luminance warp nothing to normalise: make it uniform.
      const double lumMax = *std::max_element(lum.begin(), lum.end());
      for (double v : lum) luminance.push_back(float(lumMax > 0 ? v : 1.0));
    }
  std::vector<TensorField> fields;
  TensorField text;
  text.name = "description";
  text.type = TensorField::Type::UInt8;
  text.bytes.assign(description.begin(), description.end());
  text.shape = {text.bytes.size()};
  fields.push_back(text);
  TensorField jacobian;
  jacobian.name = "jacobian";
  jacobian.type = TensorField::Type::UInt8;
  jacobian.bytes = {1};
  jacobian.shape = {1};
  fields.push_back(jacobian);
  const auto u64 = [](size_t v) { return uint64_t(v); };
  fields.push_back(floats("theta_i", {u64(nTheta)}, std::vector<float>(r.theta.begin(), r.theta.end())));
  fields.push_back(floats("phi_i", {u64(nPhi)}, std::vector<float>(r.phi.begin(), r.phi.end())));
  fields.push_back(floats("ndf", {u64(d.ny), u64(d.nx)}, d.v));
  fields.push_back(floats("sigma", {u64(s.ny), u64(s.nx)}, s.v));
  fields.push_back(floats("vndf", {u64(nPhi), u64(nTheta), u64(d.ny), u64(d.nx)}, vndf));
  fields.push_back(floats("luminance", {u64(nPhi), u64(nTheta), u64(o.nSample), u64(o.nSample)}, luminance));
  const std::vector<uint64_t> valueShape = {u64(nPhi), u64(nTheta), u64(channels), u64(o.nSample), u64(o.nSample)};
  if (rgb) {
    fields.push_back(floats("rgb", valueShape, values));
  } else {
    fields.push_back(floats("wavelengths", {u64(nm.size())}, std::vector<float>(nm.begin(), nm.end())));
    fields.push_back(floats("spectra", valueShape, values));
  }
  out.bytes = tensorFileBytes(fields);
  return out;
}

}  // namespace mbsdf
