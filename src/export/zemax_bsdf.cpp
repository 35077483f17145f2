#include "export/zemax_bsdf.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <map>

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

// The scatter direction at radial r and azimuth a about the specular direction of wi (see the header).
Vec3 scatterDirection(const Vec3& wi, double r_deg, double a_deg) {
  const Vec3 s{-wi.x, -wi.y, wi.z};
  const double sinTheta = std::hypot(wi.x, wi.y);
  // Towards the normal: n − (n·s) s normalised; at normal incidence its limit along φi.
  const double phi_i = std::atan2(wi.y, wi.x);
  const Vec3 e1 = sinTheta > 1e-12 ? normalize(Vec3{0, 0, 1} - s * s.z) : Vec3{std::cos(phi_i), std::sin(phi_i), 0.0};
  const Vec3 e2 = cross(s, e1);
  const double r = radians(r_deg), a = radians(a_deg);
  return s * std::cos(r) + (e1 * std::cos(a) + e2 * std::sin(a)) * std::sin(r);
}

std::string numbers(const std::vector<double>& v) {
  return fmt::format("{:g}\n", fmt::join(v, "\t"));
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
  if (thetas.empty()) throw InputError(source + ": no incidence above the surface: a BRDF file needs one");
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

  const double lambda_nm = file.wavelengths_nm().at(size_t(options.wavelength));
  std::string out;
  out += fmt::format("# microbsdf: {}, model {}, wavelength {:g} nm, reflection (BRDF, 1/sr)\n", source, lookup.model(),
                     lambda_nm);
  out +=
      "# computed from the microgeometry (the format's only Source keyword is Measured); TIS is the table's\n"
      "# hemispherical integral of f cos(theta_o) over the reflected side, the specular lobe included\n";
  out += "Source\tMeasured\n";
  out += std::string("Symmetry\t") + (rotation.size() > 1 ? "Asymmetrical4D" : "Asymmetrical") + "\n";
  out += "SpectralContent\tMonochrome\nScatterType\tBRDF\n";
  out += fmt::format("SampleRotation\t{}\n", rotation.size()) + numbers(rotation);
  out += fmt::format("AngleOfIncidence\t{}\n", aoi.size()) + numbers(aoi);
  out += fmt::format("ScatterAzimuth\t{}\n", options.azimuth_deg.size()) + numbers(options.azimuth_deg);
  out += fmt::format("ScatterRadial\t{}\n", options.radial_deg.size()) + numbers(options.radial_deg);
  out += "\nMonochrome\nDataBegin\n";
  for (size_t rot = 0; rot < rotation.size(); ++rot)
    for (size_t k = 0; k < aoi.size(); ++k) {
      const int i = at.at({int(rot), int(k)});
      const Vec3 wi = sphericalDirection(radians(file.incidenceTheta(i)), radians(file.incidencePhi(i)));
      out += fmt::format("TIS\t{:.6g}\n", lookup.hemisphericalIntegral(i, options.wavelength, true));
      for (double a : options.azimuth_deg) {
        std::vector<double> row;
        for (double r : options.radial_deg) {
          const Vec3 wo = scatterDirection(wi, r, a);
          row.push_back(wo.z > 0 ? std::max(0.0, lookup.eval(i, wo, options.wavelength)) : 0.0);
        }
        out += fmt::format("{:.6e}\n", fmt::join(row, "\t"));
      }
    }
  out += "DataEnd\n";
  return out;
}

}  // namespace mbsdf
