// One subcommand of the `microbsdf` executable: its options registered on the application and what
// it does once they are parsed. Each subcommand lives in its own file (run_command.cpp, …) and is
// added to the application by main.cpp in the order `--help` lists them.
// Exit codes (core/error.h, docs/running.md "Exit codes"): 0 success, 1 unexpected failure, 2 bad
// input (job file, input files, arguments, output location), 3 stopped early by a signal or
// --max-hours, 4 the output could not be written (resumable), 5 another run holds the output.
#pragma once
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "optics/material.h"

namespace mbsdf {

struct Command {
  CLI::App* app = nullptr;  // the subcommand, owned by the application
  // Runs the parsed subcommand and returns the exit code. Exceptions are mapped to exit codes by
  // main (InputError → 2, StopRequested → 3, WriteError → 4, others → 1), unless handlesOwnErrors
  // (`run`, whose ranks must fail together).
  std::function<int()> run;
  bool handlesOwnErrors = false;
};

Command addRunCommand(CLI::App& app, int argc, char** argv);  // MPI_Init sees the whole command line
Command addInfoCommand(CLI::App& app);
Command addSliceCommand(CLI::App& app);
Command addSheetCommand(CLI::App& app);
Command addRenderCommand(CLI::App& app);
Command addReportCommand(CLI::App& app);
Command addGeometryCommand(CLI::App& app);
Command addCheckCommand(CLI::App& app);
Command addKeysCommand(CLI::App& app);
Command addPlanCommand(CLI::App& app);
Command addCompareSmithCommand(CLI::App& app);
Command addExportCommand(CLI::App& app);
Command addEvalCommand(CLI::App& app);
Command addDiffCommand(CLI::App& app);

// Comma-separated lists of the command line. Model names (GS, GM, WS, WM or a component), each
// checked; empty items are skipped.
std::vector<std::string> parseModels(const std::string& s);
// Angles in degrees, each in [0, hi] (or [0, hi) when !hiInclusive); every item must be a number.
std::vector<double> parseAngles(const std::string& s, const std::string& option, double hi, bool hiInclusive);
class BsdfFileReader;
// A warning on stderr when the file's run has not finished: `how` says what the picture shows for
// the missing slices.
void warnIfIncomplete(const BsdfFileReader& f, const std::string& how);
// `model` when given, else the fullest model the file holds (WM, else WS, GM, GS); InputError naming
// `path` when there is none.
std::string modelOrFullest(const BsdfFileReader& f, const std::string& model, const std::string& path);
// The material of the job the table was computed with (its `job_text`): nothing when the file holds
// no job text, InputError naming `path` when that text's material cannot be read.
std::optional<Material> tableMaterial(const BsdfFileReader& f, const std::string& path);
// Writes j (indented by `indent`) to path; a failed write is a WriteError (exit code 4).
void writeJsonFile(const std::string& path, const nlohmann::json& j, int indent);
// "--threads N" shared by the subcommands that compute (0: all cores).
void addThreadsOption(CLI::App* cmd, int& threads, const std::string& what);

}  // namespace mbsdf
