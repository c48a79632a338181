// SPDX-License-Identifier: MIT
#pragma once
// Local visibility V^L (Kronander et al. 2012 §4.2): at every sample point of the multiresolution
// grid (each stored block's n³ samples at its selected level — Kronander computes and stores V^L
// "for each grid point in the multiresolution structure", so the visibility has the grid's
// adaptive resolution), N rays in the directions of a sphere sample set integrate absorption only,
//   V(x, ω_k) = exp(−∫_0^R σt(s(x + t·ω_k)) dt),   R = radius · h   (h = smallest spacing, mm),
// and the transmittances are projected onto real SH (sh/sh_basis.h conventions):
//   V_i(x) = Σ_k w_k V(x, ω_k) Y_i(ω_k),   i < coefficients ∈ {1, 4, 9, 16}.
//
// Directions: the spherical Fibonacci set of N directions (any N, nearly uniform; Kronander's
// subdivided polyhedra exist only for N = 2f²+2, 4f²+2, 10f²+2). Weights: the equal 4π/N changed
// by the least amount (minimum norm) that makes the rule integrate the first `coefficients` basis
// functions exactly (Σ_k w_k Y_i(ω_k) = √(4π) δ_i0). Hence empty space gives exactly
// V = (√(4π), 0, …) and a light sees no spurious directional bias from the quadrature; weights stay
// positive for N ≥ kMinRaysPerCoefficient · coefficients (checked when built).
//
// Ray integration: pre-integrated steps that follow the LOD (Kronander §4.2, "adaptive step size
// according to the LOD selection"): the step inside a block at level l is min(2^l, kMaxStepVoxels)
// voxels (one sample per reduced sample spacing), the last step shortened to end at R (or at the
// volume's box: outside the volume is empty). The value is read at both ends of a step trilinearly
// in the volume's voxels (the BlockPyramid's level 0: the continuous model itself, whatever the
// blocks' levels — the LOD sets where V is stored and how long the steps are) and the step's
// optical depth is Δ · mean σt over the
// values between them, from the TF table's cumulative integral (TfTable::sigmaIntegral; exact for
// a value linear along the step, as in the renderer). A step deeper than kRefineDepth is split
// into sub-steps, each pre-integrated: the value is linear only within a voxel, and a dense surface
// crossed mid-step would otherwise be smeared over the step. (A midpoint rule with the σt of the
// owner block alone took a step across a bone surface at its midpoint's full σt, or dropped the
// half voxel past a block face: V 0.37 instead of e^−1 … 1 instead of e^−1 next to a face.)
// A step with both ends in blocks at kNone integrates nothing (the TF is transparent over every
// value read there), nor does one with both values in a transparent tail of the TF (skipped
// without the table; rayTransmittanceReference is the plain march the tests compare with). A ray
// stops once its optical depth exceeds kOpaqueDepth (transmittance < 1e-4: the rest changes V by
// less than that).
//
// Empty space (exact): the BlockPyramid's 4³ cells whose value range the TF makes transparent
// (LodSelection::cellVisible) hold σt = 0, so rays jump across them, and grid points with no
// visible cell within 2·s + 1 voxels (s = their sample spacing) get empty space's value
// (√(4π), 0, …) without rays: a shaded render sample lies within one render step (≤ 1 voxel; the
// default is ½) of a visible cell, and its interpolation reads grid points within s + s/2 of it,
// so such points are never read where anything is shaded.
//
// Parallel over blocks with oneTBB; every sample point is computed alone with a fixed order of
// operations, so the result is identical for any thread count.
//
// Clip-aware update (clipAwareLocalVisibility): the same field with the matter outside a kept
// region (the intersection of half-spaces: the clip planes and crop box that remove matter for the
// light too, io/scene.h `shadows_from_removed: false`) treated as empty. Only points within
// R = r_s·h of a cut face can change: a point whose distance to every face is ≥ R on the kept side
// sends rays that never leave the kept region (its value is copied from the unclipped field), and a
// point ≥ R outside some face sends rays that never enter it (empty space's value, no rays). The
// rest — the blocks and points within R of a cut face — are computed again, each ray integrated
// only over its part inside the kept region (one interval: the region is convex), in whichever of
// two ways marches less: from scratch (every ray over its kept part: short outside a face), or by
// difference — only the rays a face cuts are marched, each over its whole length in pieces, and
// the point's unclipped value changes by Σ_cut w_k·Y_k·(T_kept − T_whole) (near a face on the kept
// side most rays never reach it: a quarter of the rays on average). The rays no face cuts keep the
// unclipped field's own values, so under the line sweep no march-vs-sweep seam appears at R from a
// face (the sweep's depth of a cut ray still meets the march's T_whole: their difference, tested
// within the cut's bound). Every point holding its own value may take the difference way: the
// sweep's lattice points, its boundary layers' points (marched with the same rays) and a partial
// edge block's points past the volume at level 0 (a copy of the point at their clamped position);
// at coarser levels those hold another point's value and are computed from scratch (the sweep and
// the update tell them apart by the same rule: forEachSamplePoint's `clamped`). So moving a plane
// costs rays in a slab of width 2R around it, a
// quarter of them on the kept side, not the whole field, and the unclipped field stays cached for
// the next move.
//
// Line sweep (algorithm Sweep, method param `algorithm: "sweep"`): the same V^L with the rays
// shared between points. The directions are the primitive integer steps v of the voxel lattice
// with |v_a| ≤ 1 (26 rays) or ≤ 2 (98 rays), ω = D·(v ⊙ spacing)/|v ⊙ spacing| in world space,
// weighted by their Voronoi cells on the sphere (counted on 2¹⁸ Fibonacci points) and then
// corrected as visibilityDirections' weights are. Every lattice point lies on exactly one line
// x₀ + t·v (t integer) of each direction, so per direction one pass along every line accumulates
// the optical depth P(t) from the line's start — pre-integrated between values read
// trilinearly in the voxels at sub-steps of |v|/q ≤ 1 voxel (q = ⌈|v|⌉), each split further where
// deeper than kRefineDepth, as the march's steps are — and a point at t gets
//   τ = P(t + n) − P(t),   n = R / |v ⊙ spacing|   (fractional: P linear within a sub-step),
// i.e. its ray to R, at the cost of O(1) per point and direction instead of R/step samples. So a
// ray's depth lies between its depths to the two sub-step ends around R (its end is blurred by
// less than a sub-step, ≤ 1 voxel, where the march pre-integrates a shortened last step: reading
// that end's value, 26 per point, was a sixth of a TF update's CPU time). Level-0
// samples lie on the integer lattice; every coarser level's samples lie on the lattice shifted by
// (½, ½, ½) (16·b + (j + ½)·s − ½ with s even), which has its own lines. The unit of work is a
// group of G³ blocks (sweepGroupBlocks; 4 unless too few groups for the threads): a line is
// walked once through all of the group's traced points, in runs from R before a run's first point
// to R past its last, a run ending where two consecutive points lie more than 2R apart. P is kept
// in fixed point (each sub-step's depth rounded once to 2⁻³², summed in int64), so a ray's depth
// is an exact difference, the same whichever sub-step its run started from: which points share a
// line (G, the blocks being computed) changes no bit. The steps follow the voxels, not the LOD
// (finer than the march in coarse blocks; the LOD still sets where V is stored). The voxels are
// read from BlockPyramid::flatVoxels (made once per pyramid). Points off both lattices (samples of
// a partial edge block clamped onto the volume) are marched alone along the same directions. The
// result is identical for any thread count (each point's directions are summed in one fixed
// order). A block's points depend on the voxels alone, as the march's do, so the TF update below
// recomputes only the blocks an edit reaches under either integrator.
//
// Boundary layers. Where the volume's box cuts through matter (a CT's scan range through the
// body, the bonsai's pot standing on the bottom slice) the cut is a face the viewer sees and the
// light falls on: at a point on it the outward half of the directions leaves the volume at once
// (V = 1 there) while a voxel inside, V drops steeply. A block at level l ≥ 1 has its outermost
// samples (s − 1)/2 voxels inside its faces, so on the volume's face the interpolation clamps to
// samples inside the matter: at 1:16 the bonsai's cut face was shaded from V_0/√(4π) ≈ 0.16 instead
// of the 0.31 its level-0 neighbours gave, in block-shaped patches. So every stored block at a
// level ≥ 1 whose outermost samples lie inside a face of the volume (boundaryLayerPlane) also
// stores a layer on that face: n² points on the face's voxel plane (coordinate 0 or dims − 1) at
// the block's sample positions along the other two axes, each marched alone along the field's
// directions (under the sweep too: they are off its lattices). Between a layer and the block's
// outermost samples the value blends linearly from the layer (on the face) to the block's own
// interpolation (at its samples), per face in axis order; elsewhere nothing changes, so level 0
// — which has samples on the face — and the interior are as before. A layer point costs one
// point's rays: n² per face against the block's n³ points.
//
// TF update (updateLocalVisibility; Kronander asks for a TF change in about a second): the field under a
// new TF from the one computed under the previous TF on the same block pyramid, recomputing only
// the blocks the change can reach, with a result identical bit for bit to computeLocalVisibility.
// What a point's value reads: the voxel values along its rays (all within R of it; a value read
// in a block's extent interpolates its voxels and its neighbours' next to it), the
// step lengths the selected levels give, and the cell-visibility flags of the cells its rays cross
// and of those within 2·s + 1 voxels (visibilityNeeded). A block is a *source of change* when its
// level differs between the two selections, one of its cells changed visibility, or σt changed
// (optics::extinctionChange — σt only: a colour-only edit changes no value) somewhere in the hull
// of the values of the blocks within two of it (a value read in b lies in the hull of b's and its
// neighbours' ranges, and a pre-integrated step from b ends in b or a neighbour). A stored
// block is recomputed when its own level changed or a source block lies within its reach — per
// axis, the gap between the two blocks' voxel extents within max(R / spacing_a, 2·s + 1) +
// kUpdateMarginVoxels (under the line sweep + 2·max|v_a| + 1: its lines start and end that far
// past a ray); every other block copies its
// previous coefficients (same level, same samples, same σt along every ray). So a TF edit over a
// narrow value range (moving the soft-tissue ramp) recomputes the blocks near the tissue it touches,
// and the LOD selection's own reshuffling (the budget is global) is what else it costs; the stats
// report both.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/half_space.h"
#include "core/progress.h"
#include "optics/transfer_function.h"
#include "sh/sphere_samples.h"
#include "visibility/multires_grid.h"

namespace voxlight::visibility {

/// Longest ray step (voxels): at least four samples within the default radius of 16 voxels, so a
/// fine block entered from a coarse one is never stepped over by more than 4 voxels.
inline constexpr float kMaxStepVoxels = 4.f;
/// Optical depth above which one ray step is split into sub-steps of at most this depth (up to
/// kMaxSubSteps; the loop stops once the ray is opaque): the value is linear along a ray only
/// within a voxel, so a pre-integrated step across a dense surface is smeared over the step.
/// Depth 1 keeps T within 0.01 of the continuous model at a partial-volume surface (tested) and
/// costs +7 % of the rays' CPU time on Kronander's phantom; ½ and ¼ gave the same slab and torso
/// images (to 0.1 %) at +57 % and +130 % (user time of one run each, on a loaded machine).
inline constexpr double kRefineDepth = 1.0;
inline constexpr int kMaxSubSteps = 16;
/// Optical depth at which a visibility ray stops (e^−9.21 = 1e-4).
inline constexpr double kOpaqueDepth = 9.21;

/// Parametric exit from the box [0, top] (index space) of a ray o + t·d starting inside it: the
/// smallest t at which a coordinate reaches its face, at least 0 (∞ for d = 0). The one formula
/// behind the march's and ritschel's rays and the near shadow's trace (shaders/ mirrors it in
/// GLSL).
inline float boxExitIndex(const glm::vec3& o, const glm::vec3& d, const glm::vec3& top) {
    float t = INFINITY;
    for (int a = 0; a < 3; ++a) {
        if (d[a] > 0.f) t = std::min(t, (top[a] - o[a]) / d[a]);
        if (d[a] < 0.f) t = std::min(t, -o[a] / d[a]);
    }
    return std::max(t, 0.f);
}

/// The pieces a step of pre-integrated depth `depth` > kRefineDepth is split into: enough for
/// ≤ kRefineDepth each, at most kMaxSubSteps. Clamped before the conversion: an extreme σt × step
/// (10⁶/mm over metres) or a NaN depth would overflow int (found by tests/stability under UBSan:
/// k = INT_MIN gave depth 0). Shared by preIntegratedStep and the line sweep's batched splits.
inline int densePieces(double depth) {
    const double want = std::ceil(depth / kRefineDepth);
    return want < double(kMaxSubSteps) ? std::max(int(want), 1) : kMaxSubSteps;
}

/// Optical depth of one ray step of length dt (mm) whose value runs from sFront to sBack
/// (integrals iFront/iBack: TfTable::sigmaIntegral), pre-integrated; a step deeper than
/// kRefineDepth is split into up to kMaxSubSteps sub-steps, value(x) giving the value x mm into
/// the step, and the split stops once tauBefore plus the depth so far exceeds kOpaqueDepth.
/// `samples` counts the sub-steps' extra reads. Shared by sh-local's and ritschel's rays.
template <class Value>
[[gnu::always_inline]] inline double preIntegratedStep(const optics::TfTable& table, float sFront,
                                                       double iFront, float sBack, double iBack,
                                                       float dt, double tauBefore, Value&& value,
                                                       std::uint64_t& samples) {
    double depth = double(table.meanExtinction(sFront, iFront, sBack, iBack)) * double(dt);
    if (depth <= kRefineDepth) return depth;
    // Dense: the value is linear only within a voxel, so a step across a surface (where it
    // kinks) is split into sub-steps, each pre-integrated.
    const int k = densePieces(depth);
    const float sub = dt / float(k);
    depth = 0.0;
    float s0 = sFront;
    double i0 = iFront;
    for (int j = 1; j <= k && tauBefore + depth <= kOpaqueDepth; ++j) {
        const float s1 = j == k ? sBack : value(float(j) * sub);
        const double i1 = j == k ? iBack : table.sigmaIntegral(s1);
        depth += double(table.meanExtinction(s0, i0, s1, i1)) * double(sub);
        s0 = s1;
        i0 = i1;
    }
    samples += std::uint64_t(k - 1);  // at most: the split stops once opaque
    return depth;
}
/// Fewest rays per SH coefficient for which the corrected weights are guaranteed positive (checked
/// for every allowed count by tests/visibility).
inline constexpr int kMinRaysPerCoefficient = 2;

/// How V^L's rays are integrated (header comment).
enum class VisibilityAlgorithm {
    March,  ///< each point's N rays marched alone (spherical Fibonacci directions, any N)
    Sweep,  ///< lattice directions (26 or 98), prefix sums along shared lattice lines
};

/// The ray counts of the line sweep: the primitive lattice steps with |v_a| ≤ 1 and ≤ 2.
inline constexpr int kSweepRaysCoarse = 26;
inline constexpr int kSweepRaysFine = 98;
/// Fibonacci points that measure the sweep directions' Voronoi cells (solid-angle error of a
/// weight ≈ 4π/2¹⁸ per boundary point; the weight correction then makes the low bands exact).
inline constexpr int kSweepWeightPoints = 1 << 18;

struct LocalVisibilityOptions {
    int rays = 32;               ///< N ≥ kMinRaysPerCoefficient · coefficients (sweep: 26 or 98)
    int coefficients = 4;        ///< 1, 4, 9 or 16
    double radiusVoxels = 16.0;  ///< r_s in units of the smallest spacing, > 0
    int threads = 0;             ///< 0 = all hardware threads
    VisibilityAlgorithm algorithm = VisibilityAlgorithm::March;
    /// The line sweep's unit of work: groups of this many blocks per axis (1, 2, 4 or 8; 0 =
    /// automatic). Every value gives the same bits (tested); larger groups share more of each line.
    int sweepGroupBlocks = 0;
};

/// The primitive lattice steps of the sweep: 26 (|v_a| ≤ 1) or 98 (|v_a| ≤ 2), in a fixed order;
/// InputError for other counts.
std::vector<glm::ivec3> latticeSteps(int rays);
/// The sweep's world directions (one per latticeSteps(rays) entry, in `geometry`'s frame) with
/// Voronoi weights corrected for `coefficients` (header comment).
sh::SphereSamples latticeDirections(const core::Geometry& geometry, int rays, int coefficients);

/// The N directions and their corrected weights (see header comment). InputError when N or the
/// coefficient count is not allowed.
sh::SphereSamples visibilityDirections(int rays, int coefficients);

/// Corrects the weights of any direction set in place as visibilityDirections does (minimum-norm
/// change so Σ_k w_k Y_i(ω_k) = √(4π) δ_i0 for i < coefficients); InternalError if a weight ends
/// up ≤ 0.
void correctVisibilityWeights(sh::SphereSamples& samples, int coefficients);
/// The same, but false (samples unchanged) instead of an error when a weight would end up ≤ 0 —
/// a jittered set with few rays per coefficient can be too uneven for a positive correction.
bool tryCorrectVisibilityWeights(sh::SphereSamples& samples, int coefficients);

/// What a clip-aware update did (the pipeline's stats report it).
struct ClipUpdateStats {
    std::size_t blocks = 0;         ///< stored blocks
    std::size_t blocksTouched = 0;  ///< blocks with at least one point recomputed or cleared
    std::uint64_t points = 0;       ///< stored sample points
    /// Points whose rays were marched again (all of them from scratch, or the cut ones alone); a
    /// point within reach of a face whose rays it happens not to cut keeps its value uncounted.
    std::uint64_t pointsTraced = 0;
    std::uint64_t pointsCleared = 0;  ///< points ≥ R outside a face: empty space's value, no rays
    std::uint64_t raysTraced = 0;     ///< rays marched (a cut ray marched in pieces counts once)
    double seconds = 0.0;
};

/// What a TF update did (the pipeline's stats report it).
struct TfUpdateStats {
    bool incremental = false;  ///< false: computed in full, `reason` says why
    std::string reason;
    optics::ValueInterval changed;       ///< values whose σt differs between the two TFs
    std::size_t blocks = 0;              ///< stored blocks of the new selection
    std::size_t blocksLevelChanged = 0;  ///< of those, at another level than before (or new)
    std::size_t blocksRecomputed = 0;    ///< traced again (the rest copied)
    std::uint64_t points = 0;            ///< stored sample points
    std::uint64_t pointsRecomputed = 0;  ///< in the recomputed blocks
    double seconds = 0.0;
};

/// Voxels added to a block's reach in a TF update: ownership (nearest voxel) and cell (voxels
/// [4c, 4c + 4]) boundaries sit up to one voxel from a block's extent; one more against rounding.
inline constexpr double kUpdateMarginVoxels = 2.0;

/// "No layer" in LocalVisibility's layer offsets.
inline constexpr std::size_t kNoLayer = ~std::size_t(0);

/// Whether stored block `block` has a boundary layer on the volume's face across `axis` (`side`
/// 0: the low face, 1: the high one; header comment) — a level ≥ 1 block touching that face whose
/// outermost samples lie inside it — and the face's voxel coordinate along `axis`.
bool boundaryLayerPlane(const MultiresGrid& grid, std::size_t block, int axis, int side,
                        float& plane);

/// Where LocalVisibility::locate found a point to read from: the blocks and weights of the
/// grid's interpolation and their blended sample spacing.
struct FieldLookup {
    BlockWeights weights;
    bool alone = false;  ///< the owner block alone, weight 1 (MultiresGrid::ownerAlone)
    float spacing = 1.f;
};

/// SH coefficients of V^L at every sample of every stored block (block-major, then sample-major
/// x fastest, then coefficient), and on the boundary layers of coarse blocks at the volume's faces.
class LocalVisibility {
  public:
    LocalVisibility() = default;
    int coefficients() const { return coefficients_; }
    double radiusVoxels() const { return radius_; }
    int rays() const { return rays_; }
    const MultiresGrid& grid() const { return *grid_; }
    std::shared_ptr<const MultiresGrid> gridPtr() const { return grid_; }
    /// First float of a block's coefficients (meaningless for kNone blocks).
    const float* blockData(std::size_t block) const { return data_.data() + offset_[block]; }
    std::size_t bytes() const { return (data_.size() + layerData_.size()) * sizeof(float); }
    /// Boundary-layer points (header comment).
    std::size_t layerPoints() const {
        return coefficients_ > 0 ? layerData_.size() / std::size_t(coefficients_) : 0;
    }
    /// First float of a block's layer on face 2·axis + side (n² points, the lower other axis
    /// fastest, then coefficient), nullptr where it has none.
    const float* layerData(std::size_t block, int face) const {
        const std::size_t off = layerOffset_[block * 6 + std::size_t(face)];
        return off == kNoLayer ? nullptr : layerData_.data() + off;
    }
    VisibilityAlgorithm algorithm() const { return algorithm_; }
    /// The ray directions and weights the field was projected with.
    const sh::SphereSamples& directions() const { return *directions_; }
    std::uint64_t raysTraced() const { return raysTraced_; }
    std::uint64_t samplesTaken() const { return samplesTaken_; }
    /// Grid points far from anything visible (set to empty space's value without rays).
    std::uint64_t pointsSkipped() const { return pointsSkipped_; }

    /// V at continuous voxel index p by the grid's seamless interpolation, into out[0..C); empty
    /// space's value (√(4π), 0, …) where no stored block contributes.
    void sample(const glm::vec3& p, float* out) const;
    /// The same, and in `spacing` the sample spacing (voxels) of the levels read, blended with
    /// the interpolation's weights — their quadratic mean (Σ w·s²)^½, locate's comment says why — (1
    /// where no stored block contributes): how far apart the points the value came from lie.
    void sample(const glm::vec3& p, float* out, float* spacing) const;
    /// sample() in two steps, for a caller that decides from the spacing whether it needs the
    /// value (render::ShLocalShader): where p reads from (its blocks, weights and the blended
    /// spacing), then the value; locate + read = sample, bit for bit.
    void locate(const glm::vec3& p, FieldLookup& at) const;
    void read(const FieldLookup& at, const glm::vec3& p, float* out) const;
    /// A copy in which f(x, c) has rewritten the C coefficients c of every stored point (block
    /// samples and boundary-layer points) at its voxel coordinate x (clamped onto the volume, as
    /// computed); f is called concurrently. GlobalVisibility bakes V^L ⊗ V^F into one with it.
    LocalVisibility mapped(const std::function<void(const glm::vec3&, float*)>& f) const;

    /// σt of the TF the field was computed under (what a TF update compares against).
    const optics::TfTable::ExtinctionProfile& extinction() const { return *extinction_; }

  private:
    friend LocalVisibility computeLocalVisibility(std::shared_ptr<const MultiresGrid>,
                                                  const optics::TfTable&,
                                                  const LocalVisibilityOptions&,
                                                  const core::Progress&);
    friend LocalVisibility updateLocalVisibility(const LocalVisibility&,
                                                 std::shared_ptr<const MultiresGrid>,
                                                 const optics::TfTable&,
                                                 const LocalVisibilityOptions&,
                                                 const core::Progress&, TfUpdateStats*);
    friend LocalVisibility clipAwareLocalVisibility(const LocalVisibility&, const optics::TfTable&,
                                                    std::span<const core::HalfSpace>, int,
                                                    const core::Progress&, ClipUpdateStats*);
    std::shared_ptr<const MultiresGrid> grid_;
    std::shared_ptr<const optics::TfTable::ExtinctionProfile> extinction_;
    std::shared_ptr<const sh::SphereSamples> directions_;
    VisibilityAlgorithm algorithm_ = VisibilityAlgorithm::March;
    int coefficients_ = 0, rays_ = 0;
    double radius_ = 0.0;
    std::vector<std::size_t> offset_;
    std::vector<float> data_;
    std::vector<std::size_t> layerOffset_;  ///< per block × 6 faces (2·axis + side), or kNoLayer
    std::vector<std::uint8_t> layerFaces_;  ///< per block: bit 2·axis + side set when it has one
    std::vector<float> layerData_;
    std::uint64_t raysTraced_ = 0, samplesTaken_ = 0, pointsSkipped_ = 0;
};

/// Computes V^L on `grid` under the TF `table` (InputError on bad options).
LocalVisibility computeLocalVisibility(std::shared_ptr<const MultiresGrid> grid,
                                       const optics::TfTable& table,
                                       const LocalVisibilityOptions& options,
                                       const core::Progress& progress = core::Progress::none());

/// V^L on `grid` under `table`, identical to computeLocalVisibility(grid, table, options), from
/// `previous` (computed under another TF on the same BlockPyramid object with the same rays,
/// coefficients and radius), recomputing only the blocks the change reaches (see the header
/// comment). When `previous` does not qualify it computes in full and says why in the stats.
LocalVisibility updateLocalVisibility(const LocalVisibility& previous,
                                      std::shared_ptr<const MultiresGrid> grid,
                                      const optics::TfTable& table,
                                      const LocalVisibilityOptions& options,
                                      const core::Progress& progress = core::Progress::none(),
                                      TfUpdateStats* stats = nullptr);

/// V^L of `base`'s grid, rays, coefficients and radius with the matter outside `kept` (world
/// half-spaces; their intersection is kept) treated as empty, recomputing only the points within
/// R of a face (see the header comment); `base` must have been computed under `table`. With no
/// half-spaces the result equals `base`. `threads` 0 = all hardware threads.
LocalVisibility clipAwareLocalVisibility(const LocalVisibility& base, const optics::TfTable& table,
                                         std::span<const core::HalfSpace> kept, int threads = 0,
                                         const core::Progress& progress = core::Progress::none(),
                                         ClipUpdateStats* stats = nullptr);

/// Whether V at voxel coordinate x, stored at sample spacing s voxels, can be read by a shaded
/// sample: some visible cell (LodSelection::cellVisible) within 2·s + 1 voxels (see the header
/// comment).
bool visibilityNeeded(const MultiresGrid& grid, const glm::vec3& x, float s);
/// The same test on the summed-volume table of a cell-visibility mask (the box of cells within
/// 2·s + 1 voxels of x, counted in eight reads).
bool visibilityNeeded(const VisibleCellCounts& counts, const glm::vec3& x, float s);

/// Transmittance of one ray from voxel index `origin` along the *world* unit direction `dir` over
/// `radiusVoxels`, integrated as computeLocalVisibility does (exposed for tests). `samples` counts
/// the σt evaluations.
double rayTransmittance(const MultiresGrid& grid, const optics::TfTable& table,
                        const glm::vec3& origin, const glm::dvec3& dir, double radiusVoxels,
                        std::uint64_t* samples = nullptr);
/// Sub-step (voxels) of nearTransmittance: the value is linear only within a voxel, and two
/// pre-integrated steps per voxel keep a dense surface from being smeared over a step.
inline constexpr double kNearStepVoxels = 0.5;
/// Transmittance from voxel index `origin` along the *world* unit direction `dir` over
/// `lengthVoxels` (units of the smallest spacing; clipped at the volume's box): the TF's σt
/// pre-integrated between trilinear values at equal sub-steps of at most kNearStepVoxels, no LOD
/// steps and no splitting — a march a shader can repeat sample for sample (sh-local's near shadow,
/// render/sh_shading.h).
double nearTransmittance(const MultiresGrid& grid, const optics::TfTable& table,
                         const glm::vec3& origin, const glm::dvec3& dir, double lengthVoxels);
/// The same march with the direction already in index units per mm (`dirIndex`: the world
/// direction through the geometry's world-to-index matrix) over `lengthMm`, which the caller has
/// clipped to the volume's box: the per-sample form (render/sh_shading.h's NearShadowTrace clips
/// at its exit and transforms each light's direction itself).
double nearTransmittanceIndex(const MultiresGrid& grid, const optics::TfTable& table,
                              const glm::vec3& origin, const glm::vec3& dirIndex, float lengthMm);
/// The same by the straightforward march the fast path must reproduce (every step through the
/// TF table; the slow reference tests compare against).
double rayTransmittanceReference(const MultiresGrid& grid, const optics::TfTable& table,
                                 const glm::vec3& origin, const glm::dvec3& dir,
                                 double radiusVoxels);

}  // namespace voxlight::visibility
