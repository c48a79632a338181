// SPDX-License-Identifier: MIT
#pragma once
// Small helpers shared by the renderer tests.
#include <algorithm>
#include <cmath>

#include "core/phantoms.h"
#include "grid/brick_grid.h"
#include "optics/transfer_function.h"
#include "render/ray_caster.h"

namespace voxlight::test {

inline optics::TfPoint tfPoint(float v, float sigma, glm::vec3 c = glm::vec3(0.9f)) {
    return {v, c, sigma, glm::vec3(0.f)};
}

/// σt = sigma above 0.5 and 0 below, stepping within ±0.001 (the phantoms' 0.5-level set is the
/// exact sphere/slab, so the exact optical depth is sigma × geometric length).
inline optics::TransferFunction stepTf(float sigma) {
    return optics::TransferFunction(
        {tfPoint(0, 0), tfPoint(0.499f, 0), tfPoint(0.501f, sigma), tfPoint(1, sigma)}, {0.5f, 1.f},
        "step");
}

/// The CT torso phantom (HU) at 40³.
inline core::Volume smallTorso(int size = 40) {
    core::PhantomOptions po;
    po.size = size;
    return core::makePhantom("torso", po);
}

/// Bone-like ramp over HU: transparent below 100, red-tinted 300, opaque-ish 900.
inline optics::TransferFunction boneRampTf() {
    return optics::TransferFunction(
        {tfPoint(100, 0), tfPoint(300, 0.3f, {0.9f, 0.3f, 0.2f}), tfPoint(900, 2.f)}, {500, 800});
}

/// The analytic sphere phantom (0.5-level set = the exact sphere) on a size³ grid.
inline core::Volume spherePhantom(int size) {
    core::PhantomOptions po;
    po.size = size;
    return core::makePhantom("sphere", po);
}

/// One 16×16 uint8 slice of value 200, `thickness` mm thick (the slab ±0.5 voxel on k).
inline core::Volume singleSlice(double thickness) {
    core::Geometry geom;
    geom.dims = {16, 16, 1};
    geom.spacing = {1.0, 1.0, thickness};
    core::Volume v(geom, core::VoxelType::UInt8);
    std::fill_n(v.dataAs<std::uint8_t>(), 256, std::uint8_t(200));
    return v;
}

inline render::Camera orthoCamera(const core::Volume& v, double azimuth, double elevation,
                                  double height, int pixels) {
    render::CameraSpec s;
    s.projection = render::Projection::Orthographic;
    s.azimuthDeg = azimuth;
    s.elevationDeg = elevation;
    s.orthoHeight = height;
    const auto b = v.geometry().worldBounds();
    return render::Camera(s, b[0], b[1], pixels, pixels);
}

inline core::ImageRGBA renderWith(const core::Volume& v, const optics::TransferFunction& tf,
                                  const render::Camera& cam, const render::RenderOptions& o,
                                  render::RenderStats* stats = nullptr) {
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const render::RayCaster caster(v, g, tf, o);
    return caster.render(cam, core::Progress::none(), stats);
}

/// Whether index-space point p lies in a non-empty skip cell of m (the cell the DDA assigns it to:
/// cells of cellSize() voxels from index 0, points outside clamped to the edge cell).
inline bool inNonEmptyCell(const grid::BrickMajorants& m, const glm::vec3& p) {
    const int cs = m.cellSize();
    glm::ivec3 c;
    for (int a = 0; a < 3; ++a)
        c[a] = std::clamp(int(std::floor(p[a] / float(cs))), 0, m.counts()[a] - 1);
    return m.majorant(m.index(c.x, c.y, c.z)) > 0.f;
}

inline bool allFinite(const core::ImageRGBA& img) {
    for (float x : img.pixels)
        if (!std::isfinite(x)) return false;
    return true;
}

}  // namespace voxlight::test
