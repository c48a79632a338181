// SPDX-License-Identifier: MIT
#pragma once
// Multiresolution block grid (flat blocking) for SH visibility: Kronander et al. 2012 §4.1, after
// Ljung et al. 2004 ("Transfer function based adaptive decompression for volume rendering of large
// medical data sets") and Ljung et al. 2006 ("Multiresolution interblock interpolation in direct
// volume rendering").
//
// Blocks: the volume is cut into kBlockSize³ = 16³ blocks; block b owns voxels [16·b, 16·b + 15]
// per axis (clipped at the volume edge; a partial edge block is padded by repeating the edge voxel,
// so every block has full 16³ data). Each block is kept at one level of detail:
//   level 0..4 → n = 16, 8, 4, 2, 1 samples per axis, spacing s = 16/n voxels, or kNone (not
//   stored: the TF is transparent over every value a trilinear sample inside the block's owned
//   extent reads — its own voxels and the one-voxel apron around them, judged by the cells that
//   overlap the extent, so the air block above a bone surface lying on its face is stored).
// Sample j of a level-l block lies at voxel coordinate 16·b + (j + ½)·s − ½ (cell centred), and
// its value is the mean of the s³ voxels it covers (box filter), so level 0 is the voxels
// themselves (bit for bit) and level 4 the block mean.
//
// Once per volume (BlockPyramid::build): every level of every block, the block's value range and a
// kHistogramBins-bin histogram over that range (the piecewise-constant histogram of Ljung 2004).
// On a TF change (selectLod, milliseconds): TF-based significance from the histograms, then a
// priority queue picks levels under a budget.
//
// Significance (Ljung 2004 §4, "the difference in CIE Luv between the lowest level and the full
// data, estimated from the histogram"): S_b = Σ_bins p_j · ΔE(c(v_j), c(v̄_b)), where v_j are the
// bin centres with probabilities p_j, v̄_b the block mean (its 1³ level) and c(v) the TF colour
// premultiplied by the opacity of one voxel step, α·(albedo + emission) with α = 1 − exp(−σt·h)
// (h = smallest spacing), in CIE L*u*v* (D65); ΔE is the Euclidean L*u*v* distance.
//
// Selection (Ljung 2004's adaptive priority queue): every block not at kNone (above) starts at 1³
// (an apron-only block, transparent over its own voxels, with significance 0); the distortion of block b at level l is modelled as S_b·l/4 (full data at level 0,
// S_b at 1³), so each refinement step gains S_b/4 and costs n_new³ − n_old³ samples; the queue
// always refines the block with the largest gain per sample (ties: lower block index) while the
// budget allows. Blocks with S_b = 0 gain kZeroSignificanceGain per step, so they refine last but do
// refine when the budget allows (a full budget selects level 0 everywhere). The 1³ start is never
// undercut: a budget below one sample per visible block is raised to that (selection.points says
// what was used).
//
// Sampling across blocks (MultiresGrid::weights), after Ljung 2006's idea of sampling each block
// only from its own data, clamped to its "sample box" [16·b + s/2 − ½, 16·b + 16 − s/2 − ½] (the
// hull of its samples), and blending blocks near their faces with normalised weights:
//   f(p) = Σ_b ω_b(p) · f_b(clamp(p, box_b)) / Σ_b ω_b(p),   ω_b = Π_axes ψ_b,a(p),
//   ψ_b,a = clamp(1 − d_a / g_b,f(p), 0, 1),  d_a = how far p_a lies past b's box on axis a (0
//                                              inside), f = the face of b on that side,
// a linear ramp from b's box out across the gap to the neighbours' samples. Its length:
//   g_b,f = (s_b + s_c)/2 toward the stored face neighbour c across f (s_b where c is not stored):
//     the gap between b's outermost samples and c's, so where nothing else intervenes the two
//     ramps sum to 1 and f is exactly linear between b's last sample and c's first — the two
//     blocks' own samples, whatever their levels;
//   shortened near a finer diagonal neighbour n across f (one of the other 8 blocks on that side,
//     off b on one or both other axes): g(p) = min over such n of g + t_n(p)·(ℓ_n − g) where
//     ℓ_n = (s_b + s_n)/2 < g and t_n = Π over n's other axes of clamp(d'/ℓ_n, 0, 1), d' how far
//     p lies past b's box toward n on that axis — 0 within b's box there, 1 where n's box begins,
//     so b's ramp ends at n's box inside it.
// Until 7 December the ramp was centred on b's face with one width for the block, the finest
// spacing among b and all 26 neighbours: one finer block diagonally past a face squeezed the
// blend between two coarser blocks across it into one voxel, and the step between their samples
// two voxels apart showed as a line along every such face (the T1 MRI's scalp at 1:8: 1.7× the
// interior's error within half a voxel of a face; tests/visibility LineSweep.NoLargerErrorAt…).
// Properties (tested):
//   * each ω_b depends on p and b only and is continuous (g is, and g ≥ 1), so f is continuous
//     wherever Σ ω > 0; the owner of p always has ψ ≥ 1/(s + 1) per axis (d ≤ s/2 inside its
//     extent, g ≥ (s + 1)/2), so Σ ω > 0 wherever the owner is stored;
//   * inside a block's sample box only that block contributes: any other block n differs from it
//     on some axis, and there n's ramp toward it ends at its box (its face neighbour's g, or its
//     limit faded fully in: p lies past n's box on n's other axes by at least ℓ). So a fine block
//     is never blurred by a coarse neighbour inside its box. (Per axis this need not hold: inside
//     the box on one axis a diagonal block can reach in — weights() visits its column then,
//     MultiresGrid::reachesIn_);
//   * where b and its neighbours share one level, the ramps of two neighbours sum to 1 and span
//     the gap between their boxes: exactly trilinear interpolation on that level's lattice, and at
//     level 0 everywhere exactly trilinear interpolation of the voxels.
// What remains at faces where the levels differ by two or more (1:3, 0:2: a gap of 5 or 2.5
// voxels): the linear blend across the gap misses V's curvature there — on the MRI's scalp V_0
// is 0.13–0.20 low within a voxel of 1:3 faces (README; a selection keeping neighbours within one
// level would remove it).
// Blocks at kNone hold no data and get weight 0. Where no stored block contributes (inside a
// transparent block, away from stored ones) weights() returns no block and callers use their
// empty-space value; such points are never shaded (the TF is transparent over the whole block).
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <glm/glm.hpp>
#include <iosfwd>
#include <memory>
#include <mutex>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "optics/transfer_function.h"

namespace voxlight::visibility {

inline constexpr int kBlockSize = 16;
inline constexpr int kLevels = 5;  ///< 16³, 8³, 4³, 2³, 1³
inline constexpr int kNone = -1;   ///< block not stored (transparent under the TF, apron included)
inline constexpr int kHistogramBins = 32;
/// Gain per refinement step of a block whose significance is 0 (ΔE units): far below any visible
/// colour difference (ΔE ≈ 1 is a just-noticeable difference), so such blocks refine only after
/// every block with a measurable significance has been refined as far as the budget allows.
inline constexpr double kZeroSignificanceGain = 1e-9;
/// Floats of one block at every level: 16³ + 8³ + 4³ + 2³ + 1³.
inline constexpr int kPyramidFloats = 4096 + 512 + 64 + 8 + 1;

/// Samples per axis at a level (16 >> level).
constexpr int levelResolution(int level) { return kBlockSize >> level; }
/// Voxels between samples at a level (1 << level).
constexpr int levelSpacing(int level) { return 1 << level; }
/// 1 / levelSpacing(level), exact (a power of two): hot loops multiply instead of dividing.
constexpr float levelInvSpacing(int level) { return 1.f / float(1 << level); }
/// First float of a level inside a block's pyramid.
constexpr int levelOffset(int level) {
    int o = 0;
    for (int l = 0; l < level; ++l)
        o += levelResolution(l) * levelResolution(l) * levelResolution(l);
    return o;
}

struct BlockStats {
    float min = 0.f, max = 0.f;  ///< physical value range of the owned voxels
    float mean = 0.f;            ///< = the 1³ level
    std::array<std::uint32_t, kHistogramBins> histogram{};  ///< owned voxels over [min, max]
};

/// Every level of every block plus the block statistics; built once per volume.
class BlockPyramid {
  public:
    /// Scans the volume (parallel over blocks). Non-finite voxels enter as the volume's lowest
    /// finite value (the ray caster samples NaN as the TF's lowest value too).
    static BlockPyramid build(const core::Volume& volume,
                              const core::Progress& progress = core::Progress::none());

    const core::Geometry& geometry() const { return geometry_; }
    const glm::ivec3& dims() const { return geometry_.dims; }
    const glm::ivec3& blocks() const { return blocks_; }
    std::size_t blockCount() const { return stats_.size(); }
    std::size_t blockIndex(int bx, int by, int bz) const {
        return std::size_t(bx) + std::size_t(blocks_.x) *
                                     (std::size_t(by) + std::size_t(blocks_.y) * std::size_t(bz));
    }
    glm::ivec3 blockCoord(std::size_t index) const;
    const BlockStats& stats(std::size_t block) const { return stats_[block]; }
    /// n³ samples of `level` of a block (x fastest).
    const float* data(std::size_t block, int level) const {
        return data_.data() + block * kPyramidFloats + levelOffset(level);
    }
    std::size_t bytes() const {
        return data_.size() * sizeof(float) + stats_.size() * sizeof(BlockStats) +
               cellRange_.size() * sizeof(cellRange_[0]) + flat_->bytes.load();
    }
    /// The level-0 voxels as one x-fastest array (dims().x · dims().y · dims().z values: the
    /// line sweep's reads), made on first use in parallel in the calling task arena and kept with
    /// the pyramid — it does not depend on the TF, so a TF update reads it without copying the
    /// volume again (counted in bytes() once made). Thread-safe. Held as int16 when every value
    /// is an integer in int16's range (CT in HU, 8- and most 16-bit data: each read converts
    /// back to exactly the same float), else as float: exactly one pointer is set. Half the
    /// bytes (bonsai: 32 MB instead of 64) and half the cache lines the sweep's stencils touch;
    /// its speed (6 December, bonsai 1:8, alternating pairs): an 8-bit trial copy 0.88–0.96× in
    /// a slow sitting, this int16 copy 0.99–1.04× in a quiet one — the gain follows how
    /// contended the machine's cache is.
    struct FlatView {
        const float* f = nullptr;
        const std::int16_t* i = nullptr;
        /// The value at index k.
        float operator[](std::ptrdiff_t k) const { return i ? float(i[k]) : f[k]; }
    };
    FlatView flatVoxels() const;
    /// The bytes of flatVoxels()' array once made, else 0.
    std::size_t flatBytes() const { return flat_->bytes.load(); }

    /// Value ranges of kCellVoxels³ cells (cell c spans voxels [4c, 4c + 4] per axis: the voxels
    /// every trilinear sample inside it reads), for empty-space skipping of visibility rays.
    static constexpr int kCellVoxels = 4;
    const glm::ivec3& cells() const { return cells_; }
    const std::array<float, 2>& cellRange(std::size_t cell) const { return cellRange_[cell]; }
    std::size_t cellCount() const { return cellRange_.size(); }

  private:
    core::Geometry geometry_;
    glm::ivec3 blocks_{0}, cells_{0};
    std::vector<BlockStats> stats_;
    std::vector<float> data_;  ///< kPyramidFloats per block
    std::vector<std::array<float, 2>> cellRange_;
    struct FlatVoxels {
        std::once_flag once;
        std::unique_ptr<float[]> voxels;
        std::unique_ptr<std::int16_t[]> small;
        std::atomic<std::size_t> bytes{0};
    };
    /// Shared by copies of the pyramid (same voxels); made by flatVoxels().
    std::shared_ptr<FlatVoxels> flat_ = std::make_shared<FlatVoxels>();
};

/// How many samples the selection may hold.
struct LodBudget {
    std::uint64_t maxPoints = 0;
    /// One sample per `ratio` voxels (Kronander's "data reduction 1:ratio"); ratio ≥ 1.
    static LodBudget fromReduction(double ratio, std::uint64_t voxels);
    /// `bytes` of storage at `bytesPerPoint` per sample.
    static LodBudget fromBytes(double bytes, double bytesPerPoint);
    static LodBudget unlimited() { return {~std::uint64_t(0)}; }
};

struct LodSelection {
    std::vector<std::int8_t> level;   ///< per block: 0..4 or kNone
    std::vector<float> significance;  ///< per block (0 for kNone blocks)
    std::uint64_t points = 0;         ///< Σ n³ over stored blocks
    std::uint64_t budgetPoints = 0;   ///< the budget as applied (raised to the 1³ minimum)
    std::array<std::size_t, kLevels + 1> blocksPerLevel{};  ///< [0..4] levels, [5] kNone
    /// Per BlockPyramid cell: 1 where the TF is not transparent over the cell's value range (its
    /// table's one-cell leak included). Empty = every cell visible.
    std::vector<std::uint8_t> cellVisible;
};
std::ostream& operator<<(std::ostream& os, const LodSelection& s);

/// TF significance of every block (see header comment); kNone blocks (transparent under the TF,
/// its table's interpolation leak of one cell included) get −1.
std::vector<float> blockSignificance(const BlockPyramid& pyramid,
                                     const optics::TransferFunction& tf,
                                     const optics::TfTable& table);

/// Per BlockPyramid cell: 1 where the TF is not transparent over the cell's value range, its
/// table's one-cell leak included (LodSelection::cellVisible).
std::vector<std::uint8_t> visibleCells(const BlockPyramid& pyramid,
                                       const optics::TransferFunction& tf,
                                       const optics::TfTable& table);

/// The priority-queue selection under `budget` (see header comment).
LodSelection selectLod(const BlockPyramid& pyramid, const optics::TransferFunction& tf,
                       const optics::TfTable& table, const LodBudget& budget);

/// Trilinear interpolation of an n³ block payload of `channels` floats per sample (sample-major)
/// at local sample coordinates u (already clamped to [0, n − 1]); adds w·value to out[0..channels).
/// kChannels > 0: `channels` is that compile-time count (the loop unrolls and vectorises).
template <int kChannels = 0>
inline void addTrilinear(const float* data, int n, int runtimeChannels, const glm::vec3& u, float w,
                         float* out) {
    const int channels = kChannels > 0 ? kChannels : runtimeChannels;
    const int m = n > 1 ? n - 2 : 0;
    const int i = std::min(int(u.x), m), j = std::min(int(u.y), m), k = std::min(int(u.z), m);
    const float fx = u.x - float(i), fy = u.y - float(j), fz = u.z - float(k);
    const std::size_t di = n > 1 ? std::size_t(channels) : 0;
    const std::size_t dj = n > 1 ? std::size_t(n) * channels : 0;
    const std::size_t dk = n > 1 ? std::size_t(n) * n * channels : 0;
    const float* p =
        data + (std::size_t(i) + std::size_t(n) * (std::size_t(j) + std::size_t(n) * k)) *
                   std::size_t(channels);
    const float w000 = (1 - fx) * (1 - fy) * (1 - fz), w100 = fx * (1 - fy) * (1 - fz);
    const float w010 = (1 - fx) * fy * (1 - fz), w110 = fx * fy * (1 - fz);
    const float w001 = (1 - fx) * (1 - fy) * fz, w101 = fx * (1 - fy) * fz;
    const float w011 = (1 - fx) * fy * fz, w111 = fx * fy * fz;
    for (int c = 0; c < channels; ++c) {
        const float v = w000 * p[c] + w100 * p[di + c] + w010 * p[dj + c] + w110 * p[dj + di + c] +
                        w001 * p[dk + c] + w101 * p[dk + di + c] + w011 * p[dk + dj + c] +
                        w111 * p[dk + dj + di + c];
        out[c] += w * v;
    }
}

/// Up to eight blocks and their weights for one point (MultiresGrid::weights).
struct BlockWeights {
    int count = 0;
    std::uint32_t block[8];
    float weight[8];
    glm::vec3 local[8];  ///< the point in the block's sample coordinates, clamped to its box
    std::int8_t level[8];
};

/// A summed-volume table over a BlockPyramid cell-visibility mask (LodSelection::cellVisible;
/// empty = every cell visible): whether any cell of a box is visible in eight reads, whatever the
/// box's size — the visibility fields' "needed" test per stored point.
class VisibleCellCounts {
  public:
    VisibleCellCounts() = default;
    VisibleCellCounts(const glm::ivec3& cells, const std::vector<std::uint8_t>& visible);
    const glm::ivec3& cells() const { return cells_; }
    /// Whether any cell in [lo, hi] (cell coordinates, inclusive, within the grid) is visible.
    bool any(const glm::ivec3& lo, const glm::ivec3& hi) const {
        const std::size_t sx = std::size_t(cells_.x) + 1, sxy = sx * (std::size_t(cells_.y) + 1);
        auto at = [&](int x, int y, int z) {
            return std::int64_t(sum_[std::size_t(x) + sx * std::size_t(y) + sxy * std::size_t(z)]);
        };
        const int x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x + 1, y1 = hi.y + 1, z1 = hi.z + 1;
        const std::int64_t n = at(x1, y1, z1) - at(x0, y1, z1) - at(x1, y0, z1) - at(x1, y1, z0) +
                               at(x0, y0, z1) + at(x0, y1, z0) + at(x1, y0, z0) - at(x0, y0, z0);
        return n > 0;
    }
    std::size_t bytes() const { return sum_.size() * sizeof(sum_[0]); }

  private:
    glm::ivec3 cells_{0};
    /// Entry (x, y, z) of (cells + 1)³: the visible cells with coordinates below (x, y, z) on
    /// every axis.
    std::vector<std::uint32_t> sum_;
};

/// A pyramid with a selection: the grid that local visibility is computed and stored on.
class MultiresGrid {
  public:
    MultiresGrid(std::shared_ptr<const BlockPyramid> pyramid, LodSelection selection);

    const BlockPyramid& pyramid() const { return *pyramid_; }
    const LodSelection& selection() const { return selection_; }
    /// The summed-volume table of selection().cellVisible (visibilityNeeded's box queries).
    const VisibleCellCounts& visibleCellCounts() const { return visibleCounts_; }
    int level(std::size_t block) const { return selection_.level[block]; }
    const glm::ivec3& dims() const { return pyramid_->dims(); }
    const glm::ivec3& blocks() const { return pyramid_->blocks(); }

    /// Blocks and weights of the seamless interpolation at continuous voxel index p (clamped to
    /// the volume); count 0 where no stored block contributes.
    void weights(const glm::vec3& p, BlockWeights& out) const;
    /// weights()' common case, inline (one call per shaded sample of every SH frame): true when
    /// p (clamped) lies inside its stored owner's sample box on every axis, where the owner alone
    /// contributes with weight 1 — then its index, level and local sample coordinates, exactly
    /// as weights() gives them; false otherwise (call weights()).
    bool ownerAlone(const glm::vec3& pIn, std::size_t& block, int& level, glm::vec3& local) const {
        glm::vec3 p;
        for (int a = 0; a < 3; ++a) p[a] = std::min(std::max(pIn[a], 0.f), hi_[a]);
        const glm::ivec3 b = ownerCoord(p);
        const std::size_t owner = indexOf(b);
        const int l = selection_.level[owner];
        if (l == kNone) return false;
        glm::vec3 lo, hi;
        sampleBox(b, l, lo, hi);
        if (!(p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z &&
              p.z <= hi.z))
            return false;
        block = owner;
        level = l;
        local = (p - glm::vec3(b * kBlockSize) + 0.5f) * levelInvSpacing(l) - 0.5f;  // exact: 2^-l
        return true;
    }
    /// A block's sample box at a level: [16·b + s/2 − ½, 16·b + 16 − s/2 − ½] per axis.
    static void sampleBox(const glm::ivec3& b, int level, glm::vec3& lo, glm::vec3& hi) {
        const float s = float(levelSpacing(level));
        lo = glm::vec3(b * kBlockSize) + 0.5f * s - 0.5f;
        hi = glm::vec3(b * kBlockSize) + float(kBlockSize) - 0.5f * s - 0.5f;
    }
    /// The block that owns the voxel nearest to p (p clamped to the volume).
    std::size_t ownerBlock(const glm::vec3& p) const { return indexOf(ownerCoord(p)); }
    /// Its block coordinates.
    glm::ivec3 ownerCoord(const glm::vec3& p) const {
        glm::ivec3 b;
        for (int a = 0; a < 3; ++a) {
            const float x = std::min(std::max(p[a], 0.f), hi_[a]);
            b[a] = std::min(int(x + 0.5f) >> 4, last_[a]);  // kBlockSize = 16
        }
        return b;
    }
    std::size_t indexOf(const glm::ivec3& b) const {
        return std::size_t(b.x) + stride_.y * std::size_t(b.y) + stride_.z * std::size_t(b.z);
    }
    /// Whether a BlockPyramid cell is visible under the selection's TF (LodSelection::cellVisible).
    bool cellVisible(std::size_t cell) const { return selection_.cellVisible[cell] != 0; }
    /// The selected level's n³ samples of a block (nullptr at kNone).
    const float* levelData(std::size_t block) const { return levelData_[block]; }

    /// Scalar value at p through the seamless interpolation of the selected levels; `empty` where
    /// no stored block contributes. Inline fast path inside the owner's sample box.
    float sample(const glm::vec3& pIn, float empty = 0.f) const {
        glm::vec3 p;
        for (int a = 0; a < 3; ++a) p[a] = std::min(std::max(pIn[a], 0.f), hi_[a]);
        const glm::ivec3 b = ownerCoord(p);
        const std::size_t owner = indexOf(b);
        const int l = selection_.level[owner];
        if (l != kNone) {
            const glm::vec3 u =
                (p - (glm::vec3(b) * float(kBlockSize) - 0.5f)) * levelInvSpacing(l) - 0.5f;
            const float top = float(levelResolution(l) - 1);
            if (u.x >= 0.f && u.y >= 0.f && u.z >= 0.f && u.x <= top && u.y <= top && u.z <= top) {
                float v = 0.f;
                addTrilinear(levelData_[owner], levelResolution(l), 1, u, 1.f, &v);
                return v;
            }
        }
        return sampleBlend(p, empty);
    }
    /// Voxel coordinate of sample (i, j, k) of a block at a level.
    glm::vec3 samplePosition(std::size_t block, int level, int i, int j, int k) const;

    /// Ramp length of a stored block toward its face f = 2·axis + side (voxels; header comment)
    /// at a point `pastBox` voxels past the block's sample box per axis (signed: + past its top,
    /// − below its bottom, 0 inside).
    float rampLength(std::size_t block, int face, const glm::vec3& pastBox) const;
    /// The k-th (0..7) offset on the two other axes of a face ((axis + 1) % 3, (axis + 2) % 3) of
    /// the diagonal neighbours across it: every pair in {−1, 0, 1}² but (0, 0).
    static glm::ivec2 diagonalOffset(int k) {
        const int m = k < 4 ? k : k + 1;  // skip (0, 0), the face neighbour
        return {m % 3 - 1, m / 3 - 1};
    }

  private:
    float sampleBlend(const glm::vec3& p, float empty) const;
    std::shared_ptr<const BlockPyramid> pyramid_;
    LodSelection selection_;
    std::vector<float> ramp_;  ///< per block × 6 faces (2·axis + side): g toward the face neighbour
    std::vector<float> invRamp_;       ///< 1 / ramp_
    std::vector<float> diagonalRamp_;  ///< per block × 6 faces × 8 diagonal offsets: the limits
    /// Per block × 6 faces: bit k set where diagonal neighbour k's limit is below g.
    std::vector<std::uint8_t> limited_;
    /// Per block × 6 faces: a diagonal neighbour across it may weigh inside the block's sample
    /// box on that axis (weights()' candidate pruning).
    std::vector<std::uint8_t> reachesIn_;
    /// 1 where a block and its 26 neighbours are all unstored: no stored block contributes
    /// anywhere in it (ramps reach at most 8 voxels past a block's face), so weights() returns
    /// count 0 at once there — most of a transparent TF's volume.
    std::vector<std::uint8_t> isolated_;
    std::vector<const float*> levelData_;
    VisibleCellCounts visibleCounts_;
    glm::vec3 hi_{0.f};     ///< largest index per axis
    glm::ivec3 last_{0};    ///< largest block coordinate per axis
    glm::ivec3 stride_{0};  ///< block index strides (1, bx, bx·by)
};

}  // namespace voxlight::visibility
