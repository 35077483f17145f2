#include "io/file_summary.h"

#include <cmath>

namespace mbsdf {

nlohmann::json fileSummary(const BsdfFileReader& f, const std::string& path) {
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
  if (f.hasAttribute("wave_errors")) j["wave_errors"] = f.attribute("wave_errors");
  if (f.hasAttribute("scalar_model")) j["scalar_model"] = f.attribute("scalar_model");
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
      if (!st.nonphysical.empty()) {
        std::vector<unsigned> bits;
        for (double x : st.nonphysical) bits.push_back(std::isfinite(x) ? unsigned(x) : 0u);
        s["nonphysical"] = bits;
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

SliceSummary summariseSlice(const nlohmann::json& s) {
  auto mean = [](const nlohmann::json& a) {
    double m = 0;
    for (auto& v : a) m += v.get<double>();
    return a.empty() ? 0.0 : m / double(a.size());
  };
  SliceSummary r;
  r.lost = std::nan("");
  for (const char* side : {"reflected", "transmitted"})
    for (auto& [c, v] : s["energy"][side].items()) {
      if (c == "lost")
        r.lost = (std::isnan(r.lost) ? 0.0 : r.lost) + mean(v);
      else
        (side[0] == 'r' ? r.reflected : r.transmitted) += mean(v);
    }
  if (s.contains("rel_error"))
    for (auto& [c, v] : s["rel_error"].items())
      if (c != "lost")
        for (auto& x : v) r.relError = std::max(r.relError, x.get<double>());
  r.albedoStdError = s["energy"].contains("total_stderr") ? mean(s["energy"]["total_stderr"]) : std::nan("");
  r.balance = std::nan("");
  if (s.contains("energy_balance"))
    for (auto& x : s["energy_balance"])
      if (!(std::abs(x.get<double>()) <= std::abs(r.balance))) r.balance = x.get<double>();
  r.truncated = mean(s["truncated"]);
  if (s.contains("nonphysical"))
    for (auto& x : s["nonphysical"]) r.nonphysical |= x.get<unsigned>();
  return r;
}

}  // namespace mbsdf
