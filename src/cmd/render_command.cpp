// `microbsdf render OUT.h5 [--models …] -o render.png`: a preview sphere per model under a
// directional light and a uniform environment (render/preview.h).
#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "io/bsdf_file.h"
#include "io/png_image.h"
#include "render/preview.h"

namespace mbsdf {

Command addRenderCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, outPath, models;
    RenderRequest req;
  };
  auto o = std::make_shared<Options>();
  RenderRequest& req = o->req;
  Command c;
  CLI::App* render = c.app = app.add_subcommand(
      "render", "preview PNG: a sphere with the tabulated BSDF per model, directional light + environment");
  render->add_option("file", o->h5Path, "output HDF5 file")->required();
  render->add_option("--models", o->models, "comma separated (default: the GS, GM, WS, WM the file can form)");
  render->add_option("--size", req.size, "pixels per sphere")->capture_default_str();
  render->add_option("--light-theta", req.lightTheta_deg, "light direction, polar angle (degrees)")
      ->capture_default_str();
  render->add_option("--light-phi", req.lightPhi_deg, "light direction, azimuth (degrees)")->capture_default_str();
  render->add_option("--irradiance", req.lightIrradiance, "light irradiance E")->capture_default_str();
  render->add_option("--environment", req.environment, "uniform environment radiance (0: light only)")
      ->capture_default_str();
  render->add_option("--exposure", req.exposure, "scale of the linear sRGB values")->capture_default_str();
  render->add_option("-o,--output", o->outPath, "render.png")->required();
  c.run = [o] {
    RenderRequest& req = o->req;
    req.models = parseModels(o->models);
    if (!(req.size >= 16 && req.size <= 4096)) throw InputError("--size must be in [16, 4096]");
    if (!(req.lightTheta_deg >= 0 && req.lightTheta_deg <= 180)) throw InputError("--light-theta must be in [0, 180]");
    if (!(req.environment >= 0) || !(req.lightIrradiance >= 0) || !(req.exposure > 0))
      throw InputError("--environment and --irradiance must be >= 0, --exposure > 0");
    BsdfFileReader f(o->h5Path);
    warnIfIncomplete(f, "pixels lit or seen through a missing slice are a magenta checker");
    RgbImage img = renderPreview(f, req);
    writePng(o->outPath, img);
    std::cerr << "wrote " << o->outPath << " (" << img.width << " x " << img.height << ")\n";
    return 0;
  };
  return c;
}

}  // namespace mbsdf
