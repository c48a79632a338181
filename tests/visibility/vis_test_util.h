// SPDX-License-Identifier: MIT
#pragma once
// Small volumes and TFs for the visibility tests.
#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <vector>

#include "core/hash.h"
#include "core/volume.h"
#include "optics/transfer_function.h"
#include "sh/sphere_samples.h"
#include "visibility/multires_grid.h"

namespace voxlight::test {

/// Distance from index point o along w (1 mm voxels: index units) to the face of the box [0, hi]
/// it leaves through, at most `cap`: a homogeneous box's closed forms.
inline double boxExitDistance(const glm::dvec3& o, const glm::dvec3& w, const glm::dvec3& hi,
                              double cap = INFINITY) {
    double d = cap;
    for (int a = 0; a < 3; ++a) {
        if (w[a] > 1e-12) d = std::min(d, (hi[a] - o[a]) / w[a]);
        if (w[a] < -1e-12) d = std::min(d, -o[a] / w[a]);
    }
    return d;
}

/// Directions for box-face tests: 48 Fibonacci directions and the 26 axis and diagonal ones.
inline std::vector<glm::dvec3> boxTestDirections() {
    std::vector<glm::dvec3> dirs = sh::fibonacciSamples(48).directions;
    for (int x = -1; x <= 1; ++x)
        for (int y = -1; y <= 1; ++y)
            for (int z = -1; z <= 1; ++z)
                if (x || y || z) dirs.push_back(glm::normalize(glm::dvec3(x, y, z)));
    return dirs;
}

/// An int16 volume of `dims` (1 mm voxels) with value f(i, j, k).
inline core::Volume makeVolume(const glm::ivec3& dims, const std::function<int(int, int, int)>& f) {
    core::Geometry g;
    g.dims = dims;
    core::Volume v(g, core::VoxelType::Int16);
    auto* d = v.dataAs<std::int16_t>();
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i) d[v.linearIndex(i, j, k)] = std::int16_t(f(i, j, k));
    return v;
}

/// σt rising linearly from 0 at value 0 to `sigma` at value 1000 (albedo white, no emission).
inline optics::TransferFunction rampTf(float sigma) {
    return optics::TransferFunction({{0.f, glm::vec3(1.f), 0.f, glm::vec3(0.f)},
                                     {1000.f, glm::vec3(1.f), sigma, glm::vec3(0.f)}},
                                    {500.f, 1000.f}, "ramp");
}

/// The multiresolution grid of `v` under `tf` at full budget (every visible block at 16³).
inline std::shared_ptr<const visibility::MultiresGrid> fullGrid(
    const core::Volume& v, const optics::TransferFunction& tf) {
    using namespace visibility;
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const optics::TfTable table(tf);
    return std::make_shared<const MultiresGrid>(pyr,
                                                selectLod(*pyr, tf, table, LodBudget::unlimited()));
}

/// Every block of `pyr` at `level` (every cell visible).
inline std::shared_ptr<const visibility::MultiresGrid> uniformGrid(
    std::shared_ptr<const visibility::BlockPyramid> pyr, int level) {
    using namespace visibility;
    LodSelection sel;
    sel.level.assign(pyr->blockCount(), std::int8_t(level));
    sel.significance.assign(pyr->blockCount(), 0.f);
    return std::make_shared<const MultiresGrid>(std::move(pyr), sel);
}

}  // namespace voxlight::test
