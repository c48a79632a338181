// SPDX-License-Identifier: MIT
#pragma once
// Hierarchical visibility (Ritschel 2007 §3.1, "Hierarchical Visibility"; voxlight's `ritschel`
// method): one SH visibility field V̄(x) for the whole volume, computed by rays that read a
// product-minified extinction pyramid with growing steps, so a ray to the volume's far side costs
// a few samples per doubling of its length instead of one per voxel.
//
// Opacity pyramid (OpacityPyramid::build): level 0 holds σt of every voxel under the TF
// (pre-classified, [1/mm]; non-finite voxels enter as the volume's lowest finite value, as in
// BlockPyramid). Level k has ⌈dims/2^k⌉ cells per axis, cell c covering voxels [2^k·c, 2^k·c +
// 2^k − 1], centred at voxel coordinate (c + ½)·2^k − ½, and stores an *effective extinction*
// σ_k such that T_k = exp(−σ_k·L_k), L_k = 2^k·h (h = smallest spacing, mm), is the expected
// transmittance across the cell. Minification (Ritschel's 64-term formula: the mean, over all
// ordered pairs of the 8 children, of the product of the pair's transmittances — "a ray crosses
// two successive children"):
//   T_{k+1} = (1/64) Σ_a Σ_b T_k(a)·T_k(b) = (mean_8 T_k)²,  i.e.  σ_{k+1} = −ln(mean_8 T_k) / L_k,
// over the children inside the volume (a cell at an odd edge has fewer). Unlike a box filter of
// opacity, a product never makes a ray less blocked by meeting a second occluder; unlike a box
// filter of σt (geometric mean of T), a gap beside an opaque child lets light through. A
// homogeneous region keeps its σt exactly at every level. σ is capped at kMaxCellDepth / L_k (an
// opaque child: T = 0 would give ∞).
//
// Rays (computeHierarchicalVisibility): from every grid point x (see sub-sampling) in N
// directions, a march in index space (spacing and orientation as local_visibility.h) whose step
// on level k is L_k mm, kStepsPerLevel steps per level, then one level coarser (at the coarsest
// level the step stays): segment j covers [t_j, t_j + Δ_j] and adds σ_k(midpoint)·Δ_j to the
// optical depth, σ_k read trilinearly between level-k cell centres (clamped to the level's
// lattice). Steps on level 0 are instead pre-integrated between the voxel values at their ends
// (trilinear, TfTable::meanExtinction, split where deeper than kRefineDepth — the continuous model,
// as local_visibility.h): a midpoint read of pre-classified σt puts a partial-volume surface up to
// half a voxel off (on the anti-aliased slab phantom T from the last dense voxel e^−1 instead of
// e^−½, and 30–40 % darker images than the path tracer); a step that reads a removed voxel falls
// back to that midpoint read of the clipped pyramid. Ending: at the volume's box (outside is
// empty), at max_distance, or when the optical depth exceeds kOpaqueDepth. With `hierarchical =
// false` every step is one voxel on level 0: the brute-force march the pyramid approximates.
// Memory: the values add one float per voxel beside level 0.
//
// Directions: M patterns (sh::jitteredSamples: N stratified jittered directions each, counter-based
// from (pattern, seed)); grid point g uses pattern hash(g, seed) mod M, so neighbours use different
// directions and the Monte-Carlo banding of one fixed set turns into noise that the trilinear
// reconstruction averages. Each pattern's weights are corrected as in local_visibility.h (minimum
// norm change so the first C basis functions integrate exactly): empty space gives exactly
// (√(4π), 0, …) with every pattern. Projection: V_i(x) = Σ_k w_k V(x, ω_k) Y_i(ω_k), C ∈ {1, 4, 9,
// 16}.
//
// Sub-sampling 1:s (s = 1…8 per axis; Ritschel: 1:1, 1:2, 1:4, 1:8): grid point g lies at voxel
// coordinate min(g·s, dims − 1) per axis (res = ⌈(dims − 1)/s⌉ + 1 points), so 1:1 is the voxels;
// the field is sampled trilinearly between grid points (clamped at the ends; the last cell of an
// axis whose dims − 1 is not a multiple of s is shorter — its points are squeezed onto the last
// voxel, a distortion of under one cell at that face only). Points with no visible 4³ cell
// (LodSelection::cellVisible, from the BlockPyramid's value ranges) within 2·s + 1 voxels get
// empty space's value without rays: they are never read by a shaded sample (local_visibility.h).
//
// 8-bit storage (quantize_8bit): coefficient 0 (≥ 0: positive weights, T ≥ 0) as uint8 over
// [0, max V_0], the others as int8 over [−max|V_i|, max|V_i|], one scale per coefficient:
//   |V_i − V̂_i| ≤ scale_i / 2,  scale_0 = max V_0 / 255,  scale_i = max|V_i| / 127,
// and since |V_i| ≤ Σ_k w_k |Y_i(ω_k)| ≤ √(4π) (Cauchy–Schwarz with Σ w = 4π, Σ w Y_i² = 1 for the
// corrected weights), the error is at most √(4π)/510 ≈ 0.0070 for V_0 and √(4π)/254 ≈ 0.014 for the
// others (V_0 of empty space is √(4π) ≈ 3.54). Memory: C bytes per point instead of 4·C.
//
// Clip-aware field (clipAwareHierarchicalVisibility; io/scene.h `shadows_from_removed: false`):
// the matter outside a kept region (the intersection of half-spaces: the clip planes and crop box
// that remove matter for the light too) is gone for the light. It is removed where Ritschel's
// method sees matter, at the pyramid's base (OpacityPyramid::withRemoved): every voxel's σt times
// the fraction of its box (±½ voxel cut to the volume's box) each half-space keeps (½ + the box
// centre's distance over its width across the plane, clamped: 0 for a voxel wholly outside, σt
// falling continuously as a plane moves through a voxel), and every coarser cell above a changed
// voxel (one with
// σt > 0) minified again — the other cells are copied — so all levels, and every ray that reads
// them, see it gone. A coarse cell that straddles a cut face mixes kept matter with the emptied
// part as it mixes matter with any gap beside it. Unlike sh-local's radius-bounded rays
// (local_visibility.h: only points within r_s of a face change), these rays run to the volume's
// box, so a cut changes V̄ wherever a ray from the kept side reaches the removed side: the field
// is traced again per cut, except the points more than (s + 1)·|spacing| mm outside some face —
// never read by a shaded sample (camera rays only shade the kept region, and a sample reads the
// 8 grid points of its 1:s cell, within s·|spacing| of it) — which get empty space's value
// without rays. A cut that removes only matter the TF shows transparent changes no cell and the
// result equals computeHierarchicalVisibility on the same pyramid but for those cleared points.
// Memory: the clipped pyramid is a copy of the base (as large) while the field is traced.
//
// Parallel over z-slices of grid points with oneTBB; each point is computed alone in a fixed
// order, so the field is identical for any thread count.
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/half_space.h"
#include "core/progress.h"
#include "optics/transfer_function.h"
#include "visibility/multires_grid.h"

namespace voxlight::visibility {

/// Steps per pyramid level before a ray moves one level coarser: 2 keeps the sample spacing at
/// most the level's cell size and every cell read at least half its size away from the previous
/// one; 1 would sample each level once and skip half of what lies beside the ray.
inline constexpr int kStepsPerLevel = 2;
/// Optical depth cap of one pyramid cell (e^−30 ≈ 1e-13: opaque for any ray; avoids ∞).
inline constexpr double kMaxCellDepth = 30.0;
/// Largest sub-sampling factor (Ritschel's 1:8).
inline constexpr int kMaxSubsample = 8;
/// Largest number of direction patterns M (Ritschel used a few; each costs N directions of memory).
inline constexpr int kMaxPatterns = 256;

/// The product-minified extinction pyramid (see the header comment).
class OpacityPyramid {
  public:
    /// σt under `table` at every voxel of `pyramid`'s level 0, then every coarser level (parallel).
    static OpacityPyramid build(const BlockPyramid& pyramid, const optics::TransferFunction& tf,
                                const optics::TfTable& table,
                                const core::Progress& progress = core::Progress::none());
    /// This pyramid with the matter outside `kept` (world half-spaces; their intersection is kept)
    /// removed: σt scaled by the fraction of each voxel the half-spaces keep (0 wholly outside),
    /// and the coarser cells above a voxel that changed (σt > 0 before) minified again, the rest
    /// copied (see the header comment). `voxelsChanged`/`cellsChanged` (optional) count the
    /// zeroed voxels and the re-minified cells of levels ≥ 1. With no half-spaces: a copy.
    OpacityPyramid withRemoved(std::span<const core::HalfSpace> kept,
                               std::uint64_t* voxelsChanged = nullptr,
                               std::uint64_t* cellsChanged = nullptr) const;

    int levels() const { return int(dims_.size()); }
    const glm::ivec3& dims(int level) const { return dims_[std::size_t(level)]; }
    const core::Geometry& geometry() const { return geometry_; }
    /// Effective extinction σ_k of a cell [1/mm].
    float at(int level, const glm::ivec3& c) const {
        const glm::ivec3& d = dims_[std::size_t(level)];
        return data_[std::size_t(level)]
                    [std::size_t(c.x) + std::size_t(d.x) * (c.y + std::size_t(d.y) * c.z)];
    }
    /// σ_k at continuous voxel coordinate p, trilinear between level-k cell centres (clamped).
    float sample(int level, const glm::vec3& p) const;
    /// The voxel value at p, trilinear (clamped); NaN where it reads a removed voxel (withRemoved).
    float value(const glm::vec3& p) const;
    /// The TF the pyramid was built under (the level-0 steps' pre-integrated σt).
    const optics::TfTable& table() const { return *table_; }
    std::size_t bytes() const;
    /// Per BlockPyramid 4³ cell: whether the TF shows anything there (LodSelection::cellVisible).
    const std::vector<std::uint8_t>& cellVisible() const { return cellVisible_; }
    const glm::ivec3& cells() const { return cells_; }
    /// cellVisible's summed-volume table (visibilityNeeded's box queries).
    const VisibleCellCounts& visibleCellCounts() const { return visibleCounts_; }

  private:
    core::Geometry geometry_;
    std::vector<glm::ivec3> dims_;
    std::vector<std::vector<float>> data_;
    std::vector<std::uint8_t> cellVisible_;
    glm::ivec3 cells_{0};
    VisibleCellCounts visibleCounts_;
    std::vector<float> values_;  ///< level-0 voxel values (NaN: removed)
    std::shared_ptr<const optics::TfTable> table_;
};

struct HierarchicalVisibilityOptions {
    int rays = 32;           ///< N per grid point, ≥ kMinRaysPerCoefficient · coefficients
    int coefficients = 4;    ///< 1, 4, 9 or 16
    int patterns = 16;       ///< M jittered direction patterns, 1…kMaxPatterns
    int subsample = 2;       ///< 1:s grid, s ∈ 1…kMaxSubsample
    bool quantize8 = false;  ///< 8-bit coefficients (see the header comment)
    /// Longest ray (units of the smallest spacing); ∞ = to the volume's box. Ritschel's rays run
    /// to the boundary (global shadows), and with growing steps the far half of a ray costs only
    /// kStepsPerLevel samples, so the whole volume is the default.
    double maxDistanceVoxels = INFINITY;
    bool hierarchical = true;  ///< false: 1-voxel steps on level 0 (the brute-force reference)
    std::uint64_t seed = 0;    ///< of the direction patterns and the per-point pattern choice
    int threads = 0;           ///< 0 = all hardware threads
};

/// The SH visibility field V̄ on the 1:s grid (float or 8-bit; see the header comment).
class HierarchicalVisibility {
  public:
    int coefficients() const { return coefficients_; }
    int rays() const { return rays_; }
    int patterns() const { return patterns_; }
    int subsample() const { return subsample_; }
    bool quantized() const { return !q_.empty(); }
    const glm::ivec3& resolution() const { return res_; }
    std::size_t bytes() const {
        return data_.size() * sizeof(float) + q_.size() + scale_.size() * sizeof(float);
    }
    std::uint64_t raysTraced() const { return raysTraced_; }
    std::uint64_t samplesTaken() const { return samplesTaken_; }
    std::uint64_t pointsSkipped() const { return pointsSkipped_; }
    /// Dequantisation step of coefficient i (0 for float storage).
    float scale(int i) const { return scale_.empty() ? 0.f : scale_[std::size_t(i)]; }
    /// Coefficients of grid point g (dequantised), into out[0..C).
    void at(const glm::ivec3& g, float* out) const;
    /// V̄ at continuous voxel index p, trilinear between grid points, into out[0..C).
    void sample(const glm::vec3& p, float* out) const;

  private:
    friend HierarchicalVisibility computeField(const OpacityPyramid&,
                                               const HierarchicalVisibilityOptions&,
                                               std::span<const core::HalfSpace>,
                                               const core::Progress&, std::uint64_t*);
    std::size_t index(const glm::ivec3& g) const {
        return std::size_t(g.x) + std::size_t(res_.x) * (g.y + std::size_t(res_.y) * g.z);
    }
    int coefficients_ = 0, rays_ = 0, patterns_ = 0, subsample_ = 1;
    glm::ivec3 res_{0};
    std::vector<float> data_;      ///< float storage
    std::vector<std::uint8_t> q_;  ///< 8-bit storage (coefficient 0 unsigned, others signed)
    std::vector<float> scale_;     ///< per coefficient, 8-bit storage only
    std::uint64_t raysTraced_ = 0, samplesTaken_ = 0, pointsSkipped_ = 0;
};

/// InputError (source "hierarchical visibility", field = the option's param name) on bad options.
void checkHierarchicalOptions(const HierarchicalVisibilityOptions& options);

/// Computes V̄ from `pyramid` (see the header comment); cancellable through `progress`.
HierarchicalVisibility computeHierarchicalVisibility(
    std::shared_ptr<const OpacityPyramid> pyramid, const HierarchicalVisibilityOptions& options,
    const core::Progress& progress = core::Progress::none());

/// What a clip-aware field cost (the pipeline's stats report it).
struct HierarchicalClipStats {
    std::uint64_t voxelsRemoved = 0;  ///< voxels with σt > 0 outside the kept region (zeroed)
    std::uint64_t cellsChanged = 0;   ///< pyramid cells of levels ≥ 1 minified again
    std::uint64_t points = 0;         ///< grid points of the field
    std::uint64_t pointsTraced = 0;   ///< points whose rays were traced
    std::uint64_t pointsCleared = 0;  ///< > (s + 1)·|spacing| outside a face: empty, no rays
    std::uint64_t pointsSkipped = 0;  ///< no visible cell near (as computeHierarchicalVisibility)
    std::uint64_t raysTraced = 0;
    double pyramidSeconds = 0.0;     ///< OpacityPyramid::withRemoved
    double visibilitySeconds = 0.0;  ///< the rays
};

/// V̄ with the matter outside `kept` (world half-spaces; their intersection is kept) gone for the
/// light: computeHierarchicalVisibility on base.withRemoved(kept), with the points far outside
/// the kept region cleared instead of traced (see the header comment). With no half-spaces it
/// equals computeHierarchicalVisibility(base). Cancellable through `progress`.
HierarchicalVisibility clipAwareHierarchicalVisibility(
    const OpacityPyramid& base, std::span<const core::HalfSpace> kept,
    const HierarchicalVisibilityOptions& options,
    const core::Progress& progress = core::Progress::none(),
    HierarchicalClipStats* stats = nullptr);

/// Transmittance of one ray from voxel index `origin` along the world unit direction `dir`,
/// marched as computeHierarchicalVisibility does (exposed for tests). `samples` counts σ reads.
double hierarchicalTransmittance(const OpacityPyramid& pyramid, const glm::vec3& origin,
                                 const glm::dvec3& dir, double maxDistanceVoxels, bool hierarchical,
                                 std::uint64_t* samples = nullptr);

}  // namespace voxlight::visibility
