// White furnace, reciprocity and determinism of the path tracer.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <array>
#include <chrono>
#include <thread>

#include <cmath>
#include <optional>
#include <string>

#include "core/rng.h"
#include "geometry/generators.h"
#include "optics/fresnel.h"
#include "scattering_test_util.h"

using namespace mbsdf;
using namespace mbsdf::test;

namespace {
double albedo(const TileResult& r, const DirectionGrid& g) {
  return energy(r, g, Component::Coherent, 0, true) + energy(r, g, Component::Multiple, 0, true);
}
}  // namespace

// F = 1 facets: every path must come back up (reflected albedo 1 up to the depth cut-off, which is
// reported as truncated energy, never silently lost).
TEST(WhiteFurnace, MirrorFacetsReflectEverything) {
  PathTracerSettings s;
  s.paths = 50000;
  s.maxDepth = 100;
  struct Case {
    const char* name;
    Microgeometry g;
  };
  // gaussian: rms height 0.5 µm, correlation 1 µm: rms gradient 2h/ℓ = 1 (per-axis slope 0.71).
  std::vector<Case> cases;
  cases.push_back(
      {"hemispheres",
       makeDomeLattice({.size_um = {20, 20}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 2.0 / 16})});
  cases.push_back({"overhang", makeOverhang({.size_um = {20, 20},
                                             .spacing_um = 5,
                                             .stem_radius_um = 0.8,
                                             .stem_height_um = 1.5,
                                             .cap_radius_um = 2.0,
                                             .cap_height_um = 1.0,
                                             .resolution_um = 2.0 / 16})});
  cases.push_back({"gaussian", makeGaussian(20, 20, 0.5, 1.0, 160, 160, 3)});
  for (auto& c : cases) {
    Scenario sc(c.g, material("mirror"), ThetaPhiGrid{30, 60}, {0.55}, s);
    for (double theta : {0.0, 45.0, 80.0}) {
      TileResult r = sc.run(theta, 17.0);
      double a = albedo(r, sc.grid);
      EXPECT_GE(a, 0.999) << c.name << " theta " << theta << " truncated " << r.truncated[0] << " leaked "
                          << r.leaked[0] << " missed " << r.missed[0];
      EXPECT_NEAR(a + r.truncated[0] + r.leaked[0] + r.missed[0], 1.0, 1e-9) << c.name;
      EXPECT_EQ(energy(r, sc.grid, Component::Multiple, 0, false), 0.0) << "no transmission through a conductor";
      RecordProperty(std::string(c.name) + "_theta" + std::to_string(int(theta)) + "_truncated",
                     std::to_string(r.truncated[0]));
    }
  }
}

// f(i, o) = f(o, i) for reflection (docs/physics.md §8), bin-averaged, on a rough aluminium gaussian
// surface, for 24 random bin pairs: |z| < 4 with z from the estimators' own standard errors.
TEST(Reciprocity, RoughConductorBinPairs) {
  PathTracerSettings s;
  s.paths = 400000;
  Scenario sc(makeGaussian(20, 20, 0.4, 1.0, 160, 160, 5), material("Al"), ThetaPhiGrid{6, 12}, {0.55}, s);
  const int nUpper = sc.grid.binsPerHemisphere();
  std::map<int, TileResult> tiles;
  auto tile = [&](int bin) -> const TileResult& {
    auto it = tiles.find(bin);
    if (it == tiles.end()) it = tiles.emplace(bin, sc.tracer->run(bin, 0, bin)).first;
    return it->second;
  };
  auto total = [](const TileResult& r, int b, double* se) {
    double v = r.at(Component::Coherent, 0, b) + r.at(Component::Multiple, 0, b);
    double e1 = r.stdError[int(Component::Coherent)][b], e2 = r.stdError[int(Component::Multiple)][b];
    *se = std::sqrt(e1 * e1 + e2 * e2);
    return v;
  };
  Sampler pick(99, 0, 0);
  int tested = 0;
  double maxZ = 0;
  for (int attempt = 0; attempt < 200 && tested < 24; ++attempt) {
    int i = int(pick.get1D() * nUpper), o = int(pick.get1D() * nUpper);
    if (i == o) continue;
    double sa, sb;
    double a = total(tile(i), o, &sa), b = total(tile(o), i, &sb);
    // Only well-populated bins: the standard error is itself estimated and must be reliable.
    if (!(a > 10 * sa && b > 10 * sb)) continue;
    double z = (a - b) / std::sqrt(sa * sa + sb * sb);
    maxZ = std::max(maxZ, std::abs(z));
    EXPECT_LT(std::abs(z), 4.0) << "bins " << i << " " << o << ": " << a << " vs " << b;
    ++tested;
  }
  EXPECT_GE(tested, 20);
  RecordProperty("max_abs_z", std::to_string(maxZ));
}

// The same tile with 1 and 2 threads gives bit-identical tallies.
TEST(Determinism, ThreadCountDoesNotChangeResults) {
  PathTracerSettings s;
  s.paths = 30000;
  Scenario sc(makeOverhang({.size_um = {10, 10},
                            .spacing_um = 5,
                            .stem_radius_um = 0.8,
                            .stem_height_um = 1.5,
                            .cap_radius_um = 2.0,
                            .cap_height_um = 1.0,
                            .resolution_um = 2.0 / 12}),
              material("Au"), ThetaPhiGrid{15, 30}, {0.45, 0.55, 0.65}, s);
  TileResult a, b;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    a = sc.run(40, 10, false, 3);
  }
  {
    tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    b = sc.run(40, 10, false, 3);
  }
  for (Component c : {Component::Coherent, Component::Multiple}) {
    EXPECT_EQ(a.value[int(c)], b.value[int(c)]);
    EXPECT_EQ(a.stdError[int(c)], b.stdError[int(c)]);
  }
  EXPECT_EQ(a.truncated, b.truncated);
  // A different tile key gives different samples.
  TileResult other = sc.run(40, 10, false, 4);
  EXPECT_NE(a.value[int(Component::Multiple)], other.value[int(Component::Multiple)]);
}

// Buffers made ahead of the first tile (reserveBuffers, while MPI starts) are only storage: a
// tracer whose first run uses them gives the bytes of one that allocates its own, for a conductor
// whose wavelengths share paths (with geo_masked tallied) and a dielectric traced by wavelength
// (more paths than one batch, so that later batches reuse what the first left).
TEST(Determinism, ReservedBuffersChangeNoResult) {
  struct Case {
    Material m;
    bool geoMasked;
    uint64_t paths;
  };
  for (const Case& k : {Case{material("Au"), true, 30000}, Case{material("BK7"), false, 256 * 1024 + 700}}) {
    PathTracerSettings s;
    s.paths = k.paths;
    s.tallyGeoMasked = k.geoMasked;
    auto scenario = [&] {
      return Scenario(
          makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25}),
          k.m, ThetaPhiGrid{10, 20}, {0.45, 0.65}, s);
    };
    const Scenario plain = scenario(), reserved = scenario();
    reserved.tracer->reserveBuffers();
    for (int tile = 0; tile < 2; ++tile) {
      const TileResult a = plain.run(50, 20, false, tile), b = reserved.run(50, 20, false, tile);
      for (Component c : {Component::Coherent, Component::Multiple, Component::GeoMasked}) {
        EXPECT_EQ(a.value[int(c)], b.value[int(c)]) << k.m.describe() << " tile " << tile;
        EXPECT_EQ(a.stdError[int(c)], b.stdError[int(c)]) << k.m.describe() << " tile " << tile;
      }
      EXPECT_EQ(a.rays, b.rays);
      EXPECT_EQ(a.truncated, b.truncated);
    }
  }
}

// A failing sample can be replayed: replay() of path j gives the same exit as the batch run.
TEST(Determinism, ReplayMatchesBatch) {
  PathTracerSettings s;
  s.paths = 1;
  Scenario sc(makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.2}),
              material("mirror"), ThetaPhiGrid{15, 30}, {0.55}, s);
  int bin = sc.grid.binOfAngles(30, 0);
  TileResult r = sc.tracer->run(7, 0, bin);
  auto rec = sc.tracer->replay(7, bin, 0);
  ASSERT_GE(rec.exitBin, 0);
  Component c = rec.depth == 1 ? Component::Coherent : Component::Multiple;
  EXPECT_GT(r.at(c, 0, rec.exitBin), 0.0);
}

namespace {
// The tallies of replay() of paths 0 … paths − 1 (one wavelength group), as run() reports them.
std::array<std::vector<double>, 2> replayedTallies(const Scenario& sc, int tile, int bin, uint64_t paths,
                                                   const std::optional<Vec3>& exact, size_t nL, uint64_t* rays) {
  const size_t nB = size_t(sc.grid.binCount());
  std::array<std::vector<double>, 2> sum = {std::vector<double>(nL * nB, 0.0), std::vector<double>(nL * nB, 0.0)};
  *rays = 0;
  for (uint64_t p = 0; p < paths; ++p) {
    const auto rec = sc.tracer->replay(tile, bin, p, 0, exact);
    *rays += rec.rays.size();
    if (rec.exitBin < 0) continue;
    for (size_t l = 0; l < rec.weight.size(); ++l)
      sum[rec.depth == 1 ? 0 : 1][l * nB + size_t(rec.exitBin)] += rec.weight[l];
  }
  for (auto& s : sum)
    for (size_t i = 0; i < s.size(); ++i) {
      const double op = sc.grid.projectedSolidAngle(int(i % nB));
      s[i] = op > 0 ? s[i] / (double(paths) * op) : 0.0;
    }
  return sum;
}
}  // namespace

// run() advances a batch's paths together (a wavefront: one ray per path per round, first rays as
// Embree packets, each round's rays in origin order on a scene of 4096 triangles or more);
// replay() traces one path alone with PeriodicScene::trace. The tallies of run() are the sums of
// the replayed paths' exits, in path order, to the last bit: for a mirror lattice, an Al
// heightfield (weights per wavelength), BK7 (random reflection or refraction at each hit,
// transmission), a finite patch, a small grating (rays in path order), grazing and normal
// incidence, bin-sampled and exact.
TEST(Determinism, WavefrontRunEqualsPathByPathReplay) {
  struct Case {
    const char* name;
    Microgeometry g;
    const char* material;
    std::vector<double> lambdas;
    double theta;
    bool exact;
  };
  std::vector<Case> cases;
  cases.push_back(
      {"mirror lattice 30",
       makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.25}),
       "mirror",
       {0.55},
       30,
       false});
  cases.push_back({"Al gaussian 85", makeGaussian(10, 10, 0.4, 1.0, 64, 64, 3), "Al", {0.45, 0.65}, 85, false});
  cases.push_back({"BK7 gaussian 0", makeGaussian(10, 10, 0.4, 1.0, 64, 64, 5), "BK7", {0.55}, 0, true});
  cases.push_back({"BK7 gaussian 60", makeGaussian(10, 10, 0.4, 1.0, 64, 64, 5), "BK7", {0.55}, 60, false});
  Microgeometry finite = makeGaussian(10, 10, 0.3, 1.0, 48, 48, 9);
  finite.periodic = false;
  cases.push_back({"Al finite 45", finite, "Al", {0.55}, 45, true});
  cases.push_back({"Al grating 70", makeSineGrating(2.0, 0.3, 2.0, 0.03, 64, 0), "Al", {0.5, 0.6}, 70, false});
  int ordered = 0, unordered = 0;
  for (Case& k : cases) {
    PathTracerSettings s;
    s.paths = 2500;  // more than two chunks of 1024
    Scenario sc(std::move(k.g), material(k.material), ThetaPhiGrid{9, 18}, k.lambdas, s);
    const int bin = sc.grid.binOfAngles(k.theta, 0);
    std::optional<Vec3> exact;
    if (k.exact) exact = sphericalDirection(radians(k.theta), 0);
    (sc.tracer->ordersByOrigin() ? ordered : unordered) += 1;
    const TileResult r = sc.tracer->run(3, 0, bin, exact);
    const size_t nL = k.lambdas.size();
    uint64_t rays = 0;
    // One wavelength group in every case (Al's paths carry a weight per wavelength).
    const auto expected = replayedTallies(sc, 3, bin, s.paths, exact, nL, &rays);
    EXPECT_EQ(r.rays, rays) << k.name;
    int nonZero = 0;
    for (int c = 0; c < 2; ++c)
      for (size_t i = 0; i < expected[c].size(); ++i) {
        ASSERT_EQ(r.value[c == 0 ? int(Component::Coherent) : int(Component::Multiple)][i], expected[c][i])
            << k.name << " component " << c << " index " << i;
        nonZero += expected[c][i] > 0;
      }
    EXPECT_GT(nonZero, 10) << k.name;
  }
  EXPECT_GE(ordered, 2);
  EXPECT_GE(unordered, 1);
}

// A tile of more paths than one batch (runPaths: 256 chunks of 1024), run twice by one tracer
// (the second run reuses the first's wavefront buffers, the second batch is smaller than the
// first): both equal the replayed paths to the last bit, with the rays as packets and one by one.
TEST(Determinism, WavefrontRunOverSeveralBatchesEqualsReplay) {
  for (const bool packets : {true, false}) {
    PathTracerSettings s;
    s.paths = 256 * 1024 + 1500;
    s.packets = packets;
    Scenario sc(makeGaussian(10, 10, 0.4, 1.0, 48, 48, 11), material("Al"), ThetaPhiGrid{6, 12}, {0.45, 0.65}, s);
    ASSERT_TRUE(sc.tracer->ordersByOrigin());
    const int bin = sc.grid.binOfAngles(40, 0);
    uint64_t rays = 0;
    const auto expected = replayedTallies(sc, 5, bin, s.paths, std::nullopt, 2, &rays);
    for (int run = 0; run < 2; ++run) {
      const TileResult r = sc.tracer->run(5, 0, bin);
      EXPECT_EQ(r.rays, rays);
      EXPECT_EQ(r.value[int(Component::Coherent)], expected[0]) << "run " << run << ", packets " << packets;
      EXPECT_EQ(r.value[int(Component::Multiple)], expected[1]) << "run " << run << ", packets " << packets;
    }
  }
}

// A run abandoned from its progress callback (a stop request) ends although the next batch's
// rounds are under way (the callback waits 50 ms, about the rounds' middle here, before it throws;
// whenever the cancellation comes, the cancelled rounds leave no rays behind), and the tracer runs
// again afterwards.
TEST(Determinism, AbandonedWavefrontRunEnds) {
  PathTracerSettings s;
  s.paths = 3 * 256 * 1024;
  Scenario sc(makeGaussian(10, 10, 0.4, 1.0, 48, 48, 11), material("Al"), ThetaPhiGrid{6, 12}, {0.55}, s);
  ASSERT_TRUE(sc.tracer->ordersByOrigin());
  const int bin = sc.grid.binOfAngles(40, 0);
  struct Stop {};
  TileRequest q;
  q.tile = 1;
  q.incidenceBin = bin;
  EXPECT_THROW(sc.tracer->run(q,
                              [](uint64_t) {
                                std::this_thread::sleep_for(std::chrono::milliseconds(50));
                                throw Stop{};
                              }),
               Stop);
  q.paths = 2000;
  EXPECT_EQ(sc.tracer->run(q, {}).samples, 2000u);
}

// Progressive sampling pools rounds of fresh paths: two rounds of N equal one run of 2N paths.
TEST(ProgressiveSampling, PooledRoundsEqualOneLongRun) {
  Microgeometry g = makeGaussian(10, 10, 0.4, 1.0, 64, 64, 3);
  PeriodicScene scene(g);
  Material al = test::material("Al");
  DirectionGrid grid(ThetaPhiGrid{6, 12});
  PathTracerSettings s;
  s.paths = 3000;
  PathTracer half(scene, al, {0.45, 0.65}, grid, s);
  s.paths = 6000;
  PathTracer full(scene, al, {0.45, 0.65}, grid, s);
  const int bin = grid.binOfAngles(50, 0);
  TileResult a = half.run(2, 0, bin), b = half.run(2, 0, bin, std::nullopt, {}, 3000), f = full.run(2, 0, bin);
  a.poolPaths(b);
  EXPECT_EQ(a.samples, 6000u);
  EXPECT_EQ(a.rounds, 2);
  for (Component c : {Component::Coherent, Component::Multiple})
    for (size_t i = 0; i < f.value[int(c)].size(); ++i) {
      EXPECT_NEAR(a.value[int(c)][i], f.value[int(c)][i], 1e-12 * (1 + f.value[int(c)][i]));
      EXPECT_NEAR(a.stdError[int(c)][i], f.stdError[int(c)][i], 1e-9 * (1 + f.stdError[int(c)][i]));
    }
  for (int l = 0; l < 2; ++l) EXPECT_NEAR(a.truncated[l], f.truncated[l], 1e-15);
  // The per-path energy moments pool too, and travel through the MPI message unchanged.
  for (Component c : {Component::Coherent, Component::Multiple})
    for (size_t i = 0; i < f.pathMoments[int(c)].size(); ++i)
      EXPECT_NEAR(a.pathMoments[int(c)][i], f.pathMoments[int(c)][i], 1e-12 * (1 + f.pathMoments[int(c)][i]));
  const TileResult back = TileResult::deserialize(a.serialize());
  EXPECT_EQ(back.pathMoments, a.pathMoments);
  EXPECT_EQ(back.value, a.value);
}

// The standard error of a slice's energy comes from the per-path energies (TileResult::pathMoments),
// with the covariance of the bins: each path lands in one bin. Against closed forms: a flat
// dielectric reflects the Fresnel fraction F of the paths (each path reflects or refracts with
// weight 1, so R's estimator is binomial) and transmits 1 − F, seen from above and from inside,
// 72 cases of index and angle. z = (estimate − F) / SE must have mean z² within 4 standard deviations
// (√(2/n)) of 1. A mirror's albedo is exactly 1 with a standard error of exactly 0, and so is a
// lossless dielectric's R + T (the per-bin root-sum-square said ± 1e-3 for it).
TEST(EnergyStandardError, FlatDielectricZScoresAgainstFresnel) {
  PathTracerSettings s;
  s.paths = 4000;
  std::vector<double> z;
  double rssOverSe = 0;
  int rssCases = 0;
  for (double eta : {1.3, 1.5, 2.0}) {
    Material glass;
    glass.model = Dielectric{ConstantIndex{eta, 0.0}};
    Scenario sc(makeFlat(4, 4, 0), glass, ThetaPhiGrid{9, 8}, {0.55}, s);
    for (double theta : {2.0, 12.0, 23.0, 31.0, 38.0, 47.0, 55.0, 63.0, 71.0, 77.0, 82.0, 86.0}) {
      for (bool above : {true, false}) {
        // From inside only below the critical angle (beyond it F = 1 exactly: no variance).
        const double thetaIn = above ? theta : 180.0 - theta * std::asin(1.0 / eta) / radians(90.0);
        const double cosI = std::abs(std::cos(radians(thetaIn)));
        const double F = fresnelReflectance(cosI, above ? 1.0 : eta, Complex(above ? eta : 1.0, 0));
        TileResult r = sc.run(thetaIn, 0.0, /*exact=*/true, int(z.size()));
        const int reflectedSide = above ? 0 : 1;
        const auto se = r.pathEnergyStdError({Component::Coherent}, reflectedSide);
        ASSERT_EQ(se.size(), 1u);
        const double R = energy(r, sc.grid, Component::Coherent, 0, above);
        ASSERT_GT(se[0], 0) << eta << " " << thetaIn;
        z.push_back((R - F) / se[0]);
        // Both sides together: every path leaves, the albedo is 1 and its error 0.
        EXPECT_NEAR(r.pathEnergyStdError({Component::Coherent}, -1)[0], 0.0, 1e-12);
        rssOverSe += energyStdError(r, sc.grid, Component::Coherent, 0, above) / se[0];
        ++rssCases;
      }
    }
  }
  double z2 = 0;
  for (double v : z) z2 += v * v / double(z.size());
  const double sd = std::sqrt(2.0 / double(z.size()));
  EXPECT_NEAR(z2, 1.0, 4 * sd) << z.size() << " cases";
  RecordProperty("cases", int(z.size()));
  RecordProperty("mean_z2", std::to_string(z2));
  RecordProperty("rss_over_se", std::to_string(rssOverSe / rssCases));
  // A mirror: albedo 1, standard error 0.
  Scenario mirror(makeFlat(4, 4, 0), material("mirror"), ThetaPhiGrid{9, 8}, {0.55}, s);
  TileResult r = mirror.run(40.0, 0.0, true);
  EXPECT_NEAR(energy(r, mirror.grid, Component::Coherent, 0, true), 1.0, 1e-12);
  EXPECT_EQ(r.pathEnergyStdError({Component::Coherent, Component::Multiple}, -1)[0], 0.0);
}
