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
// Layout of `values`: [point][k][channel], i.e. value(p, k) = values[(p·m + k)·3 + c]: the
// transfer matrix of a point is m×3 contiguous floats (the row CPCA clusters).
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

struct Transfer {
    TransferLayout layout;
    int basis = 0;  ///< m
    /// [point][k][rgb] (see the header comment); points·m·3 floats.
    std::vector<float> values;

    Transfer() = default;
    Transfer(TransferLayout l, int m)
        : layout(std::move(l)), basis(m), values(std::size_t(layout.points) * m * 3, 0.f) {}
    float* row(std::int32_t point) { return values.data() + std::size_t(point) * basis * 3; }
    const float* row(std::int32_t point) const {
        return values.data() + std::size_t(point) * basis * 3;
    }
    std::size_t rowSize() const { return std::size_t(basis) * 3; }
    std::size_t bytes() const {
        return values.size() * sizeof(float) + layout.slot.size() * sizeof(std::int32_t);
    }
};

}  // namespace voxlight::pvrt
