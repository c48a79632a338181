// SPDX-License-Identifier: MIT
#pragma once
// Global visibility V^G (Kronander et al. 2012 §4.3, eq. 11) on a regular grid: for each grid
// point x and each of the local visibility's N directions ω_k, march from x in steps of r_s
// (the local radius), and at each step point x_j = x + j·r_s·ω_k evaluate the stored local
// visibility in that direction,
//   T_j = clamp(Σ_i V^L_i(x_j) Y_i(ω_k), 0, 1)   (eq. 11: the transmittance of [x_j, x_j+1]),
// compose front to back T = Π_j T_j until the ray leaves the volume's box or T < kGlobalStopT
// (early termination), and project: V^G_i(x) = Σ_k w_k T(ω_k) Y_i(ω_k) with the local
// visibility's directions and corrected weights (local_visibility.h). Outside the stored blocks
// the local field is empty space's value, whose reconstruction is exactly 1 in every direction.
// The clamp is needed because a truncated SH expansion can ring outside [0, 1].
//
// Grid: res_a = min(resolution, dims_a) points per axis, point g at voxel coordinate
// (g + ½)·dims_a/res_a − ½ (cell centred, like the block levels), trilinear between points
// (clamped at the ends). Points with nothing visible within 2·spacing + 1 voxels are set to empty
// space's value without rays (as in local_visibility.h: never read by a shaded sample).
// Parallel over z-slices with oneTBB; identical results for any thread count.
#include <algorithm>
#include <memory>
#include <vector>

#include "visibility/local_visibility.h"

namespace voxlight::visibility {

/// Transmittance below which a global visibility ray stops (what lies beyond changes V by less).
inline constexpr double kGlobalStopT = 1e-4;

struct GlobalVisibilityOptions {
    int resolution = 64;  ///< points along each axis at most (capped at the volume's dims)
    int threads = 0;      ///< 0 = all hardware threads
};

class GlobalVisibility {
  public:
    int coefficients() const { return coefficients_; }
    const glm::ivec3& resolution() const { return res_; }
    std::size_t bytes() const { return data_.size() * sizeof(float); }
    std::uint64_t raysTraced() const { return rays_; }
    std::uint64_t pointsSkipped() const { return skipped_; }
    /// Coefficients of grid point g.
    const float* at(const glm::ivec3& g) const {
        return data_.data() +
               (std::size_t(g.x) + std::size_t(res_.x) * (g.y + std::size_t(res_.y) * g.z)) *
                   std::size_t(coefficients_);
    }
    /// Voxels between neighbouring grid points (the largest over the axes).
    float spacingVoxels() const { return std::max({scale_.x, scale_.y, scale_.z}); }
    /// Voxel coordinate of grid point g.
    glm::vec3 position(const glm::ivec3& g) const { return (glm::vec3(g) + 0.5f) * scale_ - 0.5f; }
    /// V^G at continuous voxel index p (trilinear between grid points), into out[0..C).
    void sample(const glm::vec3& p, float* out) const;

  private:
    friend GlobalVisibility computeGlobalVisibility(std::shared_ptr<const LocalVisibility>,
                                                    const GlobalVisibilityOptions&,
                                                    const core::Progress&);
    int coefficients_ = 0;
    glm::ivec3 res_{0};
    glm::vec3 scale_{1.f};  ///< voxels per grid step
    std::vector<float> data_;
    std::uint64_t rays_ = 0, skipped_ = 0;
};

/// V^G from a local visibility field (InputError when resolution < 1).
GlobalVisibility computeGlobalVisibility(std::shared_ptr<const LocalVisibility> local,
                                         const GlobalVisibilityOptions& options,
                                         const core::Progress& progress = core::Progress::none());

}  // namespace voxlight::visibility
