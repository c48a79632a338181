// SPDX-License-Identifier: MIT
#include "render/footprint.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "render/camera.h"
#include "render/ray_caster.h"

namespace voxlight::render {

PixelFootprint::PixelFootprint(const RayCaster& caster, const Camera& camera)
    : width_(camera.width()), height_(camera.height()), map_(camera.projectiveMap()) {
    if (!caster.options().emptySpaceSkipping || !caster.options().pixelFootprint) {
        coverAll();
        return;
    }
    const grid::BrickMajorants& m = caster.majorants();
    const int W = camera.width(), H = camera.height();
    mask_.assign(std::size_t(W) * std::size_t(H), 0);
    // The camera's projective map composed with index → world (origin + D·(ijk ⊙ spacing)), so
    // that a box corner costs three multiply-adds per coordinate.
    const core::Geometry& geo = caster.volume().geometry();
    const Camera::ProjectiveMap& pm = map_;
    auto inIndex = [&](const glm::dvec3& row, double c, glm::dvec3& out, double& out0) {
        out = (glm::transpose(geo.direction) * row) * geo.spacing;
        out0 = glm::dot(row, geo.origin) + c;
    };
    glm::dvec3 ax, ay, aw;
    double ax0, ay0, aw0;
    inIndex(pm.x, pm.x0, ax, ax0);
    inIndex(pm.y, pm.y0, ay, ay0);
    inIndex(pm.w, pm.w0, aw, aw0);
    const glm::ivec3 n = m.counts();
    const double size = m.cellSize();
    const std::array<glm::dvec3, 2> box = caster.volumeIndexBox();
    // Pixel centres sit at integers; coordinates are clamped before converting (far-off boxes).
    const double lim = double(std::max(W, H)) + 2.0 * kFootprintMarginPixels;
    for (int cz = 0; cz < n.z; ++cz)
        for (int cy = 0; cy < n.y; ++cy)
            for (int cx = 0; cx < n.x; ++cx) {
                if (!(m.majorant(m.index(cx, cy, cz)) > 0.f)) continue;
                const int cx0 = cx;
                while (cx + 1 < n.x && m.majorant(m.index(cx + 1, cy, cz)) > 0.f) ++cx;
                // The run's index box (cell edges as the DDA places them); at the grid's edge out
                // to the volume box, whose points the DDA clamps into the edge cell.
                const glm::ivec3 c0(cx0, cy, cz), c1(cx, cy, cz);
                glm::dvec3 lo, hi;
                for (int a = 0; a < 3; ++a) {
                    lo[a] = c0[a] * size;
                    hi[a] = (c1[a] + 1) * size;
                    if (c0[a] == 0) lo[a] = std::min(lo[a], box[0][a]);
                    if (c1[a] == n[a] - 1) hi[a] = std::max(hi[a], box[1][a]);
                }
                const glm::dvec3 ext = hi - lo;
                const glm::dvec3 X(glm::dot(ax, lo) + ax0, ax.y * ext.y, ax.z * ext.z);
                const glm::dvec3 Y(glm::dot(ay, lo) + ay0, ay.y * ext.y, ay.z * ext.z);
                const glm::dvec3 Wc(glm::dot(aw, lo) + aw0, aw.y * ext.y, aw.z * ext.z);
                const double dX = ax.x * ext.x, dY = ay.x * ext.x, dW = aw.x * ext.x;
                double w[8];
                int inFront = 0;
                for (int c = 0; c < 8; ++c) {
                    w[c] = Wc[0] + (c & 1) * dW + ((c >> 1) & 1) * Wc[1] + ((c >> 2) & 1) * Wc[2];
                    inFront += w[c] > 0.0 ? 1 : 0;
                }
                // Wholly behind a perspective eye: no ray gets there (rays start at the eye).
                if (inFront == 0 && std::isfinite(w[0])) continue;
                if (inFront < 8) {  // straddles the eye's plane (or NaN): unbounded projection
                    coverAll();
                    return;
                }
                double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
                for (int c = 0; c < 8; ++c) {
                    const double fx = c & 1, fy = (c >> 1) & 1, fz = (c >> 2) & 1;
                    const double px = (X[0] + fx * dX + fy * X[1] + fz * X[2]) / w[c];
                    const double py = (Y[0] + fx * dY + fy * Y[1] + fz * Y[2]) / w[c];
                    if (!std::isfinite(px) || !std::isfinite(py)) {
                        coverAll();
                        return;
                    }
                    x0 = std::min(x0, px), x1 = std::max(x1, px);
                    y0 = std::min(y0, py), y1 = std::max(y1, py);
                }
                // Clamped to the image (plus margin) before converting to int.
                const int ix0 = int(std::floor(std::clamp(x0, -lim, lim))) - kFootprintMarginPixels;
                const int ix1 = int(std::ceil(std::clamp(x1, -lim, lim))) + kFootprintMarginPixels;
                const int iy0 = int(std::floor(std::clamp(y0, -lim, lim))) - kFootprintMarginPixels;
                const int iy1 = int(std::ceil(std::clamp(y1, -lim, lim))) + kFootprintMarginPixels;
                if (ix1 < 0 || iy1 < 0 || ix0 > W - 1 || iy0 > H - 1) continue;  // off the image
                const int fx0 = std::max(ix0, 0), fx1 = std::min(ix1, W - 1);
                const int fy0 = std::max(iy0, 0), fy1 = std::min(iy1, H - 1);
                for (int y = fy0; y <= fy1; ++y)
                    std::memset(mask_.data() + std::size_t(y) * std::size_t(W) + std::size_t(fx0),
                                1, std::size_t(fx1 - fx0 + 1));
            }
}

bool PixelFootprint::builtFor(const Camera& c) const {
    // The mask depends on the camera through its projective map and image size only.
    const Camera::ProjectiveMap m = c.projectiveMap();
    return c.width() == width_ && c.height() == height_ && m.x == map_.x && m.y == map_.y &&
           m.w == map_.w && m.x0 == map_.x0 && m.y0 == map_.y0 && m.w0 == map_.w0;
}

double PixelFootprint::coveredFraction() const {
    if (all_) return 1.0;
    if (mask_.empty()) return 0.0;
    return double(std::count(mask_.begin(), mask_.end(), std::uint8_t(1))) / double(mask_.size());
}

}  // namespace voxlight::render
