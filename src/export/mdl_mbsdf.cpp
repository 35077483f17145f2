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

size_t cellOf(int ti, int to, int p, const MbsdfExport& o) {
  return (size_t(ti) * size_t(o.nTheta) + size_t(to)) * size_t(o.nPhi) + size_t(p);
}

// Per θi: the sums over Δφ of one channel, M(θi, θo), and the exit cells' projected solid angle
// w(θo) = (sin²θ1 − sin²θ0) π / nφ over both azimuth halves, as the runtime weighs them.
struct RowSums {
  std::vector<double> m, w;
  double albedo(int ti, const std::vector<double>& d, int n) const {
    double sum = 0;
    for (int to = 0; to < n; ++to) sum += m[size_t(ti * n + to)] * d[size_t(to)] * w[size_t(to)];
    return d[size_t(ti)] * sum;
  }
};

RowSums rowSums(const std::vector<double>& values, int ch, int channels, const MbsdfExport& o) {
  RowSums r{std::vector<double>(size_t(o.nTheta) * size_t(o.nTheta), 0.0), std::vector<double>(size_t(o.nTheta))};
  for (int to = 0; to < o.nTheta; ++to) {
    const double s0 = std::sin(to * 0.5 * kPi / o.nTheta), s1 = std::sin((to + 1) * 0.5 * kPi / o.nTheta);
    r.w[size_t(to)] = (s1 * s1 - s0 * s0) * kPi / o.nPhi;
  }
  for (int ti = 0; ti < o.nTheta; ++ti)
    for (int to = 0; to < o.nTheta; ++to)
      for (int p = 0; p < o.nPhi; ++p)
        r.m[size_t(ti * o.nTheta + to)] += values[cellOf(ti, to, p, o) * size_t(channels) + size_t(ch)];
  return r;
}

// Makes one part what a symmetrising runtime reads as it is. The MDL SDK's runtime evaluates
// ½[f(θi, θo) + f(θo, θi)], takes each row's albedo from those values, and scales all light by the
// inverse of the largest row albedo where that exceeds 1 (its prepare_mbsdfs_part and libbsdf's
// measured_sample). So the part is made symmetric, then scaled symmetrically, f(θi, θo) d(θi) d(θo),
// with d from symmetric Sinkhorn balancing (d ← d √(target / albedo); Knight 2008) so that every
// row's albedo, summed as the runtime sums it, is the table's hemispherical integral on that side.
MbsdfBalance balanceSymmetric(Part& part, int channels, const MbsdfExport& o) {
  const size_t n = size_t(o.nTheta);
  const std::vector<double> tabulated = part.values;
  for (int ti = 0; ti < o.nTheta; ++ti)
    for (int to = 0; to < o.nTheta; ++to)
      for (int p = 0; p < o.nPhi; ++p)
        for (int ch = 0; ch < channels; ++ch)
          part.values[cellOf(ti, to, p, o) * size_t(channels) + size_t(ch)] =
              0.5 * (tabulated[cellOf(ti, to, p, o) * size_t(channels) + size_t(ch)] +
                     tabulated[cellOf(to, ti, p, o) * size_t(channels) + size_t(ch)]);
  MbsdfBalance out;
  for (int ch = 0; ch < channels; ++ch) {
    const RowSums r = rowSums(part.values, ch, channels, o);
    std::vector<double> d(n, 1.0);
    auto target = [&](int ti) { return std::max(0.0, part.target[size_t(ti * channels + ch)]); };
    for (int ti = 0; ti < o.nTheta; ++ti)
      if (const double a = r.albedo(ti, d, o.nTheta); a > 0 && target(ti) > 0)
        out.runtimeAlbedoError = std::max(out.runtimeAlbedoError, std::abs(a / target(ti) - 1));
    for (int iteration = 0; iteration < 1000; ++iteration) {
      double worst = 0;
      for (int ti = 0; ti < o.nTheta; ++ti) {
        const double a = r.albedo(ti, d, o.nTheta);
        if (!(a > 0)) continue;
        worst = std::max(worst, std::abs(a - target(ti)) / std::max(target(ti), 1e-12));
        d[size_t(ti)] *= std::sqrt(target(ti) / a);
      }
      if (worst < 1e-9) break;
    }
    for (int ti = 0; ti < o.nTheta; ++ti)
      if (target(ti) > 1e-6)
        out.residual = std::max(out.residual, std::abs(r.albedo(ti, d, o.nTheta) / target(ti) - 1));
    for (int ti = 0; ti < o.nTheta; ++ti)
      for (int to = 0; to < o.nTheta; ++to)
        for (int p = 0; p < o.nPhi; ++p)
          part.values[cellOf(ti, to, p, o) * size_t(channels) + size_t(ch)] *= d[size_t(ti)] * d[size_t(to)];
  }
  // How far the stored lobe is from the table's: L1 weighted by the exit cells' projected solid angle.
  double change = 0, norm = 0;
  for (int ti = 0; ti < o.nTheta; ++ti)
    for (int to = 0; to < o.nTheta; ++to) {
      const double theta_o = (to + 0.5) * 0.5 * kPi / o.nTheta;
      const double weight = std::cos(theta_o) * std::sin(theta_o);
      for (int p = 0; p < o.nPhi; ++p)
        for (int ch = 0; ch < channels; ++ch) {
          const size_t k = cellOf(ti, to, p, o) * size_t(channels) + size_t(ch);
          change += std::abs(part.values[k] - tabulated[k]) * weight;
          norm += std::abs(tabulated[k]) * weight;
        }
    }
  out.lobeChangeL1 = norm > 0 ? change / norm : 0.0;
  return out;
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
    (transmitted ? out.transmissionBalance : out.reflectionBalance) = balanceSymmetric(part, rgb ? 3 : 1, o);
    differenceL1 += part.differenceL1;
    tableL1 += part.tableL1;
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
