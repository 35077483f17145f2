// `microbsdf slice OUT.h5 --theta-i DEG [--phi-i DEG] [--model GM] [--transmission|--both]
//  [--style true|false] -o x.exr|x.png|x.csv`: one BSDF slice as an image or a table (io/slice_export.h).
#include <iostream>

#include "cmd/command.h"
#include "io/bsdf_file.h"
#include "io/output_target.h"
#include "io/slice_export.h"

namespace mbsdf {

Command addSliceCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, outPath;
    SliceRequest req;
  };
  auto o = std::make_shared<Options>();
  SliceRequest& req = o->req;
  Command c;
  CLI::App* slice = c.app = app.add_subcommand("slice", "export one BSDF slice as EXR (disk projection) or CSV");
  slice->add_option("file", o->h5Path, "output HDF5 file")->required();
  slice->add_option("--theta-i", req.theta_deg, "incidence polar angle (degrees); the nearest computed slice is used");
  slice->add_option("--phi-i", req.phi_deg, "incidence azimuth (degrees)");
  slice->add_option("--model", req.model, "GS, GM, WS, WM or a component name")->capture_default_str();
  slice->add_flag("--transmission", req.transmission, "exit directions in the lower hemisphere (BTDF)");
  slice->add_option("--size", req.size, "image height in pixels")->capture_default_str();
  slice->add_flag("--both", req.both, "reflection (left) and transmission (right) side by side");
  slice->add_option("--style", req.style, "PNG: true (CIE 1931 -> sRGB) or false (log2 false colour)")
      ->check(CLI::IsMember({"true", "false"}))
      ->capture_default_str();
  slice->add_option("--exposure", req.exposure, "true colour: scale of the linear sRGB values")->capture_default_str();
  slice->add_option("--log2-min", req.log2Min, "false colour: lower end of the log2 scale")->capture_default_str();
  slice->add_option("--log2-max", req.log2Max, "false colour: upper end of the log2 scale")->capture_default_str();
  slice->add_option("-o,--output", o->outPath, "x.exr, x.png or x.csv")->required();
  c.run = [o] {
    checkOutputPath(o->outPath);  // before reading: an unusable location is named at once
    BsdfFileReader f(o->h5Path);
    const int inc = exportSlice(f, o->req, o->outPath);
    std::cerr << "wrote " << o->outPath << " (incidence theta " << f.incidenceTheta(inc) << ", phi "
              << f.incidencePhi(inc) << ")\n";
    return 0;
  };
  return c;
}

}  // namespace mbsdf
