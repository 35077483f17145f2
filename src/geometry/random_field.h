// Periodic random height fields on a grid (used by the `gaussian` and `noise` generators and by
// ground noise). Both are rescaled to exactly the requested rms after removing the mean.
#pragma once
#include <cstdint>
#include <vector>

namespace mbsdf {

// Periodic Gaussian random surface with Gaussian autocorrelation C(r) = rms² exp(−r²/corr²):
// white noise filtered in the Fourier domain by sqrt(PSD) ∝ exp(−k² corr² / 8) (FFTW).
std::vector<double> gaussianRandomField(int nx, int ny, double sizeX, double sizeY, double rms, double corr,
                                        uint64_t seed);

// Sparse convolution noise (Lewis 1989; Frisvad & Wyvill 2007, the paper's [FW07]): random
// impulses with uniform weights in [−1, 1], Poisson-distributed positions with `density` impulses
// per kernel area, convolved with the kernel K(r) = (1 + cos(π r / R))/2 for r < R, periodic.
std::vector<double> sparseConvolutionNoise(int nx, int ny, double sizeX, double sizeY, double rms, double radius,
                                           double density, uint64_t seed);

// Bilinear periodic lookup in a grid covering [-sizeX/2, sizeX/2) x [-sizeY/2, sizeY/2).
double periodicLookup(const std::vector<double>& h, int nx, int ny, double sizeX, double sizeY, double x, double y);

}  // namespace mbsdf
