#include "export/mdl_mbsdf.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/colour.h"
#include "core/error.h"
#include "export/little_endian.h"

namespace mbsdf {
namespace {

// The incidence azimuths an anisotropic table is averaged over (an isotropic one needs one): with
// every incidence bin, evenly spread ones (the table interpolates between its bins); with listed
// incidences, their one azimuth. Listed incidences at several azimuths are refused: between them the
// table takes the nearest incidence in angle, which may lie at another azimuth, so an average over
// them would not be the azimuthal mean it is reported as.
std::vector<double> incidenceAzimuths(const BsdfFileReader& file, const BsdfLookup& lookup) {
  if (tableIsIsotropic(file)) return {0.0};
  if (!lookup.nearestOnly()) {
    const auto* g = std::get_if<ThetaPhiGrid>(&file.grid().layout());
    const int n = g ? g->nPhi : 24;
    std::vector<double> phi;
    for (int k = 0; k < n; ++k) phi.push_back((k + 0.5) * 2 * kPi / n);
    return phi;
  }
  std::vector<double> phi;
  for (int i = 0; i < file.incidenceCount(); ++i) {
    const double p = radians(file.incidencePhi(i));
    if (file.incidenceTheta(i) < 90 &&
        std::none_of(phi.begin(), phi.end(), [&](double x) { return std::abs(x - p) < 1e-9; }))
      phi.push_back(p);
  }
  if (phi.size() > 1)
    throw InputError(fmt::format(
        "the table is anisotropic and lists incidences at {} azimuths: the isotropic MBSDF needs its mean over "
        "the incidence azimuth, which listed incidences do not give (use incidence = \"all\", or list one azimuth)",
        phi.size()));
  return phi;
}

// One part of the file: per (θi, θo, Δφ) cell centre and channel, f averaged over the incidence
// azimuths; with the L1 norms of the table and of its difference from that average.
struct Part {
  std::vector<double> values;  // ((θi · nθ + θo) · nφ + Δφ) · channels + channel
  std::vector<double> target;  // per θi and channel: the table's hemispherical integral on this side
  double differenceL1 = 0, tableL1 = 0;
};

Part tabulate(const BsdfLookup& lookup, const SpectrumToColour* rgb, int wavelength,
              const std::vector<double>& azimuths, bool transmitted, const MbsdfExport& o) {
  const int channels = rgb ? 3 : 1, nL = lookup.wavelengthCount();
  Part part;
  part.values.assign(size_t(o.nTheta) * size_t(o.nTheta) * size_t(o.nPhi) * size_t(channels), 0.0);
  std::vector<std::vector<double>> perAzimuth(azimuths.size(), std::vector<double>(size_t(channels)));
  std::vector<double> spectrum(static_cast<size_t>(nL), 0.0);
  part.target.assign(size_t(o.nTheta) * size_t(channels), 0.0);
  for (int ti = 0; ti < o.nTheta; ++ti)
    for (double phi : azimuths) {
      const Vec3 wi = sphericalDirection((ti + 0.5) * 0.5 * kPi / o.nTheta, phi);
      for (int l = 0; l < nL; ++l) spectrum[size_t(l)] = lookup.hemisphericalIntegral(wi, l, !transmitted);
      const Colour3 c = rgb ? rgb->linearSrgb(spectrum.data()) : Colour3{spectrum[size_t(wavelength)], 0, 0};
      for (int ch = 0; ch < channels; ++ch) part.target[size_t(ti * channels + ch)] += c[size_t(ch)] / azimuths.size();
    }
  for (int ti = 0; ti < o.nTheta; ++ti)
    for (int to = 0; to < o.nTheta; ++to)
      for (int p = 0; p < o.nPhi; ++p) {
        const double theta_i = (ti + 0.5) * 0.5 * kPi / o.nTheta, theta_o = (to + 0.5) * 0.5 * kPi / o.nTheta;
        const double dphi = (p + 0.5) * kPi / o.nPhi;
        const size_t at =
            ((size_t(ti) * size_t(o.nTheta) + size_t(to)) * size_t(o.nPhi) + size_t(p)) * size_t(channels);
        for (size_t a = 0; a < azimuths.size(); ++a) {
          const Vec3 wi = sphericalDirection(theta_i, azimuths[a]);
          const Vec3 wo = sphericalDirection(transmitted ? kPi - theta_o : theta_o, azimuths[a] + dphi);
          if (rgb) {
            for (int l = 0; l < nL; ++l) spectrum[size_t(l)] = lookup.eval(wi, wo, l);
            const Colour3 c = rgb->linearSrgb(spectrum.data());
            for (int ch = 0; ch < 3; ++ch) perAzimuth[a][size_t(ch)] = c[size_t(ch)];
          } else {
            perAzimuth[a][0] = lookup.eval(wi, wo, wavelength);
          }
          for (int ch = 0; ch < channels; ++ch)
            part.values[at + size_t(ch)] += perAzimuth[a][size_t(ch)] / azimuths.size();
        }
        const double weight = std::cos(theta_o) * std::sin(theta_o);  // the exit cell's projected solid angle
        for (const auto& v : perAzimuth)
          for (int ch = 0; ch < channels; ++ch) {
            part.differenceL1 += std::abs(v[size_t(ch)] - part.values[at + size_t(ch)]) * weight;
            part.tableL1 += std::abs(v[size_t(ch)]) * weight;
          }
      }
  return part;
}

// Scales each incidence's row so that its albedo — Σ f cos θo dω over the exit cells, as the runtime
// sums it — is the table's hemispherical integral: the resampling's own integral error (a lobe
// narrower than the table's bins, near the pole, gains a few percent) must not become light gained or
// lost in a renderer. Returns the largest relative change.
double conserveEnergy(Part& part, int channels, const MbsdfExport& o) {
  double largest = 0;
  for (int ti = 0; ti < o.nTheta; ++ti)
    for (int ch = 0; ch < channels; ++ch) {
      auto at = [&](int to, int p) -> double& {
        return part
            .values[((size_t(ti) * size_t(o.nTheta) + size_t(to)) * size_t(o.nPhi) + size_t(p)) * size_t(channels) +
                    size_t(ch)];
      };
      double albedo = 0;
      for (int to = 0; to < o.nTheta; ++to) {
        const double s0 = std::sin(to * 0.5 * kPi / o.nTheta), s1 = std::sin((to + 1) * 0.5 * kPi / o.nTheta);
        for (int p = 0; p < o.nPhi; ++p) albedo += at(to, p) * (s1 * s1 - s0 * s0) * kPi / o.nPhi;
      }
      const double target = part.target[size_t(ti * channels + ch)];
      if (!(albedo > 0) || !(target > 0) || target / albedo < 0.5 || target / albedo > 2) continue;
      largest = std::max(largest, std::abs(target / albedo - 1));
      for (int to = 0; to < o.nTheta; ++to)
        for (int p = 0; p < o.nPhi; ++p) at(to, p) *= target / albedo;
    }
  return largest;
}

// L1 of what a symmetrising runtime changes, ½[f(θi, θo) + f(θo, θi)] − f, relative to f's L1.
double symmetrisationL1(const Part& part, int channels, const MbsdfExport& o) {
  double change = 0, norm = 0;
  for (int ti = 0; ti < o.nTheta; ++ti)
    for (int to = 0; to < o.nTheta; ++to)
      for (int p = 0; p < o.nPhi; ++p)
        for (int ch = 0; ch < channels; ++ch) {
          auto at = [&](int a, int b) {
            return part
                .values[((size_t(a) * size_t(o.nTheta) + size_t(b)) * size_t(o.nPhi) + size_t(p)) * size_t(channels) +
                        size_t(ch)];
          };
          const double theta_o = (to + 0.5) * 0.5 * kPi / o.nTheta;
          const double weight = std::cos(theta_o) * std::sin(theta_o);
          change += std::abs(0.5 * (at(ti, to) + at(to, ti)) - at(ti, to)) * weight;
          norm += std::abs(at(ti, to)) * weight;
        }
  return norm > 0 ? change / norm : 0.0;
}

}  // namespace

MbsdfFile mbsdfFile(const BsdfFileReader& file, const BsdfLookup& lookup, const MbsdfExport& o,
                    const std::string& description) {
  bool above = false, transmits = false;
  for (int i = 0; i < file.incidenceCount(); ++i) {
    if (file.incidenceTheta(i) >= 90) continue;
    above = true;
    if (!file.done(i)) throw InputError(fmt::format("incidence {} is unfinished: finish the run first", i));
    for (int l = 0; l < lookup.wavelengthCount(); ++l) transmits |= lookup.hemisphericalIntegral(i, l, false) > 0;
  }
  if (!above) throw InputError("the table holds no incidence above the surface: an MBSDF file needs light from above");
  const bool rgb = o.colour == MbsdfExport::Colour::rgb;
  const SpectrumToColour colour = file.toColour();
  const std::vector<double> azimuths = incidenceAzimuths(file, lookup);
  MbsdfFile out;
  out.transmission = transmits;
  out.anisotropic = !tableIsIsotropic(file);
  for (double a : azimuths) out.azimuths_deg.push_back(degrees(a));
  std::string data;
  double differenceL1 = 0, tableL1 = 0;
  for (bool transmitted : {false, true}) {
    if (transmitted && !transmits) break;
    Part part = tabulate(lookup, rgb ? &colour : nullptr, o.wavelength, azimuths, transmitted, o);
    out.energyCorrection = std::max(out.energyCorrection, conserveEnergy(part, rgb ? 3 : 1, o));
    differenceL1 += part.differenceL1;
    tableL1 += part.tableL1;
    if (transmitted) out.btdfSymmetrisationL1 = symmetrisationL1(part, rgb ? 3 : 1, o);
    data += transmitted ? "MBSDF_DATA_TRANSMISSION=\n" : "MBSDF_DATA_REFLECTION=\n";
    putLittleEndian(data, uint32_t(rgb ? 1 : 0));
    putLittleEndian(data, uint32_t(o.nTheta));
    putLittleEndian(data, uint32_t(o.nPhi));
    for (double v : part.values) {
      out.negativeClamped += v < 0;
      ++out.values;
      putFloat32(data, float(std::max(0.0, v)));
    }
  }
  out.anisotropyL1 = tableL1 > 0 ? differenceL1 / tableL1 : 0.0;
  std::string header = "NVIDIA ARC MBSDF V1\n";
  std::string quoted;
  // One metadata line (readers take lines of up to 1024 bytes): quotes, backslashes and line breaks escaped.
  for (char c : description.substr(0, 512))
    quoted += c == '\n' ? std::string("\\n") : (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
  header += "DESCRIPTION=\"" + quoted + "\"\n";
  header += rgb ? "COLOUR=\"linear sRGB\"\n"
                : fmt::format("WAVELENGTH_NM=\"{:g}\"\n", file.wavelengths_nm()[size_t(o.wavelength)]);
  out.bytes = header + data;
  return out;
}

}  // namespace mbsdf
