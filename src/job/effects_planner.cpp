#include "job/effects_planner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <sstream>

#include "job/transport.h"
#include "scattering/wave_estimator.h"

namespace mbsdf {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

std::vector<int> pilotIncidences(const Job& job) {
  std::vector<int> order(job.incidence.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = int(i);
  auto cosTheta = [&](int i) { return std::abs(std::cos(radians(job.incidence[size_t(i)].theta_deg))); };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return cosTheta(a) > cosTheta(b); });
  std::vector<int> picks{order.front(), order[order.size() / 2], order.back()};
  std::sort(picks.begin(), picks.end());
  picks.erase(std::unique(picks.begin(), picks.end()), picks.end());
  return picks;
}

namespace {

// Projected-area-weighted rms height of the microgeometry (for the Rayleigh criterion).
double rmsHeight(const Microgeometry& g) {
  double w = 0, z = 0, z2 = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const auto& tri = g.triangles[t];
    const double a = std::abs(g.triangleNormal(t).z) * 0.5;
    const double c = (g.vertices[tri[0]].z + g.vertices[tri[1]].z + g.vertices[tri[2]].z) / 3.0;
    w += a;
    z += a * c;
    z2 += a * c * c;
  }
  if (w <= 0) return 0;
  z /= w;
  return std::sqrt(std::max(0.0, z2 / w - z * z));
}

// Projected-area-weighted rms slope, sqrt(<tan² θn>), of the microgeometry's facets.
double rmsSlope(const Microgeometry& g) {
  double w = 0, s2 = 0;
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const Vec3 n = g.triangleNormal(t);
    const double a = std::abs(n.z) * 0.5;
    if (a <= 0) continue;
    w += a;
    s2 += a * (n.x * n.x + n.y * n.y) / (n.z * n.z);
  }
  return w > 0 ? std::sqrt(s2 / w) : 0.0;
}

nlohmann::json decision(const std::string& effect, bool on, const std::string& reason) {
  return {{"effect", effect}, {"on", on}, {"reason", reason}};
}

std::string fmt3(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}

}  // namespace

nlohmann::json planEffects(const Job& job, const EffectsPilotOptions& options) {
  const auto t0 = Clock::now();
  const DirectionGrid grid(job.gridLayout);
  const int nL = int(job.lambda_nm.size()), nB = grid.binCount();
  const double tol = job.scene.tolerance;
  // Components named beside "auto" are kept whatever the pilots say.
  ComponentSet forced;
  for (const auto& c : job.requestedComponents)
    if (auto comp = componentFromName(c)) forced.add(*comp);

  Job pilotJob = job;
  pilotJob.components = ComponentSet{};
  pilotJob.components.add(Component::Coherent);
  pilotJob.components.add(Component::Multiple);
  const uint64_t paths = std::min<uint64_t>(options.paths, job.pathsPerSlice);
  GeometricTransport transport(pilotJob, grid, paths);
  const std::vector<int> pilots = pilotIncidences(job);
  std::vector<TileResult> geo;
  // Collimated pilot beams through the centres of the incidence bins: the geometric and the wave
  // pilot see the same incidence, a narrow lobe is not smeared over an incidence bin by a handful of
  // wave incidence samples, and a specular reflection lands inside a bin (a beam along a bin edge or
  // the pole would split a diffraction lobe between bins that the geometric delta does not share).
  auto beam = [&](int p) { return grid.centre(job.incidence[size_t(p)].bin); };
  for (int p : pilots) geo.push_back(transport.run(p, p, job.incidence[size_t(p)].bin, beam(p)));
  // Σ f Ω⊥ of a component and its standard error (root-sum-square over bins).
  auto energy = [&](const TileResult& r, Component c, int l, double* se) {
    double e = 0, v = 0;
    for (int b = 0; b < nB; ++b) {
      const double op = grid.projectedSolidAngle(b);
      e += r.at(c, l, b) * op;
      v += std::pow(r.stdError[int(c)][size_t(l) * nB + b] * op, 2);
    }
    *se = std::sqrt(v);
    return e;
  };

  nlohmann::json plan;
  nlohmann::json decisions = nlohmann::json::array();
  ComponentSet chosen;
  chosen.add(Component::Coherent);
  decisions.push_back(decision("coherent", true, "always: the geometric single scattering every model starts from"));

  // Multiple scattering.
  {
    double worst = 0, worstValue = 0, worstTheta = 0;
    for (size_t k = 0; k < geo.size(); ++k)
      for (int l = 0; l < nL; ++l) {
        double se;
        const double e = energy(geo[k], Component::Multiple, l, &se);
        if (e + 3 * se > worst) {
          worst = e + 3 * se;
          worstValue = e;
          worstTheta = job.incidence[size_t(pilots[k])].theta_deg;
        }
      }
    const bool on = worst > tol || forced.has(Component::Multiple);
    auto d = decision("multiple", on,
                      "pilot multiply scattered energy " + fmt3(worstValue) + " (+3 SE: " + fmt3(worst) + ") at theta " +
                          fmt3(worstTheta) + " deg " + (worst > tol ? "exceeds" : "is below") + " the tolerance " +
                          fmt3(tol) + (forced.has(Component::Multiple) && worst <= tol ? "; kept: requested" : ""));
    d["pilot_energy"] = worstValue;
    d["pilot_energy_upper"] = worst;
    decisions.push_back(d);
    if (on) chosen.add(Component::Multiple);
  }

  // Diffraction.
  {
    nlohmann::json d;
    bool on = false;
    const double meanLambda = job.meanLambda_um();
    const double binDeg = degrees(std::sqrt(2 * kPi / grid.binsPerHemisphere()));
    if (job.statistical) {
      d = decision("incoherent", false, "a statistical surface has no explicit geometry to diffract (microflake model)");
    } else {
      WaveSettings ws;
      ws.estimator = job.resolvedWaveEstimator();
      ws.samplesPerBin = std::max<int>(options.waveSamplesPerBin, int(job.waveSamplesPerBin));
      ws.pointsPerDirection = int(job.wavePointsPerDirection);
      ws.incidenceDirections = int(job.waveIncidenceDirections);
      ws.seed = job.seed;
      auto est = makeWaveEstimator(WaveContext{job.geometry, *transport.scene(), job.material, job.lambda_um(), grid,
                                               CoherenceWindow::fromCoherenceLength(job.scene.coherenceLength_um,
                                                                                    job.geometry.sizeX, job.geometry.sizeY,
                                                                                    job.geometry.periodic),
                                               ws});
      // Per pilot and wavelength: the L1 difference and its noise; the decision uses the largest
      // upper estimate (L1 − floor + 2 sd) and the largest lower estimate (L1 − floor − 2 sd).
      double upper = -1e300, lower = -1e300, worstL1 = 0, worstFloor = 0, worstTheta = 0;
      for (size_t k = 0; k < pilots.size(); ++k) {
        const auto& inc = job.incidence[size_t(pilots[k])];
        const WaveTileResult w = est->run(pilots[k], inc.bin, beam(pilots[k]));
        const TileResult& r = geo[k];
        for (int l = 0; l < nL; ++l) {
          double l1 = 0, floor = 0, var = 0;
          for (int b = 0; b < nB; ++b) {
            const size_t x = size_t(l) * nB + b;
            const double op = grid.projectedSolidAngle(b);
            const double s = std::hypot(w.fwsErr[x], r.stdError[int(Component::Coherent)][x]);
            l1 += std::abs(w.fws[x] - r.at(Component::Coherent, l, b)) * op;
            floor += std::sqrt(2 / kPi) * s * op;
            var += s * op * s * op;
          }
          lower = std::max(lower, l1 - floor - 2 * std::sqrt(var));
          if (l1 - floor + 2 * std::sqrt(var) > upper) {
            upper = l1 - floor + 2 * std::sqrt(var);
            worstL1 = l1;
            worstFloor = floor;
            worstTheta = inc.theta_deg;
          }
        }
      }
      const double sigmaH = rmsHeight(job.geometry), slope = rmsSlope(job.geometry);
      // Rayleigh roughness at the most grazing pilot (the smallest g, the strongest specular spike).
      double cosMin = 1;
      for (int p : pilots) cosMin = std::min(cosMin, std::abs(grid.centre(job.incidence[size_t(p)].bin).z));
      const double g = std::pow(4 * kPi * sigmaH * cosMin / meanLambda, 2);
      const double blurDeg = job.scene.coherenceLength_um > 0 ? degrees(meanLambda / job.scene.coherenceLength_um) : 0;
      std::string why = "pilot WS - GS difference sum|f_ws - f_coh| * proj. solid angle = " + fmt3(worstL1) +
                        " (noise floor " + fmt3(worstFloor) + "; beyond noise: lower estimate " + fmt3(lower) +
                        ", upper " + fmt3(upper) + ") at theta " + fmt3(worstTheta) + " deg";
      // Kirchhoff-theory estimate, used when the pilot cannot decide (its noise straddles the
      // tolerance): the diffraction-limited specular spike 2 R e^{-g} (geometric optics has none;
      // R <= 1) plus the blur of a lobe of width 2·slope by the window's diffraction, angular sd
      // λ/(2√2 π σ_w) with σ_w = δc/6, which changes a Gaussian lobe by about (blur/width)² in L1.
      // Valid only for features much larger than λ: correlation length √2 σ_h / slope >= 5 λ.
      const double corr = slope > 0 ? std::sqrt(2.0) * sigmaH / slope : 0.0;
      const double sigmaW = job.scene.coherenceLength_um / 6.0;
      const double blurRad = sigmaW > 0 ? meanLambda / (2 * std::sqrt(2.0) * kPi * sigmaW) : kPi;
      const double lobeRad = 2 * slope;
      const double physical = 2 * std::exp(-std::min(g, 700.0)) + (lobeRad > 0 ? std::pow(blurRad / lobeRad, 2) : 1e300);
      const bool geometricRegime = corr >= 5 * meanLambda && slope > 0;
      if (upper <= tol) {
        on = false;
        why += " is below the tolerance " + fmt3(tol);
      } else if (lower > tol) {
        on = true;
        why += " exceeds the tolerance " + fmt3(tol);
      } else if (geometricRegime) {
        on = physical > tol;
        why += " cannot decide at the tolerance " + fmt3(tol) + "; Kirchhoff estimate 2 exp(-g) + (blur/lobe)^2 = " +
               fmt3(physical) + " (correlation length " + fmt3(corr) + " um >= 5 lambda, blur " + fmt3(degrees(blurRad)) +
               " deg, lobe " + fmt3(degrees(lobeRad)) + " deg) " + (on ? "exceeds it" : "is below it");
      } else {
        on = true;
        why += " cannot decide at the tolerance " + fmt3(tol) + " and the features (correlation length " + fmt3(corr) +
               " um) are not >> lambda: kept on";
      }
      d = decision("incoherent", on,
                   why + "; Rayleigh roughness g = " + fmt3(g) +
                       (g < 0.1 ? " (smooth: specular with a diffuse halo)" : g > 10 ? " (rough)" : " (intermediate)") +
                       "; coherence blur lambda/delta_c = " + fmt3(blurDeg) + " deg vs bins of " + fmt3(binDeg) + " deg");
      d["pilot_lower"] = lower;
      d["kirchhoff_estimate"] = physical;
      d["rms_slope"] = slope;
      d["correlation_length_um"] = corr;
      d["pilot_l1"] = worstL1;
      d["pilot_noise_floor"] = worstFloor;
      d["pilot_upper"] = upper;
      d["rayleigh_g"] = g;
      d["rms_height_um"] = sigmaH;
      d["coherence_blur_deg"] = blurDeg;
      d["bin_deg"] = binDeg;
      d["wave_samples_per_bin"] = ws.samplesPerBin;
    }
    if (forced.has(Component::Incoherent) && !on) {
      d["reason"] = d["reason"].get<std::string>() + "; kept: requested";
      on = true;
    }
    d["on"] = on;
    decisions.push_back(d);
    if (on) chosen.add(Component::Incoherent);
  }

  // Lost, transmission, wavelengths.
  {
    const bool lost = forced.has(Component::Lost);
    decisions.push_back(decision("lost", lost, lost ? "requested" : "a diagnostic, not part of any model: only on request"));
    if (lost) chosen.add(Component::Lost);
  }
  if (job.material.isConductor()) {
    decisions.push_back(decision("btdf", false, "a conductor transmits nothing: no BTDF (transmitted bins are zero)"));
  } else {
    const bool needs = std::find(job.scene.needs.begin(), job.scene.needs.end(), "btdf") != job.scene.needs.end();
    // Without a BTDF to render, the wave term's transmitted bins are not worth their cost; the
    // paths still cross the surface (a dielectric's reflection depends on what comes back through
    // it), so the transmitted table keeps geometric optics. Kept when `lost` is requested (its
    // masked power needs every exit bin).
    const bool skip = !needs && chosen.has(Component::Incoherent) && !chosen.has(Component::Lost);
    auto d = decision("btdf", needs, needs ? "a dielectric transmits and the renderer needs the BTDF"
                                           : skip ? "the renderer needs only the BRDF: the wave term skips the transmitted "
                                                    "bins, which keep geometric optics (incoherent = 0 there)"
                                                  : "the renderer needs only the BRDF; transmission is traced with the "
                                                    "reflection (the paths cross the surface) and costs no wave term here");
    decisions.push_back(d);
    plan["wave_transmission"] = !skip;
  }
  {
    const bool shared = job.material.directionsIndependentOfLambda();
    decisions.push_back(decision(
        "wavelengths", true,
        std::to_string(nL) + " wavelengths; " +
            (shared ? "paths shared by all of them (only Fresnel depends on lambda: per-wavelength weights)"
                    : "one path set per wavelength (dispersive dielectric: refraction depends on lambda)") +
            (chosen.has(Component::Incoherent) ? "; the wave term is evaluated per wavelength" : "")));
  }

  std::vector<std::string> names;
  for (Component c : chosen.list()) names.push_back(componentName(c));
  plan["components"] = names;
  plan["decisions"] = decisions;
  plan["tolerance"] = tol;
  plan["coherence_length_um"] = job.scene.coherenceLength_um;
  plan["coherence_source"] = job.scene.coherenceSource;
  if (job.scene.sourceAngularDiameter_deg > 0) plan["source_angular_diameter_deg"] = job.scene.sourceAngularDiameter_deg;
  plan["pilots"] = pilots;
  plan["pilot_paths"] = paths;
  plan["pilot_seconds"] = std::chrono::duration<double>(Clock::now() - t0).count();
  return plan;
}

void applyEffectsPlan(Job& job, const nlohmann::json& plan) {
  job.components = ComponentSet{};
  for (const auto& n : plan["components"]) job.components.add(*componentFromName(n.get<std::string>()));
  job.waveTransmission = plan.value("wave_transmission", true);
  job.effectsPlan = plan.dump();
}

std::string formatEffects(const nlohmann::json& plan) {
  std::ostringstream o;
  o << "effects (auto, tolerance " << fmt3(plan["tolerance"].get<double>()) << ", coherence length "
    << fmt3(plan["coherence_length_um"].get<double>()) << " um from " << plan["coherence_source"].get<std::string>()
    << "; pilots " << plan["pilots"].dump() << " in " << fmt3(plan["pilot_seconds"].get<double>()) << " s):\n";
  for (const auto& d : plan["decisions"]) {
    std::string e = d["effect"].get<std::string>();
    e.resize(12, ' ');
    o << "  " << e << (d["on"].get<bool>() ? "on   " : "off  ") << d["reason"].get<std::string>() << "\n";
  }
  return o.str();
}

}  // namespace mbsdf
