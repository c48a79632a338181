// SPDX-License-Identifier: MIT
#pragma once
// Empty-space skipping on the brick grid: per-brick majorants under a classification (usually "max
// σt of the TF over the brick's [min, max]"), and a 3D-DDA along a ray (Amanatides & Woo 1987)
// that yields maximal intervals {tRange, valueRange, maxExtinction} of consecutive bricks that are
// either all skippable (maxExtinction == 0) or all not. Ray caster, visibility and path tracer
// consume the same intervals (Open VKL VKLInterval / pbrt DDAMajorantIterator).
//
// Space: the ray is given in continuous *index* space (voxel centres at integers) as
// p(t) = origin + t·direction, with t in whatever unit the caller uses (the renderer uses world
// mm, so direction is "index units per mm"). A sample at p lies in the trilinear cell floor(p),
// which brick floor(p)/16 bounds (BrickGrid includes the apron voxel), so brick b covers
// [16·b, 16·b + 16) on each axis; positions outside the grid clamp to the edge bricks. The same
// holds for finer majorant cells of any size (BrickMajorants::fromCells).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "grid/brick_grid.h"

namespace voxlight::grid {

/// One value per brick: the largest extinction (or any non-negative "interest") over the brick's
/// value range; 0 means the brick can be skipped. Brick value ranges are kept for the intervals.
class BrickMajorants {
  public:
    BrickMajorants() = default;
    /// classify(lo, hi) → majorant ≥ 0 over physical values [lo, hi]. Called once per brick
    /// (not per sample), so a std::function-free template is not needed for speed but is cheap.
    template <class F>
    static BrickMajorants build(const BrickGrid& grid, F&& classify) {
        BrickMajorants m;
        m.counts_ = grid.brickCounts();
        m.majorant_.resize(grid.size());
        m.range_.resize(grid.size());
        for (std::size_t i = 0; i < grid.size(); ++i) {
            const BrickStats& s = grid.bricks()[i];
            m.range_[i] = {s.min, s.max};
            const float v = s.valid() ? float(classify(s.min, s.max)) : 0.f;
            m.majorant_[i] = v > 0.f ? v : 0.f;
        }
        m.finish();
        return m;
    }
    /// A majorant grid of cells of `cellSize` voxels (same apron rule as the bricks), e.g. finer
    /// cells computed inside the non-empty bricks. Sizes must agree (counts = ceil(dims / size)).
    static BrickMajorants fromCells(const glm::ivec3& counts, int cellSize,
                                    std::vector<float> majorants,
                                    std::vector<std::array<float, 2>> ranges) {
        VL_CHECK_EQ(majorants.size(), ranges.size());
        VL_CHECK_EQ(majorants.size(), std::size_t(counts.x) * counts.y * counts.z);
        VL_CHECK_GE(cellSize, 1);
        BrickMajorants m;
        m.counts_ = counts;
        m.cellSize_ = cellSize;
        m.majorant_ = std::move(majorants);
        m.range_ = std::move(ranges);
        m.finish();
        return m;
    }
    const glm::ivec3& counts() const { return counts_; }
    /// Voxels per cell side (kBrickSize for BrickGrid-based majorants).
    int cellSize() const { return cellSize_; }
    std::size_t index(int bx, int by, int bz) const {
        return std::size_t(bx) + std::size_t(counts_.x) *
                                     (std::size_t(by) + std::size_t(counts_.y) * std::size_t(bz));
    }
    float majorant(std::size_t i) const { return majorant_[i]; }
    const std::array<float, 2>& valueRange(std::size_t i) const { return range_[i]; }
    std::size_t size() const { return majorant_.size(); }
    std::size_t nonEmptyCount() const { return nonEmpty_; }
    /// Smallest and largest cell coordinates of the non-empty cells (inclusive; lo > hi when there
    /// is none). Found once when the majorants are built, so callers per frame need no scan.
    const std::array<glm::ivec3, 2>& nonEmptyCellRange() const { return nonEmptyRange_; }
    /// 1 where majorant(i) > 0 (a byte per cell, for the traversal's hot loop).
    const std::uint8_t* nonEmptyFlags() const { return flags_.data(); }
    /// Per cell, the Chebyshev distance (in cells) to the nearest non-empty cell, capped at
    /// kMaxSkipDistance: 0 for a non-empty cell, d > 0 means every cell within distance d − 1 of
    /// this one (a cube of 2d − 1 cells a side) is empty, so a ray may leave that cube in one jump.
    const std::uint8_t* skipDistances() const { return distance_.data(); }
    static constexpr int kMaxSkipDistance = 255;

  private:
    void finish();
    glm::ivec3 counts_{0};
    int cellSize_ = kBrickSize;
    std::vector<float> majorant_;
    std::vector<std::array<float, 2>> range_;
    std::vector<std::uint8_t> flags_;
    std::vector<std::uint8_t> distance_;
    std::size_t nonEmpty_ = 0;
    std::array<glm::ivec3, 2> nonEmptyRange_{glm::ivec3(0), glm::ivec3(-1)};
};

/// Per cell of a grid of `counts` cells (x fastest), the Chebyshev (max-norm) distance in cells to
/// the nearest cell whose flag is non-zero, capped at `cap` (1…255): 0 for a flagged cell; d > 0
/// means every cell within distance d − 1 of this one (a cube of 2d − 1 cells a side) is unflagged.
/// Breadth-first over the 26-neighbourhood (one level = one cell of max-norm distance).
std::vector<std::uint8_t> chebyshevDistances(const glm::ivec3& counts, const std::uint8_t* flags,
                                             int cap);

struct RayInterval {
    float t0 = 0.f, t1 = 0.f;              ///< parameter range along the ray
    float valueMin = 0.f, valueMax = 0.f;  ///< union of the bricks' value ranges
    float maxExtinction = 0.f;             ///< majorant; 0 = skippable
    bool empty() const { return !(maxExtinction > 0.f); }
};

/// The 3D-DDA state over the cells of a BrickMajorants, shared by RayIntervalIterator and
/// forEachNonEmptyRun (same arithmetic, so both yield bit-identical interval ends).
struct CellDda {
    CellDda(const BrickMajorants& majorants, const glm::vec3& originIndex,
            const glm::vec3& directionIndex, float tMin, float tMax);
    /// The next cell along the ray: its linear index and parameter range [t0, t1]; false when the
    /// ray has left [tMin, tMax] (the last cell extends to tMax).
    [[gnu::always_inline]] bool step(float& t0, float& t1, std::size_t& cellIndex) {
        if (done) return false;
        cellIndex = index;
        t0 = t;
        // One branch per axis with constant indices, so that the state stays in registers.
        if (tNext[0] <= tNext[1])
            t1 = tNext[0] <= tNext[2] ? advance<0>() : advance<2>();
        else
            t1 = tNext[1] <= tNext[2] ? advance<1>() : advance<2>();
        t = t1;
        return true;
    }
    /// Crosses the next boundary on axis A; returns the end of the cell being left.
    template <int A>
    [[gnu::always_inline]] float advance() {
        const float t1 = std::min(tNext[A], tMax);
        if (t1 >= tMax) {
            done = true;
            return t1;
        }
        index += indexStep[A];
        tNext[A] += tDelta[A];
        // Leaving the grid: the rest of the ray is in the edge cell.
        if (--left[A] < 0) {
            done = true;
            return tMax;
        }
        return t1;
    }

    /// Leaves the cube of cells within Chebyshev distance `radius` of the current (not yet
    /// returned) cell in one jump: afterwards the current cell is the last cell of that cube along
    /// the ray, so the next step() returns it and then crosses the cube's face. The caller
    /// guarantees that the cube holds only empty cells. Cells stay inside the grid.
    [[gnu::always_inline]] void jump(int radius) {
        if (done || radius < 1) return;
        const float r = float(radius);
        float tExit = std::min(
            {tNext[0] + r * tDelta[0], tNext[1] + r * tDelta[1], tNext[2] + r * tDelta[2]});
        if (!(tExit < tMax)) tExit = tMax;
        for (int a = 0; a < 3; ++a) {
            if (!(tNext[a] < tExit)) continue;  // also an axis the ray does not cross (tNext = ∞)
            // Boundary crossings on this axis strictly before tExit, at most `radius`.
            int k = int(std::ceil((tExit - tNext[a]) * invDelta[a]));
            k = std::min({k, radius, left[a]});
            if (k <= 0) continue;
            left[a] -= k;
            index += indexStep[a] * k;
            tNext[a] += float(k) * tDelta[a];
        }
    }

    /// Per axis: cells left in the stepping direction before the ray leaves the grid (a large
    /// number on an axis it does not cross).
    int left[3] = {0, 0, 0};
    std::ptrdiff_t indexStep[3] = {0, 0, 0};
    std::size_t index = 0;
    float tNext[3] = {0.f, 0.f, 0.f}, tDelta[3] = {0.f, 0.f, 0.f};
    float invDelta[3] = {0.f, 0.f, 0.f};  ///< 1 / tDelta (0 on axes the ray does not cross)
    float t = 0.f, tMax = 0.f;
    bool done = false;
};

/// Calls f(t0, t1) for each maximal run of consecutive non-empty cells along the ray within
/// [tMin, tMax], in order; f returns false to stop. The non-empty intervals of a merging
/// RayIntervalIterator, bit for bit, without the value ranges (the ray caster's fast path).
/// Long empty stretches are crossed in jumps over the skip-distance cubes, so the cost grows with
/// the number of runs rather than with the number of cells crossed. The runs cover every non-empty
/// cell the ray crosses; their ends can differ from RayIntervalIterator's by float rounding of the
/// jumped-over boundaries (they lie in empty cells, which contribute nothing).
///
/// With `maxRunCells` > 0 a run is handed over in pieces of at most that many cells, back to back
/// (each piece starts exactly where the previous one ended). A ray marcher wants this: it can stop
/// (early ray termination) only when it is handed an interval, and a ray that enters a large opaque
/// object would otherwise cross all of its cells before the first sample is taken.
template <class F>
inline void forEachNonEmptyRun(const BrickMajorants& majorants, const glm::vec3& originIndex,
                               const glm::vec3& directionIndex, float tMin, float tMax, F&& f,
                               int maxRunCells = 0) {
    CellDda dda(majorants, originIndex, directionIndex, tMin, tMax);
    const std::uint8_t* dist = majorants.skipDistances();
    float t0, t1, runT0 = 0.f, runT1 = 0.f;
    std::size_t i;
    bool inRun = false;
    // Cells until the current piece is handed over (never reaches 0 without a limit).
    int cellsLeft = maxRunCells > 0 ? maxRunCells : -1;
    while (dda.step(t0, t1, i)) {
        const int d = dist[i];
        if (d == 0) {
            if (!inRun) runT0 = t0, inRun = true;
            runT1 = t1;
            if (--cellsLeft == 0) {
                inRun = false;
                cellsLeft = maxRunCells;
                if (!f(runT0, runT1)) return;
            }
            continue;
        }
        if (inRun) {
            inRun = false;
            if (maxRunCells > 0) cellsLeft = maxRunCells;
            if (!f(runT0, runT1)) return;
        }
        // The cell just returned is the centre of an empty cube of radius d − 1; the DDA already
        // stands in its neighbour, the centre of an empty cube of radius d − 2.
        if (d >= 3) dda.jump(d - 2);
    }
    if (inRun) f(runT0, runT1);
}

/// Calls f(t0, t1, cellIndex) for every cell along the ray within [tMin, tMax], in order (no
/// merging); f returns false to stop.
template <class F>
inline void forEachCell(const BrickMajorants& majorants, const glm::vec3& originIndex,
                        const glm::vec3& directionIndex, float tMin, float tMax, F&& f) {
    CellDda dda(majorants, originIndex, directionIndex, tMin, tMax);
    float t0, t1;
    std::size_t i;
    while (dda.step(t0, t1, i))
        if (!f(t0, t1, i)) return;
}

/// DDA over the bricks a ray crosses within [tMin, tMax], merging runs of the same kind.
class RayIntervalIterator {
  public:
    /// `mergeNonEmpty` false yields one interval per non-empty brick (tighter majorants for
    /// delta tracking); empty runs are always merged.
    RayIntervalIterator(const BrickMajorants& majorants, const glm::vec3& originIndex,
                        const glm::vec3& directionIndex, float tMin, float tMax,
                        bool mergeNonEmpty = true);
    /// Next interval, in increasing t; false when the ray has left [tMin, tMax].
    bool next(RayInterval& out);

  private:
    const BrickMajorants* m_;
    CellDda dda_;
    bool merge_ = true;
    bool havePending_ = false;
    RayInterval pending_;
};

}  // namespace voxlight::grid
