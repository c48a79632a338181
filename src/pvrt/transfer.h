// SPDX-License-Identifier: MIT
#pragma once
// Where PVRT keeps its transfer (Zhang, Dong & Ma 2013 §4, §6): a regular grid of points over the
// volume, and for each point that can be seen a transfer matrix — m basis lights (basis.h) × RGB
// in-scattered radiance.
//
// Grid: res_a = min(resolution, dims_a) points per axis, point g at voxel coordinate
// (g + ½)·dims_a/res_a − ½ (cell centred, as visibility/global_visibility.h), trilinear between
// points (clamped at the ends). A point is *stored* when a non-empty skip cell (the TF's σt > 0)
// overlaps the box of its trilinear support (its neighbours' positions, widened by one voxel):
// points no rendered sample interpolates from are "empty voxels excluded" (Zhang §6) and cost
// neither precompute nor memory. Stored points are numbered 0…points−1 in grid order (x fastest),
// so every loop over them is deterministic.
//
// The transfer of basis light k at a stored point x, t_k(x) (RGB), is the in-scattered radiance
//   S(x) = ∫ p(ω) L_in(x, ω) dω      (isotropic p = 1/4π)
// that the incident distant radiance B_k alone would produce there, before the albedo of x (the
// ray marcher multiplies by α and the albedo, render/shading.h). Direct part (direct.h): light that
// reaches x unscattered, (1/4π)∫ T∞(x,ω) B_k(ω) dω, the same in R, G and B. Indirect part
// (photons.h): light scattered one or more times on its way to x, coloured by the albedos it met.
// The render combines S(x) = Σ_k c_k ⊙ t_k(x) (radiance.h), or through CPCA (cpca.h).
//
// Exitance coefficients (issue #16; anisotropic scattering): with n = 1 (the default) a transfer
// entry is the isotropic S above. With n = 4, 9 or 16 it is instead the SH projection of the
// incident radiance L_in(x, ω) (ω toward where the light comes from, as basis.h), in the scaled
// real SH Ŷ_j = √(4π)·Y_j of sh/sh_basis.h (so Ŷ_0 = 1):
//   t_{k,j}(x) = (1/4π) ∫ L_in,k(x, ω) Ŷ_j(ω) dω,      j = 0 … n−1 (bands 0 … √n − 1),
// and t_{k,0} is exactly the isotropic S of n = 1. The render evaluates the Henyey–Greenstein
// in-scattered radiance toward the eye by Funk–Hecke (HG's zonal coefficients are g^l times the
// isotropic one):
//   L_s(x, ω_e) = ∫ p_HG(−ω·ω_e) L_in(x, ω) dω = Σ_j g^{l(j)} t_j(x) Ŷ_j(−ω_e)
// with ω_e the unit direction from x toward the eye (light arriving from ω propagates along −ω and
// leaves toward the eye along ω_e: cos θ = −ω·ω_e), see exitanceWeights().
//
// Layout of `values`: [point][j][k][channel], i.e. value(p, j, k) = values[((p·n + j)·m + k)·3 +
// c]: the transfer matrix of a point is n·m×3 contiguous floats (the row CPCA clusters); for n = 1
// this is today's [point][k][channel].
#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "core/volume.h"
#include "grid/brick_traversal.h"

namespace voxlight::pvrt {

struct TransferLayout {
    glm::ivec3 res{0};     ///< points per axis
    glm::vec3 scale{1.f};  ///< voxels per grid step along each axis (dims / res)
    /// Per grid point (x fastest): its stored index, or −1 (nothing visible uses it).
    std::vector<std::int32_t> slot;
    std::int32_t points = 0;  ///< stored points

    std::size_t linear(const glm::ivec3& g) const {
        return std::size_t(g.x) +
               std::size_t(res.x) * (std::size_t(g.y) + std::size_t(res.y) * g.z);
    }
    /// Voxel coordinate of grid point g.
    glm::vec3 position(const glm::ivec3& g) const { return (glm::vec3(g) + 0.5f) * scale - 0.5f; }
    /// Continuous grid coordinate of voxel coordinate p (inverse of position()).
    glm::vec3 gridCoordinate(const glm::vec3& p) const { return (p + 0.5f) / scale - 0.5f; }
    /// Grid points of each stored index (points entries), in order.
    std::vector<glm::ivec3> storedPoints() const;
};

/// The layout for `volume` at most `resolution` points per axis (InputError, field
/// "method.params.resolution", when resolution < 1). `cells`: the TF's skip cells
/// (render::buildSkipCells; kSkipCellVoxels³ voxels each).
TransferLayout makeTransferLayout(const core::Volume& volume, const grid::BrickMajorants& cells,
                                  int resolution);

/// Exitance coefficient counts a transfer may have (SH bands 0, 0–1, 0–2, 0–3).
inline constexpr int kMaxExitance = 16;
/// True for n ∈ {1, 4, 9, 16}.
constexpr bool validExitance(int n) { return n == 1 || n == 4 || n == 9 || n == 16; }

/// The weights w_j = g^{l(j)}·Ŷ_j(−toEye) (j < n) that turn exitance coefficients into the HG
/// in-scattered radiance toward the eye: L_s = Σ_j w_j t_j (header comment). toEye unit; |g| ≤ 1 (g = 1 gives Ŷ_j(−toEye) alone, for a per-sample g).
void exitanceWeights(int n, float g, const glm::vec3& toEye, float* w);
/// Ŷ_j(ω) = √(4π)·Y_j(ω) for j < n at a unit direction ω (double; the photons' and the direct
/// part's projection weights).
void scaledSh(int n, const glm::dvec3& unitDir, double* out);

struct Transfer {
    TransferLayout layout;
    int basis = 0;     ///< m
    int exitance = 1;  ///< n: SH coefficients of L_in per basis light (1 = isotropic S)
    /// [point][j][k][rgb] (see the header comment); points·n·m·3 floats.
    std::vector<float> values;

    Transfer() = default;
    Transfer(TransferLayout l, int m, int n = 1)
        : layout(std::move(l)),
          basis(m),
          exitance(n),
          values(std::size_t(layout.points) * std::size_t(n) * m * 3, 0.f) {}
    float* row(std::int32_t point) { return values.data() + std::size_t(point) * rowSize(); }
    const float* row(std::int32_t point) const {
        return values.data() + std::size_t(point) * rowSize();
    }
    std::size_t rowSize() const { return std::size_t(exitance) * std::size_t(basis) * 3; }
    std::size_t bytes() const {
        return values.size() * sizeof(float) + layout.slot.size() * sizeof(std::int32_t);
    }
};

}  // namespace voxlight::pvrt
