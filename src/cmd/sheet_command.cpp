// `microbsdf sheet OUT.h5 [--models …] [--theta-i …] -o sheet.png`: a contact sheet of slices over
// incidence angles (columns) and models (rows) (io/contact_sheet.h).
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "io/bsdf_file.h"
#include "io/contact_sheet.h"
#include "io/output_target.h"
#include "io/png_image.h"

namespace mbsdf {

Command addSheetCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, outPath, models, thetas;
    SheetRequest req;
  };
  auto o = std::make_shared<Options>();
  SheetRequest& req = o->req;
  Command c;
  CLI::App* sheet = c.app =
      app.add_subcommand("sheet", "contact sheet PNG: slices over incidence angles (columns) and models (rows)");
  sheet->add_option("file", o->h5Path, "output HDF5 file")->required();
  sheet->add_option("--models", o->models, "comma separated (default: the GS, GM, WS, WM the file can form)");
  sheet->add_option("--theta-i", o->thetas, "incidence angles in degrees, comma separated (default: every slice)");
  sheet->add_option("--phi-i", req.phi_deg, "incidence azimuth (degrees)")->capture_default_str();
  sheet->add_option("--size", req.cell.size, "cell height in pixels")->capture_default_str();
  sheet->add_flag("--both", req.cell.both, "reflection and transmission side by side in each cell");
  sheet->add_option("--style", req.cell.style, "true (CIE 1931 -> sRGB) or false (log2 false colour)")
      ->check(CLI::IsMember({"true", "false"}))
      ->capture_default_str();
  sheet->add_option("--exposure", req.cell.exposure, "true colour: scale of the linear sRGB values")
      ->capture_default_str();
  sheet->add_option("--log2-min", req.cell.log2Min, "false colour: lower end of the log2 scale")->capture_default_str();
  sheet->add_option("--log2-max", req.cell.log2Max, "false colour: upper end of the log2 scale")->capture_default_str();
  sheet->add_option("-o,--output", o->outPath, "sheet.png")->required();
  c.run = [o] {
    o->req.models = parseModels(o->models);
    o->req.theta_deg = parseAngles(o->thetas, "--theta-i", 180, true);
    if (!(o->req.cell.size >= 16 && o->req.cell.size <= 4096)) throw InputError("--size must be in [16, 4096]");
    checkOutputPath(o->outPath);  // before reading: an unusable location is named at once
    BsdfFileReader f(o->h5Path);
    warnIfIncomplete(f, "missing slices are hatched red cells");
    RgbImage img = renderContactSheet(f, o->req);
    writePng(o->outPath, img);
    std::cerr << "wrote " << o->outPath << " (" << img.width << " x " << img.height << ")\n";
    return 0;
  };
  return c;
}

}  // namespace mbsdf
