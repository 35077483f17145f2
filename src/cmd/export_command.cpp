// `microbsdf export OUT.h5 --format zemax -o FILE [--model WM] [--lambda-nm NM]`: a stored table in a
// format other tools read (export/zemax_bsdf.h). One file per wavelength: with several, "_<λ>nm" goes
// before FILE's extension. Every file is written whole or not at all (an existing one is replaced
// only by a complete file).
#include <fmt/format.h>

#include <filesystem>
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "export/zemax_bsdf.h"
#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"
#include "io/output_target.h"

namespace mbsdf {
namespace {

// FILE, or FILE with "_<λ>nm" before its extension when the export writes several wavelengths.
std::string perWavelengthPath(const std::string& path, double lambda_nm, bool several) {
  if (!several) return path;
  const std::filesystem::path p(path);
  return (p.parent_path() / (p.stem().string() + fmt::format("_{:g}nm", lambda_nm) + p.extension().string())).string();
}

}  // namespace

Command addExportCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, outPath, format = "zemax", model;
    std::vector<double> lambda_nm;
  };
  auto o = std::make_shared<Options>();
  Command c;
  CLI::App* cmd = c.app = app.add_subcommand("export", "write a table in a format optical-design tools read");
  cmd->add_option("file", o->h5Path, "output HDF5 file")->required();
  cmd->add_option("--format", o->format, "zemax: OpticStudio's tabular BSDF (BRDF, one wavelength per file)")
      ->check(CLI::IsMember({"zemax"}))
      ->capture_default_str();
  cmd->add_option("--model", o->model,
                  "GS, GM, WS, WM or a component name (default: the fullest model the file holds)");
  cmd->add_option("--lambda-nm", o->lambda_nm, "wavelengths to write, each one of the table's (default: all)");
  cmd->add_option("-o,--output", o->outPath, "the file to write (x.bsdf)")->required();
  c.run = [o] {
    BsdfFileReader f(o->h5Path);
    const std::string model = modelOrFullest(f, o->model, o->h5Path);
    const BsdfLookup lookup(f, model);
    const std::vector<double>& table = f.wavelengths_nm();
    std::vector<int> which;
    for (double l : o->lambda_nm) {
      int k = -1;
      for (size_t i = 0; i < table.size(); ++i)
        if (std::abs(table[i] - l) < 1e-6) k = int(i);
      if (k < 0)
        throw InputError("--lambda-nm " + fmt::format("{:g}", l) + ": not a wavelength of " + o->h5Path + " (" +
                         fmt::format("{}", fmt::join(table, ", ")) + " nm)");
      which.push_back(k);
    }
    if (which.empty())
      for (size_t i = 0; i < table.size(); ++i) which.push_back(int(i));
    warnIfIncomplete(f, "unfinished slices make the export fail");
    for (int k : which) {
      ZemaxExport e = defaultZemaxExport();
      e.wavelength = k;
      const std::string path = perWavelengthPath(o->outPath, table[size_t(k)], which.size() > 1);
      writeFileAtomically(path, zemaxBsdfText(f, lookup, e, o->h5Path));
      std::cerr << "wrote " << path << " (model " << model << ", " << table[size_t(k)] << " nm)\n";
    }
    return 0;
  };
  return c;
}

}  // namespace mbsdf
