// SPDX-License-Identifier: MIT
#pragma once
// Windowing (ringing control) and zonal convolution of SH coefficient vectors (conventions:
// sh_basis.h).
//
// Truncating an expansion at band L rings (Gibbs): a light or visibility that is ≥ 0 reconstructs
// with negative lobes (Kronander 2012 §5, "bright spots" at the base of the sphere/torus). A window
// multiplies band l by a factor w_l ∈ [0, 1], w_0 = 1 (the integral is kept):
// * Hanning:  w_l = (1 + cos(π l/(L+1)))/2
// * Lanczos σ-factors: w_l = sinc(π l/(L+1)) = sin(π l/(L+1)) / (π l/(L+1))
// * Gaussian (heat kernel, Sloan "Stupid SH tricks" §windowing): w_l = exp(−λ l(l+1)), λ ≥ 0 the
//   strength.
// applyWindow() applies one; nonNegativeGaussianStrength() finds the weakest Gaussian window that
// makes a reconstruction non-negative on a direction set (Sloan's "minimum ringing" goal as a 1-D
// search).
//
// Zonal functions g(ω) = g(ω·a) are rotationally symmetric about an axis a. With
// z_l = ∫ g(cosθ) Y_l^0 dω (the coefficients of g about +z):
// * aligned to unit axis a: c_lm = z_l √(4π/(2l+1)) Y_lm(a) (zonalToAxis)
// * convolution f ∗ g (Funk–Hecke): (f∗g)_lm = √(4π/(2l+1)) z_l f_lm = Â_l f_lm (convolveZonal)
// The clamped cosine max(cosθ, 0) has Â_l = π, 2π/3, π/4, 0, −π/24, 0, π/64, … (Ramamoorthi &
// Hanrahan 2001): irradiance E_lm = Â_l L_lm.
#include <functional>
#include <glm/glm.hpp>
#include <span>
#include <string_view>
#include <vector>

#include "sh/sphere_samples.h"

namespace voxlight::sh {

enum class ShWindow { None, Hanning, Lanczos, Gaussian };
std::string_view toString(ShWindow w);
/// Parses "none", "hanning", "lanczos", "gaussian"; InputError (source, field) otherwise.
ShWindow parseShWindow(std::string_view name, const char* source = "sh",
                       const char* field = "window");

/// Factors w_0..w_L; `strength` is λ for Gaussian (≥ 0) and ignored otherwise.
std::vector<double> windowFactors(ShWindow window, int maxBand, double strength = 0.0);
/// Multiplies band l of `coeffs` (size (L+1)²) by w_l, in place.
void applyWindow(std::span<float> coeffs, ShWindow window, double strength = 0.0);
void applyWindowRgb(std::span<glm::vec3> coeffs, ShWindow window, double strength = 0.0);

/// Smallest λ ≥ 0 (to 1e-4 relative) such that the Gaussian-windowed reconstruction is ≥
/// −tolerance·c_0/√(4π) at every direction of `dirs`. Returns 0 if the input is already
/// non-negative there.
double nonNegativeGaussianStrength(std::span<const float> coeffs, const SphereSamples& dirs,
                                   double tolerance = 1e-6);

/// z_l, l = 0..L, for a zonal g(cosθ) by Gauss–Legendre quadrature in cosθ (exact for polynomial g
/// of degree ≤ 2·quadratureNodes − 1 − L).
std::vector<double> projectZonal(int maxBand, const std::function<double(double)>& g,
                                 int quadratureNodes = 256);
/// Closed-form z_l of max(cosθ, 0).
std::vector<double> clampedCosineZonal(int maxBand);
/// Â_l = √(4π/(2l+1)) z_l of max(cosθ, 0), l = 0..L (closed form).
std::vector<double> clampedCosineConvolution(int maxBand);
/// Coefficients (size (L+1)²) of the zonal function with coefficients z about +z, re-aligned to
/// unit axis `axis`.
std::vector<float> zonalToAxis(std::span<const double> zonal, const glm::dvec3& axis);
/// Allocation-free form: writes the shCount(zonal.size() − 1) coefficients to `out` (at least that
/// many entries).
void zonalToAxis(std::span<const double> zonal, const glm::dvec3& axis, std::span<float> out);
/// In place: f_lm ← √(4π/(2l+1)) z_l f_lm.
void convolveZonal(std::span<float> coeffs, std::span<const double> zonal);
void convolveZonalRgb(std::span<glm::vec3> coeffs, std::span<const double> zonal);

}  // namespace voxlight::sh
