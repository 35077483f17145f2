// microbsdf: the command-line entry point (README "A five-minute tour", docs/running.md).
//   microbsdf run JOB.toml [-o OUT.h5] [--threads N] [--log-dir DIR] [--resume] [--max-hours H] [-v]
//   microbsdf info OUT.h5 [--json]
//   microbsdf slice OUT.h5 --theta-i DEG [--phi-i DEG] [--model GM] [--transmission|--both]
//                  [--style true|false] -o x.exr|x.png|x.csv
//   microbsdf geometry JOB.toml -o patch.ply
//   microbsdf check JOB.toml
//   microbsdf plan JOB.toml [--json plan.json]
// Exit codes (core/error.h, README "Exit codes"): 0 success, 1 unexpected failure, 2 bad input (job
// file, input files, arguments, output location), 3 stopped early by a signal (SIGTERM, SIGINT,
// SIGUSR1) or --max-hours (rerun with --resume), 4 the output could not be written (resumable),
// 5 another run holds the output.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>

#include <tbb/global_control.h>

#include "core/error.h"
#include "core/log.h"
#include "core/stop.h"
#include "io/hdf5_handle.h"
#include "io/output_target.h"
#include "cluster/mpi_session.h"
#include "cluster/runner.h"
#include "geometry/microgeometry.h"
#include "microflake/compare_smith.h"
#include "microflake/ndf.h"
#include "io/bsdf_file.h"
#include "io/slice_export.h"
#include "io/contact_sheet.h"
#include "render/preview.h"
#include "job/job.h"
#include "job/job_keys.h"
#include "job/effects_planner.h"
#include "job/plan.h"
#include "job/scalar_validity.h"

using namespace mbsdf;

namespace {

// Comma-separated lists of the command line.
std::vector<std::string> splitList(const std::string& s, bool skipEmpty) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!(skipEmpty && item.empty())) v.push_back(item);
  return v;
}
// Model names (GS, GM, WS, WM or a component), each checked; empty items are skipped.
std::vector<std::string> parseModels(const std::string& s) {
  std::vector<std::string> models = splitList(s, true);
  for (const auto& m : models)
    if (!modelComponents(m)) throw InputError("--models: unknown model '" + m + "' (GS, GM, WS, WM or a component)");
  return models;
}
// Angles in degrees, each in [0, hi] (or [0, hi) when !hiInclusive); every item must be a number.
std::vector<double> parseAngles(const std::string& s, const std::string& option, double hi, bool hiInclusive) {
  std::vector<double> angles;
  for (const auto& item : splitList(s, false)) {
    size_t used = 0;
    double v = std::nan("");
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
    }
    if (used != item.size() || !(v >= 0 && (hiInclusive ? v <= hi : v < hi)))
      throw InputError(option + ": '" + item + "' is not an angle in [0, " + fmt::format("{}", hi) +
                       (hiInclusive ? "]" : ")"));
    angles.push_back(v);
  }
  return angles;
}

constexpr int kExitInput = exitCode(ExitCode::BadInput), kExitFailure = exitCode(ExitCode::Failure);

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

void warnIfIncomplete(const BsdfFileReader& f, const std::string& how) {
  if (f.doneCount() < f.incidenceCount())
    std::cerr << "warning: incomplete: " << f.doneCount() << " of " << f.incidenceCount() << " slices; " << how << "\n";
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
            << (j.contains("effects_plan") ? formatEffects(j["effects_plan"]) : "")
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
  int reached = 0, budget = 0, verified = 0;
  std::vector<int> reenabled;
  double worstCheck = 0;
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
    if (s.contains("multiple_check")) {
      ++verified;
      if (s["multiple_reenabled"].get<bool>()) reenabled.push_back(s["index"].get<int>());
      worstCheck = std::max(worstCheck, s["multiple_check"].get<double>());
    }
  }
  if (reached + budget > 0)
    std::printf("progressive sampling: %d slices reached target_rel_error, %d stopped at max_paths_per_slice first\n",
                reached, budget);
  if (verified > 0) {
    std::string which;
    for (int i : reenabled) which += (which.empty() ? "" : " ") + std::to_string(i);
    std::printf(
        "multiple scattering: skipped by the effects planner, verified on %d slice(s) (largest energy + 3 s.e. "
        "%.4f): %s\n",
        verified, worstCheck,
        reenabled.empty() ? "the skip held on every one"
                          : ("beyond the tolerance, computed after all, on slice(s) " + which).c_str());
  }
}

// `run`: every rank loads the job; rank 0 checks the output location and takes its lock before any
// compute, runs the effects planner's pilots, then all ranks run the tiles. Foreseeable failures end
// every rank with the same exit code and one message; only an unexpected one aborts the job.
int runCommand(int argc, char** argv, const std::string& jobPath, std::string outPath, std::string logDir, int threads,
               bool resume, double maxHours, bool verbose) {
  MpiSession mpi(&argc, &argv);
  installStopHandlers();
  setupLogging(mpi.rank(), "", "", verbose);
  // Rank 0's outcome of a step on every rank: "" to go on, else "<exit code> <message>".
  auto agree = [&](const std::string& failure) -> std::optional<int> {
    const std::string f = mpi.broadcast(failure);
    if (f.empty()) return std::nullopt;
    if (mpi.rank() == 0) spdlog::error("{}", f.substr(f.find(' ') + 1));
    return std::stoi(f.substr(0, f.find(' ')));
  };
  auto failure = [](ExitCode c, const std::string& msg) { return std::to_string(exitCode(c)) + " " + msg; };
  std::optional<Job> job;
  std::string error;
  try {
    job = loadJob(jobPath);
  } catch (const InputError& e) {
    error = e.what();
  } catch (const std::exception& e) {
    error = std::string(jobPath) + ": " + e.what();
  }
  // Fail together: every rank exits non-zero, one message from rank 0, no hang.
  if (mpi.anyRank(!error.empty())) {
    if (mpi.rank() == 0) spdlog::error("{}", error.empty() ? "another rank could not read the job" : error);
    return exitCode(ExitCode::BadInput);
  }
  const std::string out = outPath.empty() ? job->outputPath : outPath;
  if (logDir.empty()) logDir = out + ".logs";
  // The output location, before any compute: a folder, an unwritable place or a busy output fail
  // in a second instead of after the allocation is spent.
  std::optional<OutputLock> lock;
  std::string setup;
  if (mpi.rank() == 0) {
    try {
      checkOutputPath(out);
      checkWritableFolder(logDir, "log");
      lock.emplace(out);
    } catch (const InputError& e) {
      setup = failure(ExitCode::BadInput, e.what());
    } catch (const OutputBusyError& e) {
      setup = failure(ExitCode::OutputBusy, e.what());
    } catch (const WriteError& e) {
      setup = failure(ExitCode::WriteFailed, e.what());
    }
  }
  if (auto code = agree(setup)) return *code;
  try {
    setupLogging(mpi.rank(), logDir, std::filesystem::path(out).stem().string(), verbose);
  } catch (const InputError& e) {
    error = e.what();
  }
  if (mpi.anyRank(!error.empty())) {
    if (!error.empty()) std::cerr << "error: " << error << "\n";
    return exitCode(ExitCode::BadInput);
  }
  if (lock && !lock->previousHolder().empty())
    spdlog::info("output lock {}: the run that held it ({}) is gone; taken over", lock->path(), lock->previousHolder());
  if (mpi.rank() == 0) {
    const ScalarValidity validity = scalarValidity(*job);
    if (validity.applies) {
      if (validity.beyondTolerance)
        spdlog::warn("scalar model: {}", validity.note);
      else
        spdlog::info("scalar model: {}", validity.note);
    }
  }
  try {
    if (job->autoComponents) {
      // components = "auto": rank 0 runs the pilots, every rank applies the same plan.
      std::string planText, stopped;
      if (mpi.rank() == 0) {
        std::optional<tbb::global_control> limit;
        if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(threads));
        try {
          nlohmann::json p = planEffects(*job);
          for (std::istringstream lines(formatEffects(p)); std::getline(lines, planText);) spdlog::info("{}", planText);
          planText = p.dump();
        } catch (const StopRequested&) {
          stopped =
              failure(ExitCode::Stopped, "stop requested during the effects planner's pilots (" + stopAnswerNote() +
                                             "); nothing was written (run the same command again to start over)");
        }
      }
      if (auto code = agree(stopped)) return *code;
      applyEffectsPlan(*job, nlohmann::json::parse(mpi.broadcast(planText)));
    }
    RunOptions opt;
    opt.outputPath = out;
    opt.threads = threads;
    opt.resume = resume;
    opt.maxHours = maxHours;
    RunSummary s = runJob(*job, mpi, opt);
    if (s.exit != ExitCode::Ok) {
      if (mpi.rank() == 0) spdlog::error("{}", s.error.empty() ? "run failed" : s.error);
      return exitCode(s.exit);
    }
    if (s.stoppedEarly) return exitCode(ExitCode::Stopped);
    if (mpi.rank() == 0)
      spdlog::info("done: {} slices ({} tiles computed now, {} slices resumed), {} paths in total, {:.2f} s, wrote {}",
                   s.tiles, s.computed, s.resumed, s.paths, s.seconds, out);
  } catch (const std::bad_alloc&) {
    spdlog::error("run failed: out of memory (see `microbsdf plan` for the job's estimate per rank)");
    MPI_Abort(MPI_COMM_WORLD, exitCode(ExitCode::Failure));
    return exitCode(ExitCode::Failure);
  } catch (const std::exception& e) {
    spdlog::error("run failed: {}", e.what());
    MPI_Abort(MPI_COMM_WORLD, exitCode(ExitCode::Failure));
    return exitCode(ExitCode::Failure);
  }
  return exitCode(ExitCode::Ok);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"microbsdf: tabulated BSDFs (BRDF + BTDF) of explicit surface microgeometry"};
  app.require_subcommand(1);
  app.set_version_flag("--version", MICROBSDF_VERSION);

  std::string jobPath, outPath, logDir, h5Path, model = "GM";
  int threads = 0, sliceSize = 256;
  bool verbose = false, json = false, transmission = false, resume = false;
  double maxHours = 0;
  double thetaI = 0, phiI = 0;

  auto* run = app.add_subcommand("run", "compute the BSDF of a job (run it under mpirun/srun for several ranks)");
  run->add_option("job", jobPath, "job file (TOML)")->required();
  run->add_option("-o,--output", outPath, "output HDF5 file (default: [output] path of the job)");
  run->add_option("--threads", threads, "threads per rank (default: all cores)")->check(CLI::NonNegativeNumber);
  run->add_option("--log-dir", logDir, "folder for the per-rank log files (default: <output>.logs)");
  run->add_flag("-v,--verbose", verbose, "debug-level logging");
  run->add_flag("--resume", resume,
                "keep the finished slices of an interrupted run of the same job (harmless on a fresh run)");
  run->add_option("--max-hours", maxHours, "stop cleanly (exit code 3) before this wall time, in hours")
      ->check(CLI::NonNegativeNumber);

  auto* info = app.add_subcommand("info", "provenance, completeness and energy per slice of an output file");
  info->add_option("file", h5Path, "output HDF5 file")->required();
  info->add_flag("--json", json, "machine-readable summary");

  auto* slice = app.add_subcommand("slice", "export one BSDF slice as EXR (disk projection) or CSV");
  slice->add_option("file", h5Path, "output HDF5 file")->required();
  slice->add_option("--theta-i", thetaI, "incidence polar angle (degrees); the nearest computed slice is used");
  slice->add_option("--phi-i", phiI, "incidence azimuth (degrees)");
  slice->add_option("--model", model, "GS, GM, WS, WM or a component name")->capture_default_str();
  slice->add_flag("--transmission", transmission, "exit directions in the lower hemisphere (BTDF)");
  slice->add_option("--size", sliceSize, "image height in pixels")->capture_default_str();
  bool both = false;
  std::string style = "true";
  double exposure = 1.0, log2Min = -10, log2Max = 10;
  slice->add_flag("--both", both, "reflection (left) and transmission (right) side by side");
  slice->add_option("--style", style, "PNG: true (CIE 1931 -> sRGB) or false (log2 false colour)")
      ->check(CLI::IsMember({"true", "false"}))
      ->capture_default_str();
  slice->add_option("--exposure", exposure, "true colour: scale of the linear sRGB values")->capture_default_str();
  slice->add_option("--log2-min", log2Min, "false colour: lower end of the log2 scale")->capture_default_str();
  slice->add_option("--log2-max", log2Max, "false colour: upper end of the log2 scale")->capture_default_str();
  slice->add_option("-o,--output", outPath, "x.exr, x.png or x.csv")->required();

  SheetRequest sheetReq;
  std::string sheetModels, sheetThetas;
  auto* sheet =
      app.add_subcommand("sheet", "contact sheet PNG: slices over incidence angles (columns) and models (rows)");
  sheet->add_option("file", h5Path, "output HDF5 file")->required();
  sheet->add_option("--models", sheetModels, "comma separated (default: the GS, GM, WS, WM the file can form)");
  sheet->add_option("--theta-i", sheetThetas, "incidence angles in degrees, comma separated (default: every slice)");
  sheet->add_option("--phi-i", sheetReq.phi_deg, "incidence azimuth (degrees)")->capture_default_str();
  sheet->add_option("--size", sheetReq.cell.size, "cell height in pixels")->capture_default_str();
  sheet->add_flag("--both", sheetReq.cell.both, "reflection and transmission side by side in each cell");
  sheet->add_option("--style", sheetReq.cell.style, "true (CIE 1931 -> sRGB) or false (log2 false colour)")
      ->check(CLI::IsMember({"true", "false"}))
      ->capture_default_str();
  sheet->add_option("--exposure", sheetReq.cell.exposure, "true colour: scale of the linear sRGB values")
      ->capture_default_str();
  sheet->add_option("--log2-min", sheetReq.cell.log2Min, "false colour: lower end of the log2 scale")
      ->capture_default_str();
  sheet->add_option("--log2-max", sheetReq.cell.log2Max, "false colour: upper end of the log2 scale")
      ->capture_default_str();
  sheet->add_option("-o,--output", outPath, "sheet.png")->required();

  RenderRequest renderReq;
  std::string renderModels;
  auto* render = app.add_subcommand(
      "render", "preview PNG: a sphere with the tabulated BSDF per model, directional light + environment");
  render->add_option("file", h5Path, "output HDF5 file")->required();
  render->add_option("--models", renderModels, "comma separated (default: the GS, GM, WS, WM the file can form)");
  render->add_option("--size", renderReq.size, "pixels per sphere")->capture_default_str();
  render->add_option("--light-theta", renderReq.lightTheta_deg, "light direction, polar angle (degrees)")
      ->capture_default_str();
  render->add_option("--light-phi", renderReq.lightPhi_deg, "light direction, azimuth (degrees)")
      ->capture_default_str();
  render->add_option("--irradiance", renderReq.lightIrradiance, "light irradiance E")->capture_default_str();
  render->add_option("--environment", renderReq.environment, "uniform environment radiance (0: light only)")
      ->capture_default_str();
  render->add_option("--exposure", renderReq.exposure, "scale of the linear sRGB values")->capture_default_str();
  render->add_option("-o,--output", outPath, "render.png")->required();

  auto* geometry = app.add_subcommand("geometry", "write the job's microgeometry patch as PLY");
  geometry->add_option("job", jobPath, "job file (TOML)")->required();
  geometry->add_option("-o,--output", outPath, "patch.ply")->required();

  auto* check = app.add_subcommand("check", "validate a job file and print what it describes");

  bool keysMarkdown = false;
  auto* keys = app.add_subcommand("keys", "every key a job file may hold: type, default, accepted values, meaning");
  keys->add_flag("--markdown", keysMarkdown, "as the Markdown table of docs/job-reference.md");

  std::string planJson;
  auto* plan = app.add_subcommand(
      "plan", "what a job will compute and cost (tiles, core-hours, output size), from a short pilot");
  plan->add_option("job", jobPath, "job file (TOML)")->required();
  plan->add_option("--json", planJson, "also write the plan as JSON to this file");
  plan->add_option("--threads", threads, "threads for the pilot (default: all cores)")->check(CLI::NonNegativeNumber);
  check->add_option("job", jobPath, "job file (TOML)")->required();

  CompareSmithOptions cs;
  std::string csJson, csThetas;
  auto* compare = app.add_subcommand(
      "compare-smith", "Smith microflake model vs an explicit Gaussian heightfield with the same Beckmann NDF");
  compare->add_option("--alpha", cs.alpha, "Beckmann roughness")->capture_default_str();
  compare->add_option("--material", cs.material, "built-in conductor")->capture_default_str();
  compare->add_option("--lambda-nm", cs.lambda_nm, "wavelength (nm)")->capture_default_str();
  compare->add_option("--theta", csThetas, "incidence angles in degrees, comma separated (default 0,30,60,80)");
  compare->add_option("--paths", cs.paths, "paths per incidence angle and model")->capture_default_str();
  compare->add_option("--size-um", cs.size_um, "side of the periodic heightfield patch")->capture_default_str();
  compare->add_option("--correlation-um", cs.correlation_um, "correlation length ℓ of exp(-r²/ℓ²)")
      ->capture_default_str();
  compare->add_option("--texel-um", cs.texel_um, "heightfield spacing")->capture_default_str();
  compare->add_option("--seed", cs.seed, "random seed (surface and paths)")->capture_default_str();
  compare->add_option("--threads", threads, "threads (default: all cores)")->check(CLI::NonNegativeNumber);
  compare->add_option("--json", csJson, "also write the full result (incl. plane-of-incidence lobes) as JSON");

  silenceHdf5Diagnostics();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int code = app.exit(e);
    return code == 0 ? 0 : kExitInput;
  }

  if (run->parsed()) return runCommand(argc, argv, jobPath, outPath, logDir, threads, resume, maxHours, verbose);

  try {
    if (keys->parsed()) {
      std::cout << (keysMarkdown ? jobKeysMarkdown() : jobKeysText());
      return 0;
    }
    if (info->parsed()) {
      BsdfFileReader f(h5Path);
      nlohmann::json j = infoJson(f, h5Path);
      if (json)
        std::cout << j.dump(2) << "\n";
      else
        printInfo(j);
      return 0;
    }
    if (slice->parsed()) {
      BsdfFileReader f(h5Path);
      SliceRequest req;
      req.theta_deg = thetaI;
      req.phi_deg = phiI;
      req.model = model;
      req.transmission = transmission;
      req.both = both;
      req.size = sliceSize;
      req.style = style;
      req.exposure = exposure;
      req.log2Min = log2Min;
      req.log2Max = log2Max;
      int inc = exportSlice(f, req, outPath);
      std::cerr << "wrote " << outPath << " (incidence theta " << f.incidenceTheta(inc) << ", phi "
                << f.incidencePhi(inc) << ")\n";
      return 0;
    }
    if (render->parsed()) {
      renderReq.models = parseModels(renderModels);
      if (!(renderReq.size >= 16 && renderReq.size <= 4096)) throw InputError("--size must be in [16, 4096]");
      if (!(renderReq.lightTheta_deg >= 0 && renderReq.lightTheta_deg <= 180))
        throw InputError("--light-theta must be in [0, 180]");
      if (!(renderReq.environment >= 0) || !(renderReq.lightIrradiance >= 0) || !(renderReq.exposure > 0))
        throw InputError("--environment and --irradiance must be >= 0, --exposure > 0");
      BsdfFileReader f(h5Path);
      warnIfIncomplete(f, "pixels lit or seen through a missing slice are a magenta checker");
      RgbImage img = renderPreview(f, renderReq);
      writePng(outPath, img);
      std::cerr << "wrote " << outPath << " (" << img.width << " x " << img.height << ")\n";
      return 0;
    }
    if (sheet->parsed()) {
      sheetReq.models = parseModels(sheetModels);
      sheetReq.theta_deg = parseAngles(sheetThetas, "--theta-i", 180, true);
      if (!(sheetReq.cell.size >= 16 && sheetReq.cell.size <= 4096)) throw InputError("--size must be in [16, 4096]");
      BsdfFileReader f(h5Path);
      warnIfIncomplete(f, "missing slices are hatched red cells");
      RgbImage img = renderContactSheet(f, sheetReq);
      writePng(outPath, img);
      std::cerr << "wrote " << outPath << " (" << img.width << " x " << img.height << ")\n";
      return 0;
    }
    if (geometry->parsed()) {
      Job job = loadJob(jobPath);
      if (job.statistical)
        throw InputError(jobPath + ": [geometry] kind = \"statistical\" has no explicit microgeometry to write");
      writePly(job.geometry, outPath);
      std::cerr << "wrote " << outPath << ": " << job.geometry.vertices.size() << " vertices, "
                << job.geometry.triangles.size() << " triangles, " << job.geometry.sizeX << " x " << job.geometry.sizeY
                << " µm, z in [" << job.geometry.zMin() << ", " << job.geometry.zMax() << "] µm\n";
      return 0;
    }
    if (plan->parsed()) {
      installStopHandlers();
      setupLogging(0, "", "", false);
      Job job = loadJob(jobPath);
      PlanOptions po;
      po.threads = threads;
      po.writeSecondsPerSlice = measureWriteSecondsPerSlice;
      nlohmann::json p = planJob(job, po);
      std::cout << formatPlan(p);
      if (!planJson.empty()) {
        std::ofstream f(planJson);
        f << p.dump(2) << "\n";
        if (!f) throw std::runtime_error("cannot write " + planJson);
      }
      return 0;
    }
    if (compare->parsed()) {
      if (!csThetas.empty()) cs.theta_deg = parseAngles(csThetas, "--theta", 90, false);
      std::optional<tbb::global_control> limit;
      if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(threads));
      nlohmann::json r = compareSmith(cs);
      std::cout << formatCompareSmith(r);
      if (!csJson.empty()) {
        std::ofstream f(csJson);
        f << r.dump(1) << "\n";
        if (!f) throw std::runtime_error("cannot write " + csJson);
      }
      return 0;
    }
    if (check->parsed()) {
      Job job = loadJob(jobPath);
      DirectionGrid grid(job.gridLayout);
      std::cout << jobPath << ": ok\n  geometry " << job.geometryKind << ", "
                << (job.statistical
                        ? MicroflakeDistribution(job.statistical->ndf).describe()
                        : std::to_string(job.geometry.triangles.size()) + " triangles, " +
                              std::to_string(job.geometry.sizeX) + " x " + std::to_string(job.geometry.sizeY) + " µm")
                << (job.statistical ? "" : "\n  surface " + job.closure.describe()) << "\n  material "
                << job.material.describe() << "\n  " << job.lambda_nm.size() << " wavelengths, grid " << grid.kind()
                << " with " << grid.binCount() << " bins, " << job.incidence.size() << " incidence directions\n"
                << "  memory about " << fmt::format("{:.3g}", memoryBytesPerRank(job, 0) / 1e9)
                << " GB per rank before the "
                << "wave estimator's own (`plan` measures it), output up to "
                << fmt::format("{:.3g}", outputBytesUncompressed(job) / 1e9) << " GB\n";
      if (const double avail = availableMemoryBytes(); avail > 0 && memoryBytesPerRank(job, 0) > avail)
        throw InputError(jobPath + ": the job needs about " + fmt::format("{:.3g}", memoryBytesPerRank(job, 0) / 1e9) +
                         " GB per rank but this machine has " + fmt::format("{:.3g}", avail / 1e9) +
                         " GB available ([directions] bins, [spectrum] wavelengths)");
      return 0;
    }
  } catch (const InputError& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kExitInput;
  } catch (const StopRequested&) {
    std::cerr << "stopped on request (" << stopAnswerNote() << ")\n";
    return exitCode(ExitCode::Stopped);
  } catch (const WriteError& e) {
    std::cerr << "error: " << e.what() << "\n";
    return exitCode(ExitCode::WriteFailed);
  } catch (const std::invalid_argument& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kExitInput;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return kExitFailure;
  }
  return 0;
}
