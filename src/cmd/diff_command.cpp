// `microbsdf diff A.h5 B.h5 [-o report.json|.csv|.png]`: what differs between two tables beyond the
// noise both state (io/table_diff.h), printed per slice; the report file by extension, the picture
// for one incidence (--theta-i/--phi-i, the nearest slice) and model.
#include <filesystem>
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "io/output_target.h"
#include "io/table_diff.h"

namespace mbsdf {
namespace {

struct DiffOptions {
  std::string a, b, out, model = "GM";
  double theta_deg = 0, phi_deg = 0;
  int size = 256;
};

int diffFiles(const DiffOptions& o) {
  const BsdfFileReader a(o.a), b(o.b);
  const TableDiff d = diffTables(a, b, o.a, o.b);
  std::cout << d.text();
  if (o.out.empty()) return 0;
  const std::string ext = std::filesystem::path(o.out).extension().string();
  if (ext == ".json") {
    writeFileAtomically(o.out, d.json().dump(1) + "\n");
  } else if (ext == ".csv") {
    writeFileAtomically(o.out, d.csv());
  } else if (ext == ".png") {
    const int inc = a.nearestIncidence(o.theta_deg, o.phi_deg);
    if (!a.done(inc) || !b.done(inc))
      throw InputError("the slice nearest to --theta-i/--phi-i is not finished in both files");
    writePng(o.out, diffImage(a, b, inc, o.model, o.size));
  } else {
    throw InputError("-o " + o.out + ": the report is .json, .csv or .png");
  }
  std::cout << "written " << o.out << "\n";
  return 0;
}

}  // namespace

Command addDiffCommand(CLI::App& app) {
  auto o = std::make_shared<DiffOptions>();
  Command c;
  c.app = app.add_subcommand("diff", "what differs between two tables beyond their noise (energy, L1, colour, lobe)");
  c.app->add_option("a", o->a, "first output file (e.g. the designed surface)")->required();
  c.app->add_option("b", o->b, "second output file (e.g. the produced surface)")->required();
  c.app->add_option("-o,--output", o->out, "report: .json, .csv, or .png (both slices and their difference)");
  c.app->add_option("--theta-i", o->theta_deg, "picture: incidence polar angle (degrees; the nearest slice)");
  c.app->add_option("--phi-i", o->phi_deg, "picture: incidence azimuth (degrees)");
  c.app->add_option("--model", o->model, "picture: GS, GM, WS, WM or a component");
  c.app->add_option("--size", o->size, "picture: height of each panel in pixels")->check(CLI::Range(32, 4096));
  c.run = [o] { return diffFiles(*o); };
  return c;
}

}  // namespace mbsdf
