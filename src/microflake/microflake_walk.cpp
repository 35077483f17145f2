#include "microflake/microflake_walk.h"

#include <cmath>
#include <stdexcept>

#include "core/rng.h"

namespace mbsdf {

MicroflakeWalk::MicroflakeWalk(const MicroflakeDistribution& dist, const Material& material,
                               std::vector<double> lambda_um, const DirectionGrid& grid, MicroflakeSettings settings)
    : dist_(dist), material_(material), lambda_um_(std::move(lambda_um)), grid_(grid), settings_(settings) {
  ior_ = material_.iorAt(lambda_um_);
  fresnel_ = conductorFresnelTables(material_, ior_);  // optics/fresnel_table.h
  const bool specularDielectric = settings_.flakes == FlakeKind::Specular && !material_.isConductor();
  if (specularDielectric && !dist_.isHeightfield())
    throw std::invalid_argument(
        "dielectric flakes need a heightfield NDF (the flip to the other side of the surface assumes one)");
  groups_ = wavelengthGroups(int(lambda_um_.size()),
                             settings_.flakes == FlakeKind::Diffuse || material_.directionsIndependentOfLambda());
}

std::optional<MicroflakeWalk::FirstCollision> MicroflakeWalk::firstCollision(const std::optional<Vec3>& exact) const {
  if (!exact) return std::nullopt;
  // The first flight's direction in the local frame of the side the light comes from (walk below).
  const Vec3 d = exact->z >= 0 ? -*exact : *exact;
  return FirstCollision{dist_.sigma(d), dist_.visibleFrom(-d)};
}

void MicroflakeWalk::walk(int tile, int incidenceBin, const std::optional<Vec3>& exact, const FirstCollision* first,
                          uint64_t path, int group, PathChunk& out, PathRecord* rec) const {
  const std::vector<int>& lambdas = groups_[group];
  const size_t nl = lambdas.size();
  Sampler s(settings_.seed, uint32_t(tile), path, uint32_t(group));
  const DirectionSample wi = pathIncidence(grid_, incidenceBin, exact, s);
  double w[64];
  std::vector<double> wbig;
  double* wp = w;
  if (nl > 64) {
    wbig.resize(nl);
    wp = wbig.data();
  }
  for (size_t k = 0; k < nl; ++k) wp[k] = wi.weight;
  auto addTo = [&](std::vector<double>& v) {
    for (size_t k = 0; k < nl; ++k) v[lambdas[k]] += wp[k];
  };
  if (rec) rec->wi = wi.w;
  const bool conductor = material_.isConductor(), perfect = material_.isPerfectConductor();
  const bool specular = settings_.flakes == FlakeKind::Specular;
  const double n1 = material_.outsideIor;
  const double n2 = conductor ? 1.0 : ior_[lambdas[0]].real();

  // Local frame of the current side: upper side = world frame; lower side = point-reflected.
  bool upper = wi.w.z >= 0;
  if (!upper && (conductor || !specular)) {
    // Light from below an opaque surface: nothing enters.
    addTo(out.missed);
    return;
  }
  Vec3 d = upper ? -wi.w : wi.w;  // travel direction in the local frame (downward)
  double z = 0;                   // depth in the local medium (z <= 0)
  // The first flight of a collimated incidence goes down to the depth z₁ = log(1 − u₁) d_z / σ₁,
  // which only the next flight needs, and that one, the exit flight of most short walks, usually
  // escapes whatever z₁ is within a bound: z₁ waits as its number (firstU) until it is needed.
  const double firstDz = d.z;
  const bool hasUpwardBound = dist_.hasUpwardSigmaBound();
  double firstU = -1;
  auto settleDepth = [&] {
    if (firstU < 0) return;
    z = 0.0 + MicroflakeDistribution::freePathAt(first->sigma, firstU) * firstDz;  // the flight below, exactly
    firstU = -1;
  };
  int depth = 0;
  while (true) {
    // Free flight (Dupuy et al. 2016, Eqs. 9–11); escape through z = 0 when travelling upward.
    const double u = s.get1D();
    if (depth == 0 && first && first->sigma >= 1e-300) {
      firstU = u;  // a finite depth (u < 1, σ₁ not tiny): no escape, no truncation
    } else {
      // An upward flight escapes if its exponential number −log(1 − u) >= u reaches σ(d)/d_z times
      // the depth, and −z <= u₁/(1 − u₁) |d_z,1| / σ₁ while z₁ waits. With an upper bound of σ
      // (upwardSigmaBound) this decides most exit flights without a logarithm, σ's square roots or
      // its erfc; whenever it decides so, the exact flight below escapes too (a margin covers its
      // rounding). (Asked only where there can be a bound: a long walk of another distribution does
      // not pay for the question at every flight.)
      const double bound = hasUpwardBound && d.z > 0 ? dist_.upwardSigmaBound(d) : -1;
      bool certainEscape = false;
      if (bound >= 0) {
        const double zMax = firstU >= 0 ? firstU / (1 - firstU) * -firstDz / first->sigma : -z;
        certainEscape = u * d.z >= bound * zMax * (1 + 1e-9);
      }
      if (!certainEscape) settleDepth();
      // (σ only when the flight is not decided already.)
      auto flight = [&] {
        return depth == 0 && first ? MicroflakeDistribution::freePathAt(first->sigma, u) : dist_.freePath(d, u);
      };
      const double zNext = certainEscape ? 0.0 : z + flight() * d.z;
      if (d.z > 0 && !(zNext < 0)) {  // depth >= 1: the first flight is downward
        const Vec3 wo = upper ? d : -d;
        const int bin = grid_.binOf(wo);
        out.tally(bin, depth == 1 ? Component::Coherent : Component::Multiple, group, wp, nl);
        if (rec) {
          rec->wo = wo;
          rec->exitBin = bin;
        }
        break;
      }
      z = zNext;
    }
    if (!std::isfinite(z)) {  // horizontal flight with σ = 0 cannot occur for a valid NDF; be safe
      addTo(out.truncated);
      break;
    }
    if (++depth > settings_.maxDepth) {
      addTo(out.truncated);
      break;
    }
    // Russian roulette once every weight is below 1/4: unbiased, and it ends the long walks of
    // absorbing media (a conservative walk's length is heavy-tailed) instead of truncating them.
    double wmax = 0;
    for (size_t k = 0; k < nl; ++k) wmax = std::max(wmax, wp[k]);
    if (wmax < 0.25) {
      const double survive = wmax / 0.25;
      if (!(s.get1D() < survive)) break;
      for (size_t k = 0; k < nl; ++k) wp[k] /= survive;
    }
    const Vec3 v = -d;  // towards where the light came from
    std::optional<Vec3> m = depth == 1 && first ? dist_.sampleVisible(first->visible, s) : dist_.sampleVisible(v, s);
    if (!m) {
      addTo(out.truncated);
      break;
    }
    const double cosM = std::clamp(dot(v, *m), 0.0, 1.0);
    for (size_t k = 0; k < nl; ++k) wp[k] *= settings_.flakeAlbedo;
    if (!specular) {
      // Lambertian flake: cosine-weighted about m.
      const double u1 = s.get1D(), u2 = s.get1D();
      const double r = std::sqrt(u1), phi = 2 * kPi * u2;
      const Vec3 a = std::abs(m->x) > 0.9 ? Vec3{0, 1, 0} : Vec3{1, 0, 0};
      const Vec3 t = normalize(cross(a, *m)), b = cross(*m, t);
      d = normalize(t * (r * std::cos(phi)) + b * (r * std::sin(phi)) + *m * safeSqrt(1 - u1));
    } else if (conductor) {
      if (!perfect)
        for (size_t k = 0; k < nl; ++k) wp[k] *= fresnel_[size_t(lambdas[k])](cosM);
      d = normalize(reflect(v, *m));
    } else {
      const double etaI = upper ? n1 : n2, etaT = upper ? n2 : n1;
      const double F = fresnelReflectance(cosM, etaI, Complex(etaT, 0));
      Vec3 wt;
      if (s.get1D() < F || !refract(v, *m, etaI / etaT, &wt)) {
        d = normalize(reflect(v, *m));
      } else {
        // Continue on the other side (Heitz et al. 2016): point-reflected frame, flipped height.
        upper = !upper;
        d = -wt;
        settleDepth();
        z = std::log(-std::expm1(z));
      }
    }
  }
  if (rec) {
    rec->depth = depth;
    rec->weight.assign(wp, wp + nl);
  }
}

TileResult MicroflakeWalk::run(const TileRequest& q, const std::function<void(uint64_t)>& progress) const {
  const int tile = q.tile, incidenceBin = q.incidenceBin;
  std::optional<Vec3> exactDirection = q.exactDirection;
  if (exactDirection) exactDirection = normalize(*exactDirection);
  const PathTallyPlan plan{tile,
                           q.incidenceIndex,
                           incidenceBin,
                           &grid_,
                           int(lambda_um_.size()),
                           groups_,
                           q.paths > 0 ? q.paths : settings_.paths,
                           q.firstPath,
                           {Component::Coherent, Component::Multiple}};
  const std::optional<FirstCollision> first = firstCollision(exactDirection);
  const FirstCollision* firstPtr = first ? &*first : nullptr;
  return runPaths(
      plan,
      [&](uint64_t p, int g, PathChunk& c) { walk(tile, incidenceBin, exactDirection, firstPtr, p, g, c, nullptr); },
      progress);
}

MicroflakeWalk::PathRecord MicroflakeWalk::replay(int tile, int incidenceBin, uint64_t path, int group,
                                                  std::optional<Vec3> exactDirection) const {
  PathChunk c(int(lambda_um_.size()));
  PathRecord rec;
  if (exactDirection) exactDirection = normalize(*exactDirection);
  const std::optional<FirstCollision> first = firstCollision(exactDirection);
  walk(tile, incidenceBin, exactDirection, first ? &*first : nullptr, path, group, c, &rec);
  return rec;
}

}  // namespace mbsdf
