// SPDX-License-Identifier: MIT
#pragma once
// Discrete spherical function (DSF), Zhang, Dong & Ma 2013, §5 (eq. 7–8) and §8 (prefiltering).
//
// n directions ω_k from a subdivided icosahedron (42, 162, 642, 2562 = 10 f² + 2 for
// f = 2, 4, 8, 16; see sphere_samples.h). A spherical function is represented by its values s_k
// ("coefficients") and reconstructed as
//     S(ω) = Σ_k w̄_k(ω) s_k,   w̄_k(ω) = W_h(ω, ω_k) / Σ_j W_h(ω, ω_j),
//     W_h = (h² − θ²)³ for θ < h, else 0,
// θ = angle between the directions [rad], h = the minimum angle between two directions of the set.
// Properties: interpolating (S(ω_k) = s_k), local support (only directions closer than h
// contribute: ≤ ~7), rotation by re-sampling. Every direction on the sphere has at least one ω_k
// within h (checked at construction).
//
// Units and meaning of the coefficients: s_k is a *radiance* [same unit as the light's radiance] in
// direction ω_k. Basis solid angle A_k = ∫ w̄_k dω (Σ A_k = 4π) turns them into power:
// ∫ S dω = Σ_k A_k s_k (integrate()).
// * Environment light: s_k = Gaussian-prefiltered radiance at ω_k (Zhang §8: Gaussian of
//   "bandwidth h"). σ defaults to h/3: in the Fig. 7 experiment (tests/sh/test_dsf.cpp) the L2
//   error is flat for σ ∈ [h/4, h/3] and grows ~4 % (relative) at h/2 and for point sampling.
// * Directional light of irradiance E from ω_d (Zhang §5.2): barycentric blend over the 3 vertices
//   of the icosahedral triangle containing ω_d, s_k += E b_k / A_k — so Σ_k A_k s_k = E exactly.
//
// Evaluation cost: one cube-map cell lookup plus ~6–12 candidate dot products (precomputed
// candidate lists).
#include <glm/glm.hpp>
#include <span>
#include <vector>

#include "sh/sh_projection.h"
#include "sh/sphere_samples.h"

namespace voxlight::sh {

class Dsf {
  public:
    /// Largest number of directions that can lie within h of any point (bounded by the packing; 16
    /// is ample).
    static constexpr int kMaxSupport = 16;

    /// directionCount ∈ {12, 42, 162, 642, 2562, 10242}; InputError otherwise.
    explicit Dsf(int directionCount);

    int size() const { return int(dirs_.size()); }
    const std::vector<glm::dvec3>& directions() const { return dirs_; }
    const std::vector<glm::ivec3>& triangles() const { return tris_; }
    /// Kernel radius h [rad] = minimum angle between two directions.
    double kernelRadius() const { return h_; }
    /// A_k = ∫ w̄_k dω [sr]; Σ = 4π.
    const std::vector<double>& basisSolidAngles() const { return area_; }

    /// Normalised weights w̄_k(ω) at a unit direction: writes up to kMaxSupport (index, weight)
    /// pairs, returns count.
    int weights(const glm::dvec3& unitDir, int* index, double* weight) const;
    /// S(ω) for scalar or RGB coefficients (size() entries).
    float evaluate(std::span<const float> s, const glm::dvec3& unitDir) const;
    glm::vec3 evaluateRgb(std::span<const glm::vec3> s, const glm::dvec3& unitDir) const;

    /// The icosahedral triangle containing the unit direction and its barycentric weights (≥ 0, sum
    /// 1).
    void barycentric(const glm::dvec3& unitDir, int index[3], double b[3]) const;
    /// Adds a directional light (irradiance E [radiance·sr] arriving from unit direction
    /// `towardLight`).
    void addDirectional(std::span<glm::vec3> s, const glm::dvec3& towardLight,
                        const glm::vec3& irradiance) const;

    /// Point samples s_k = f(ω_k) of a callable f(const glm::dvec3&) → glm::vec3 (no prefilter).
    template <class F>
    std::vector<glm::vec3> sampleFunction(F&& f) const {
        std::vector<glm::vec3> s(dirs_.size());
        for (std::size_t k = 0; k < dirs_.size(); ++k) s[k] = glm::vec3(f(dirs_[k]));
        return s;
    }
    /// s_k = Gaussian-weighted mean of an equirect grid (sh_projection.h layout) around ω_k,
    /// weights exp(−θ²/2σ²)·pixel solid angle, truncated at 3σ. σ ≤ 0 means h/3.
    /// `mapFromWorld` rotates the DSF directions into the grid's frame first (an environment map
    /// rotated by R is sampled with mapFromWorld = Rᵀ): the DSF way to rotate lighting (Zhang
    /// §5.1).
    std::vector<glm::vec3> sampleEquirect(const EquirectLayout& layout,
                                          std::span<const glm::vec3> rgb, double sigma = 0.0,
                                          const glm::dmat3& mapFromWorld = glm::dmat3(1.0)) const;

    /// Energy-conserving alternative to sampleEquirect: s_k = (1/A_k) Σ_p L_p Ω_p w̄_k(ω_p) — each
    /// pixel is split among the basis functions covering it, so Σ_k A_k s_k = Σ_p L_p Ω_p exactly
    /// (a small sun between directions keeps its power, and rotating it does not make the total
    /// flicker). Pixels coarse against h are split into sub-cells (kProjectionCellsPerKernel), so a
    /// constant map gives constant coefficients to ~1e-3 at any grid resolution. `mapFromWorld` as
    /// above.
    std::vector<glm::vec3> projectEquirect(const EquirectLayout& layout,
                                           std::span<const glm::vec3> rgb,
                                           const glm::dmat3& mapFromWorld = glm::dmat3(1.0)) const;

    /// projectEquirect splits pixels so that the kernel radius h spans at least this many cells
    /// (at most kMaxProjectionSubdivision² cells per pixel): pixel quadrature of A_k to ~1e-3.
    static constexpr int kProjectionCellsPerKernel = 16;
    static constexpr int kMaxProjectionSubdivision = 16;

    /// ∫ S dω = Σ A_k s_k.
    glm::dvec3 integrate(std::span<const glm::vec3> s) const;

  private:
    int cellOf(const glm::dvec3& d) const;
    template <class T>
    T evaluateImpl(std::span<const T> s, const glm::dvec3& d) const;

    std::vector<glm::dvec3> dirs_;
    std::vector<glm::ivec3> tris_;
    double h_ = 0, cosH_ = 1;
    std::vector<double> area_;
    int gridN_ = 1;  // cube-map cells per face edge
    std::vector<int> dirStart_, dirList_, triStart_, triList_;
};

}  // namespace voxlight::sh

namespace voxlight::sh {

/// One row of the DSF-vs-SH lighting reconstruction experiment (Zhang 2013 Fig. 7): relative L2
/// error √(∫|f − f̂|²dω / ∫|f|²dω) over the grid's pixels (solid-angle weighted, summed over RGB).
struct DsfShComparisonRow {
    int dsfCount = 0;
    double dsfError = 0;
    int shBand = 0;  ///< band with (L+1)² closest to dsfCount (ties: more coefficients)
    int shCount = 0;
    double shError = 0;         ///< plain truncation
    double shHanningError = 0;  ///< with the Hanning window
    /// DSF with the energy-conserving projectEquirect instead of sampling.
    double dsfProjectedError = 0;
};

/// Reconstructs an equirect environment with DSF of each count (prefiltered sampling) and with SH
/// of a similar coefficient count (bands ≤ kMaxBand) and measures the errors on the same grid.
std::vector<DsfShComparisonRow> compareDsfWithSh(const EquirectLayout& layout,
                                                 std::span<const glm::vec3> rgb,
                                                 std::span<const int> dsfCounts);

}  // namespace voxlight::sh
