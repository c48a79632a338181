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
    const core::Geometry& geo = caster.volume().geometry();
    const int W = camera.width(), H = camera.height();
    mask_.assign(std::size_t(W) * std::size_t(H), 0);
    const glm::ivec3 n = m.counts();
    const double size = m.cellSize();
    for (int cz = 0; cz < n.z; ++cz)
        for (int cy = 0; cy < n.y; ++cy)
            for (int cx = 0; cx < n.x; ++cx) {
                if (!(m.majorant(m.index(cx, cy, cz)) > 0.f)) continue;
                const int cx0 = cx;
                while (cx + 1 < n.x && m.majorant(m.index(cx + 1, cy, cz)) > 0.f) ++cx;
                // The run's index box (cell edges as the DDA places them).
                const glm::dvec3 lo(cx0 * size, cy * size, cz * size);
                const glm::dvec3 hi((cx + 1) * size, (cy + 1) * size, (cz + 1) * size);
                double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
                for (int c = 0; c < 8; ++c) {
                    const glm::dvec3 ijk(c & 1 ? hi.x : lo.x, c & 2 ? hi.y : lo.y,
                                         c & 4 ? hi.z : lo.z);
                    double px, py;
                    if (!camera.project(geo.indexToWorld(ijk), px, py) || !std::isfinite(px) ||
                        !std::isfinite(py)) {
                        coverAll();
                        return;
                    }
                    x0 = std::min(x0, px), x1 = std::max(x1, px);
                    y0 = std::min(y0, py), y1 = std::max(y1, py);
                }
                // Pixel centres sit at integers; clamp before converting (far-off boxes).
                const double lim = double(std::max(W, H)) + 2.0 * kFootprintMarginPixels;
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
