// SPDX-License-Identifier: MIT
#include "grid/brick_grid.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <limits>

namespace voxlight::grid {

std::array<glm::ivec3, 2> BrickGrid::ownedVoxels(int bx, int by, int bz) const {
    const glm::ivec3 first = glm::ivec3(bx, by, bz) * kBrickSize;
    return {first, glm::min(first + kBrickSize - 1, dims_ - 1)};
}

int BrickGrid::binOf(float value) const {
    if (!(hi_ > lo_)) return 0;
    const int b = int(std::floor((value - lo_) / (hi_ - lo_) * kHistogramBins));
    return std::clamp(b, 0, kHistogramBins - 1);
}

std::array<float, 2> BrickGrid::binRange(int b) const {
    const float w = (hi_ - lo_) / kHistogramBins;
    return {lo_ + w * b, lo_ + w * (b + 1)};
}

bool BrickGrid::fromParts(const glm::ivec3& dims, float valueLo, float valueHi,
                          std::vector<BrickStats> bricks, BrickGrid& out) {
    if (dims.x < 1 || dims.y < 1 || dims.z < 1 || dims.x > core::kMaxDim ||
        dims.y > core::kMaxDim || dims.z > core::kMaxDim)
        return false;
    const glm::ivec3 counts = (dims + kBrickSize - 1) / kBrickSize;
    if (bricks.size() != std::size_t(counts.x) * counts.y * counts.z) return false;
    out.dims_ = dims;
    out.counts_ = counts;
    out.lo_ = valueLo;
    out.hi_ = valueHi;
    out.bricks_ = std::move(bricks);
    return true;
}

BrickGrid BrickGrid::build(const core::Volume& volume, const core::Progress& progress) {
    BrickGrid g;
    g.dims_ = volume.dims();
    g.counts_ = (g.dims_ + kBrickSize - 1) / kBrickSize;
    const auto range = volume.physicalRange();
    g.lo_ = float(range[0]);
    g.hi_ = float(range[1]);
    g.bricks_.resize(std::size_t(g.counts_.x) * g.counts_.y * g.counts_.z);
    const int slabs = g.counts_.z;
    std::atomic<int> done{0};
    volume.visit([&](const auto& v) {
        tbb::parallel_for(0, slabs * g.counts_.y, [&](int row) {
            progress.checkCancel();
            const int bz = row / g.counts_.y, by = row % g.counts_.y;
            for (int bx = 0; bx < g.counts_.x; ++bx) {
                const auto [first, last] = g.ownedVoxels(bx, by, bz);
                const glm::ivec3 apron = glm::min(last + 1, g.dims_ - 1);
                BrickStats s;
                s.min = std::numeric_limits<float>::max();
                s.max = std::numeric_limits<float>::lowest();
                for (int k = first.z; k <= apron.z; ++k)
                    for (int j = first.y; j <= apron.y; ++j)
                        for (int i = first.x; i <= apron.x; ++i) {
                            const float x = v.at(i, j, k);
                            if (!std::isfinite(x)) continue;
                            s.min = std::min(s.min, x);
                            s.max = std::max(s.max, x);
                            if (i <= last.x && j <= last.y && k <= last.z)
                                ++s.histogram[g.binOf(x)];
                        }
                g.bricks_[std::size_t(bx) + std::size_t(g.counts_.x) *
                                                (std::size_t(by) + std::size_t(g.counts_.y) * bz)] =
                    s;
            }
            const int d = ++done;
            if (d % 64 == 0) progress.report("bricks", double(d) / (slabs * g.counts_.y));
        });
    });
    return g;
}

}  // namespace voxlight::grid
