// SPDX-License-Identifier: MIT
#include "pvrt/transfer.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <span>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::pvrt {

void scaledSh(int n, const glm::dvec3& unitDir, double* out) {
    VL_CHECK(validExitance(n));
    const int band = sh::shBandForCount(n);
    sh::evalShUnitDouble(band, unitDir, std::span<double>(out, std::size_t(n)));
    const double s = std::sqrt(4.0 * std::numbers::pi);
    for (int j = 1; j < n; ++j) out[j] *= s;
    out[0] = 1.0;  // exactly (√(4π)·Y_0 may round off it): n = 1 stays today's arithmetic
}

void exitanceWeights(int n, float g, const glm::vec3& toEye, float* w) {
    VL_CHECK(validExitance(n));
    double y[kMaxExitance];
    scaledSh(n, -glm::dvec3(toEye), y);
    double gl = 1.0;  // g^l, band by band
    for (int l = 0, j = 0; j < n; ++l, gl *= double(g))
        for (int m = -l; m <= l; ++m, ++j) w[j] = float(gl * y[j]);
}

std::vector<glm::ivec3> TransferLayout::storedPoints() const {
    std::vector<glm::ivec3> out(std::size_t(std::max(points, 0)));
    for (int z = 0; z < res.z; ++z)
        for (int y = 0; y < res.y; ++y)
            for (int x = 0; x < res.x; ++x) {
                const std::int32_t s = slot[linear({x, y, z})];
                if (s >= 0) out[std::size_t(s)] = {x, y, z};
            }
    return out;
}

TransferLayout makeTransferLayout(const core::Volume& volume, const grid::BrickMajorants& cells,
                                  int resolution) {
    if (resolution < 1)
        throw InputError(
            "pvrt", "method.params.resolution",
            "must be at least 1 point per axis (got " + std::to_string(resolution) + ")",
            "use e.g. 64 (points per axis, capped at the volume's size)");
    const glm::ivec3 dims = volume.dims();
    TransferLayout l;
    l.res = glm::min(glm::ivec3(resolution), dims);
    l.scale = glm::vec3(dims) / glm::vec3(l.res);
    l.slot.assign(std::size_t(l.res.x) * l.res.y * l.res.z, -1);
    const int cs = cells.cellSize();
    const glm::ivec3 counts = cells.counts();
    const std::uint8_t* flags = cells.nonEmptyFlags();
    // Per axis, the range of cells the support of grid point g overlaps (the same for every point
    // with that coordinate).
    std::array<std::vector<glm::ivec2>, 3> cellRange;
    for (int a = 0; a < 3; ++a) {
        cellRange[a].resize(std::size_t(l.res[a]));
        for (int g = 0; g < l.res[a]; ++g) {
            const float lo = std::max(0.f, (float(g) - 0.5f) * l.scale[a] - 0.5f - 1.f);
            const float hi =
                std::min(float(dims[a] - 1), (float(g) + 1.5f) * l.scale[a] - 0.5f + 1.f);
            const int c0 = std::clamp(int(std::floor(lo)) / cs, 0, counts[a] - 1);
            const int c1 = std::clamp(int(std::floor(hi)) / cs, 0, counts[a] - 1);
            cellRange[a][std::size_t(g)] = {c0, c1};
        }
    }
    std::int32_t next = 0;
    for (int z = 0; z < l.res.z; ++z)
        for (int y = 0; y < l.res.y; ++y)
            for (int x = 0; x < l.res.x; ++x) {
                const glm::ivec2 rx = cellRange[0][std::size_t(x)];
                const glm::ivec2 ry = cellRange[1][std::size_t(y)];
                const glm::ivec2 rz = cellRange[2][std::size_t(z)];
                bool visible = false;
                for (int cz = rz.x; cz <= rz.y && !visible; ++cz)
                    for (int cy = ry.x; cy <= ry.y && !visible; ++cy)
                        for (int cx = rx.x; cx <= rx.y && !visible; ++cx)
                            visible = flags[cells.index(cx, cy, cz)] != 0;
                if (visible) l.slot[l.linear({x, y, z})] = next++;
            }
    l.points = next;
    return l;
}

}  // namespace voxlight::pvrt
