// SPDX-License-Identifier: MIT
#include "render/sh_field_grid.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <glm/gtc/packing.hpp>
#include <thread>

#include "core/error.h"

namespace voxlight::render {

std::size_t ShFieldGrid::bytes() const {
    std::size_t n = 0;
    for (const auto& t : texels) n += t.size() * sizeof(std::uint16_t);
    return n;
}

float ShFieldGrid::at(const glm::ivec3& g, int i) const {
    const std::size_t p = std::size_t(g.x) + std::size_t(res.x) * (g.y + std::size_t(res.y) * g.z);
    return glm::unpackHalf1x16(texels[std::size_t(i / 4)][4 * p + std::size_t(i % 4)]);
}

glm::ivec3 shFieldGridResolution(const glm::ivec3& dims, int coefficients, std::size_t budgetBytes,
                                 int maxPerAxis) {
    VL_CHECK(dims.x > 0 && dims.y > 0 && dims.z > 0);
    VL_CHECK(coefficients >= 1 && coefficients <= 16);
    const double perPoint = double((coefficients + 3) / 4) * 4.0 * sizeof(std::uint16_t);
    const double maxPoints = double(budgetBytes) / perPoint;
    const auto count = [](const glm::ivec3& r) { return double(r.x) * r.y * r.z; };
    const glm::ivec3 fine = (dims - 1) * kShFieldGridOversample + 1;
    const bool fits =
        maxPerAxis <= 0 || (fine.x <= maxPerAxis && fine.y <= maxPerAxis && fine.z <= maxPerAxis);
    if (fits && count(fine) <= maxPoints) return fine;
    if (count(dims) <= maxPoints) return dims;
    double f = std::cbrt(maxPoints / count(dims));
    for (;;) {
        const glm::ivec3 r = glm::min(
            dims, glm::max(glm::ivec3(glm::floor(glm::dvec3(dims - 1) * f)) + 1, glm::ivec3(2)));
        if (count(r) <= maxPoints || f < 1e-6) return r;
        f *= 0.99;
    }
}

namespace {
template <class Field>
ShFieldGrid resample(const Field& field, const glm::ivec3& dims, std::size_t budgetBytes,
                     int maxPerAxis, const core::Progress& progress) {
    ShFieldGrid g;
    g.coefficients = field.coefficients();
    g.res = shFieldGridResolution(dims, g.coefficients, budgetBytes, maxPerAxis);
    const int textures = (g.coefficients + 3) / 4;
    const std::size_t points = std::size_t(g.res.x) * g.res.y * g.res.z;
    g.texels.assign(std::size_t(textures), std::vector<std::uint16_t>(4 * points, 0));
    for (int a = 0; a < 3; ++a)
        g.step[a] = g.res[a] > 1 ? float(dims[a] - 1) / float(g.res[a] - 1) : 0.f;
    std::atomic<int> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    progress.report("SH field resampling", 0.0);
    tbb::parallel_for(0, g.res.z, [&](int z) {
        if (progress.cancelled()) return;  // the other slices are skipped, then it throws
        float v[16];
        for (int y = 0; y < g.res.y; ++y)
            for (int x = 0; x < g.res.x; ++x) {
                field.sample(g.position({x, y, z}), v);
                const std::size_t i =
                    std::size_t(x) + std::size_t(g.res.x) * (y + std::size_t(g.res.y) * z);
                for (int c = 0; c < g.coefficients; ++c)
                    g.texels[std::size_t(c / 4)][4 * i + std::size_t(c % 4)] =
                        glm::packHalf1x16(v[c]);
            }
        const int now = ++done;
        if (std::this_thread::get_id() == caller && !progress.cancelled())
            progress.report("SH field resampling", double(now) / g.res.z);
    });
    if (progress.cancelled()) throw CancelledError();
    progress.report("SH field resampling", 1.0);
    return g;
}
}  // namespace

ShFieldGrid resampleShField(const visibility::LocalVisibility& field, const glm::ivec3& dims,
                            std::size_t budgetBytes, int maxPerAxis,
                            const core::Progress& progress) {
    return resample(field, dims, budgetBytes, maxPerAxis, progress);
}
ShFieldGrid resampleShField(const visibility::GlobalVisibility& field, const glm::ivec3& dims,
                            std::size_t budgetBytes, int maxPerAxis,
                            const core::Progress& progress) {
    return resample(field, dims, budgetBytes, maxPerAxis, progress);
}
ShFieldGrid resampleShField(const visibility::HierarchicalVisibility& field, const glm::ivec3& dims,
                            std::size_t budgetBytes, int maxPerAxis,
                            const core::Progress& progress) {
    return resample(field, dims, budgetBytes, maxPerAxis, progress);
}

}  // namespace voxlight::render
