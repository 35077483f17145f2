#include "io/table_diff.h"

#include <fmt/format.h>
#include <lcms2.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "core/error.h"
#include "io/bitmap_text.h"
#include "io/slice_export.h"

namespace mbsdf {

Colour3 xyzToLab(const Colour3& xyz, const Colour3& white) {
  const cmsCIEXYZ w{white[0], white[1], white[2]}, c{xyz[0], xyz[1], xyz[2]};
  cmsCIELab lab;
  cmsXYZ2Lab(&w, &lab, &c);
  return {lab.L, lab.a, lab.b};
}

double deltaE2000(const Colour3& lab1, const Colour3& lab2) {
  const cmsCIELab a{lab1[0], lab1[1], lab1[2]}, b{lab2[0], lab2[1], lab2[2]};
  return cmsCIE2000DeltaE(&a, &b, 1.0, 1.0, 1.0);
}

namespace {

double radToDeg(double r) {
  return r * 180.0 / M_PI;
}

void checkComparable(const BsdfFileReader& a, const BsdfFileReader& b, const std::string& na, const std::string& nb) {
  const DirectionGrid &ga = a.grid(), &gb = b.grid();
  if (ga.kind() != gb.kind() || ga.binCount() != gb.binCount())
    throw InputError(
        fmt::format("{} and {} are on different direction grids ({}, {} bins against {}, {} bins); "
                    "compare tables of one grid",
                    na, nb, ga.kind(), ga.binCount(), gb.kind(), gb.binCount()));
  if (a.channelNames() != b.channelNames())
    throw InputError(
        fmt::format("{} and {} hold different rows: {} ({} … {}) against {} ({} … {}); compare tables "
                    "of the same wavelengths and storage colour",
                    na, nb, a.channelCount(), a.channelNames().front(), a.channelNames().back(), b.channelCount(),
                    b.channelNames().front(), b.channelNames().back()));
  if (a.incidenceCount() != b.incidenceCount())
    throw InputError(
        fmt::format("{} has {} incidence directions and {} has {}; compare tables of the same "
                    "incidences",
                    na, a.incidenceCount(), nb, b.incidenceCount()));
  for (int i = 0; i < a.incidenceCount(); ++i)
    if (std::abs(a.incidenceTheta(i) - b.incidenceTheta(i)) > 1e-9 ||
        std::abs(a.incidencePhi(i) - b.incidencePhi(i)) > 1e-9)
      throw InputError(fmt::format("incidence {} is (θ {:g}°, φ {:g}°) in {} but (θ {:g}°, φ {:g}°) in {}", i,
                                   a.incidenceTheta(i), a.incidencePhi(i), na, b.incidenceTheta(i), b.incidencePhi(i),
                                   nb));
}

std::vector<double> energyOf(const SliceStats& s, const std::string& c, bool error) {
  auto add = [&](const std::map<std::string, std::vector<double>>& m, std::vector<double>& out, bool squares) {
    const auto it = m.find(c);
    if (it == m.end()) return;
    out.resize(std::max(out.size(), it->second.size()), 0.0);
    for (size_t l = 0; l < it->second.size(); ++l) out[l] += squares ? it->second[l] * it->second[l] : it->second[l];
  };
  std::vector<double> out;
  if (error) {
    add(s.energyReflectedStdError, out, true);
    add(s.energyTransmittedStdError, out, true);
    for (double& v : out) v = std::sqrt(v);
  } else {
    add(s.energyReflected, out, false);
    add(s.energyTransmitted, out, false);
  }
  return out;
}

// One file's slice of each compared component, read once for the table and the colour comparisons:
// the values and, where the file keeps them, the per-bin errors (empty otherwise).
struct ComponentSlice {
  std::vector<double> f, err;
};
using SliceTables = std::map<std::string, ComponentSlice>;

SliceTables readSlice(const BsdfFileReader& file, const std::vector<std::string>& comps, int inc) {
  SliceTables out;
  for (const std::string& c : comps)
    out[c] = {file.slice(c, inc), file.hasBinErrors(c) ? file.sliceStdError(c, inc) : std::vector<double>{}};
  return out;
}

ComponentDiff diffComponent(const DirectionGrid& grid, const std::string& c, const ComponentSlice& ta,
                            const ComponentSlice& tb, const SliceStats& sa, const SliceStats& sb) {
  ComponentDiff d;
  d.component = c;
  d.energyA = energyOf(sa, c, false);
  d.energyB = energyOf(sb, c, false);
  const std::vector<double> ea = energyOf(sa, c, true), eb = energyOf(sb, c, true);
  bool energyBeyond = false;
  for (size_t l = 0; l < std::min(d.energyA.size(), d.energyB.size()); ++l) {
    const double delta = d.energyB[l] - d.energyA[l];
    const double s = std::hypot(l < ea.size() ? ea[l] : 0.0, l < eb.size() ? eb[l] : 0.0);
    const double z = s > 0 ? delta / s : (std::abs(delta) > 1e-9 * std::abs(d.energyA[l]) ? INFINITY : 0.0);
    d.energyZ.push_back(std::isinf(z) ? std::copysign(1e300, delta) : z);
    energyBeyond = energyBeyond || std::abs(z) > 5;
  }
  const std::vector<double>&fa = ta.f, &fb = tb.f, &sa2 = ta.err, &sb2 = tb.err;
  const int nB = grid.binCount(), nL = int(fa.size()) / nB;
  d.perSliceErrors = sa2.empty() || sb2.empty();
  double mass = 0, l1 = 0, noise = 0, chi2 = 0;
  for (int l = 0; l < nL; ++l)
    for (int bin = 0; bin < nB; ++bin) {
      const size_t k = size_t(l) * nB + bin;
      const double w = grid.projectedSolidAngle(bin), delta = fb[k] - fa[k];
      mass += std::abs(fa[k]) * w;
      l1 += std::abs(delta) * w;
      if (d.perSliceErrors) continue;
      const double s = std::hypot(sa2[k], sb2[k]);
      noise += std::sqrt(2 / M_PI) * s * w;
      if (s > 0) {
        const double z = delta / s;
        chi2 += z * z;
        ++d.binsWithError;
        if (std::abs(z) > 4) ++d.binsBeyond4;
      } else if (std::abs(delta) > 1e-9 * std::max(std::abs(fa[k]), std::abs(fb[k]))) {
        ++d.deterministicDiffering;
      }
    }
  d.l1 = mass > 0 ? l1 / mass : (l1 > 0 ? INFINITY : 0.0);
  if (d.perSliceErrors) {
    // The files' stated relative L1 errors of the component (per wavelength, averaged).
    auto rel = [&](const SliceStats& s) {
      const auto it = s.relError.find(c);
      if (it == s.relError.end() || it->second.empty()) return 0.0;
      double m = 0;
      for (double v : it->second) m += v / double(it->second.size());
      return m;
    };
    d.l1Noise = std::hypot(rel(sa), rel(sb));
    d.beyondNoise = energyBeyond || d.l1 > 3 * d.l1Noise + 1e-12;
  } else {
    d.l1Noise = mass > 0 ? noise / mass : 0.0;
    d.chi2Z = d.binsWithError ? (chi2 - double(d.binsWithError)) / std::sqrt(2.0 * double(d.binsWithError)) : 0.0;
    d.beyondNoise = energyBeyond || d.chi2Z > 5 || d.deterministicDiffering > 0;
  }
  return d;
}

// The XYZ (under D65, a perfect reflector Y = 1) of each reflected bin's π f, summed over components,
// and the standard error of its Y (Σ_λ w_λ σ_λ: an upper bound whatever the correlation between rows;
// empty where a file keeps errors per slice only).
struct BinColours {
  std::vector<Colour3> xyz;  // per bin of the upper hemisphere
  std::vector<double> sigmaY;
};

BinColours binColours(const BsdfFileReader& f, const SliceTables& tables) {
  const DirectionGrid& grid = f.grid();
  const int nB = grid.binCount(), nUp = grid.binsPerHemisphere();
  std::vector<double> total, var;
  bool errors = true;
  for (const auto& [c, t] : tables) {
    if (total.empty()) total.assign(t.f.size(), 0.0), var.assign(t.f.size(), 0.0);
    for (size_t k = 0; k < t.f.size(); ++k) total[k] += t.f[k];
    errors = errors && !t.err.empty();
    if (!errors) continue;
    for (size_t k = 0; k < t.err.size(); ++k) var[k] += t.err[k] * t.err[k];
  }
  const int nL = int(total.size()) / nB;
  const std::optional<SpectrumToColour> d65 =
      f.spectral() ? std::optional<SpectrumToColour>(SpectrumToColour(f.wavelengths_nm(), Illuminant::D65))
                   : std::nullopt;
  const SpectrumToColour stored = f.toColour();
  BinColours out;
  std::vector<double> rows(static_cast<size_t>(nL), 0.0), sig(static_cast<size_t>(nL), 0.0);
  for (int bin = 0; bin < nUp; ++bin) {
    for (int l = 0; l < nL; ++l) {
      rows[size_t(l)] = M_PI * total[size_t(l) * nB + bin];
      sig[size_t(l)] = M_PI * std::sqrt(var[size_t(l) * nB + bin]);
    }
    out.xyz.push_back(d65 ? d65->xyz(rows.data()) : adaptXyzEToD65(stored.xyz(rows.data())));
    if (errors)
      out.sigmaY.push_back(std::abs(d65 ? d65->xyz(sig.data())[1] : adaptXyzEToD65(stored.xyz(sig.data()))[1]));
  }
  return out;
}

// The main lobe's direction: the mean direction of the reflected bins weighted by their squared
// luminance (× Ω⊥). Squaring lets the peak dominate; unlike the brightest bin or a threshold it moves
// continuously, so noise moves it little.
Vec3 lobeDirection(const DirectionGrid& grid, const BinColours& c) {
  Vec3 sum{0, 0, 0};
  for (size_t bin = 0; bin < c.xyz.size(); ++bin) {
    const double y = std::max(c.xyz[bin][1], 0.0);
    sum = sum + grid.centre(int(bin)) * (y * y * grid.projectedSolidAngle(int(bin)));
  }
  return length(sum) > 0 ? normalize(sum) : Vec3{0, 0, 1};
}

void toAngles(const Vec3& w, double* theta_deg, double* phi_deg) {
  *theta_deg = radToDeg(std::acos(std::clamp(w.z, -1.0, 1.0)));
  *phi_deg = std::fmod(radToDeg(std::atan2(w.y, w.x)) + 360, 360);
}

std::vector<double> albedoSpectrum(const SliceStats& s, const std::vector<std::string>& comps, size_t nL,
                                   bool reflected, bool error) {
  std::vector<double> out(nL, 0.0);
  for (const std::string& c : comps) {
    const auto& m = error ? (reflected ? s.energyReflectedStdError : s.energyTransmittedStdError)
                          : (reflected ? s.energyReflected : s.energyTransmitted);
    const auto it = m.find(c);
    if (it == m.end()) continue;
    for (size_t l = 0; l < std::min(nL, it->second.size()); ++l)
      out[l] += error ? it->second[l] * it->second[l] : it->second[l];
  }
  if (error)
    for (double& v : out) v = std::sqrt(v);
  return out;
}

void diffColour(const BsdfFileReader& a, const BsdfFileReader& b, const std::vector<std::string>& comps,
                const SliceTables& ta, const SliceTables& tb, const SliceStats& sa, const SliceStats& sb,
                SliceDiff& d) {
  const Colour3 white = whitePoint(Illuminant::D65);
  const std::vector<double>& lambda = a.wavelengths_nm();
  const SpectrumToColour conv(lambda, Illuminant::D65);
  auto lab = [&](const std::vector<double>& spectrum) { return xyzToLab(conv.xyz(spectrum.data()), white); };
  for (const bool reflected : {true, false}) {
    const std::vector<double> fa = albedoSpectrum(sa, comps, lambda.size(), reflected, false),
                              fb = albedoSpectrum(sb, comps, lambda.size(), reflected, false),
                              ea = albedoSpectrum(sa, comps, lambda.size(), reflected, true),
                              eb = albedoSpectrum(sb, comps, lambda.size(), reflected, true);
    // The noise's scale in ΔE00: A against A moved by the combined standard error, all wavelengths up,
    // or alternately up and down (a hue change), the largest of the three.
    double noise = 0;
    for (int pattern = 0; pattern < 3; ++pattern) {
      std::vector<double> moved = fa;
      for (size_t l = 0; l < moved.size(); ++l)
        moved[l] += std::hypot(ea[l], eb[l]) * (pattern == 0 ? 1.0 : ((l + pattern) % 2 ? 1.0 : -1.0));
      noise = std::max(noise, deltaE2000(lab(fa), lab(moved)));
    }
    (reflected ? d.deltaE00Reflected : d.deltaE00Transmitted) = deltaE2000(lab(fa), lab(fb));
    (reflected ? d.deltaE00ReflectedNoise : d.deltaE00TransmittedNoise) = noise;
  }
  const BinColours ca = binColours(a, ta), cb = binColours(b, tb);
  const bool errors = !ca.sigmaY.empty() && !cb.sigmaY.empty();
  double peak = 0;
  for (size_t bin = 0; bin < ca.xyz.size(); ++bin) peak = std::max({peak, ca.xyz[bin][1], cb.xyz[bin][1]});
  const DirectionGrid& grid = a.grid();
  for (size_t bin = 0; bin < ca.xyz.size(); ++bin) {
    // Bins whose luminance differs beyond noise (|ΔY| > 4σ), or, without per-bin errors, every bin
    // holding 1 % of the peak.
    const double dY = std::abs(cb.xyz[bin][1] - ca.xyz[bin][1]);
    if (errors ? !(dY > 4 * std::hypot(ca.sigmaY[bin], cb.sigmaY[bin]))
               : std::max(ca.xyz[bin][1], cb.xyz[bin][1]) < 1e-2 * peak)
      continue;
    const double e = deltaE2000(xyzToLab(ca.xyz[bin], white), xyzToLab(cb.xyz[bin], white));
    if (e > d.maxBinDeltaE00) {
      d.maxBinDeltaE00 = e;
      toAngles(grid.centre(int(bin)), &d.maxBinTheta_deg, &d.maxBinPhi_deg);
    }
  }
  const Vec3 wa = lobeDirection(grid, ca), wb = lobeDirection(grid, cb);
  toAngles(wa, &d.lobeA_theta, &d.lobeA_phi);
  toAngles(wb, &d.lobeB_theta, &d.lobeB_phi);
  d.lobeShift_deg = radToDeg(std::atan2(length(cross(wa, wb)), dot(wa, wb)));  // exact near 0
  d.colour = true;
}

}  // namespace

TableDiff diffTables(const BsdfFileReader& a, const BsdfFileReader& b, const std::string& nameA,
                     const std::string& nameB) {
  checkComparable(a, b, nameA, nameB);
  TableDiff out;
  out.fileA = nameA;
  out.fileB = nameB;
  const std::vector<std::string> ca = a.components(), cb = b.components();
  std::vector<std::string> common;
  for (const auto& c : ca) (std::find(cb.begin(), cb.end(), c) != cb.end() ? common : out.onlyInA).push_back(c);
  for (const auto& c : cb)
    if (std::find(ca.begin(), ca.end(), c) == ca.end()) out.onlyInB.push_back(c);
  if (common.empty()) throw InputError(nameA + " and " + nameB + " have no component in common");
  bool visible = true;
  try {
    SpectrumToColour(a.wavelengths_nm(), Illuminant::D65);
  } catch (const std::invalid_argument&) {
    visible = false;
  }
  for (int i = 0; i < a.incidenceCount(); ++i) {
    if (!a.done(i) || !b.done(i)) continue;
    SliceDiff d;
    d.incidence = i;
    d.theta_deg = a.incidenceTheta(i);
    d.phi_deg = a.incidencePhi(i);
    const SliceStats sa = a.stats(i), sb = b.stats(i);
    const SliceTables ta = readSlice(a, common, i), tb = readSlice(b, common, i);
    for (const auto& c : common) d.components.push_back(diffComponent(a.grid(), c, ta.at(c), tb.at(c), sa, sb));
    if (visible) diffColour(a, b, common, ta, tb, sa, sb, d);
    out.slices.push_back(std::move(d));
  }
  if (out.slices.empty()) throw InputError(nameA + " and " + nameB + " have no finished slice in common");
  return out;
}

namespace {
// The energy difference averaged over wavelengths, and the z of largest magnitude.
double meanEnergyDelta(const ComponentDiff& c, double* zMax) {
  double dE = 0;
  *zMax = 0;
  for (size_t l = 0; l < c.energyZ.size(); ++l) {
    dE += (c.energyB[l] - c.energyA[l]) / double(c.energyZ.size());
    if (std::abs(c.energyZ[l]) > std::abs(*zMax)) *zMax = c.energyZ[l];
  }
  return dE;
}
}  // namespace

bool TableDiff::beyondNoise() const {
  for (const auto& s : slices)
    for (const auto& c : s.components)
      if (c.beyondNoise) return true;
  return false;
}

std::string TableDiff::text() const {
  std::ostringstream o;
  o << "A = " << fileA << "\nB = " << fileB << "\n";
  if (!onlyInA.empty() || !onlyInB.empty())
    o << fmt::format("components only in A: {}; only in B: {}\n", fmt::join(onlyInA, ", "), fmt::join(onlyInB, ", "));
  int differing = 0;
  for (const auto& s : slices) {
    o << fmt::format("θi {:.2f}°, φi {:.2f}°\n", s.theta_deg, s.phi_deg);
    bool any = false;
    for (const auto& c : s.components) {
      double zMax = 0;
      const double dE = meanEnergyDelta(c, &zMax);
      const std::string noiseTest =
          c.perSliceErrors
              ? fmt::format("stated noise {:.3g} %", 100 * c.l1Noise)
              : fmt::format(
                    "noise {:.3g} %, χ² z {:.2f}, {} of {} bins |z| > 4{}", 100 * c.l1Noise, c.chi2Z, c.binsBeyond4,
                    c.binsWithError,
                    c.deterministicDiffering ? fmt::format(", {} exact bins differ", c.deterministicDiffering) : "");
      o << fmt::format("  {:<11} energy Δ {:+.4g} (largest z {:+.3g}), L1 {:.3g} % ({}): {}\n", c.component, dE,
                       std::abs(zMax) > 1e100 ? (zMax > 0 ? INFINITY : -INFINITY) : zMax, 100 * c.l1, noiseTest,
                       c.beyondNoise ? "BEYOND NOISE" : "within noise");
      any = any || c.beyondNoise;
    }
    if (s.colour)
      o << fmt::format(
          "  colour (D65): reflected ΔE00 {:.3g} (noise ~{:.2g}), transmitted {:.3g} (~{:.2g}); {}\n"
          "  main lobe: A θ {:.1f}° φ {:.1f}°, B θ {:.1f}° φ {:.1f}°: shift {:.2f}°\n",
          s.deltaE00Reflected, s.deltaE00ReflectedNoise, s.deltaE00Transmitted, s.deltaE00TransmittedNoise,
          s.maxBinDeltaE00 > 0 ? fmt::format("largest in a bin differing beyond noise {:.3g} at θ {:.1f}°, φ {:.1f}°",
                                             s.maxBinDeltaE00, s.maxBinTheta_deg, s.maxBinPhi_deg)
                               : std::string("no bin's luminance differs beyond noise"),
          s.lobeA_theta, s.lobeA_phi, s.lobeB_theta, s.lobeB_phi, s.lobeShift_deg);
    differing += any ? 1 : 0;
  }
  o << fmt::format("{} of {} slices differ beyond noise\n", differing, slices.size());
  return o.str();
}

std::string TableDiff::csv() const {
  std::ostringstream o;
  o << "theta_i_deg,phi_i_deg,component,energy_delta,energy_z_max,l1,l1_noise,chi2_z,bins_with_error,bins_beyond_4,"
       "exact_bins_differing,beyond_noise,delta_e00_reflected,delta_e00_transmitted,max_bin_delta_e00,lobe_shift_deg\n";
  for (const auto& s : slices)
    for (const auto& c : s.components) {
      double zMax = 0;
      const double dE = meanEnergyDelta(c, &zMax);
      o << fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", s.theta_deg, s.phi_deg, c.component, dE,
                       zMax, c.l1, c.l1Noise, c.chi2Z, c.binsWithError, c.binsBeyond4, c.deterministicDiffering,
                       c.beyondNoise ? 1 : 0, s.deltaE00Reflected, s.deltaE00Transmitted, s.maxBinDeltaE00,
                       s.lobeShift_deg);
    }
  return o.str();
}

nlohmann::json TableDiff::json() const {
  nlohmann::json j;
  j["a"] = fileA;
  j["b"] = fileB;
  j["only_in_a"] = onlyInA;
  j["only_in_b"] = onlyInB;
  j["beyond_noise"] = beyondNoise();
  for (const auto& s : slices) {
    nlohmann::json js{{"theta_i_deg", s.theta_deg}, {"phi_i_deg", s.phi_deg}};
    for (const auto& c : s.components)
      js["components"][c.component] = {{"energy_a", c.energyA},
                                       {"energy_b", c.energyB},
                                       {"energy_z", c.energyZ},
                                       {"l1", c.l1},
                                       {"l1_noise", c.l1Noise},
                                       {"chi2_z", c.chi2Z},
                                       {"bins_with_error", c.binsWithError},
                                       {"bins_beyond_4", c.binsBeyond4},
                                       {"exact_bins_differing", c.deterministicDiffering},
                                       {"per_slice_errors", c.perSliceErrors},
                                       {"beyond_noise", c.beyondNoise}};
    if (s.colour) {
      js["delta_e00_reflected"] = s.deltaE00Reflected;
      js["delta_e00_transmitted"] = s.deltaE00Transmitted;
      js["delta_e00_noise"] = {s.deltaE00ReflectedNoise, s.deltaE00TransmittedNoise};
      js["max_bin_delta_e00"] = {
          {"value", s.maxBinDeltaE00}, {"theta_deg", s.maxBinTheta_deg}, {"phi_deg", s.maxBinPhi_deg}};
      js["lobe"] = {
          {"a", {s.lobeA_theta, s.lobeA_phi}}, {"b", {s.lobeB_theta, s.lobeB_phi}}, {"shift_deg", s.lobeShift_deg}};
    }
    j["slices"].push_back(js);
  }
  return j;
}

RgbImage diffImage(const BsdfFileReader& a, const BsdfFileReader& b, int inc, const std::string& model, int size) {
  SliceRequest req;
  req.model = model;
  req.size = size;
  req.style = "false";
  const RgbImage ia = renderSliceImage(a, req, inc), ib = renderSliceImage(b, req, inc);
  // The difference's z-score per bin, on the same disk projection (the model's summed errors).
  std::vector<double> ea, eb;
  const std::vector<double> fa = modelSlice(a, model, inc, &ea), fb = modelSlice(b, model, inc, &eb);
  const DirectionGrid& grid = a.grid();
  const int nB = grid.binCount(), nL = int(fa.size()) / nB;
  const bool errors = !ea.empty() && !eb.empty();
  const int label = 12, W = 3 * ia.width, H = ia.height + label;
  RgbImage img;
  img.width = W;
  img.height = H;
  img.rgb.assign(size_t(W) * H * 3, 0);
  auto blit = [&](const RgbImage& src, int x0) {
    for (int j = 0; j < src.height; ++j)
      for (int i = 0; i < src.width; ++i)
        for (int k = 0; k < 3; ++k)
          img.rgb[(size_t(j + label) * W + x0 + i) * 3 + k] = src.rgb[(size_t(j) * src.width + i) * 3 + k];
  };
  blit(ia, 0);
  blit(ib, ia.width);
  const int S = size;
  for (int j = 0; j < S; ++j)
    for (int i = 0; i < S; ++i) {
      const double x = -1 + 2.0 * (i + 0.5) / S, y = 1 - 2.0 * (j + 0.5) / S, r2 = x * x + y * y;
      if (r2 > 1) continue;
      const int bin = grid.binOf({x, y, std::sqrt(1 - r2)});
      double delta = 0, var = 0, ref = 0;
      for (int l = 0; l < nL; ++l) {
        const size_t k = size_t(l) * nB + bin;
        delta += fb[k] - fa[k];
        if (errors) var += ea[k] * ea[k] + eb[k] * eb[k];
        ref += std::abs(fa[k]);
      }
      // z-score where both files have errors; else the relative difference, ±100 % full scale.
      const double t = errors ? (var > 0 ? delta / std::sqrt(var) / 5 : (delta != 0 ? std::copysign(1.0, delta) : 0.0))
                              : (ref > 0 ? delta / ref : 0.0);
      const double u = std::clamp(t, -1.0, 1.0);
      // Diverging: blue (B below A) – white – red (B above A).
      const Colour3 c = u < 0 ? Colour3{1 + u, 1 + u, 1} : Colour3{1, 1 - u, 1 - u};
      for (int k = 0; k < 3; ++k)
        img.rgb[(size_t(j + label) * W + 2 * ia.width + i) * 3 + k] = uint8_t(std::lround(srgbEncode(c[k]) * 255));
    }
  drawText(img, 2, 2, "A", 1, 255);
  drawText(img, ia.width + 2, 2, "B", 1, 255);
  // Blue: B lower, red: B higher; full scale ±5 standard errors (or ±100 % without per-bin errors).
  drawText(img, 2 * ia.width + 2, 2, errors ? "B - A  Z  -5 ... +5" : "B - A  REL  -1 ... +1", 1, 255);
  return img;
}

}  // namespace mbsdf
