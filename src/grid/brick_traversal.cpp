// SPDX-License-Identifier: MIT
#include "grid/brick_traversal.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace voxlight::grid {

CellDda::CellDda(const BrickMajorants& majorants, const glm::vec3& originIndex,
                 const glm::vec3& directionIndex, float tMin, float tMax)
    : counts(majorants.counts()), t(tMin), tMax(tMax) {
    done = !(tMax > tMin) || majorants.size() == 0;
    if (done) return;
    const glm::vec3 p = originIndex + tMin * directionIndex;
    const int size = majorants.cellSize();
    const float kInf = std::numeric_limits<float>::infinity();
    const std::ptrdiff_t stride[3] = {1, std::ptrdiff_t(counts.x),
                                      std::ptrdiff_t(counts.x) * std::ptrdiff_t(counts.y)};
    for (int a = 0; a < 3; ++a) {
        const int n = counts[a];
        int c = int(std::floor(p[a] / float(size)));
        c = std::clamp(c, 0, n - 1);
        cell[a] = c;
        const float d = directionIndex[a];
        if (d > 0.f) {
            stepDir[a] = 1;
            tNext[a] = tMin + (float(size * (c + 1)) - p[a]) / d;
            tDelta[a] = float(size) / d;
        } else if (d < 0.f) {
            stepDir[a] = -1;
            tNext[a] = tMin + (float(size * c) - p[a]) / d;
            tDelta[a] = -float(size) / d;
        } else {
            stepDir[a] = 0;
            tNext[a] = kInf;
            tDelta[a] = kInf;
        }
        indexStep[a] = stepDir[a] * stride[a];
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
