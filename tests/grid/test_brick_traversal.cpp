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
            if (!first) EXPECT_NE(prevEmpty, iv.empty()) << "runs of one kind are merged";
            // Every point strictly inside the interval lies in a brick of the interval's kind.
            for (float f = 0.05f; f < 1.f; f += 0.1f) {
                const float tt = iv.t0 + f * (iv.t1 - iv.t0);
                const glm::ivec3 b = glm::clamp(glm::ivec3(glm::floor((o + tt * d) / 16.f)),
                                                glm::ivec3(0), m.counts() - 1);
                const std::size_t i = m.index(b.x, b.y, b.z);
                if (std::abs(tt - iv.t0) > kTTol && std::abs(tt - iv.t1) > kTTol)
                    EXPECT_EQ(m.majorant(i) > 0.f, !iv.empty()) << "ray " << n << " t " << tt;
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
