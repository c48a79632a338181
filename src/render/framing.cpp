// SPDX-License-Identifier: MIT
#include "render/framing.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

namespace voxlight::render {

namespace {

/// The 26 directions to the neighbours of a voxel (components −1, 0, 1, not all 0).
const std::array<glm::ivec3, 26> kDirections = [] {
    std::array<glm::ivec3, 26> d;
    int n = 0;
    for (int z = -1; z <= 1; ++z)
        for (int y = -1; y <= 1; ++y)
            for (int x = -1; x <= 1; ++x)
                if (x || y || z) d[n++] = glm::ivec3(x, y, z);
    return d;
}();

/// A kept-side test with a tolerance of a millionth of a millimetre (points computed on a plane).
constexpr double kOnPlane = 1e-6;

struct HalfSpace {
    glm::dvec3 point, normal;
    double side(const glm::dvec3& x) const { return glm::dot(x - point, normal); }
};

bool keptByAll(const std::vector<HalfSpace>& keep, const glm::dvec3& p) {
    for (const HalfSpace& h : keep)
        if (h.side(p) < -kOnPlane) return false;
    return true;
}

/// World corners of the index box [lo, hi].
std::array<glm::dvec3, 8> worldCorners(const core::Geometry& g, const glm::dvec3& lo,
                                       const glm::dvec3& hi) {
    std::array<glm::dvec3, 8> w;
    for (int c = 0; c < 8; ++c)
        w[c] = g.indexToWorld(
            glm::dvec3((c & 1) ? hi.x : lo.x, (c & 2) ? hi.y : lo.y, (c & 4) ? hi.z : lo.z));
    return w;
}

}  // namespace

std::vector<glm::dvec3> visibleHullPoints(const core::Volume& volume,
                                          const grid::BrickMajorants& cells,
                                          const VoxelShows& shows,
                                          std::span<const ClipPlane> planes,
                                          const std::optional<CropBox>& crop) {
    const core::Geometry& g = volume.geometry();
    std::vector<HalfSpace> keep;
    for (const ClipPlane& p : planes) keep.push_back({p.point, p.normal});
    if (crop)
        for (int a = 0; a < 3; ++a) {
            glm::dvec3 n(0.0);
            n[a] = 1.0;
            keep.push_back({crop->min, n});
            keep.push_back({crop->max, -n});
        }
    const glm::ivec3 counts = cells.counts();
    const int size = cells.cellSize();
    const glm::ivec3 last = glm::max(g.dims - 1, 0);
    auto cellLo = [&](const glm::ivec3& c) { return glm::min(c * size, last); };
    auto cellHi = [&](const glm::ivec3& c) { return glm::min((c + 1) * size, last); };
    // Per cell: 2 = shows and is wholly kept, 1 = shows and is cut or removed, 0 = empty.
    std::vector<std::uint8_t> state(cells.size(), 0);
    const std::uint8_t* nonEmpty = cells.nonEmptyFlags();
    for (int z = 0; z < counts.z; ++z)
        for (int y = 0; y < counts.y; ++y)
            for (int x = 0; x < counts.x; ++x) {
                const std::size_t i = cells.index(x, y, z);
                if (!nonEmpty[i]) continue;
                const glm::ivec3 c(x, y, z);
                bool whole = true;
                for (const glm::dvec3& w :
                     worldCorners(g, glm::dvec3(cellLo(c)), glm::dvec3(cellHi(c))))
                    whole = whole && keptByAll(keep, w);
                state[i] = whole ? 2 : 1;
            }
    std::vector<glm::dvec3> out;
    for (int z = 0; z < counts.z; ++z)
        for (int y = 0; y < counts.y; ++y)
            for (int x = 0; x < counts.x; ++x) {
                const std::size_t i = cells.index(x, y, z);
                if (state[i] == 0) continue;
                // Inside the non-empty set, wholly kept and among wholly kept neighbours: its
                // points are never on the hull.
                bool edge = state[i] != 2;
                for (int n = 0; n < 27 && !edge; ++n) {
                    const glm::ivec3 q(x + n % 3 - 1, y + (n / 3) % 3 - 1, z + n / 9 - 1);
                    edge = glm::any(glm::lessThan(q, glm::ivec3(0))) ||
                           glm::any(glm::greaterThanEqual(q, counts)) ||
                           state[cells.index(q.x, q.y, q.z)] != 2;
                }
                if (!edge) continue;
                const glm::ivec3 c(x, y, z);
                glm::ivec3 lo = cellLo(c), hi = cellHi(c);
                if (shows) {
                    // The showing voxels farthest out along each of the 26 cube directions, moved
                    // half a voxel further (where, on average, the value crosses the TF's edge
                    // towards a neighbour that does not show): a hull within about half a voxel
                    // of the matter, where the cell's box would overshoot by up to a cell.
                    std::array<double, 26> best;
                    std::array<glm::ivec3, 26> at;
                    best.fill(-INFINITY);
                    glm::ivec3 vlo(INT32_MAX), vhi(INT32_MIN);
                    const glm::ivec3 end = glm::min((c + 1) * size, g.dims);
                    for (int k = c.z * size; k < end.z; ++k)
                        for (int j = c.y * size; j < end.y; ++j)
                            for (int ii = c.x * size; ii < end.x; ++ii) {
                                if (!shows(volume.at(ii, j, k))) continue;
                                const glm::ivec3 v(ii, j, k);
                                vlo = glm::min(vlo, v), vhi = glm::max(vhi, v);
                                for (int d = 0; d < 26; ++d) {
                                    const double s =
                                        glm::dot(glm::dvec3(kDirections[d]), glm::dvec3(v));
                                    if (s > best[d]) best[d] = s, at[d] = v;
                                }
                            }
                    if (vlo.x > vhi.x) continue;  // non-empty only through its apron
                    if (state[i] == 2) {
                        for (int d = 0; d < 26; ++d) {
                            const glm::dvec3 p = g.indexToWorld(glm::dvec3(at[d]) +
                                                                0.5 * glm::dvec3(kDirections[d]));
                            out.push_back(p);
                        }
                        continue;
                    }
                    lo = glm::max(vlo - 1, 0);
                    hi = glm::min(vhi + 1, last);
                }
                const auto w = worldCorners(g, glm::dvec3(lo), glm::dvec3(hi));
                for (const glm::dvec3& p : w)
                    if (keptByAll(keep, p)) out.push_back(p);
                if (state[i] == 2) continue;
                // Cut by a plane: where the box's edges cross one, on the kept side of all.
                for (int a = 0; a < 8; ++a)
                    for (int bit = 1; bit < 8; bit <<= 1) {
                        if (a & bit) continue;
                        const glm::dvec3 &p = w[a], &q = w[a | bit];
                        for (const HalfSpace& h : keep) {
                            const double sp = h.side(p), sq = h.side(q);
                            if ((sp < 0.0) != (sq < 0.0)) {
                                const glm::dvec3 x = p + (q - p) * (sp / (sp - sq));
                                if (keptByAll(keep, x)) out.push_back(x);
                            }
                        }
                    }
            }
    return out;
}

std::vector<glm::dvec3> framingPoints(const core::Volume& volume, const grid::BrickMajorants& cells,
                                      const VoxelShows& shows, std::span<const ClipPlane> planes,
                                      const std::optional<CropBox>& crop) {
    std::vector<glm::dvec3> p = visibleHullPoints(volume, cells, shows, planes, crop);
    if (!p.empty()) return p;
    const auto b = volume.geometry().worldBounds();
    for (int c = 0; c < 8; ++c)
        p.emplace_back((c & 1) ? b[1].x : b[0].x, (c & 2) ? b[1].y : b[0].y,
                       (c & 4) ? b[1].z : b[0].z);
    return p;
}

}  // namespace voxlight::render
