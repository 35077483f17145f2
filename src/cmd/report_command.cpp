// `microbsdf report OUT.h5 -o report.html`: a self-contained HTML page about an output file
// (report/html_report.h).
#include <spdlog/spdlog.h>

#include <memory>

#include "cmd/command.h"
#include "core/error.h"
#include "core/log.h"
#include "core/stop.h"
#include "io/bsdf_file.h"
#include "io/output_target.h"
#include "report/html_report.h"

namespace mbsdf {

Command addReportCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, outPath;
    ReportRequest req;
  };
  auto o = std::make_shared<Options>();
  ReportRequest& req = o->req;
  Command c;
  CLI::App* report = c.app = app.add_subcommand(
      "report", "one self-contained HTML page: provenance, planner, energies, slices by incidence, lobes, preview");
  report->add_option("file", o->h5Path, "output HDF5 file")->required();
  report->add_option("-o,--output", o->outPath, "report.html")->required();
  report->add_option("--slice-size", req.sliceSize, "pixels of each slice picture")->capture_default_str();
  report->add_option("--max-incidences", req.maxIncidences, "slider positions at most")->capture_default_str();
  report->add_option("--render-size", req.renderSize, "preview pixels per model (0: no preview)")
      ->capture_default_str();
  report->add_option("--render-spp", req.renderSpp, "preview samples per pixel")->capture_default_str();
  report->add_option("--shape", req.shape, "preview object: sphere, ball, plane, or an .obj / .ply file")
      ->capture_default_str();
  c.run = [o] {
    const ReportRequest& req = o->req;
    installStopHandlers();
    setupLogging(0, "", "", false);
    if (!(req.sliceSize >= 32 && req.sliceSize <= 1024)) throw InputError("--slice-size must be in [32, 1024]");
    if (!(req.maxIncidences >= 2 && req.maxIncidences <= 1000))
      throw InputError("--max-incidences must be in [2, 1000]");
    if (!(req.renderSize == 0 || (req.renderSize >= 16 && req.renderSize <= 2048)))
      throw InputError("--render-size must be 0 or in [16, 2048]");
    if (!(req.renderSpp >= 1 && req.renderSpp <= 65536)) throw InputError("--render-spp must be in [1, 65536]");
    checkOutputPath(o->outPath);
    BsdfFileReader f(o->h5Path);
    warnIfIncomplete(f, "the report shows the finished slices");
    const std::string html = htmlReport(f, o->h5Path, req, [](const std::string& what) {
      throwIfStopped();
      spdlog::info("report: {}", what);
    });
    writeFileAtomically(o->outPath, html);  // an existing report is replaced whole or left as it was
    spdlog::info("wrote {} ({:.1f} MB)", o->outPath, html.size() / 1e6);
    return 0;
  };
  return c;
}

}  // namespace mbsdf
