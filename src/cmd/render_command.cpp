// `microbsdf render OUT.h5 -o preview.png|exr`: a path-traced material preview per model, side by
// side (render/preview.h).
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <cmath>
#include <mutex>
#include <optional>

#include "cmd/command.h"
#include "core/error.h"
#include "core/log.h"
#include "core/stop.h"
#include "io/bsdf_file.h"
#include "io/exr_image.h"
#include "io/output_target.h"
#include "io/png_image.h"
#include "render/preview.h"

namespace mbsdf {

namespace {

std::optional<GgxReference> parseGgxReference(const std::string& s) {
  if (s.empty()) return std::nullopt;
  const auto comma = s.find(',');
  GgxReference g;
  try {
    size_t used = 0;
    g.alpha = std::stod(s.substr(0, comma), &used);
    if (used != s.substr(0, comma).size()) throw std::invalid_argument(s);
  } catch (const std::exception&) {
    throw InputError("--ggx-reference: \"" + s + "\" is not ALPHA[,MATERIAL]");
  }
  if (!(g.alpha > 0 && g.alpha <= 4)) throw InputError("--ggx-reference: alpha must be in (0, 4]");
  if (comma != std::string::npos) g.material = s.substr(comma + 1);
  return g;
}

void writeOutput(const std::string& path, const std::vector<PreviewPanel>& panels, double exposure, ToneCurve curve) {
  const bool exr = path.size() > 4 && path.substr(path.size() - 4) == ".exr";
  if (exr) {
    const LinearImage img = composeLinear(panels);
    std::vector<ExrChannel> channels{{"R", {}}, {"G", {}}, {"B", {}}};
    for (size_t p = 0; p < img.rgb.size() / 3; ++p)
      for (int k = 0; k < 3; ++k) channels[size_t(k)].pixels.push_back(img.rgb[3 * p + size_t(k)]);
    writeExr(path, img.width, img.height, channels);
  } else {
    writePng(path, composePanels(panels, exposure, curve));
  }
}

// The index below the surface relative to above, the mean over the file's wavelengths, from the
// material of the job the file was computed with; 0 when the job text holds none (a conductor: no
// light passes) or cannot be read.
double insideIorOf(const BsdfFileReader& f, const std::string& path) {
  try {
    const std::optional<Material> material = tableMaterial(f, path);
    if (!material || material->isConductor()) return 0;
    const Material& m = *material;
    std::vector<double> lambda_um;
    for (double nm : f.wavelengths_nm()) lambda_um.push_back(nm / 1000);
    double sum = 0;
    for (const Complex& n : m.iorAt(lambda_um)) sum += n.real() / m.outsideIor;
    return lambda_um.empty() ? 0 : sum / double(lambda_um.size());
  } catch (const std::exception& e) {
    spdlog::warn("{}: the material of its job_text cannot be read ({}); give --inside-ior", path, e.what());
    return 0;
  }
}

}  // namespace

Command addRenderCommand(CLI::App& app) {
  struct Options {
    std::string h5Path, outPath, models, ggx, toneCurve = "filmic";
    double exposure = 0;
    int threads = 0;
    RenderRequest req;
  };
  auto o = std::make_shared<Options>();
  RenderRequest& req = o->req;
  Command c;
  CLI::App* render = c.app = app.add_subcommand(
      "render", "material preview: the tabulated BSDF on an object under an environment, path traced, per model");
  render->add_option("file", o->h5Path, "output HDF5 file")->required();
  render->add_option("-o,--output", o->outPath, "preview.png (tone mapped, labelled) or preview.exr (linear)")
      ->required();
  render->add_option("--models", o->models, "comma separated (default: the GS, GM, WS, WM the file can form)");
  render->add_option("--shape", req.shape, "sphere, ball (a shader ball), plane, or an .obj / .ply file")
      ->capture_default_str();
  render->add_option("--environment", req.environment, "studio, sky, or an equirectangular .exr (z up)")
      ->capture_default_str();
  render->add_option("--environment-turn", req.environmentTurn_deg, "turn the environment about z (degrees)")
      ->capture_default_str();
  render->add_option("--size", req.size, "pixels per panel (square)")->capture_default_str();
  render->add_option("--spp", req.settings.samplesPerPixel, "samples per pixel")->capture_default_str();
  render->add_option("--max-depth", req.settings.maxDepth, "bounces off the object")->capture_default_str();
  render->add_option("--seed", req.settings.seed, "random seed")->capture_default_str();
  render->add_option("--camera-elevation", req.cameraElevation_deg, "degrees above the horizon")->capture_default_str();
  render->add_option("--camera-azimuth", req.cameraAzimuth_deg, "degrees from +x (-90: from -y)")
      ->capture_default_str();
  render->add_option("--exposure", o->exposure, "exposure in stops (PNG)")->capture_default_str();
  render->add_option("--tone-curve", o->toneCurve, "filmic (ACES fit) or clip (PNG)")->capture_default_str();
  render->add_option("--ggx-reference", o->ggx,
                     "ALPHA[,MATERIAL]: add a panel of the closed-form GGX conductor (single scattering; Al default)");
  render->add_option("--inside-ior", req.insideIor,
                     "index below the surface relative to above, for light inside an object the table has no "
                     "incidence for (default: from the file's job)");
  addThreadsOption(render, o->threads, "render");
  c.run = [o] {
    RenderRequest& req = o->req;
    installStopHandlers();
    setupLogging(0, "", "", false);
    req.models = parseModels(o->models);
    req.ggx = parseGgxReference(o->ggx);
    const ToneCurve curve = toneCurveFromName(o->toneCurve);
    if (!(req.size >= 16 && req.size <= 8192)) throw InputError("--size must be in [16, 8192]");
    if (!(req.settings.samplesPerPixel >= 1 && req.settings.samplesPerPixel <= 1 << 20))
      throw InputError("--spp must be in [1, 1048576]");
    if (!(req.settings.maxDepth >= 1 && req.settings.maxDepth <= 1000))
      throw InputError("--max-depth must be in [1, 1000]");
    if (!(req.cameraElevation_deg > -90 && req.cameraElevation_deg < 90))
      throw InputError("--camera-elevation must be in (-90, 90)");
    if (!std::isfinite(o->exposure) || !std::isfinite(req.cameraAzimuth_deg) || !std::isfinite(req.environmentTurn_deg))
      throw InputError("--exposure, --camera-azimuth and --environment-turn must be finite");
    std::optional<tbb::global_control> threads;
    if (o->threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, size_t(o->threads));
    checkOutputPath(o->outPath);
    BsdfFileReader f(o->h5Path);
    if (req.insideIor == 0) req.insideIor = insideIorOf(f, o->h5Path);
    if (!(req.insideIor >= 0) || !std::isfinite(req.insideIor)) throw InputError("--inside-ior must be > 0");
    warnIfIncomplete(f, "where a slice is not computed yet, the nearest finished incidence on its side stands in");
    std::mutex mutex;
    std::vector<std::unique_ptr<ProgressReporter>> reporters;
    auto progress = [&](int panel, int rows) {
      const std::lock_guard<std::mutex> lock(mutex);
      while (int(reporters.size()) <= panel)
        reporters.push_back(std::make_unique<ProgressReporter>("render panel " + std::to_string(reporters.size() + 1),
                                                               uint64_t(req.size), 2.0, false));
      reporters[size_t(panel)]->update(uint64_t(rows));
      throwIfStopped();
    };
    const std::vector<PreviewPanel> panels = renderPreview(f, req, progress);
    for (const PreviewPanel& p : panels) {
      if (p.etaFactorMissing)
        spdlog::warn(
            "{}: the table holds no incidence from one side; light from that side (inside the object) is "
            "taken by reciprocity f(wi -> wo) = f(wo -> wi), without the (eta_o/eta_i)^2 of transmission "
            "(give --inside-ior)",
            p.label);
      else if (p.reciprocityUsed)
        spdlog::info(
            "{}: light from the side the table holds no incidence on (inside the object) by reciprocity, "
            "f(wi -> wo) = f(wo -> wi) (eta_o/eta_i)^2 with the index ratio {:.4f}",
            p.label, req.insideIor);
      if (p.lightSliceInside)
        spdlog::warn(
            "{}: the table lists incidences from one side only; inside the object each light direction "
            "takes its nearest slice, which can return more light than the table has (a sharp lobe over "
            "the slice's whole region): the light through the object is not to be trusted. Compute "
            "incidence = \"all\" on both sides for a transparent material",
            p.label);
      if (p.unfinishedReplaced)
        spdlog::warn(
            "{}: unfinished slices were replaced by the nearest finished ones: the picture is not the "
            "final table's",
            p.label);
      if (p.nearestSlice)
        spdlog::warn(
            "{}: the table's {} incidences are a list without a rule between them: each point of the object "
            "shows the nearest slice, and the edges between their regions show as rings (a table with "
            "incidence = \"all\" or an isotropic surface interpolates)",
            p.label, f.incidenceCount());
      if (p.dropped > 0) spdlog::warn("{}: {} samples with a non-finite value left out", p.label, p.dropped);
    }
    writeOutput(o->outPath, panels, o->exposure, curve);
    spdlog::info("wrote {} ({} panels of {} x {}, {} samples per pixel)", o->outPath, panels.size(), req.size, req.size,
                 req.settings.samplesPerPixel);
    return 0;
  };
  return c;
}

}  // namespace mbsdf
