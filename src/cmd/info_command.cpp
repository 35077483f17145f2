// `microbsdf info OUT.h5 [--json]`: provenance, completeness, the effects planner's decisions and
// the energy, error and sampling of every slice of an output file.
#include <spdlog/fmt/fmt.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <iostream>

#include "cmd/command.h"
#include "io/bsdf_file.h"
#include "io/file_summary.h"
#include "job/effects_planner.h"

namespace mbsdf {
namespace {

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
            << (j.contains("wave_errors") ? "WARNING:     " + j["wave_errors"].get<std::string>() + "\n" : "")
            << (j.contains("scalar_model") ? "WARNING:     " + j["scalar_model"].get<std::string>() + "\n" : "")
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
  std::vector<std::string> nonphysical;  // one line per flagged slice
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
    const SliceSummary r = summariseSlice(s);
    std::printf("%5d %6.2f %6.2f %11llu %11.3f %12.6f %16.2e %12.6f %12.6f %10.2e %10.2e %+8.4f %s\n",
                s["index"].get<int>(), s["theta_deg"].get<double>(), s["phi_deg"].get<double>(),
                (unsigned long long)s["samples"].get<uint64_t>(), s["seconds"].get<double>(),
                r.reflected + r.transmitted, r.albedoStdError, r.reflected, r.transmitted, r.truncated, r.relError,
                r.balance, std::isnan(r.lost) ? "       —" : fmt::format("{:+8.4f}", r.lost).c_str());
    if (r.nonphysical)
      nonphysical.push_back(fmt::format("  slice {} (theta {:.2f}, phi {:.2f}): {}", s["index"].get<int>(),
                                        s["theta_deg"].get<double>(), s["phi_deg"].get<double>(),
                                        describeSliceFlags(r.nonphysical)));
    if (s["sampling_stop"] == "target") ++reached;
    if (s["sampling_stop"] == "budget") ++budget;
    tally(multiple, s, "multiple_check", "multiple_reenabled");
    tally(diffraction, s, "diffraction_check", "diffraction_reenabled");
  }
  if (!nonphysical.empty()) {
    std::printf(
        "not physical: %zu slice(s) (/stats/nonphysical: energy outside [0, 1] or a balance beyond the "
        "tolerance, each beyond 3 s.e., or paths lost beyond the tolerance)\n",
        nonphysical.size());
    for (const std::string& line : nonphysical) std::printf("%s\n", line.c_str());
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

// Reads every table of a finished file once (BsdfFileReader::slice refuses a NaN, an Inf or a
// negative value where its component cannot hold one, with the slice): what `info` vouches for.
// Files above kScanBytes are scanned only with --scan. Returns the values read (0: not scanned).
constexpr double kScanBytes = 2e9;
enum class ScanScope { UpToLimit, Always };
uint64_t scanTables(const BsdfFileReader& f, ScanScope scope, double* bytes) {
  const std::vector<std::string> components = f.components();
  const double perSlice = double(f.grid().binCount()) * double(f.channelCount());
  *bytes = 4.0 * perSlice * double(f.incidenceCount()) * double(components.size());
  if (f.doneCount() != f.incidenceCount() || (*bytes > kScanBytes && scope != ScanScope::Always)) return 0;
  uint64_t values = 0;
  for (const std::string& c : components)
    for (int i = 0; i < f.incidenceCount(); ++i) {
      values += f.slice(c, i).size();
      if (f.hasBinErrors(c)) values += f.sliceStdError(c, i).size();
    }
  return values;
}

}  // namespace

Command addInfoCommand(CLI::App& app) {
  struct Options {
    std::string h5Path;
    bool json = false;
    bool scan = false;
  };
  auto o = std::make_shared<Options>();
  Command c;
  c.app = app.add_subcommand("info", "provenance, completeness and energy per slice of an output file");
  c.app->add_option("file", o->h5Path, "output HDF5 file")->required();
  c.app->add_flag("--json", o->json, "machine-readable summary");
  c.app->add_flag("--scan", o->scan, "read every value even of a file above 2 GB (smaller ones always are)");
  c.run = [o] {
    BsdfFileReader f(o->h5Path);
    nlohmann::json j = fileSummary(f, o->h5Path);
    double bytes = 0;
    const uint64_t values = scanTables(f, o->scan ? ScanScope::Always : ScanScope::UpToLimit, &bytes);
    j["values_scanned"] = values;
    if (o->json)
      std::cout << j.dump(2) << "\n";
    else {
      printInfo(j);
      if (values > 0)
        fmt::print("values: {} read, all finite and none negative where a component cannot be\n", values);
      else if (f.doneCount() == f.incidenceCount())
        fmt::print("values: not read ({:.3g} GB; `info --scan` reads them)\n", bytes / 1e9);
    }
    return 0;
  };
  return c;
}

}  // namespace mbsdf
