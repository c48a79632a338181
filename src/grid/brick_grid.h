// SPDX-License-Identifier: MIT
#pragma once
// 16³ bricks over a volume with per-brick value range and a small value histogram: the base of
// empty-space skipping (a brick is skipped when the TF is transparent over its whole [min, max])
// and of the multiresolution grid (Ljung/Kronander block significance is estimated from the brick
// histogram).
//
// Brick (bx,by,bz) *owns* voxels [16·b, 16·b+15] per axis (clipped at the volume edge); its min/max
// also cover one apron voxel on the high side (16·b+16) so that every trilinear sample whose cell
// lies in the brick is bounded by [min, max]. Histograms count owned voxels only (each voxel
// counted exactly once over all bricks) over kHistogramBins equal bins spanning the volume's
// physical value range [valueLo, valueHi]. Values are physical (HU for CT). Non-finite voxels
// (NaN/Inf) are excluded from min/max and histograms.
#include <array>
#include <cstdint>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"

namespace voxlight::grid {

inline constexpr int kBrickSize = 16;
inline constexpr int kHistogramBins = 16;

struct BrickStats {
    float min = 0.f, max = 0.f;
    std::array<std::uint32_t, kHistogramBins> histogram{};
    bool valid() const { return min <= max; }  ///< false when every voxel is non-finite
};

class BrickGrid {
  public:
    BrickGrid() = default;
    /// Scans the volume once (parallel over bricks).
    static BrickGrid build(const core::Volume& volume,
                           const core::Progress& progress = core::Progress::none());

    /// From stored parts (a cache file): the bricks of a `dims` volume with histogram domain
    /// [valueLo, valueHi]. Returns false, leaving `out` untouched, when the parts do not fit
    /// together (dims out of range, brick count).
    static bool fromParts(const glm::ivec3& dims, float valueLo, float valueHi,
                          std::vector<BrickStats> bricks, BrickGrid& out);

    const glm::ivec3& dims() const { return dims_; }
    const glm::ivec3& brickCounts() const { return counts_; }
    std::size_t size() const { return bricks_.size(); }
    const BrickStats& at(int bx, int by, int bz) const {
        return bricks_[std::size_t(bx) +
                       std::size_t(counts_.x) * (std::size_t(by) + std::size_t(counts_.y) * bz)];
    }
    const std::vector<BrickStats>& bricks() const { return bricks_; }
    /// Owned voxel range of a brick, inclusive: {first, last}.
    std::array<glm::ivec3, 2> ownedVoxels(int bx, int by, int bz) const;
    /// Histogram domain (the volume's finite physical range).
    float valueLo() const { return lo_; }
    float valueHi() const { return hi_; }
    /// Bin of a physical value, clamped to [0, kHistogramBins − 1].
    int binOf(float value) const;
    /// Physical value range covered by bin b: {lo, hi}.
    std::array<float, 2> binRange(int b) const;

  private:
    glm::ivec3 dims_{0}, counts_{0};
    float lo_ = 0.f, hi_ = 0.f;
    std::vector<BrickStats> bricks_;
};

}  // namespace voxlight::grid
