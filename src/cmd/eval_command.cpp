// `microbsdf eval OUT.h5 --wi THETA,PHI --wo THETA,PHI [--model WM]`: f(ωi → ωo) of a stored table per
// wavelength, between its bins and incidences as the exporters see it (io/bsdf_lookup.h). With
// `--pairs FILE` (or `-` for standard input), one row per line "theta_i,phi_i,theta_o,phi_o" in
// degrees: the way scripts (Python's subprocess, a spreadsheet) evaluate many pairs in one call.
#include <fmt/format.h>

#include <fstream>
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"

namespace mbsdf {
namespace {

Vec3 directionOf(const std::string& s, const std::string& where) {
  const std::vector<double> a = parseAngles(s, where, 360.0, true);
  if (a.size() != 2 || a[0] > 180) throw InputError(where + ": expected THETA,PHI with THETA in [0, 180] degrees");
  return sphericalDirection(radians(a[0]), radians(a[1]));
}

// The rows of a pairs file: each "theta_i,phi_i,theta_o,phi_o"; blank lines and '#' comments skipped.
std::vector<std::pair<Vec3, Vec3>> readPairs(std::istream& in, const std::string& name) {
  std::vector<std::pair<Vec3, Vec3>> pairs;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    const std::string where = fmt::format("{}:{}", name, n);
    const std::vector<double> a = parseAngles(line, where, 360.0, true);
    if (a.size() != 4 || a[0] > 180 || a[2] > 180)
      throw InputError(where + ": expected theta_i,phi_i,theta_o,phi_o in degrees (theta in [0, 180])");
    pairs.emplace_back(sphericalDirection(radians(a[0]), radians(a[1])),
                       sphericalDirection(radians(a[2]), radians(a[3])));
  }
  if (pairs.empty()) throw InputError(name + ": no pairs of directions");
  return pairs;
}

}  // namespace

Command addEvalCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, model, wi, wo, pairs;
  };
  auto o = std::make_shared<Options>();
  Command c;
  CLI::App* cmd = c.app = app.add_subcommand("eval", "f(wi -> wo) of a table per wavelength, interpolated");
  cmd->add_option("file", o->h5Path, "output HDF5 file")->required();
  auto* wi =
      cmd->add_option("--wi", o->wi, "incidence THETA,PHI in degrees (towards the light; THETA > 90: from below)");
  auto* wo = cmd->add_option("--wo", o->wo, "exit THETA,PHI in degrees (THETA > 90: transmitted for light from above)");
  auto* pairs = cmd->add_option("--pairs", o->pairs,
                                "a file of lines theta_i,phi_i,theta_o,phi_o (degrees), or - for standard input: "
                                "one CSV row of f per wavelength for each");
  wi->needs(wo);
  wo->needs(wi);
  pairs->excludes(wi)->excludes(wo);
  cmd->add_option("--model", o->model,
                  "GS, GM, WS, WM or a component name (default: the fullest model the file holds)");
  c.run = [o] {
    if (o->pairs.empty() && o->wi.empty()) throw InputError("eval: give --wi and --wo, or --pairs");
    BsdfFileReader f(o->h5Path);
    std::vector<std::pair<Vec3, Vec3>> directions;
    if (o->pairs.empty()) {
      directions.emplace_back(directionOf(o->wi, "--wi"), directionOf(o->wo, "--wo"));
    } else if (o->pairs == "-") {
      directions = readPairs(std::cin, "standard input");
    } else {
      std::ifstream in(o->pairs);
      if (!in) throw InputError("--pairs " + o->pairs + ": cannot open the file");
      directions = readPairs(in, o->pairs);
    }
    const std::string model = modelOrFullest(f, o->model, o->h5Path);
    const BsdfLookup lookup(f, model);
    const std::vector<std::string>& rowNames = f.channelNames();  // "450nm", … or "X", "Y", "Z"
    std::string rows;  // every value first: an error leaves no half-written table
    if (o->pairs.empty()) {
      for (int l = 0; l < lookup.wavelengthCount(); ++l)
        rows += f.spectral() ? fmt::format("{:g},{:.8g}\n", f.wavelengths_nm()[size_t(l)],
                                           lookup.eval(directions[0].first, directions[0].second, l))
                             : fmt::format("{},{:.8g}\n", rowNames[size_t(l)],
                                           lookup.eval(directions[0].first, directions[0].second, l));
    } else {
      for (const auto& [in, out] : directions) {
        rows += fmt::format("{:.10g},{:.10g},{:.10g},{:.10g}", degrees(safeAcos(in.z)), degrees(sphericalPhi(in)),
                            degrees(safeAcos(out.z)), degrees(sphericalPhi(out)));
        for (int l = 0; l < lookup.wavelengthCount(); ++l) rows += fmt::format(",{:.8g}", lookup.eval(in, out, l));
        rows += "\n";
      }
    }
    std::cout << "# " << model << " of " << o->h5Path << ", f in 1/sr; incidence " << lookup.incidenceRule()
              << ", exit interpolated between bins\n";
    if (o->pairs.empty()) {
      std::cout << (f.spectral() ? "lambda_nm,f\n" : "channel,f\n") << rows;
    } else {
      std::cout << "theta_i,phi_i,theta_o,phi_o";
      for (const std::string& n : rowNames) std::cout << ",f_" << n;
      std::cout << "\n" << rows;
    }
    return 0;
  };
  return c;
}

}  // namespace mbsdf
