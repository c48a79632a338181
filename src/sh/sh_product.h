// SPDX-License-Identifier: MIT
#pragma once
// Product of two real SH expansions, truncated to their own band (the "triple product"):
//   (f ⊗ g)_k = Σ_ij Γ_ijk f_i g_j,   Γ_ijk = ∫_S² Y_i Y_j Y_k dω,   i, j, k < coefficients.
// Γ is computed once per coefficient count by a Gauss–Legendre product rule that is exact for
// the integrand (three functions of band ≤ L: degree 3L; the rule's n = ⌈(3L + 1)/2⌉ + 1 nodes
// integrate up to degree 2n − 1), and stored as its non-zero entries (|Γ| > kTripleZero): 10
// for 4 coefficients, 83 for 9, 353 for 16 — the real Gaunt coefficients, zero unless the three bands
// satisfy the triangle inequality with an even sum.
//
// Used by sh-global (visibility/global_visibility.h): the fine local visibility near a sample
// times the coarse far visibility beyond r_s. The truncation is the projection of the product
// onto the first `coefficients` functions: exact for the product's low bands, so the mean
// (band 0) is exact: (f ⊗ g)_0 = ∫ f g / √(4π).
#include <cstdint>
#include <vector>

namespace voxlight::sh {

/// Entries of Γ below this magnitude are zero (quadrature rounding of exact zeros is ~1e-16).
inline constexpr double kTripleZero = 1e-10;

class ShProduct {
  public:
    /// coefficients ∈ {1, 4, 9, 16, …, kMaxCoeffs} (InternalError otherwise).
    explicit ShProduct(int coefficients);
    int coefficients() const { return coefficients_; }
    /// Non-zero entries of Γ.
    std::size_t entries() const { return terms_.size(); }
    /// out[k] = Σ Γ_ijk a_i b_j for k < coefficients; out may not alias a or b.
    void apply(const float* a, const float* b, float* out) const;

  private:
    struct Term {
        std::uint8_t i, j, k;
        float gamma;
    };
    int coefficients_ = 0;
    std::vector<Term> terms_;
};

}  // namespace voxlight::sh
