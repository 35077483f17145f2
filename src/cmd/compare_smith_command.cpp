// `microbsdf compare-smith [--alpha …]`: the Smith microflake model against an explicit Gaussian
// heightfield with the same Beckmann distribution of normals (microflake/compare_smith.h).
#include <iostream>
#include <optional>

#include <tbb/global_control.h>

#include "cmd/command.h"
#include "microflake/compare_smith.h"

namespace mbsdf {

Command addCompareSmithCommand(CLI::App& app) {
  struct Options {
    CompareSmithOptions cs;
    std::string json, thetas;
    int threads = 0;
  };
  auto o = std::make_shared<Options>();
  CompareSmithOptions& cs = o->cs;
  Command c;
  CLI::App* compare = c.app = app.add_subcommand(
      "compare-smith", "Smith microflake model vs an explicit Gaussian heightfield with the same Beckmann NDF");
  compare->add_option("--alpha", cs.alpha, "Beckmann roughness")->capture_default_str();
  compare->add_option("--material", cs.material, "built-in conductor")->capture_default_str();
  compare->add_option("--lambda-nm", cs.lambda_nm, "wavelength (nm)")->capture_default_str();
  compare->add_option("--theta", o->thetas, "incidence angles in degrees, comma separated (default 0,30,60,80)");
  compare->add_option("--paths", cs.paths, "paths per incidence angle and model")->capture_default_str();
  compare->add_option("--size-um", cs.size_um, "side of the periodic heightfield patch")->capture_default_str();
  compare->add_option("--correlation-um", cs.correlation_um, "correlation length ℓ of exp(-r²/ℓ²)")
      ->capture_default_str();
  compare->add_option("--texel-um", cs.texel_um, "heightfield spacing")->capture_default_str();
  compare->add_option("--seed", cs.seed, "random seed (surface and paths)")->capture_default_str();
  addThreadsOption(compare, o->threads, "threads (default: all cores)");
  compare->add_option("--json", o->json, "also write the full result (incl. plane-of-incidence lobes) as JSON");
  c.run = [o] {
    if (!o->thetas.empty()) o->cs.theta_deg = parseAngles(o->thetas, "--theta", 90, false);
    std::optional<tbb::global_control> limit;
    if (o->threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(o->threads));
    nlohmann::json r = compareSmith(o->cs);
    std::cout << formatCompareSmith(r);
    if (!o->json.empty()) writeJsonFile(o->json, r, 1);
    return 0;
  };
  return c;
}

}  // namespace mbsdf
