// `microbsdf eval OUT.h5 --wi THETA,PHI --wo THETA,PHI [--model WM]`: f(ωi → ωo) of a stored table per
// wavelength, between its bins and incidences as the exporters see it (io/bsdf_lookup.h).
#include <fmt/format.h>

#include <iostream>

#include "cmd/command.h"
#include "core/error.h"
#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"

namespace mbsdf {

Command addEvalCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, model, wi, wo;
  };
  auto o = std::make_shared<Options>();
  Command c;
  CLI::App* cmd = c.app = app.add_subcommand("eval", "f(wi -> wo) of a table per wavelength, interpolated");
  cmd->add_option("file", o->h5Path, "output HDF5 file")->required();
  cmd->add_option("--wi", o->wi, "incidence THETA,PHI in degrees (towards the light; THETA > 90: from below)")
      ->required();
  cmd->add_option("--wo", o->wo, "exit THETA,PHI in degrees (THETA > 90: transmitted for light from above)")
      ->required();
  cmd->add_option("--model", o->model,
                  "GS, GM, WS, WM or a component name (default: the fullest model the file holds)");
  c.run = [o] {
    BsdfFileReader f(o->h5Path);
    auto direction = [](const std::string& s, const std::string& option) {
      const std::vector<double> a = parseAngles(s, option, 360.0, true);
      if (a.size() != 2 || a[0] > 180) throw InputError(option + ": expected THETA,PHI with THETA in [0, 180] degrees");
      return sphericalDirection(radians(a[0]), radians(a[1]));
    };
    const Vec3 wi = direction(o->wi, "--wi"), wo = direction(o->wo, "--wo");
    const std::string model = modelOrFullest(f, o->model, o->h5Path);
    const BsdfLookup lookup(f, model);
    std::string rows;  // every value first: an error leaves no half-written table
    for (int l = 0; l < lookup.wavelengthCount(); ++l)
      rows += fmt::format("{:g},{:.8g}\n", f.wavelengths_nm()[size_t(l)], lookup.eval(wi, wo, l));
    std::cout << "# " << model << " of " << o->h5Path << ", f in 1/sr; incidence "
              << (lookup.nearestOnly() ? "from the nearest slice" : "interpolated between incidence bins")
              << ", exit interpolated between bins\nlambda_nm,f\n"
              << rows;
    return 0;
  };
  return c;
}

}  // namespace mbsdf
