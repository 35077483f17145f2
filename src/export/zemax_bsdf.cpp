#include "export/zemax_bsdf.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include "core/colour.h"
#include "core/error.h"

namespace mbsdf {
namespace {

// Distinct values of v (degrees), ascending, equal within 1e-9 degree.
std::vector<double> distinct(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  std::vector<double> out;
  for (double x : v)
    if (out.empty() || x - out.back() > 1e-9) out.push_back(x);
  return out;
}
int indexOf(const std::vector<double>& v, double x) {
  for (size_t i = 0; i < v.size(); ++i)
    if (std::abs(v[i] - x) <= 1e-9) return int(i);
  return -1;
}

// The specular direction of wi on the file's side: reflected, or refracted by Snell's law with eta
// (none under total internal reflection).
std::optional<Vec3> specularDirection(const Vec3& wi, const ZemaxExport& o) {
  if (!o.transmission) return Vec3{-wi.x, -wi.y, wi.z};
  const double tx = -wi.x / o.eta, ty = -wi.y / o.eta, sin2 = tx * tx + ty * ty;
  if (sin2 >= 1) return std::nullopt;
  return Vec3{tx, ty, -std::sqrt(1 - sin2)};
}

// The scatter direction at radial r and azimuth a about the specular direction c (see the header):
// e1 points from c towards the normal of c's side (at normal incidence its limit as the incidence
// tilts towards its azimuth phi_i), e2 = c × e1.
Vec3 scatterDirection(const Vec3& c, double phi_i, double r_deg, double a_deg) {
  const Vec3 axis{0, 0, c.z >= 0 ? 1.0 : -1.0};
  const Vec3 towardsAxis = axis - c * dot(c, axis);
  const Vec3 e1 = length(towardsAxis) > 1e-12 ? normalize(towardsAxis) : Vec3{std::cos(phi_i), std::sin(phi_i), 0.0};
  const Vec3 e2 = cross(c, e1);
  const double r = radians(r_deg), a = radians(a_deg);
  return c * std::cos(r) + (e1 * std::cos(a) + e2 * std::sin(a)) * std::sin(r);
}

std::string numbers(const std::vector<double>& v) {
  return fmt::format("{:g}\n", fmt::join(v, "\t"));
}

std::string zemaxHeader(const BsdfFileReader& file, const BsdfLookup& lookup, const ZemaxExport& o,
                        const std::string& source, const std::vector<double>& rotation,
                        const std::vector<double>& angle) {
  const std::string side = o.transmission ? "transmission (BTDF, 1/sr)" : "reflection (BRDF, 1/sr)";
  std::string out = o.xyz ? fmt::format("# microbsdf: {}, model {}, CIE XYZ of {} wavelengths{}, {}\n", source,
                                        lookup.model(), file.wavelengths_nm().size(),
                                        file.spectral() ? "" : " (stored in colour: " + file.colourSpace() + ")", side)
                          : fmt::format("# microbsdf: {}, model {}, wavelength {:g} nm, {}\n", source, lookup.model(),
                                        file.wavelengths_nm().at(size_t(o.wavelength)), side);
  out += std::string("# computed from the microgeometry (the format's only Source keyword is Measured); TIS is the ") +
         "table's\n# hemispherical integral of f cos(theta_o) over the " +
         (o.transmission ? "transmitted" : "reflected") + " side, the specular lobe included\n";
  if (o.transmission)
    out += fmt::format(
        "# AngleOfIncidence: the refracted angle theta_t (relative index {:.6g}); scatter angles about the refracted "
        "direction\n",
        o.eta);
  out += "Source\tMeasured\n";
  // The format description spells the four-dimensional keyword with two capitals, and readers that
  // follow it (libbsdf's ZemaxBsdfReader) know no other spelling.
  out += std::string("Symmetry\t") + (rotation.size() > 1 ? "ASymmetrical4D" : "Asymmetrical") + "\n";
  out += std::string("SpectralContent\t") + (o.xyz ? "XYZ" : "Monochrome") + "\n";
  out += std::string("ScatterType\t") + (o.transmission ? "BTDF" : "BRDF") + "\n";
  out += fmt::format("SampleRotation\t{}\n", rotation.size()) + numbers(rotation);
  out += fmt::format("AngleOfIncidence\t{}\n", angle.size()) + numbers(angle);
  out += fmt::format("ScatterAzimuth\t{}\n", o.azimuth_deg.size()) + numbers(o.azimuth_deg);
  out += fmt::format("ScatterRadial\t{}\n", o.radial_deg.size()) + numbers(o.radial_deg);
  return out + "\n";
}

// One angle of incidence: its TIS line and a row of f per scatter azimuth, the table's wavelengths
// weighted by `weight`.
std::string zemaxBlock(const BsdfFileReader& file, const BsdfLookup& lookup, const ZemaxExport& o, int incidence,
                       const std::vector<double>& weight) {
  const Vec3 wi = sphericalDirection(radians(file.incidenceTheta(incidence)), radians(file.incidencePhi(incidence)));
  const Vec3 c = *specularDirection(wi, o);
  auto weighted = [&](auto&& perWavelength) {
    double v = 0;
    for (size_t l = 0; l < weight.size(); ++l)
      if (weight[l] != 0) v += weight[l] * perWavelength(int(l));
    return v;
  };
  std::string out = fmt::format(
      "TIS\t{:.6g}\n", weighted([&](int l) { return lookup.hemisphericalIntegral(incidence, l, !o.transmission); }));
  for (double a : o.azimuth_deg) {
    std::vector<double> row;
    for (double r : o.radial_deg) {
      const Vec3 wo = scatterDirection(c, radians(file.incidencePhi(incidence)), r, a);
      const bool onSide = o.transmission ? wo.z < 0 : wo.z > 0;
      row.push_back(onSide ? std::max(0.0, weighted([&](int l) { return lookup.eval(incidence, wo, l); })) : 0.0);
    }
    out += fmt::format("{:.6e}\n", fmt::join(row, "\t"));
  }
  return out;
}

}  // namespace

ZemaxExport defaultZemaxExport() {
  ZemaxExport e;
  e.radial_deg = {0.0, 0.25, 0.5, 0.75};
  for (int r = 1; r <= 180; ++r) e.radial_deg.push_back(r);
  for (int a = 0; a < 360; a += 5) e.azimuth_deg.push_back(a);
  return e;
}

std::string zemaxBsdfText(const BsdfFileReader& file, const BsdfLookup& lookup, const ZemaxExport& options,
                          const std::string& source) {
  // The incidences above the surface as a θ × φ grid.
  std::vector<double> thetas, phis;
  for (int i = 0; i < file.incidenceCount(); ++i)
    if (file.incidenceTheta(i) < 90) {
      thetas.push_back(file.incidenceTheta(i));
      phis.push_back(file.incidencePhi(i));
    }
  if (thetas.empty()) throw InputError(source + ": no incidence above the surface: the file needs one");
  // An isotropic table (the file's `symmetry` attribute) is the same at every incidence azimuth: one
  // sample rotation, the first azimuth, says it all.
  const bool isotropic = tableIsIsotropic(file);
  const std::vector<double> aoi = distinct(thetas);
  std::vector<double> rotation = distinct(phis);
  if (isotropic) rotation.resize(1);
  std::map<std::pair<int, int>, int> at;
  for (int i = 0; i < file.incidenceCount(); ++i)
    if (file.incidenceTheta(i) < 90 && indexOf(rotation, file.incidencePhi(i)) >= 0)
      at[{indexOf(rotation, file.incidencePhi(i)), indexOf(aoi, file.incidenceTheta(i))}] = i;
  if (at.size() != aoi.size() * rotation.size())
    throw InputError(source + ": the incidences above the surface are not a theta x phi grid (" +
                     std::to_string(at.size()) + " incidences for " + std::to_string(aoi.size()) + " angles x " +
                     std::to_string(rotation.size()) +
                     " azimuths); the Zemax format needs every angle of incidence at every sample rotation");
  for (const auto& [key, i] : at)
    if (!file.done(i)) throw InputError(source + ": incidence slice " + std::to_string(i) + " is not finished");

  // Per channel (one, or X, Y, Z): weights of the table's wavelengths.
  const std::vector<double>& nm = file.wavelengths_nm();
  std::vector<std::vector<double>> weights;
  if (options.xyz) {
    const SpectrumToColour colour = file.toColour();  // of the wavelengths, or of a colour table's channels
    for (int c = 0; c < 3; ++c) {
      weights.emplace_back();
      for (const Colour3& w : colour.weights()) weights.back().push_back(w[size_t(c)]);
    }
  } else {
    weights.assign(1, std::vector<double>(nm.size(), 0.0));
    weights[0].at(size_t(options.wavelength)) = 1;
  }
  // AngleOfIncidence: the specular angle on the file's side.
  std::vector<double> angle;
  for (double t : aoi) {
    const auto c = specularDirection(sphericalDirection(radians(t), 0.0), options);
    if (!c)
      throw InputError(
          fmt::format("{}: at theta_i {:g} deg the light is totally reflected: no direct transmission to "
                      "centre a BTDF on",
                      source, t));
    angle.push_back(degrees(safeAcos(std::abs(c->z))));
  }
  std::string out = zemaxHeader(file, lookup, options, source, rotation, angle);
  const char* channelName[] = {"TristimulusX", "TristimulusY", "TristimulusZ"};
  for (size_t ch = 0; ch < weights.size(); ++ch) {
    out += std::string(options.xyz ? channelName[ch] : "Monochrome") + "\nDataBegin\n";
    for (size_t rot = 0; rot < rotation.size(); ++rot)
      for (size_t k = 0; k < aoi.size(); ++k)
        out += zemaxBlock(file, lookup, options, at.at({int(rot), int(k)}), weights[ch]);
    out += "DataEnd\n";
  }
  return out;
}

}  // namespace mbsdf
