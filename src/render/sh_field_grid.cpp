// SPDX-License-Identifier: MIT
#include "render/sh_field_grid.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/gtc/packing.hpp>
#include <type_traits>

#include "core/error.h"

namespace voxlight::render {

std::size_t ShFieldGrid::bytes() const {
    std::size_t n = spacing.size() * sizeof(std::uint16_t);
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
void fill(const Field& field, ShFieldResampling& r, const core::Progress& progress) {
    ShFieldGrid& g = r.grid;
    VL_CHECK_EQ(g.coefficients, field.coefficients());
    // Reports only while not cancelled (Progress::report throws on a cancel): the chunk below is
    // filled before the flag is looked at, so every attempt gets somewhere.
    const auto report = [&] {
        if (!progress.cancelled())
            progress.report("SH field resampling", double(r.slicesDone) / std::max(g.res.z, 1));
    };
    report();
    // The local field's blended spacing, for the near shadow: sh-local's, and sh-global's where
    // its near factor is that field (resamplesSpacing).
    const bool withSpacing = resamplesSpacing(field);
    if (withSpacing) g.spacing.resize(std::size_t(g.res.x) * g.res.y * g.res.z);
    while (!r.finished()) {
        const int end = std::min(r.slicesDone + kShFieldResampleChunk, g.res.z);
        tbb::parallel_for(r.slicesDone, end, [&](int z) {
            float v[16];
            for (int y = 0; y < g.res.y; ++y)
                for (int x = 0; x < g.res.x; ++x) {
                    const std::size_t i =
                        std::size_t(x) + std::size_t(g.res.x) * (y + std::size_t(g.res.y) * z);
                    const glm::vec3 p = g.position({x, y, z});
                    float s = 1.f;
                    if constexpr (std::is_same_v<Field, visibility::HierarchicalVisibility>)
                        field.sample(p, v);
                    else if (withSpacing)
                        field.sample(p, v, &s);
                    else
                        field.sample(p, v);
                    if (withSpacing) g.spacing[i] = glm::packHalf1x16(s);
                    for (int c = 0; c < g.coefficients; ++c)
                        g.texels[std::size_t(c / 4)][4 * i + std::size_t(c % 4)] =
                            glm::packHalf1x16(v[c]);
                }
        });
        r.slicesDone = end;
        if (!r.finished() && progress.cancelled()) throw CancelledError();
        report();
    }
}

template <class Field>
ShFieldGrid resample(const Field& field, const glm::ivec3& dims, std::size_t budgetBytes,
                     int maxPerAxis, const core::Progress& progress) {
    ShFieldResampling r =
        startShFieldResampling(field.coefficients(), dims, budgetBytes, maxPerAxis);
    fill(field, r, progress);
    return std::move(r.grid);
}
}  // namespace

ShFieldResampling startShFieldResampling(int coefficients, const glm::ivec3& dims,
                                         std::size_t budgetBytes, int maxPerAxis) {
    ShFieldResampling r;
    ShFieldGrid& g = r.grid;
    g.coefficients = coefficients;
    g.res = shFieldGridResolution(dims, g.coefficients, budgetBytes, maxPerAxis);
    const int textures = (g.coefficients + 3) / 4;
    const std::size_t points = std::size_t(g.res.x) * g.res.y * g.res.z;
    g.texels.assign(std::size_t(textures), std::vector<std::uint16_t>(4 * points, 0));
    for (int a = 0; a < 3; ++a)
        g.step[a] = g.res[a] > 1 ? float(dims[a] - 1) / float(g.res[a] - 1) : 0.f;
    return r;
}

void continueShFieldResampling(const visibility::LocalVisibility& field, ShFieldResampling& r,
                               const core::Progress& progress) {
    fill(field, r, progress);
}
void continueShFieldResampling(const visibility::GlobalVisibility& field, ShFieldResampling& r,
                               const core::Progress& progress) {
    fill(field, r, progress);
}
void continueShFieldResampling(const visibility::HierarchicalVisibility& field,
                               ShFieldResampling& r, const core::Progress& progress) {
    fill(field, r, progress);
}

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
