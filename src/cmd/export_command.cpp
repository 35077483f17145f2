// `microbsdf export OUT.h5 --format zemax|rgl -o FILE [--model WM] [--lambda-nm NM] [--colour C]`: a
// stored table in a format other tools read (export/zemax_bsdf.h, export/rgl_bsdf.h). Zemax: one file
// per wavelength ("_<λ>nm" before FILE's extension when there are several); RGL: one file with every
// chosen wavelength, or linear sRGB. Every file is written whole or not at all (an existing one is
// replaced only by a complete file).
#include <fmt/format.h>

#include <filesystem>
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "export/rgl_bsdf.h"
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
    std::string h5Path, outPath, format = "zemax", model, colour = "spectral", side = "reflection";
    std::vector<double> lambda_nm;
  };
  auto o = std::make_shared<Options>();
  Command c;
  CLI::App* cmd = c.app =
      app.add_subcommand("export", "write a table in a format renderers or optical-design tools read");
  cmd->add_option("file", o->h5Path, "output HDF5 file")->required();
  cmd->add_option("--format", o->format,
                  "zemax: OpticStudio's tabular BSDF (BRDF, one wavelength per file); rgl: the RGL database's "
                  ".bsdf (Mitsuba 3, pbrt-v4; reflection)")
      ->check(CLI::IsMember({"zemax", "rgl"}))
      ->capture_default_str();
  cmd->add_option("--colour", o->colour, "rgl: spectral (the table's wavelengths) or rgb (linear sRGB)")
      ->check(CLI::IsMember({"spectral", "rgb"}))
      ->capture_default_str();
  cmd->add_option("--side", o->side, "reflection or transmission (no format written yet holds a BTDF)")
      ->check(CLI::IsMember({"reflection", "transmission"}))
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
    if (o->side == "transmission")
      throw InputError("--side transmission: the " + o->format +
                       " format as written here holds reflection only (a BRDF); transmission is not exported");
    if (o->colour == "rgb" && o->format != "rgl") throw InputError("--colour rgb: only the rgl format writes colours");
    warnIfIncomplete(f, "unfinished slices make the export fail");
    if (o->format == "rgl") {
      RglExport e;
      e.wavelengths = which;
      e.colour = o->colour == "rgb" ? RglExport::Colour::rgb : RglExport::Colour::spectral;
      if (e.colour == RglExport::Colour::rgb && !o->lambda_nm.empty())
        throw InputError("--colour rgb uses every wavelength of the table: leave out --lambda-nm");
      const RglFile rgl = rglBsdfFile(f, lookup, e, "microbsdf " + model + " of " + o->h5Path);
      writeFileAtomically(o->outPath, rgl.bytes);
      std::cerr << "wrote " << o->outPath << " (model " << model << ", " << (rgl.bytes.size() + 512) / 1024
                << " KiB)\n";
      if (rgl.negativeClamped > 0)
        std::cerr << "note: " << rgl.negativeClamped << " of " << rgl.nodes
                  << " values were below 0 (Monte Carlo noise, or colours outside sRGB) and are stored as 0\n";
      return 0;
    }
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
