#include "render/image_render.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>

namespace mbsdf {

namespace {

// The local frame of a surface point: z the shading normal, x along the parallels about the world's
// z axis (an anisotropic table's x axis runs around a sphere like a line of latitude), or the
// world's x axis where the normal is vertical.
struct Frame {
  Vec3 t, b, n;
  explicit Frame(const Vec3& normal) : n(normal) {
    Vec3 along = cross(Vec3{0, 0, 1}, n);
    if (length(along) < 1e-6) along = Vec3{1, 0, 0} - n.x * n;
    t = normalize(along);
    b = cross(n, t);
  }
  Vec3 toLocal(const Vec3& w) const { return {dot(w, t), dot(w, b), dot(w, n)}; }
  Vec3 toWorld(const Vec3& w) const { return w.x * t + w.y * b + w.z * n; }
};

double powerHeuristic(double a, double b) {
  return a * a / (a * a + b * b);
}

// Numbers of a path: block 0 the pixel position, then four blocks per bounce (the light's
// direction, two for the material's draw, Russian roulette).
uint32_t bounceBlock(int depth) {
  return 1 + 4 * uint32_t(depth);
}

struct PathTracer {
  const RenderScene& scene;
  const RenderMaterial& material;
  const Environment& env;
  const RenderSettings& settings;

  Colour3 radiance(Vec3 o, Vec3 d, Sampler& s) const {
    Colour3 L{0, 0, 0}, beta{1, 1, 1};
    double prevPdf = 0;  // the material's density of the direction d, 0 for the camera ray
    for (int depth = 0;; ++depth) {
      const std::optional<SurfaceHit> hit = scene.intersect(o, d);
      if (!hit) {
        if (depth > 0 || settings.showEnvironment) {
          const Colour3 Le = env.radiance(d);
          const double w = prevPdf > 0 ? powerHeuristic(prevPdf, env.pdf(d)) : 1.0;
          for (int k = 0; k < 3; ++k) L[size_t(k)] += beta[size_t(k)] * Le[size_t(k)] * w;
        }
        break;
      }
      if (depth >= settings.maxDepth) break;
      const Frame frame(hit->ns);
      const Vec3 wo = frame.toLocal(-d);
      // The environment's own draw, weighed against the material's density for it.
      s.setDimension(bounceBlock(depth));
      const double e1 = s.get1D(), e2 = s.get1D();
      const Environment::Sample light = env.sample(e1, e2);
      if (light.pdf > 0) {
        const Vec3 wi = frame.toLocal(light.w);
        const Colour3 f = material.eval(wi, wo);
        if ((f[0] > 0 || f[1] > 0 || f[2] > 0) && !scene.occluded(scene.offset(*hit, light.w), light.w)) {
          const double w = powerHeuristic(light.pdf, material.pdf(wo, wi));
          for (int k = 0; k < 3; ++k)
            L[size_t(k)] += beta[size_t(k)] * f[size_t(k)] * std::abs(wi.z) * light.L[size_t(k)] * w / light.pdf;
        }
      }
      s.setDimension(bounceBlock(depth) + 1);
      const std::optional<MaterialSample> m = material.sample(wo, s);
      if (!m) break;
      for (int k = 0; k < 3; ++k) beta[size_t(k)] *= m->weight[size_t(k)];
      prevPdf = m->pdf;
      d = normalize(frame.toWorld(m->wi));
      o = scene.offset(*hit, d);
      if (depth >= 2) {
        const double q = std::max({beta[0], beta[1], beta[2]});
        if (!(q > 0)) break;
        if (q < 1) {
          s.setDimension(bounceBlock(depth) + 3);
          if (s.get1D() >= q) break;
          for (double& c : beta) c /= q;
        }
      }
    }
    return L;
  }
};

}  // namespace

LinearImage renderImage(const RenderScene& scene, const Camera& camera, const RenderMaterial& material,
                        const Environment& env, const RenderSettings& settings,
                        const std::function<void(int)>& progress, RenderCounts* counts) {
  LinearImage img;
  img.width = camera.width();
  img.height = camera.height();
  img.rgb.assign(size_t(img.width) * img.height * 3, 0.f);
  const PathTracer tracer{scene, material, env, settings};
  std::atomic<int> rowsDone{0};
  std::atomic<uint64_t> dropped{0};
  tbb::parallel_for(0, img.height, [&](int y) {
    for (int x = 0; x < img.width; ++x) {
      double sum[3] = {0, 0, 0};
      for (int k = 0; k < settings.samplesPerPixel; ++k) {
        Sampler s(settings.seed, uint32_t(y * img.width + x), uint64_t(k));
        const double jx = s.get1D(), jy = s.get1D();
        const Colour3 L = tracer.radiance(camera.eye(), camera.rayDirection(x + jx, y + jy), s);
        if (!(std::isfinite(L[0]) && std::isfinite(L[1]) && std::isfinite(L[2]))) {
          dropped.fetch_add(1);
          continue;
        }
        for (int c = 0; c < 3; ++c) sum[c] += L[size_t(c)];
      }
      for (int c = 0; c < 3; ++c)
        img.rgb[(size_t(y) * img.width + x) * 3 + size_t(c)] = float(sum[c] / settings.samplesPerPixel);
    }
    const int done = rowsDone.fetch_add(1) + 1;
    if (progress) progress(done);
  });
  if (counts) {
    counts->paths = uint64_t(img.width) * img.height * uint64_t(settings.samplesPerPixel);
    counts->dropped = dropped.load();
  }
  return img;
}

}  // namespace mbsdf
