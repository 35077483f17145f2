// `microbsdf info OUT.h5 [--json]`: provenance, completeness, the effects planner's decisions and
// the energy, error and sampling of every slice of an output file.
#include <spdlog/fmt/fmt.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <iostream>

#include "cmd/command.h"
#include "io/bsdf_file.h"
#include "job/effects_planner.h"

namespace mbsdf {
namespace {

nlohmann::json infoJson(const BsdfFileReader& f, const std::string& path) {
  nlohmann::json j;
  j["file"] = path;
  j["schema_version"] = f.intAttribute("schema_version");
  j["program_version"] = f.attribute("program_version");
  j["geometry_kind"] = f.attribute("geometry_kind");
  j["geometry_hash"] = f.attribute("geometry_hash");
  j["material"] = f.attribute("material");
  j["grid"] = f.grid().kind();
  j["bins"] = f.grid().binCount();
  j["wavelengths_nm"] = f.wavelengths_nm();
  j["components"] = f.components();
  if (f.hasAttribute("reciprocity")) j["reciprocity"] = f.attribute("reciprocity");
  j["storage_profile"] = f.storageProfile();
  // components = "auto": the effects planner's decisions, their reasons, pilots and pilot budget.
  if (f.hasAttribute("effects_plan")) j["effects_plan"] = nlohmann::json::parse(f.attribute("effects_plan"));
  int done = 0;
  uint64_t waveSamples = 0;
  nlohmann::json slices = nlohmann::json::array();
  for (int i = 0; i < f.incidenceCount(); ++i) {
    nlohmann::json s;
    s["index"] = i;
    s["bin"] = f.incidenceBin(i);
    s["theta_deg"] = f.incidenceTheta(i);
    s["phi_deg"] = f.incidencePhi(i);
    s["done"] = f.done(i);
    if (f.done(i)) {
      ++done;
      SliceStats st = f.stats(i);
      s["samples"] = st.samples;
      s["wave_samples"] = st.waveSamples;
      waveSamples += st.waveSamples;
      s["seconds"] = st.seconds;
      s["sampling_stop"] = st.samplingStop == 1 ? "target" : st.samplingStop == 2 ? "budget" : "fixed";
      if (!std::isnan(st.multipleCheck)) {
        s["multiple_check"] = st.multipleCheck;
        s["multiple_reenabled"] = st.multipleReenabled;
      }
      if (!std::isnan(st.diffractionCheck)) {
        s["diffraction_check"] = st.diffractionCheck;
        s["diffraction_reenabled"] = st.diffractionReenabled;
      }
      s["truncated"] = st.truncated;
      s["leaked"] = st.leaked;
      s["missed"] = st.missed;
      for (auto& [c, v] : st.energyReflected) s["energy"]["reflected"][c] = v;
      for (auto& [c, v] : st.energyTransmitted) s["energy"]["transmitted"][c] = v;
      for (auto& [c, v] : st.relError) s["rel_error"][c] = v;
      if (!st.pathsRelError.empty()) s["paths_rel_error"] = st.pathsRelError;
      // Albedo of the model the file holds (its components summed, reflected + transmitted), per
      // wavelength; `lost` is a diagnostic, not part of any model, and is left out.
      std::vector<double> total(f.wavelengths_nm().size(), 0.0);
      for (auto& [c, v] : st.energyReflected)
        if (c != "lost")
          for (size_t l = 0; l < v.size(); ++l) total[l] += v[l] + st.energyTransmitted[c][l];
      s["energy"]["total"] = total;
      if (!st.pathsAlbedoStdError.empty()) {
        // The albedo's standard error: the path-traced components' from the per-path energies, the
        // others' (wave term; the facet sum's bound where no path ran) added in quadrature.
        for (auto& [c, v] : st.energyReflectedStdError) s["energy"]["reflected_stderr"][c] = v;
        for (auto& [c, v] : st.energyTransmittedStdError) s["energy"]["transmitted_stderr"][c] = v;
        std::vector<double> se2(total.size(), 0.0);
        for (size_t l = 0; l < se2.size(); ++l) se2[l] = st.pathsAlbedoStdError[l] * st.pathsAlbedoStdError[l];
        for (auto& [c, v] : st.energyReflectedStdError) {
          const bool traced = st.samples > 0 && (c == "coherent" || c == "multiple");
          if (c == "lost" || traced) continue;
          for (size_t l = 0; l < se2.size(); ++l)
            se2[l] += v[l] * v[l] + st.energyTransmittedStdError[c][l] * st.energyTransmittedStdError[c][l];
        }
        std::vector<double> se(se2.size());
        for (size_t l = 0; l < se.size(); ++l) se[l] = std::sqrt(se2[l]);
        s["energy"]["total_stderr"] = se;
      }
      if (!st.energyBalance.empty()) {
        s["energy_balance"] = st.energyBalance;
        s["energy_balance_stderr"] = st.energyBalanceStdError;
      }
    }
    slices.push_back(s);
  }
  j["incidence_count"] = f.incidenceCount();
  j["done_count"] = done;
  j["complete"] = done == f.incidenceCount();
  j["wave_samples"] = waveSamples;
  j["slices"] = slices;
  return j;
}

void printInfo(const nlohmann::json& j) {
  std::cout << "file:        " << j["file"].get<std::string>() << "\n"
            << "geometry:    " << j["geometry_kind"].get<std::string>() << " (hash "
            << j["geometry_hash"].get<std::string>() << ")\n"
            << "material:    " << j["material"].get<std::string>() << "\n"
            << "grid:        " << j["grid"].get<std::string>() << ", " << j["bins"] << " bins over the sphere\n"
            << "wavelengths: " << j["wavelengths_nm"].dump() << " nm\n"
            << "components:  " << j["components"].dump() << "\n"
            << (j.contains("reciprocity") ? "reciprocity: " + j["reciprocity"].get<std::string>() + "\n" : "")
            << "storage:     " << j["storage_profile"].get<std::string>() << "\n"
            << (j.contains("effects_plan") ? formatEffects(EffectsPlan::fromJson(j["effects_plan"])) : "")
            << (j["wave_samples"].get<uint64_t>()
                    ? "wave term:   " + j["wave_samples"].dump() + " Kirchhoff samples per wavelength\n"
                    : "")
            << (j["complete"].get<bool>()
                    ? "complete:    " + j["done_count"].dump() + "/" + j["incidence_count"].dump() + " slices\n"
                    : "incomplete:  " + j["done_count"].dump() + " of " + j["incidence_count"].dump() +
                          " slices (a run that has not finished; the missing slices are not listed below)\n");
  std::cout << "slice  theta   phi     samples     seconds  albedo(mean over λ)  ± s.e.     reflected  transmitted  "
               "truncated  rel.error  balance     lost\n"
            << "(albedo: the components the file holds, without the lost diagnostic, ± its standard error (the\n"
            << " mean over λ of each λ's); rel.error: the largest estimated relative per-bin error of a slice over\n"
            << " its components but lost, and wavelengths; balance: reflected + transmitted + lost paths − 1, the\n"
            << " largest over λ, for a material that absorbs only an excess over 1 — the model's energy error;\n"
            << " lost: the energy of the lost component (Falster et al. 2020, Eq. 20, mean over λ), which WM + lost "
               "should bring\n"
            << " to GM's energy; — when the file has no lost component)\n";
  int reached = 0, budget = 0;
  // Skips the effects planner made, verified per slice: slices checked, those re-enabled, the largest check.
  struct Verified {
    int slices = 0;
    std::vector<int> reenabled;
    double worst = 0;
  } multiple, diffraction;
  auto tally = [](Verified& v, const nlohmann::json& s, const char* check, const char* reenabled) {
    if (!s.contains(check)) return;
    ++v.slices;
    if (s[reenabled].get<bool>()) v.reenabled.push_back(s["index"].get<int>());
    v.worst = std::max(v.worst, s[check].get<double>());
  };
  for (const auto& s : j["slices"]) {
    if (!s["done"].get<bool>()) continue;
    auto mean = [](const nlohmann::json& a) {
      double m = 0;
      for (auto& v : a) m += v.get<double>();
      return a.empty() ? 0.0 : m / a.size();
    };
    double refl = 0, trans = 0, lost = std::nan("");
    for (const char* side : {"reflected", "transmitted"})
      for (auto& [c, v] : s["energy"][side].items()) {
        if (c == "lost")
          lost = (std::isnan(lost) ? 0.0 : lost) + mean(v);
        else
          (side[0] == 'r' ? refl : trans) += mean(v);
      }
    double rel = 0;
    if (s.contains("rel_error"))
      for (auto& [c, v] : s["rel_error"].items())
        if (c != "lost")
          for (auto& x : v) rel = std::max(rel, x.get<double>());
    const double se = s["energy"].contains("total_stderr") ? mean(s["energy"]["total_stderr"]) : std::nan("");
    double balance = std::nan("");
    if (s.contains("energy_balance"))
      for (auto& x : s["energy_balance"])
        if (!(std::abs(x.get<double>()) <= std::abs(balance))) balance = x.get<double>();
    std::printf("%5d %6.2f %6.2f %11llu %11.3f %12.6f %16.2e %12.6f %12.6f %10.2e %10.2e %+8.4f %s\n",
                s["index"].get<int>(), s["theta_deg"].get<double>(), s["phi_deg"].get<double>(),
                (unsigned long long)s["samples"].get<uint64_t>(), s["seconds"].get<double>(), refl + trans, se, refl,
                trans, mean(s["truncated"]), rel, balance,
                std::isnan(lost) ? "       —" : fmt::format("{:+8.4f}", lost).c_str());
    if (s["sampling_stop"] == "target") ++reached;
    if (s["sampling_stop"] == "budget") ++budget;
    tally(multiple, s, "multiple_check", "multiple_reenabled");
    tally(diffraction, s, "diffraction_check", "diffraction_reenabled");
  }
  if (reached + budget > 0)
    std::printf("progressive sampling: %d slices reached target_rel_error, %d stopped at max_paths_per_slice first\n",
                reached, budget);
  auto report = [](const Verified& v, const char* what, const char* figure) {
    if (v.slices == 0) return;
    std::string which;
    for (int i : v.reenabled) which += (which.empty() ? "" : " ") + std::to_string(i);
    std::printf("%s: skipped by the effects planner, verified on %d slice(s) (largest %s %.4f): %s\n", what, v.slices,
                figure, v.worst,
                v.reenabled.empty() ? "the skip held on every one"
                                    : ("beyond the tolerance, computed after all, on slice(s) " + which).c_str());
  };
  report(multiple, "multiple scattering", "energy + 3 s.e.");
  report(diffraction, "diffraction", "WS - GS difference beyond noise");
}

}  // namespace

Command addInfoCommand(CLI::App& app) {
  struct Options {
    std::string h5Path;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  Command c;
  c.app = app.add_subcommand("info", "provenance, completeness and energy per slice of an output file");
  c.app->add_option("file", o->h5Path, "output HDF5 file")->required();
  c.app->add_flag("--json", o->json, "machine-readable summary");
  c.run = [o] {
    BsdfFileReader f(o->h5Path);
    nlohmann::json j = infoJson(f, o->h5Path);
    if (o->json)
      std::cout << j.dump(2) << "\n";
    else
      printInfo(j);
    return 0;
  };
  return c;
}

}  // namespace mbsdf
