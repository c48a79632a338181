// SPDX-License-Identifier: MIT
#include "render/footprint.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "render/camera.h"
#include "render/ray_caster.h"

namespace voxlight::render {

PixelFootprint::PixelFootprint(const RayCaster& caster, const Camera& camera)
    : width_(camera.width()) {
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
    const Camera::ProjectiveMap pm = camera.projectiveMap();
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
    // Pixel centres sit at integers; coordinates are clamped before converting (far-off boxes).
    const double lim = double(std::max(W, H)) + 2.0 * kFootprintMarginPixels;
    for (int cz = 0; cz < n.z; ++cz)
        for (int cy = 0; cy < n.y; ++cy)
            for (int cx = 0; cx < n.x; ++cx) {
                if (!(m.majorant(m.index(cx, cy, cz)) > 0.f)) continue;
                const int cx0 = cx;
                while (cx + 1 < n.x && m.majorant(m.index(cx + 1, cy, cz)) > 0.f) ++cx;
                // The run's index box (cell edges as the DDA places them).
                const glm::dvec3 lo(cx0 * size, cy * size, cz * size);
                const glm::dvec3 ext((cx + 1 - cx0) * size, size, size);
                const glm::dvec3 X(glm::dot(ax, lo) + ax0, ax.y * ext.y, ax.z * ext.z);
                const glm::dvec3 Y(glm::dot(ay, lo) + ay0, ay.y * ext.y, ay.z * ext.z);
                const glm::dvec3 Wc(glm::dot(aw, lo) + aw0, aw.y * ext.y, aw.z * ext.z);
                const double dX = ax.x * ext.x, dY = ay.x * ext.x, dW = aw.x * ext.x;
                double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
                for (int c = 0; c < 8; ++c) {
                    const double fx = c & 1, fy = (c >> 1) & 1, fz = (c >> 2) & 1;
                    const double w = Wc[0] + fx * dW + fy * Wc[1] + fz * Wc[2];
                    if (!(w > 0.0)) {  // not in front of the camera: unbounded projection
                        coverAll();
                        return;
                    }
                    const double px = (X[0] + fx * dX + fy * X[1] + fz * X[2]) / w;
                    const double py = (Y[0] + fx * dY + fy * Y[1] + fz * Y[2]) / w;
                    x0 = std::min(x0, px), x1 = std::max(x1, px);
                    y0 = std::min(y0, py), y1 = std::max(y1, py);
                }
                if (!(x0 <= x1 && y0 <= y1)) {  // NaN
                    coverAll();
                    return;
                }
                const int ix0 =
                    std::max(0, int(std::floor(std::max(x0, -lim))) - kFootprintMarginPixels);
                const int ix1 =
                    std::min(W - 1, int(std::ceil(std::min(x1, lim))) + kFootprintMarginPixels);
                const int iy0 =
                    std::max(0, int(std::floor(std::max(y0, -lim))) - kFootprintMarginPixels);
                const int iy1 =
                    std::min(H - 1, int(std::ceil(std::min(y1, lim))) + kFootprintMarginPixels);
                if (ix0 > ix1) continue;
                for (int y = iy0; y <= iy1; ++y)
                    std::memset(mask_.data() + std::size_t(y) * std::size_t(W) + std::size_t(ix0),
                                1, std::size_t(ix1 - ix0 + 1));
            }
}

double PixelFootprint::coveredFraction() const {
    if (all_) return 1.0;
    if (mask_.empty()) return 0.0;
    return double(std::count(mask_.begin(), mask_.end(), std::uint8_t(1))) / double(mask_.size());
}

}  // namespace voxlight::render
