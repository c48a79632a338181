// SPDX-License-Identifier: MIT
#pragma once
// Global visibility V^G (Kronander et al. 2012 §4.3, eq. 11), split into near and far.
//
// Far part, on a regular grid: for each grid point x and each of the local visibility's N
// directions ω_k, march from x in steps of r_s (the local radius), and at each step point
// x_j = x + j·r_s·ω_k, j ≥ 1, evaluate the stored local visibility in that direction,
//   T_j = clamp(Σ_i V^L_i(x_j) Y_i(ω_k), 0, 1)   (eq. 11: the transmittance of [x_j, x_j+1]),
// compose front to back T = Π_j T_j until the ray leaves the volume's box or T < kGlobalStopT
// (early termination), and project: V^F_i(x) = Σ_k w_k T(ω_k) Y_i(ω_k) with the local
// visibility's directions and corrected weights (local_visibility.h). Outside the stored blocks
// the local field is empty space's value, whose reconstruction is exactly 1 in every direction.
// The clamp is needed because a truncated SH expansion can ring outside [0, 1].
//
// Near part, where the render reads it (sample): Kronander's eq. 11 also takes the first piece,
// j = 0, from the grid point, and shades from V^G = Π_{j≥0} on the regular grid alone. At a dense
// surface that grid (64³: 2–4 voxels apart) interpolates between points inside bone and points in
// the air, and a sample on the surface gets their blend: on the 128³ torso under ct-bone the
// light-ward visibility at surface voxels averaged 0.207 against 0.127 for exact hard shadows and
// 0.135 for the exact field projected to 4 coefficients at the voxel — the 36–39 % too-bright
// sh-global images. So the first piece comes from the local field itself, at the sample, on its
// fine TF-adaptive grid, and the two are multiplied as SH functions (sh/sh_product.h):
//   V^G(p) = V^L(p) ⊗ V^F(p)
// (0.154 on the same voxels; the far part, made only of matter ≥ r_s away, varies smoothly in
// space, so its coarse grid is enough). The r_s boundary between the two parts is exact at grid
// points and off by at most the grid spacing between them.
// The product is baked: computed once at every stored point of the local field (block samples and
// boundary layers, with V^F read there) and interpolated by the local field's own interpolation,
// so a shaded sample reads one field, as sh-local does, instead of two and a product. Against
// the product of the two interpolations (until 5 December): the abdominal CT's 512² image at
// 64 dB PSNR, the same NRMSE against the path tracer to ±0.004 in the accuracy study's
// sh-global rows (three coarse corner-case rows 0.005–0.013 better); BM_ShFrame512 (2 threads)
// ×2.10–2.19 the gradient frame → ×1.84–1.96. The price: a second field of the local field's size
// (bytes()) and the bake in the global stage.
//
// GlobalVisibilityOptions::nearFromLocal = false keeps the paper's grid-only field (the chain from
// j = 0, plain trilinear).
//
// Recursive integration (GlobalIntegration::Recursive, the default): eq. 11's product obeys
//   F_k(x) = T_0(x, ω_k) · F_k(x + r_s·ω_k)
// (F_k: the transmittance from x to the box along ω_k, T_0 the first piece), so per direction the
// grid points are visited plane by plane, farthest first along the direction's dominant axis, and
// each takes its first piece from the local field sampled once at the point (one SH dot per
// direction) and the rest by trilinear interpolation of F_k at x + r_s·ω_k, in planes already
// done (r_s·|ω_a| ≥ 1 grid step along the dominant axis a; otherwise the piecewise integration
// runs). Where x + r_s·ω_k is inside the box but beyond the outermost grid points on some axis
// (within half a grid step of a face; past the last plane along a, one piece before the box) the
// rest of that ray is integrated piece by piece from the local field as eq. 11 does — a read
// clamped onto the outermost points would take F from up to a step farther from the face (0.16
// off per coefficient at a homogeneous cube's edges, tested). The far part is F_k(x + r_s·ω_k).
// Cost: one local-field sample per grid point and one 1-float trilinear read per point and direction,
// against up to (box length / r_s) samples per ray; the price is that the far field is read
// through the grid's interpolation at every hop, which spreads a shadow's edge by up to a grid
// step per hop (measured against the piecewise field and the path tracer in the README).
// Memory: besides the field, the recursive integration holds the local field once per grid point
// (C floats), a byte per point, and per direction of a group of kRecursiveDirectionGroup processed
// at once its F_k and far-part grids (one float per point each; F_k alone without the near/far
// split); each group is added into the field (in double from the field's float, in k order)
// before the next starts (recursiveTransientBytes). When that exceeds
// GlobalVisibilityOptions::maxRecursiveBytes the piecewise integration runs instead, which holds
// nothing besides the field (integration() and integrationNote() say so).
//
// Grid: res_a = min(resolution, dims_a) points per axis, point g at voxel coordinate
// (g + ½)·dims_a/res_a − ½ (cell centred, like the block levels), trilinear between points
// (clamped at the ends). Points with nothing visible within 2·spacing + 1 voxels are set to empty
// space's value without rays (as in local_visibility.h: never read by a shaded sample).
// Parallel over z-slices with oneTBB; identical results for any thread count.
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "sh/sh_product.h"
#include "visibility/local_visibility.h"

namespace voxlight::visibility {

/// Transmittance below which a global visibility ray stops (what lies beyond changes V by less).
inline constexpr double kGlobalStopT = 1e-4;
/// Interpolation weight of a fully buried grid point relative to an open one (sampleFar): small,
/// so points inside dense matter barely pull a surface sample's far visibility toward theirs, but
/// non-zero, so a sample with only buried neighbours still gets their plain trilinear blend.
inline constexpr float kBuriedWeight = 1e-3f;

/// Directions the recursive integration processes at once, each with its own scalar grids; fixed
/// (not the thread count), so the field is the same for any thread count.
inline constexpr int kRecursiveDirectionGroup = 8;
/// Default bound on the recursive integration's transient memory (recursiveTransientBytes): a
/// sixth of the 24 GB machines voxlight is sized for, so that with the field and the local field
/// it reads the stage stays well under half of one (256³ points at 16 coefficients need 2.2 GB;
/// the largest resolution, 1024³, would need 138 GB). Above it the piecewise integration runs.
inline constexpr std::size_t kMaxRecursiveTransientBytes = std::size_t(4) << 30;

/// How the far part's rays are integrated (header comment).
enum class GlobalIntegration {
    Piecewise,  ///< eq. 11 along every ray: the local field read at each x + j·r_s·ω_k
    Recursive,  ///< one piece per grid point and direction, the rest read back from the grid
};

struct GlobalVisibilityOptions {
    int resolution = 64;  ///< points along each axis at most (capped at the volume's dims)
    /// Recursive by default: the same error against the path tracer as Piecewise on the torso
    /// and the abdominal CT (README), at a fraction of the cost.
    GlobalIntegration integration = GlobalIntegration::Recursive;
    /// true: the first piece from the local field at the sample (V^L ⊗ V^F, openness-weighted far
    /// grid); false: Kronander's grid-only V^G (chain from the grid point, plain trilinear).
    bool nearFromLocal = true;
    /// Recursive integration only while recursiveTransientBytes stays within this; else piecewise.
    std::size_t maxRecursiveBytes = kMaxRecursiveTransientBytes;
    int threads = 0;  ///< 0 = all hardware threads
};

class GlobalVisibility {
  public:
    int coefficients() const { return coefficients_; }
    bool nearFromLocal() const { return product_ != nullptr; }
    const glm::ivec3& resolution() const { return res_; }
    /// The far grid's storage and the baked V^L ⊗ V^F (the size of the local field).
    std::size_t bytes() const {
        return packed_.size() * sizeof(float) + (baked_ ? baked_->bytes() : 0);
    }
    /// The far grid alone.
    std::size_t farBytes() const { return packed_.size() * sizeof(float); }
    std::uint64_t raysTraced() const { return rays_; }
    /// The integration used (Recursive falls back to Piecewise when r_s is under ~1 grid step,
    /// or when its transient memory would exceed GlobalVisibilityOptions::maxRecursiveBytes).
    GlobalIntegration integration() const { return integration_; }
    /// Why integration() is not the one asked for, in words; empty when it is.
    const std::string& integrationNote() const { return integrationNote_; }
    std::uint64_t pointsSkipped() const { return skipped_; }
    /// Far coefficient V^F_i of grid point g (from the packed form: rounding of one float
    /// multiplication and division).
    float at(const glm::ivec3& g, int i) const {
        const float* d = packed_.data() + index(g) * std::size_t(coefficients_ + 1);
        return d[1 + i] / d[0];
    }
    /// Grid point g as stored: C + 1 floats, the weight q and q·V^F_i (packed_ below).
    const float* packedAt(const glm::ivec3& g) const {
        return packed_.data() + index(g) * std::size_t(coefficients_ + 1);
    }
    /// Openness of grid point g: its local V_0/√(4π) in [0, 1] (1 where skipped as empty, and
    /// everywhere without the near/far split).
    float openness(const glm::ivec3& g) const {
        return product_ ? packed_[index(g) * std::size_t(coefficients_ + 1)] - kBuriedWeight : 1.f;
    }
    /// Voxels between neighbouring grid points (the largest over the axes).
    float spacingVoxels() const { return std::max({scale_.x, scale_.y, scale_.z}); }
    /// Voxel coordinate of grid point g.
    glm::vec3 position(const glm::ivec3& g) const { return (glm::vec3(g) + 0.5f) * scale_ - 0.5f; }
    /// V^G at continuous voxel index p, into out[0..C): the baked V^L ⊗ V^F through the local
    /// field's interpolation, or the grid's own trilinear value when !nearFromLocal().
    void sample(const glm::vec3& p, float* out) const;
    /// The grid alone at p (trilinear between grid points, weighted by their openness when
    /// nearFromLocal()), into out[0..C).
    void sampleFar(const glm::vec3& p, float* out) const;
    /// sample(p, out), and the local field's blended sample spacing at p into *spacing
    /// (LocalVisibility::sample; nearFromLocal() only).
    void sample(const glm::vec3& p, float* out, float* spacing) const;
    /// sample(p, out) where local().locate(p, at) was done (nearFromLocal() only).
    void sample(const FieldLookup& at, const glm::vec3& p, float* out) const;
    const LocalVisibility& local() const { return *local_; }

  private:
    friend GlobalVisibility computeGlobalVisibility(std::shared_ptr<const LocalVisibility>,
                                                    const GlobalVisibilityOptions&,
                                                    const core::Progress&);
    std::size_t index(const glm::ivec3& g) const {
        return std::size_t(g.x) + std::size_t(res_.x) * (g.y + std::size_t(res_.y) * g.z);
    }
    std::shared_ptr<const LocalVisibility> local_;
    std::shared_ptr<const sh::ShProduct> product_;
    std::shared_ptr<const LocalVisibility> baked_;  ///< V^L ⊗ V^F at the local field's points
    int coefficients_ = 0;
    glm::ivec3 res_{0};
    glm::vec3 scale_{1.f};  ///< voxels per grid step
    /// The field as sampleFar interpolates it, C + 1 floats per grid point: the weight q
    /// (openness + kBuriedWeight with the near/far split, else 1) and q·V^F_i, so the
    /// openness-weighted mean is one plain trilinear interpolation and a division. While
    /// computed it holds [openness, V^F_i]; pack() weights it in place at the end.
    std::vector<float> packed_;
    void pack();
    /// baked_ from the local field and the packed far grid (after pack()).
    void bake();
    std::uint64_t rays_ = 0, skipped_ = 0;
    GlobalIntegration integration_ = GlobalIntegration::Piecewise;
    std::string integrationNote_;
};

/// Bytes the recursive integration holds while it runs, besides the field it returns, for a grid
/// of `resolution` points and `coefficients` SH coefficients (header comment).
std::size_t recursiveTransientBytes(const glm::ivec3& resolution, int coefficients,
                                    bool nearFromLocal);

/// V^G from a local visibility field (InputError when resolution < 1).
GlobalVisibility computeGlobalVisibility(std::shared_ptr<const LocalVisibility> local,
                                         const GlobalVisibilityOptions& options,
                                         const core::Progress& progress = core::Progress::none());

}  // namespace voxlight::visibility
