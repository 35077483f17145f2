// The `fft` wave estimator: the Kirchhoff single-scattering BSDF of a periodic heightfield from the
// FFT of its facet fields (heightfield_spectrum.h) instead of sampled points — deterministic, no
// Monte Carlo noise.
//
// Two regimes of the coherence window σ against the patch (the copy sum by Poisson summation,
// orders_estimator.h: I(q) = (1/A_fp) Σ_G ŵ(q_xy − G) Ĥ_G(q_z, k2), ŵ(k) = 2πσ² e^{−σ²|k|²/2}):
//  - 2πσ/L >= 4 (the `orders` regime): the orders' lobes do not overlap; each order's power goes
//    to the bins under its Gaussian lobe (OrdersWaveEstimator with Fourier amplitudes, including
//    the sparse masking correction).
//  - narrower windows (lobes overlap: speckle): I(q) is evaluated at Gauss–Legendre nodes of
//    each exit bin and f_ws(Ω) = Σ_nodes w p(ωo) / cos θo / Ω⊥(Ω) (dω = dx dy / cos θo). On a disk
//    grid the nodes are 3 x 3 per cell in (x, y) of ωo, pixels cut into cells no wider than the
//    speckle size 1/(σ n_o k0): separable, as ŵ is, so the sum over G is two banded matrix products
//    per table. On other grids, 3 x 3 nodes per cell of the bin's cosine-weighted
//    sample space, cut into cells no wider than about two speckles, with a direct sum over the
//    orders within the window's reach. The error reported per bin is |Q_3 − Q_2| plus that of the
//    incidence rule (wave::incidenceRule). Masking is not modelled
//    here (V(x, ωo) = 1): exact where the exit elevation exceeds the steepest facet slope (the
//    angle is in `notes()`); `lost` (the masked field) needs the orders regime or another estimator.
// Accuracy of the one-point rule per facet: texels well below λ/4 (the FFT's orders reach
// |G| = 2 n k0 only then without aliasing).
#pragma once
#include <memory>

#include "scattering/wave_estimator.h"

namespace mbsdf {

// Why the fft estimator cannot run on this setup, or "" when it can: it needs a periodic heightfield
// under a window, at most kMaxFourierCells texels after the split for the shortest wavelength
// (memory: 8 complex fields per facet, ~256 B per texel), and with 2πσ/L < 4 no masked field
// (`lost`).
inline constexpr size_t kMaxFourierCells = size_t(1) << 22;
std::string fftUnsuitable(const Microgeometry& geometry, const Material& material, const std::vector<double>& lambda_um,
                          double sigma, bool masked);

// The fft estimator for either regime; throws std::invalid_argument when !fftApplicable.
std::unique_ptr<WaveEstimator> makeFftWaveEstimator(const WaveContext& ctx);

}  // namespace mbsdf
