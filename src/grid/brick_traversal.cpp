// SPDX-License-Identifier: MIT
#include "grid/brick_traversal.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace voxlight::grid {

void BrickMajorants::finish() {
    const std::size_t n = majorant_.size();
    flags_.resize(n);
    nonEmpty_ = 0;
    for (std::size_t i = 0; i < n; ++i) {
        flags_[i] = majorant_[i] > 0.f ? 1 : 0;
        nonEmpty_ += flags_[i];
    }
    nonEmptyRange_ = {glm::ivec3(0), glm::ivec3(-1)};
    distance_ = chebyshevDistances(counts_, flags_.data(), kMaxSkipDistance);
    if (nonEmpty_ == 0) return;
    nonEmptyRange_ = {counts_, glm::ivec3(-1)};
    for (std::size_t i = 0; i < n; ++i)
        if (flags_[i]) {
            const glm::ivec3 p(int(i % std::size_t(counts_.x)),
                               int((i / std::size_t(counts_.x)) % std::size_t(counts_.y)),
                               int(i / (std::size_t(counts_.x) * std::size_t(counts_.y))));
            nonEmptyRange_[0] = glm::min(nonEmptyRange_[0], p);
            nonEmptyRange_[1] = glm::max(nonEmptyRange_[1], p);
        }
}

std::vector<std::uint8_t> chebyshevDistances(const glm::ivec3& c, const std::uint8_t* flags,
                                             int cap) {
    VL_CHECK(cap >= 1 && cap <= 255);
    const std::size_t n = std::size_t(c.x) * std::size_t(c.y) * std::size_t(c.z);
    VL_CHECK(n <= std::numeric_limits<std::uint32_t>::max());  // the fronts' indices
    std::vector<std::uint8_t> distance(n, std::uint8_t(cap));
    std::vector<std::uint32_t> front, next;
    for (std::size_t i = 0; i < n; ++i)
        if (flags[i]) {
            distance[i] = 0;
            front.push_back(std::uint32_t(i));
        }
    const auto index = [&](int u, int v, int w) {
        return std::size_t(u) +
               std::size_t(c.x) * (std::size_t(v) + std::size_t(c.y) * std::size_t(w));
    };
    for (int level = 1; level < cap && !front.empty(); ++level) {
        next.clear();
        for (const std::uint32_t i : front) {
            const int x = int(i % std::uint32_t(c.x)),
                      y = int((i / std::uint32_t(c.x)) % std::uint32_t(c.y));
            const int z = int(i / (std::uint32_t(c.x) * std::uint32_t(c.y)));
            for (int dz = -1; dz <= 1; ++dz)
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int u = x + dx, v = y + dy, w = z + dz;
                        if (u < 0 || v < 0 || w < 0 || u >= c.x || v >= c.y || w >= c.z) continue;
                        const std::size_t j = index(u, v, w);
                        if (distance[j] != cap) continue;
                        distance[j] = std::uint8_t(level);
                        next.push_back(std::uint32_t(j));
                    }
        }
        front.swap(next);
    }
    return distance;
}

CellDda::CellDda(const BrickMajorants& majorants, const glm::vec3& originIndex,
                 const glm::vec3& directionIndex, float tMin, float tMax)
    : t(tMin), tMax(tMax) {
    const glm::ivec3 counts = majorants.counts();
    done = !(tMax > tMin) || majorants.size() == 0;
    if (done) return;
    const glm::vec3 p = originIndex + tMin * directionIndex;
    const int size = majorants.cellSize();
    const float kInf = std::numeric_limits<float>::infinity();
    const std::ptrdiff_t stride[3] = {1, std::ptrdiff_t(counts.x),
                                      std::ptrdiff_t(counts.x) * std::ptrdiff_t(counts.y)};
    glm::ivec3 cell;
    for (int a = 0; a < 3; ++a) {
        const int n = counts[a];
        int c = int(std::floor(p[a] / float(size)));
        c = std::clamp(c, 0, n - 1);
        cell[a] = c;
        const float d = directionIndex[a];
        if (d > 0.f) {
            indexStep[a] = stride[a];
            left[a] = n - 1 - c;
            tNext[a] = tMin + (float(size * (c + 1)) - p[a]) / d;
            tDelta[a] = float(size) / d;
            invDelta[a] = d / float(size);
        } else if (d < 0.f) {
            indexStep[a] = -stride[a];
            left[a] = c;
            tNext[a] = tMin + (float(size * c) - p[a]) / d;
            tDelta[a] = -float(size) / d;
            invDelta[a] = -d / float(size);
        } else {
            indexStep[a] = 0;
            left[a] = std::numeric_limits<int>::max();
            tNext[a] = kInf;
            tDelta[a] = kInf;
        }
        // A position clamped into the edge cell from outside: its boundary may be "behind" us.
        if (tNext[a] < tMin) tNext[a] = tMin;
    }
    index = majorants.index(cell.x, cell.y, cell.z);
}

RayIntervalIterator::RayIntervalIterator(const BrickMajorants& majorants,
                                         const glm::vec3& originIndex,
                                         const glm::vec3& directionIndex, float tMin, float tMax,
                                         bool mergeNonEmpty)
    : m_(&majorants),
      dda_(majorants, originIndex, directionIndex, tMin, tMax),
      merge_(mergeNonEmpty) {}

bool RayIntervalIterator::next(RayInterval& out) {
    float t0, t1;
    std::size_t b;
    while (dda_.step(t0, t1, b)) {
        RayInterval cur;
        cur.t0 = t0;
        cur.t1 = t1;
        cur.valueMin = m_->valueRange(b)[0];
        cur.valueMax = m_->valueRange(b)[1];
        cur.maxExtinction = m_->majorant(b);
        if (!havePending_) {
            pending_ = cur;
            havePending_ = true;
            continue;
        }
        const bool sameKind = pending_.empty() == cur.empty();
        if (sameKind && (merge_ || cur.empty())) {
            pending_.t1 = cur.t1;
            pending_.valueMin = std::min(pending_.valueMin, cur.valueMin);
            pending_.valueMax = std::max(pending_.valueMax, cur.valueMax);
            pending_.maxExtinction = std::max(pending_.maxExtinction, cur.maxExtinction);
            continue;
        }
        out = pending_;
        pending_ = cur;
        return true;
    }
    if (havePending_) {
        out = pending_;
        havePending_ = false;
        return true;
    }
    return false;
}

}  // namespace voxlight::grid
