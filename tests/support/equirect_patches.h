// SPDX-License-Identifier: MIT
#pragma once
// Brute force for SH projections of latitude–longitude maps (tests only): each pixel a constant
// over its patch, ∫ Y_i over the patch — rotated — by a tensor Gauss–Legendre rule in (θ, φ)
// with sin θ. The layout of lights::EnvironmentLight: row r covers θ ∈ [π r/H, π (r+1)/H],
// column c φ from π − 2π c/W to π − 2π (c+1)/W.
#include <cmath>
#include <glm/glm.hpp>
#include <numbers>
#include <vector>

#include "sh/sh_basis.h"
#include "sh/sphere_samples.h"

namespace voxlight::test {

/// Calls add(row, col, y) with y[i] = ∫ over the pixel's patch of Y_i(rotation · ω) dω, for
/// every pixel of a width × height map, band ≤ `band`, nodes² points per patch.
template <class Add>
void forEachEquirectPatchSh(int band, int width, int height, const glm::dmat3& rotation, int nodes,
                            Add&& add) {
    constexpr double kPi = std::numbers::pi;
    std::vector<double> x, wx;
    sh::gaussLegendre(nodes, x, wx);
    std::vector<double> y(sh::shCount(band)), patch(y.size());
    for (int row = 0; row < height; ++row) {
        const double t0 = kPi * row / height, t1 = kPi * (row + 1) / height;
        for (int col = 0; col < width; ++col) {
            const double p0 = kPi - 2.0 * kPi * col / width,
                         p1 = kPi - 2.0 * kPi * (col + 1) / width;
            std::fill(patch.begin(), patch.end(), 0.0);
            for (int i = 0; i < nodes; ++i)
                for (int j = 0; j < nodes; ++j) {
                    const double theta = 0.5 * (t0 + t1) + 0.5 * (t1 - t0) * x[i];
                    const double phi = 0.5 * (p0 + p1) + 0.5 * (p1 - p0) * x[j];
                    const double omega =
                        0.25 * (t1 - t0) * (p0 - p1) * wx[i] * wx[j] * std::sin(theta);
                    sh::evalShUnitDouble(band, rotation * sh::sphericalToDirection(theta, phi), y);
                    for (std::size_t k = 0; k < y.size(); ++k) patch[k] += omega * y[k];
                }
            add(row, col, patch);
        }
    }
}

}  // namespace voxlight::test
