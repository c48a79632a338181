// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>

#include "core/phantoms.h"
#include "core/rng.h"
#include "grid/brick_traversal.h"

using namespace voxlight;

namespace {
// Interval ends are accumulated in float; a hundredth of a voxel is far below any sample spacing.
constexpr float kTTol = 1e-3f;
}  // namespace

TEST(RayIntervals, TileTheRayContiguouslyAndMatchBruteForceBrickLookup) {
    core::PhantomOptions o;
    o.size = 50;  // 4 bricks per axis, the last one partial
    const core::Volume v = core::makePhantom("torso", o);
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    // Non-empty = brick can hold bone (> 300 HU).
    const auto m =
        grid::BrickMajorants::build(g, [](float, float hi) { return hi > 300.f ? 1.f : 0.f; });
    ASSERT_GT(m.nonEmptyCount(), 0u);
    ASSERT_LT(m.nonEmptyCount(), m.size());
    core::CounterRng rng(7);
    for (int n = 0; n < 300; ++n) {
        const glm::vec3 o(rng.uniform() * 80 - 15, rng.uniform() * 80 - 15,
                          rng.uniform() * 80 - 15);
        glm::vec3 d(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
        if (n % 10 == 0) d = glm::vec3(0, 0, 1);  // axis-aligned: zero components
        d = glm::normalize(d);
        // Clip to the grid [0, 49] like the renderer does.
        float t0 = 0, t1 = 1e9f;
        bool miss = false;
        for (int a = 0; a < 3; ++a) {
            if (d[a] == 0) {
                miss |= o[a] < 0 || o[a] > 49;
                continue;
            }
            float u = (0 - o[a]) / d[a], w = (49 - o[a]) / d[a];
            if (u > w) std::swap(u, w);
            t0 = std::max(t0, u), t1 = std::min(t1, w);
        }
        if (miss || !(t1 > t0)) continue;
        grid::RayIntervalIterator it(m, o, d, t0, t1);
        grid::RayInterval iv;
        float t = t0;
        bool prevEmpty = false, first = true;
        while (it.next(iv)) {
            EXPECT_NEAR(iv.t0, t, kTTol);
            EXPECT_GE(iv.t1, iv.t0);
            if (!first) {
                EXPECT_NE(prevEmpty, iv.empty()) << "runs of one kind are merged";
            }
            // Every point strictly inside the interval lies in a brick of the interval's kind.
            for (float f = 0.05f; f < 1.f; f += 0.1f) {
                const float tt = iv.t0 + f * (iv.t1 - iv.t0);
                const glm::ivec3 b = glm::clamp(glm::ivec3(glm::floor((o + tt * d) / 16.f)),
                                                glm::ivec3(0), m.counts() - 1);
                const std::size_t i = m.index(b.x, b.y, b.z);
                if (std::abs(tt - iv.t0) > kTTol && std::abs(tt - iv.t1) > kTTol) {
                    EXPECT_EQ(m.majorant(i) > 0.f, !iv.empty()) << "ray " << n << " t " << tt;
                }
            }
            prevEmpty = iv.empty();
            first = false;
            t = iv.t1;
        }
        EXPECT_NEAR(t, t1, kTTol) << "ray " << n;
    }
}

TEST(RayIntervals, EmptyRangeYieldsNothing) {
    core::PhantomOptions o;
    o.size = 20;
    const core::Volume v = core::makePhantom("sphere", o);
    const auto m =
        grid::BrickMajorants::build(grid::BrickGrid::build(v), [](float, float) { return 1.f; });
    grid::RayIntervalIterator it(m, glm::vec3(1), glm::vec3(1, 0, 0), 5.f, 5.f);
    grid::RayInterval iv;
    EXPECT_FALSE(it.next(iv));
}

TEST(RayIntervals, FinerCellsFromCellsFollowTheirOwnCellSize) {
    // 4³ cells over a 10³ grid: cell c covers [4c, 4c + 4); only cell (1, 1, 1) is non-empty.
    const glm::ivec3 counts(3);
    std::vector<float> maj(27, 0.f);
    std::vector<std::array<float, 2>> ranges(27, {0.f, 0.f});
    maj[1 + 3 * (1 + 3 * 1)] = 2.f;
    const auto m = grid::BrickMajorants::fromCells(counts, 4, maj, ranges);
    EXPECT_EQ(m.cellSize(), 4);
    EXPECT_EQ(m.nonEmptyCount(), 1u);
    // A ray along x through y = z = 5 (cells y = z = 1): empty [0,4), full [4,8), empty [8,9].
    grid::RayIntervalIterator it(m, glm::vec3(0, 5, 5), glm::vec3(1, 0, 0), 0.f, 9.f);
    grid::RayInterval iv;
    ASSERT_TRUE(it.next(iv));
    EXPECT_TRUE(iv.empty());
    EXPECT_NEAR(iv.t1, 4.f, kTTol);
    ASSERT_TRUE(it.next(iv));
    EXPECT_FALSE(iv.empty());
    EXPECT_NEAR(iv.t0, 4.f, kTTol);
    EXPECT_NEAR(iv.t1, 8.f, kTTol);
    EXPECT_EQ(iv.maxExtinction, 2.f);
    ASSERT_TRUE(it.next(iv));
    EXPECT_TRUE(iv.empty());
    EXPECT_NEAR(iv.t1, 9.f, kTTol);
    EXPECT_FALSE(it.next(iv));
}

namespace {
/// Sparse random majorants on a 40×33×27 grid of 4³ cells (a few non-empty cells in clusters and
/// isolated, so that skip distances from 1 to > 10 occur).
grid::BrickMajorants sparseCells(std::uint64_t seed) {
    const glm::ivec3 counts(40, 33, 27);
    const std::size_t n = std::size_t(counts.x) * counts.y * counts.z;
    std::vector<float> maj(n, 0.f);
    std::vector<std::array<float, 2>> ranges(n, {0.f, 0.f});
    core::CounterRng rng(seed);
    for (int k = 0; k < 12; ++k) {
        const glm::ivec3 c(int(rng.uniform() * counts.x), int(rng.uniform() * counts.y),
                           int(rng.uniform() * counts.z));
        const int r = k % 3;  // single cells and small blocks
        for (int z = c.z - r; z <= c.z + r; ++z)
            for (int y = c.y - r; y <= c.y + r; ++y)
                for (int x = c.x - r; x <= c.x + r; ++x)
                    if (x >= 0 && y >= 0 && z >= 0 && x < counts.x && y < counts.y && z < counts.z)
                        maj[std::size_t(x) +
                            std::size_t(counts.x) * (y + std::size_t(counts.y) * z)] = 1.f;
    }
    return grid::BrickMajorants::fromCells(counts, 4, std::move(maj), std::move(ranges));
}
}  // namespace

TEST(SkipDistance, IsTheChebyshevDistanceToTheNearestNonEmptyCell) {
    const auto m = sparseCells(3);
    const glm::ivec3 c = m.counts();
    std::vector<glm::ivec3> full;
    for (int z = 0; z < c.z; ++z)
        for (int y = 0; y < c.y; ++y)
            for (int x = 0; x < c.x; ++x)
                if (m.nonEmptyFlags()[m.index(x, y, z)]) full.emplace_back(x, y, z);
    ASSERT_GT(full.size(), 0u);
    int maxSeen = 0;
    for (int z = 0; z < c.z; ++z)
        for (int y = 0; y < c.y; ++y)
            for (int x = 0; x < c.x; ++x) {
                int best = grid::BrickMajorants::kMaxSkipDistance;
                for (const glm::ivec3& f : full)
                    best = std::min(
                        best, std::max({std::abs(f.x - x), std::abs(f.y - y), std::abs(f.z - z)}));
                ASSERT_EQ(int(m.skipDistances()[m.index(x, y, z)]), best)
                    << x << " " << y << " " << z;
                maxSeen = std::max(maxSeen, best);
            }
    EXPECT_GT(maxSeen, 5) << "the grid should have long empty stretches to jump over";
}

TEST(SkipDistance, JumpingRunsCoverEveryNonEmptyCellAndNothingElse) {
    // forEachNonEmptyRun jumps over empty cubes; its runs must be exactly the non-empty intervals
    // of the cell-by-cell RayIntervalIterator (ends within float rounding).
    for (std::uint64_t seed = 1; seed <= 4; ++seed) {
        const auto m = sparseCells(seed);
        const glm::vec3 hi = glm::vec3(m.counts() * 4) - 1.f;
        core::CounterRng rng(100 + seed);
        int runsSeen = 0, pieces = 0, runsJoined = 0;
        for (int n = 0; n < 2000; ++n) {
            const glm::vec3 o(rng.uniform() * hi.x, rng.uniform() * hi.y, rng.uniform() * hi.z);
            glm::vec3 d(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
            if (n % 7 == 0) d.y = 0.f;
            if (n % 11 == 0) d = glm::vec3(0, 0, -1);
            d = glm::normalize(d);
            float t1 = 1e9f;  // exit of the box [0, hi]
            for (int a = 0; a < 3; ++a)
                if (d[a] != 0.f) t1 = std::min(t1, ((d[a] > 0 ? hi[a] : 0.f) - o[a]) / d[a]);
            std::vector<std::array<float, 2>> expect, got;
            grid::RayIntervalIterator it(m, o, d, 0.f, t1);
            grid::RayInterval iv;
            while (it.next(iv))
                if (!iv.empty()) expect.push_back({iv.t0, iv.t1});
            grid::forEachNonEmptyRun(m, o, d, 0.f, t1, [&](float a, float b) {
                got.push_back({a, b});
                return true;
            });
            ASSERT_EQ(got.size(), expect.size()) << "seed " << seed << " ray " << n;
            for (std::size_t i = 0; i < got.size(); ++i) {
                EXPECT_NEAR(got[i][0], expect[i][0], kTTol) << "seed " << seed << " ray " << n;
                EXPECT_NEAR(got[i][1], expect[i][1], kTTol) << "seed " << seed << " ray " << n;
            }
            runsSeen += int(got.size());
            // Handed over in pieces of at most k cells: the pieces join back to the same runs
            // exactly (each starts where the previous ended), and a piece stops the walk.
            for (int k : {1, 2, 3}) {
                std::vector<std::array<float, 2>> joined;
                grid::forEachNonEmptyRun(
                    m, o, d, 0.f, t1,
                    [&](float a, float b) {
                        ++pieces;
                        // k cells span at most k cell diagonals along the ray.
                        EXPECT_LE(b - a, float(k) * 4.f * std::sqrt(3.f) + kTTol);
                        if (!joined.empty() && joined.back()[1] == a)
                            joined.back()[1] = b;
                        else
                            joined.push_back({a, b});
                        return true;
                    },
                    k);
                runsJoined += int(joined.size());
                ASSERT_EQ(joined, got) << "pieces of " << k << ", seed " << seed << " ray " << n;
                int calls = 0;
                grid::forEachNonEmptyRun(
                    m, o, d, 0.f, t1, [&](float, float) { return ++calls < 2; }, k);
                EXPECT_LE(calls, 2);
            }
        }
        EXPECT_GT(runsSeen, 100) << "rays should hit non-empty cells";
        EXPECT_GT(pieces, runsJoined + 100) << "runs should be split into pieces";
    }
}

TEST(RayIntervals, NonEmptyCellRangeIsTheBoxOfTheNonEmptyCells) {
    const glm::ivec3 counts(7, 5, 6);
    const std::size_t n = std::size_t(counts.x) * counts.y * counts.z;
    std::vector<float> maj(n, 0.f);
    std::vector<std::array<float, 2>> ranges(n, {0.f, 0.f});
    auto at = [&](int x, int y, int z) { return std::size_t(x) + counts.x * (y + counts.y * z); };
    EXPECT_GT(grid::BrickMajorants::fromCells(counts, 4, maj, ranges).nonEmptyCellRange()[0].x,
              grid::BrickMajorants::fromCells(counts, 4, maj, ranges).nonEmptyCellRange()[1].x)
        << "empty: lo > hi";
    maj[at(2, 4, 1)] = 1.f;
    maj[at(5, 1, 3)] = 0.5f;
    const auto m = grid::BrickMajorants::fromCells(counts, 4, maj, ranges);
    EXPECT_EQ(m.nonEmptyCellRange()[0], glm::ivec3(2, 1, 1));
    EXPECT_EQ(m.nonEmptyCellRange()[1], glm::ivec3(5, 4, 3));
}
