// SPDX-License-Identifier: MIT
#include "grid/brick_traversal.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace voxlight::grid {

RayIntervalIterator::RayIntervalIterator(const BrickMajorants& majorants,
                                         const glm::vec3& originIndex,
                                         const glm::vec3& directionIndex, float tMin, float tMax,
                                         bool mergeNonEmpty)
    : m_(&majorants), t_(tMin), tMax_(tMax), merge_(mergeNonEmpty) {
    done_ = !(tMax > tMin) || majorants.size() == 0;
    if (done_) return;
    const glm::vec3 p = originIndex + tMin * directionIndex;
    const int size = majorants.cellSize();
    const float kInf = std::numeric_limits<float>::infinity();
    for (int a = 0; a < 3; ++a) {
        const int n = majorants.counts()[a];
        int c = int(std::floor(p[a] / float(size)));
        c = std::clamp(c, 0, n - 1);
        cell_[a] = c;
        const float d = directionIndex[a];
        if (d > 0.f) {
            step_[a] = 1;
            tNext_[a] = tMin + (float(size * (c + 1)) - p[a]) / d;
            tDelta_[a] = float(size) / d;
        } else if (d < 0.f) {
            step_[a] = -1;
            tNext_[a] = tMin + (float(size * c) - p[a]) / d;
            tDelta_[a] = -float(size) / d;
        } else {
            step_[a] = 0;
            tNext_[a] = kInf;
            tDelta_[a] = kInf;
        }
        // A position clamped into the edge brick from outside: its boundary may be "behind" us.
        if (tNext_[a] < tMin) tNext_[a] = tMin;
    }
}

bool RayIntervalIterator::stepBrick(float& t0, float& t1, std::size_t& brick) {
    if (done_) return false;
    const int a =
        tNext_.x <= tNext_.y ? (tNext_.x <= tNext_.z ? 0 : 2) : (tNext_.y <= tNext_.z ? 1 : 2);
    brick = m_->index(cell_.x, cell_.y, cell_.z);
    t0 = t_;
    t1 = std::min(tNext_[a], tMax_);
    t_ = t1;
    if (t1 >= tMax_) {
        done_ = true;
    } else {
        cell_[a] += step_[a];
        tNext_[a] += tDelta_[a];
        if (cell_[a] < 0 || cell_[a] >= m_->counts()[a]) done_ = true;
        if (done_) t1 = tMax_;  // leaving the grid: the rest of the ray is in the edge brick
        t_ = t1;
    }
    return true;
}

bool RayIntervalIterator::next(RayInterval& out) {
    float t0, t1;
    std::size_t b;
    while (stepBrick(t0, t1, b)) {
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
