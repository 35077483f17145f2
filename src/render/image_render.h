// The preview's path tracer: unidirectional, with next-event estimation of the environment and
// multiple importance sampling of the light's and the material's densities by the power heuristic
// (Veach & Guibas 1995; Veach 1997, Ch. 9), Russian roulette after the third bounce. One material
// on every surface of the scene; the environment at infinity. Pixel (x, y), sample k draws its
// numbers from Sampler(seed, y · width + x, k): an image is the same bytes for any thread count, and
// one pixel's sample can be replayed alone.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include "render/camera.h"
#include "render/environment.h"
#include "render/render_material.h"
#include "render/render_scene.h"

namespace mbsdf {

struct LinearImage {
  int width = 0, height = 0;
  std::vector<float> rgb;  // linear sRGB radiance, width × height × 3, row 0 at the top
};

struct RenderSettings {
  int samplesPerPixel = 64;
  int maxDepth = 12;  // bounces off the object (light through a glass ball needs a few)
  uint64_t seed = 1;
  bool showEnvironment = true;  // camera rays that miss see the environment (else black)
};

struct RenderCounts {
  uint64_t paths = 0;
  uint64_t dropped = 0;  // samples with a non-finite value, left out of their pixel (never expected)
};

// progress(rowsDone) is called from the rendering threads, at most once per row; it may throw to
// abandon the render.
LinearImage renderImage(const RenderScene& scene, const Camera& camera, const RenderMaterial& material,
                        const Environment& env, const RenderSettings& settings,
                        const std::function<void(int)>& progress = {}, RenderCounts* counts = nullptr);

}  // namespace mbsdf
