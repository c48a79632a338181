// SPDX-License-Identifier: MIT
#pragma once
// Small volumes and TFs for the visibility tests.
#include <functional>

#include "core/hash.h"
#include "core/volume.h"
#include "optics/transfer_function.h"

namespace voxlight::test {

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

}  // namespace voxlight::test
