// SPDX-License-Identifier: MIT
#pragma once
// Projection of spherical functions onto the SH basis of sh_basis.h: c_i = ∫ f(ω) Y_i(ω) dω,
// approximated by a weighted sum Σ_k w_k f(ω_k) Y_i(ω_k) (w_k in steradians). Sums are accumulated
// in double (ARCHITECTURE §3).
//
// * ShProjector: an accumulator — add(direction, weight·value) one sample at a time (area lights,
//   cube maps, any custom quadrature). Evaluates each direction with the unrolled path for L ≤ 4.
// * projectSamples / projectSamplesRgb: values given at the directions of a SphereSamples set.
// * projectFunction: a callable f(const glm::dvec3&) → double or glm::dvec3, sampled at a set.
// * projectEquirect: a latitude–longitude grid of RGB values, separable fast path
//   (O(W·H·L + H·(L+1)²) instead of O(W·H·(L+1)²)), exactly equal to the pixel-centre midpoint
//   rule with exact per-row pixel solid angles.
#include <glm/glm.hpp>
#include <span>
#include <type_traits>
#include <vector>

#include "sh/sh_basis.h"
#include "sh/sphere_samples.h"

namespace voxlight::sh {

/// Accumulates Σ w f Y_i(ω) for RGB values. Not thread-safe; use one per thread and merge().
class ShProjector {
  public:
    explicit ShProjector(int maxBand);
    int maxBand() const { return band_; }
    /// Adds weightedValue · Y_i(unitDir) to every coefficient (weightedValue = f(ω) · solid angle).
    void add(const glm::dvec3& unitDir, const glm::dvec3& weightedValue);
    void merge(const ShProjector& other);
    std::vector<glm::vec3> coefficientsRgb() const;
    /// The red channel only (for scalar projections where r = g = b).
    std::vector<float> coefficients() const;

  private:
    int band_;
    std::vector<glm::dvec3> sum_;
};

/// The allocation-free core of ShProjector::add, for callers that keep their own sums (per-voxel
/// light projection): sum[i] += weightedValue · Y_i(unitDir) for i < shCount(maxBand) (sum.size()
/// must be at least that; maxBand is not re-validated beyond VL_CHECK).
void addShSample(int maxBand, const glm::dvec3& unitDir, const glm::dvec3& weightedValue,
                 std::span<glm::dvec3> sum);

std::vector<float> projectSamples(int maxBand, const SphereSamples& samples,
                                  std::span<const float> values);
std::vector<glm::vec3> projectSamplesRgb(int maxBand, const SphereSamples& samples,
                                         std::span<const glm::vec3> values);

/// Projects a callable f(const glm::dvec3& unitDir) onto bands 0..L with the set's weights. f may
/// return a scalar (double, float → std::vector<double>) or RGB (glm::dvec3, glm::vec3 →
/// std::vector<glm::dvec3>, each channel projected like the scalar case).
template <class F>
auto projectFunction(int maxBand, const SphereSamples& samples, F&& f) {
    using R = std::remove_cvref_t<std::invoke_result_t<F&, const glm::dvec3&>>;
    constexpr bool kRgb = std::is_same_v<R, glm::dvec3> || std::is_same_v<R, glm::vec3>;
    static_assert(kRgb || std::is_arithmetic_v<R>,
                  "projectFunction: f must return a scalar, glm::dvec3 or glm::vec3");
    using T = std::conditional_t<kRgb, glm::dvec3, double>;
    checkBand(maxBand);
    const int n = shCount(maxBand);
    std::vector<T> c(n, T(0.0));
    std::vector<double> y(n);
    for (std::size_t k = 0; k < samples.size(); ++k) {
        evalShUnitDouble(maxBand, samples.directions[k], y);
        const T v = samples.weights[k] * T(f(samples.directions[k]));
        for (int i = 0; i < n; ++i) c[i] += v * y[i];
    }
    return c;
}

/// Latitude–longitude layout of an RGB grid for projectEquirect: row r covers θ ∈ [π r/H, π
/// (r+1)/H] (row 0 at θ = 0, the +z pole); column c is centred on φ = phi0 + phiStep · (c + ½)
/// (phiStep may be negative; |phiStep|·W must be 2π).
struct EquirectLayout {
    int width = 0, height = 0;
    double phi0 = 0.0;
    double phiStep = 0.0;
};

/// Projects `rgb` (row-major, width·height entries, layout above) onto bands 0..L, each pixel a
/// constant over its patch: exact in φ, Gauss–Legendre in θ with nodes enough for band L, so
/// that a map of a few pixels projects as exactly as a large one.
std::vector<glm::vec3> projectEquirect(int maxBand, const EquirectLayout& layout,
                                       std::span<const glm::vec3> rgb);

/// Convenience: coefficient vectors of one channel of an RGB vector.
std::vector<float> channel(std::span<const glm::vec3> rgb, int c);

}  // namespace voxlight::sh
