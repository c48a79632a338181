// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <numeric>

#include "core/phantoms.h"
#include "grid/brick_grid.h"

using namespace voxlight;

TEST(BrickGrid, BoundsEveryTrilinearSampleAndCountsEachVoxelOnce) {
    core::PhantomOptions o;
    o.size = 40;  // not a multiple of 16: partial bricks at the high edge
    const core::Volume v = core::makePhantom("torso", o);
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    EXPECT_EQ(g.brickCounts(), glm::ivec3(3));
    std::uint64_t total = 0;
    for (const auto& b : g.bricks())
        total += std::accumulate(b.histogram.begin(), b.histogram.end(), 0ull);
    EXPECT_EQ(total, v.voxelCount());
    // Random samples: the value lies within the min/max of the brick owning the sample's cell.
    for (int n = 0; n < 2000; ++n) {
        const glm::dvec3 q(std::fmod(n * 0.618, 39.0), std::fmod(n * 0.414, 39.0),
                           std::fmod(n * 0.732, 39.0));
        const glm::ivec3 b = glm::ivec3(glm::floor(q)) / grid::kBrickSize;
        const auto& s = g.at(b.x, b.y, b.z);
        const float x = v.sampleIndex(q);
        EXPECT_GE(x, s.min - 1e-3f);
        EXPECT_LE(x, s.max + 1e-3f);
    }
}
