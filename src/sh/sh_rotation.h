// SPDX-License-Identifier: MIT
#pragma once
// Rotation of SH coefficient vectors (conventions: sh_basis.h).
//
// Meaning: for a 3×3 rotation R acting on directions (ω' = R ω, glm column-vector convention),
// ShRotation(R) maps the coefficients of f to those of the rotated function g(ω) = f(R⁻¹ ω) — the
// content of f carried along by R (rotate an environment map by R ⇒ rotate its coefficients with
// ShRotation(R)).
//
// Method: Ivanic & Ruedenberg, J. Phys. Chem. 100 (1996) 6342, with the errata of J. Phys. Chem. A
// 102 (1998) 9099; restated in Wyman et al. 2006 Appendix (Table 3: u, v, w, U, V, W, P). The
// band-1 block is R itself with rows and columns permuted to (y, z, x) — exact because voxlight's
// basis has no Condon–Shortley phase — and band l is built from band l−1 and band 1. The matrix is
// block-diagonal (bands do not mix); each block is orthogonal.
//
// Cost: building is O(L⁴)-ish but tiny (≈ 1k entries at L = 8); build once per rotation (ShRotation
// *is* that cache, CachedShRotation rebuilds only when the rotation changes) and apply per vector
// (O(Σ(2l+1)²)). rotateZ() is the fast path for rotations about +z (O(L²), no matrix).
#include <glm/glm.hpp>
#include <span>
#include <vector>

namespace voxlight::sh {

/// InputError unless `r` is a proper rotation (RᵀR = I within 1e-4, det = +1) — e.g. a scene's
/// light rotation. The tolerance admits matrices typed with a few digits or composed in float; such
/// a near-rotation must not be used as is (its transpose is not its inverse): store
/// orthonormalizeRotation(r).
void checkRotation(const glm::dmat3& r, const char* source = "sh", const char* field = "rotation");

/// The rotation nearest to `r` in the Frobenius norm (the orthogonal factor of the polar
/// decomposition r = Q·S), by the Newton iteration Q ← (Q + Q⁻ᵀ)/2 (Higham 1986), which converges
/// quadratically from a matrix accepted by checkRotation: |QᵀQ − I| ~ 1e-16 after ≤ 4 steps. A
/// matrix already orthonormal to kRotationRoundingTol is returned unchanged (bit for bit).
/// Precondition: r passes checkRotation (VL_CHECK on det > 0).
glm::dmat3 orthonormalizeRotation(const glm::dmat3& r);
/// max |RᵀR − I| up to which orthonormalizeRotation keeps a matrix as given: a few ulps of the sums
/// of three products (rotations built from cos/sin in double reach ~1e-15).
inline constexpr double kRotationRoundingTol = 1e-14;

class ShRotation {
  public:
    /// Builds blocks for bands 0..maxBand (≤ kMaxBand). InputError if `r` is not a rotation; a
    /// near-rotation accepted by checkRotation is orthonormalised first (orthonormalizeRotation).
    ShRotation(const glm::dmat3& r, int maxBand);

    int maxBand() const { return band_; }
    /// The (orthonormalised) rotation the blocks were built from.
    const glm::dmat3& matrix() const { return r_; }

    /// out = R · in for the first in.size() coefficients (any (L'+1)² with L' ≤ maxBand); in and
    /// out may alias.
    void apply(std::span<const float> in, std::span<float> out) const;
    void apply(std::span<const double> in, std::span<double> out) const;
    void applyRgb(std::span<const glm::vec3> in, std::span<glm::vec3> out) const;

    /// Entry (m, n), m, n ∈ [−l, l], of band l's (2l+1)×(2l+1) block.
    double element(int l, int m, int n) const {
        return blocks_[offset(l) + (m + l) * (2 * l + 1) + (n + l)];
    }

  private:
    static int offset(int l) { return l * (4 * l * l - 1) / 3; }  // Σ_{k<l} (2k+1)²
    double& at(int l, int m, int n) { return blocks_[offset(l) + (m + l) * (2 * l + 1) + (n + l)]; }
    template <class T>
    void applyImpl(std::span<const T> in, std::span<T> out) const;

    int band_;
    glm::dmat3 r_;
    std::vector<double> blocks_;
};

/// Keeps the ShRotation of the last rotation asked for; rebuilds only when the matrix or the band
/// changes. Keyed on the matrix as given (ShRotation::matrix() is its orthonormalised form).
class CachedShRotation {
  public:
    const ShRotation& get(const glm::dmat3& r, int maxBand);
    /// How many ShRotations get() has built (cache misses): for tests and profiling.
    std::size_t builds() const { return builds_; }

  private:
    std::vector<ShRotation> cached_;  // zero or one element
    std::size_t builds_ = 0;
    glm::dmat3 key_{1.0};  // the matrix cached_ was built from
};

/// Rotation by `angle` radians about +z (counter-clockwise seen from +z): out_lm for
/// g(ω) = f(Rz(angle)⁻¹ ω). in and out may alias.
void rotateZ(double angle, std::span<const float> in, std::span<float> out);

}  // namespace voxlight::sh
