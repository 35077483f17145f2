// microbsdf: the command-line entry point (README "A five-minute tour", docs/running.md). Each
// subcommand is its own file (command.h); this maps what they throw to the exit codes of
// core/error.h.
#include <CLI/CLI.hpp>

#include <csignal>
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "core/stop.h"
#include "io/hdf5_handle.h"

using namespace mbsdf;

int main(int argc, char** argv) {
  // A write beyond the file-size limit (ulimit -f) raises SIGXFSZ, whose default action kills the
  // process (exit 153, no message); ignored, the write fails with EFBIG, which every writer reports
  // as a write failure (exit 4, the file named, outputs intact).
  std::signal(SIGXFSZ, SIG_IGN);
  CLI::App app{"microbsdf: tabulated BSDFs (BRDF + BTDF) of explicit surface microgeometry"};
  app.require_subcommand(1);
  app.set_version_flag("--version", MICROBSDF_VERSION);
  const std::vector<Command> commands = {addRunCommand(app, argc, argv),
                                         addInfoCommand(app),
                                         addSliceCommand(app),
                                         addSheetCommand(app),
                                         addRenderCommand(app),
                                         addReportCommand(app),
                                         addGeometryCommand(app),
                                         addCheckCommand(app),
                                         addKeysCommand(app),
                                         addPlanCommand(app),
                                         addCompareSmithCommand(app),
                                         addExportCommand(app),
                                         addEvalCommand(app),
                                         addDiffCommand(app)};

  setUpHdf5();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : exitCode(ExitCode::BadInput);
  }
  for (const Command& c : commands) {
    if (!c.app->parsed()) continue;
    if (c.handlesOwnErrors) return c.run();
    try {
      return c.run();
    } catch (const InputError& e) {
      std::cerr << "error: " << e.what() << "\n";
      return exitCode(ExitCode::BadInput);
    } catch (const StopRequested&) {
      std::cerr << "stopped on request (" << stopAnswerNote() << ")\n";
      return exitCode(ExitCode::Stopped);
    } catch (const WriteError& e) {
      std::cerr << "error: " << e.what() << "\n";
      return exitCode(ExitCode::WriteFailed);
    } catch (const std::invalid_argument& e) {
      std::cerr << "error: " << e.what() << "\n";
      return exitCode(ExitCode::BadInput);
    } catch (const std::exception& e) {
      std::cerr << "error: " << e.what() << "\n";
      return exitCode(ExitCode::Failure);
    }
  }
  return 0;
}
