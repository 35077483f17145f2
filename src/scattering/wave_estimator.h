// Estimators of the scalar-diffraction single-scattering BSDF f_ws (docs/physics.md §5) and of the power
// diffracted by masked points P_msk (§6), behind one interface so that they can be compared
// (the `paper` baseline against better ones) and new ones plugged in.
//
// Both estimate, per exit bin Ωo and wavelength, the bin-averaged
//   f_ws(Ωo) = ∫_Ωo p(ωo) dω / Ω⊥(Ωo)
// with visibility rays shared by all wavelengths and phases in double precision.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/direction_grid.h"
#include "geometry/embree_scene.h"
#include "geometry/microgeometry.h"
#include "optics/material.h"
#include "scattering/coherence_window.h"
#include "scattering/tile_request.h"
#include "scattering/wave_estimator_kind.h"

namespace mbsdf {

// The range of WaveSettings::subdirections (powers of two) and its default: with the lobes' shares
// integrated (lobe_shares.h) 16 leaves 0.04–0.08 % (L1) on the paper's HEMISPHERES slice at
// 75 × 300 bins, at a quarter of 32's binning cost.
inline constexpr int kMinSubdirections = 16, kMaxSubdirections = 512, kDefaultSubdirections = 16;

// Whether `area` uses the mean plane's field as a control variate (mean_plane_control.h); None is
// the baseline of the variance benchmark (bench/bench_wave_variance.cpp).
enum class WaveControlVariate { MeanPlane, None };

struct WaveSettings {
  WaveEstimatorKind estimator = WaveEstimatorKind::Area;
  int samplesPerBin = 256;      // area: points x directions per exit bin; paper: passes
  int pointsPerDirection = 64;  // area: points per exit direction; directions = samples / points (>= 2)
  int incidenceDirections = 4;  // orders: incidence directions per slice (bin-averaged incidence)
  // The same for the incidence bins at normal incidence and at the horizon
  // (DirectionGrid::atPoleOrHorizon), where a bin's integrand varies fastest; 0: incidenceDirections.
  int poleHorizonIncidenceDirections = 0;
  // exact and fft with bin-averaged incidence: sub-directions per axis of the incidence bin through
  // which each order's power is binned (a power of two, kMinSubdirections to kMaxSubdirections).
  int subdirections = kDefaultSubdirections;
  uint64_t seed = 1;
  bool computeMasked = false;  // also estimate P_msk for the lost component
  WaveControlVariate controlVariate = WaveControlVariate::MeanPlane;
  // exact: directions per axis of the shared visibility table (visibility_table.h); 0 casts every
  // ray per order instead.
  int visibilityTable = 0;
};

struct WaveTileResult {
  WaveTileResult() = default;
  // Zeroed tables for nLambda x nBins values (P_msk too when `masked`).
  WaveTileResult(int nL, int nB, bool masked)
      : nLambda(nL),
        nBins(nB),
        fws(size_t(nL) * nB, 0.0),
        fwsErr(size_t(nL) * nB, 0.0),
        pmsk(masked ? size_t(nL) * nB : 0, 0.0),
        pmskErr(masked ? size_t(nL) * nB : 0, 0.0) {}
  int nLambda = 0, nBins = 0;
  // Per (λ, bin), λ-major, 1/sr. Bins that were not computed (the other hemisphere of a
  // conductor) hold 0.
  std::vector<double> fws, fwsErr, pmsk, pmskErr;
  // Exit bins the estimator skipped (reciprocity, see reciprocity.h) hold 0 and computed[b] = 0;
  // empty when every bin was computed.
  std::vector<uint8_t> computed;
  uint64_t samples = 0;  // Kirchhoff samples (point x direction) per wavelength
  uint64_t rays = 0;
  double seconds = 0;
  // Of `seconds`, what did not depend on the number of incidence nodes: the binning of an incidence
  // bin's interpolated orders over its sub-directions (exact, fft; 0 otherwise). `plan` scales the
  // rest when it times a finer incidence rule than the job's.
  double binningSeconds = 0;
};

struct WaveContext {
  const Microgeometry& geometry;
  const PeriodicScene& scene;
  const Material& material;
  std::vector<double> lambda_um;
  const DirectionGrid& grid;
  CoherenceWindow window;
  WaveSettings settings;
};

class WaveEstimator {
 public:
  virtual ~WaveEstimator() = default;
  virtual std::string name() const = 0;
  // What a user should know about this estimator on this job (for the log), or "".
  virtual std::string notes() const { return ""; }
  // No samples: the cost does not scale with wave_samples_per_bin (exact, fft).
  virtual bool deterministic() const { return false; }
  // Memory it holds or allocates while running a tile, beyond the scene (bytes; for `plan`).
  virtual double memoryBytes() const { return 0; }
  // Seconds its runs so far spent building what every later tile shares (once per estimator, so
  // once per rank; included in the first run's `seconds`; for `plan`).
  virtual double setupSeconds() const { return 0; }
  // exactDirection: a collimated beam (as in PathTracer::run); otherwise the incidence direction is
  // drawn cosine-weighted inside the incidence bin. exitMask (one entry per sphere bin, empty = all):
  // only the bins with a non-zero entry are estimated (estimators whose cost is not per exit bin
  // may compute more and say so in `computed`). A bin's estimate does not depend on the mask.
  // The request's tile, incidenceBin and exactDirection are read (firstPath and paths are the
  // geometric estimators'); the tile keys the samplers.
  virtual WaveTileResult run(const TileRequest& request, const std::function<void(uint64_t)>& progress = {},
                             const std::vector<uint8_t>& exitMask = {}) const = 0;

  // The same request in positional form.
  WaveTileResult run(int tile, int incidenceBin, std::optional<Vec3> exactDirection,
                     const std::function<void(uint64_t)>& progress = {},
                     const std::vector<uint8_t>& exitMask = {}) const {
    return run(TileRequest{tile, tile, incidenceBin, exactDirection, 0, 0}, progress, exitMask);
  }
};

// The order n of the deterministic estimators' n x n Gauss–Legendre rule over an incidence bin
// (with its (n − 1) x (n − 1) companion for the error estimate): n² >= directions, n >= 2.
int incidenceRuleOrder(int directions);
// The incidence directions over incidence bin `bin`: ws.poleHorizonIncidenceDirections at the bins
// that reach normal incidence or the horizon when it is set, ws.incidenceDirections elsewhere.
int incidenceDirectionsOf(const WaveSettings& ws, const DirectionGrid& grid, int bin);
// The incidence directions a deterministic estimator evaluates per tile over an incidence bin with
// the n × n rule: its own nodes and the (n − 1) × (n − 1) companion's (wave::incidenceRule).
inline int incidenceRuleNodes(int n) {
  return n * n + (n - 1) * (n - 1);
}

// "area", "orders", "exact", "fft" or "paper"; throws std::invalid_argument.
std::unique_ptr<WaveEstimator> makeWaveEstimator(const WaveContext& ctx);

// Adds the wave components to a path-traced tile (docs/physics.md §3, §6):
//   incoherent = f_ws − coherent,   lost = P_msk / Ω⊥ − geo_masked,
// with standard errors combined in quadrature. `tile` must hold coherent (and geo_masked for lost).
// Bins the wave estimator skipped get NaN (filled later from the reciprocal tile).
struct TileResult;
void addWaveComponents(TileResult& tile, const WaveTileResult& wave, bool incoherent, bool lost);

}  // namespace mbsdf
