// SPDX-License-Identifier: MIT
#include "io/slice_stack.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <iomanip>
#include <limits>
#include <sstream>
#include <type_traits>

namespace voxlight::io::detail {

namespace {

/// Grid indices within this fraction of a pixel of an integer count as that integer: slice
/// positions are DS strings with ≥ 3 decimals, so a footprint edge computed from them is off an
/// exact pixel multiple by rounding only (≪ 1e-4 pixel); without it, a stack shifted by exactly
/// one pixel per slice would grow a spurious extra column.
constexpr double kLatticeSnap = 1e-4;
/// A sample this far (in pixels) outside a slice's first or last pixel centre is still taken as on
/// its edge (the same rounding, seen from the sampling side).
constexpr double kEdgeTol = 1e-4;
// Step along the normal: the smallest gap between neighbouring slices (rounded down so that the
// steps divide the stack's length evenly). The minimum, not the mean or median: a variable-spacing
// series is usually thin slices through the region of interest and thicker ones elsewhere, and
// the median or mean would average away the thin slices the scan was planned for; Slicer's
// regularisation likewise keeps the finest spacing. The cost (more slices than acquired) is checked
// against core::kMaxVoxels and kMaxResampleGrowth.

/// The regular grid may hold at most this many times the acquired voxels. A real series grows by
/// its shear (a 30° tilt over a stack as deep as it is wide: ×1.6) times the ratio of its largest
/// to its smallest slice gap (0.5 mm slices through a region of interest in a 5 mm scan: ×10);
/// 64 is well above both together. Beyond it the positions are damaged, not acquired (a fuzzed
/// series of three 8×6 slices tilted 89.8° with gaps of 0.4–520 mm asked for 12.7 M voxels, 88,000
/// times its 144, all interpolated from nothing).
constexpr double kMaxResampleGrowth = 64.0;

/// A count as text without converting it to an integer type (a damaged series' counts can exceed
/// any: converting them would be undefined).
std::string count(double n) {
    std::ostringstream s;
    if (n < 1e15)
        s << std::fixed << std::setprecision(0) << n;
    else
        s << std::setprecision(3) << n;
    return s.str();
}
std::string voxelCount(double nx, double ny, double nz) {
    return count(nx) + "x" + count(ny) + "x" + count(nz);
}

}  // namespace

SliceStackGrid sliceStackGrid(const core::Geometry& stack, const std::vector<glm::dvec3>& positions,
                              const std::string& source) {
    VL_CHECK_GE(positions.size(), std::size_t(2));
    VL_CHECK_EQ(int(positions.size()), stack.dims.z);
    const glm::dvec3 i = stack.direction[0], j = stack.direction[1], n = stack.direction[2];
    const double sx = stack.spacing.x, sy = stack.spacing.y;
    const std::size_t ns = positions.size();

    // Each slice's offset from slice 0 along i, j (in pixels) and n (mm).
    double uMin = 0.0, uMax = 0.0, vMin = 0.0, vMax = 0.0, minGap = 0.0;
    std::vector<double> w(ns);
    for (std::size_t k = 0; k < ns; ++k) {
        const glm::dvec3 d = positions[k] - positions[0];
        const double u = glm::dot(d, i) / sx, v = glm::dot(d, j) / sy;
        uMin = std::min(uMin, u), uMax = std::max(uMax, u);
        vMin = std::min(vMin, v), vMax = std::max(vMax, v);
        w[k] = glm::dot(d, n);
        if (k > 0) {
            const double gap = w[k] - w[k - 1];
            VL_CHECK_GT(gap, 0.0);  // duplicates were refused while sorting
            minGap = k == 1 ? gap : std::min(minGap, gap);
        }
    }
    // In-plane: slice 0's pixel lattice, widened to every slice's footprint.
    const double i0 = std::floor(uMin + kLatticeSnap);
    const double i1 = std::ceil(uMax + double(stack.dims.x - 1) - kLatticeSnap);
    const double j0 = std::floor(vMin + kLatticeSnap);
    const double j1 = std::ceil(vMax + double(stack.dims.y - 1) - kLatticeSnap);
    // Along n: equal steps ≤ the smallest gap from the first to the last slice.
    const double length = w.back();
    const double steps = std::ceil(length / minGap - kLatticeSnap);

    SliceStackGrid g;
    const double nx = i1 - i0 + 1.0, ny = j1 - j0 + 1.0, nz = steps + 1.0;
    const double acquired = double(stack.dims.x) * double(stack.dims.y) * double(ns);
    if (nx * ny * nz > kMaxResampleGrowth * acquired)
        throw InputError(source, "ImagePositionPatient",
                         "resampling the irregular slices onto a regular grid needs " +
                             voxelCount(nx, ny, nz) + " voxels, " +
                             count(std::ceil(nx * ny * nz / acquired)) + " times the " +
                             count(acquired) + " acquired (at most " + count(kMaxResampleGrowth) +
                             " times is resampled): the slice positions drift or jump far "
                             "more than a gantry tilt or a variable spacing does",
                         "check the files' ImagePositionPatient (the series looks damaged), or "
                         "pass --strict-geometry (scene: volume.strict_geometry) to see the "
                         "irregularity refused "
                         "by name");
    if (nx > core::kMaxDim || ny > core::kMaxDim || nz > core::kMaxDim ||
        nx * ny * nz > double(core::kMaxVoxels))
        throw InputError(source, "ImagePositionPatient",
                         "resampling the irregular slices onto a regular grid needs " +
                             voxelCount(nx, ny, nz) + " voxels, beyond voxlight's limit",
                         "load a part of the series, or resample it outside voxlight");
    g.geometry.dims = {int(nx), int(ny), int(nz)};
    g.geometry.spacing = {sx, sy, length / steps};
    g.geometry.direction = stack.direction;
    g.geometry.origin = positions[0] + i0 * sx * i + j0 * sy * j;
    g.below.resize(std::size_t(nz));
    g.t.resize(std::size_t(nz));
    std::size_t k = 0;
    for (int c = 0; c < int(nz); ++c) {
        const double wc = length * double(c) / steps;
        while (k + 2 < ns && w[k + 1] <= wc) ++k;
        g.below[std::size_t(c)] = int(k);
        g.t[std::size_t(c)] = std::clamp((wc - w[k]) / (w[k + 1] - w[k]), 0.0, 1.0);
    }
    return g;
}

namespace {

template <class T>
void resampleTyped(const core::Volume& stack, const std::vector<glm::dvec3>& positions,
                   const SliceStackGrid& grid, core::Volume& out, const core::Progress& progress) {
    const core::Geometry& sg = stack.geometry();
    const glm::dvec3 i = sg.direction[0], j = sg.direction[1];
    const int nx = sg.dims.x, ny = sg.dims.y;
    const T* src = stack.dataAs<T>();
    T* dst = out.dataAs<T>();
    const std::size_t slice = std::size_t(nx) * std::size_t(ny);
    // Background: the smallest stored value (finite, for float).
    T background = std::numeric_limits<T>::max();
    for (std::size_t q = 0, e = std::size_t(stack.voxelCount()); q < e; ++q)
        if (src[q] < background) background = src[q];  // NaN compares false: skipped

    // Slice k's pixel coordinates of the output voxel (0, 0, ·): offsets from the grid origin.
    std::vector<glm::dvec2> offset(positions.size());
    for (std::size_t k = 0; k < positions.size(); ++k) {
        const glm::dvec3 d = grid.geometry.origin - positions[k];
        offset[k] = {glm::dot(d, i) / sg.spacing.x, glm::dot(d, j) / sg.spacing.y};
    }
    const glm::ivec3 od = grid.geometry.dims;
    // Bilinear sample of slice k at pixel (x, y); false when outside its footprint.
    const auto bilinear = [&](int k, double x, double y, double& value) {
        if (x < -kEdgeTol || y < -kEdgeTol || x > nx - 1 + kEdgeTol || y > ny - 1 + kEdgeTol)
            return false;
        x = std::clamp(x, 0.0, double(nx - 1));
        y = std::clamp(y, 0.0, double(ny - 1));
        const int a = std::min(int(x), std::max(nx - 2, 0)),
                  b = std::min(int(y), std::max(ny - 2, 0));
        const double fx = x - a, fy = y - b;
        const int da = nx > 1 ? 1 : 0;
        const std::size_t db = ny > 1 ? std::size_t(nx) : 0;
        const T* p = src + std::size_t(k) * slice + std::size_t(b) * std::size_t(nx) + a;
        const double c0 = double(p[0]) + fx * (double(p[da]) - double(p[0]));
        const double c1 = double(p[db]) + fx * (double(p[db + da]) - double(p[db]));
        value = c0 + fy * (c1 - c0);
        return true;
    };
    std::atomic<int> done{0};
    tbb::parallel_for(0, od.z, [&](int c) {
        progress.checkCancel();
        const int k = grid.below[std::size_t(c)];
        const double t = grid.t[std::size_t(c)];
        // A slice with weight 0 is not needed (an output slice on an input slice).
        const bool useLo = t<1.0, useHi = t> 0.0;
        T* row = dst + std::size_t(c) * std::size_t(od.x) * std::size_t(od.y);
        for (int b = 0; b < od.y; ++b)
            for (int a = 0; a < od.x; ++a) {
                double lo = 0.0, hi = 0.0;
                bool inside = true;
                if (useLo) inside = bilinear(k, offset[k].x + a, offset[k].y + b, lo);
                if (inside && useHi)
                    inside = bilinear(k + 1, offset[k + 1].x + a, offset[k + 1].y + b, hi);
                T& v = row[std::size_t(b) * std::size_t(od.x) + std::size_t(a)];
                if (!inside) {
                    v = background;
                    continue;
                }
                const double f = (useLo ? (1.0 - t) * lo : 0.0) + (useHi ? t * hi : 0.0);
                if constexpr (std::is_floating_point_v<T>)
                    v = T(f);
                else
                    v = T(std::lround(f));  // a convex blend of stored values: in range
            }
        const int d = ++done;
        if (d % 16 == 0) progress.report("dicom resample", double(d) / od.z);
    });
    progress.report("dicom resample", 1.0);
}

}  // namespace

core::Volume resampleSliceStack(const core::Volume& stack, const std::vector<glm::dvec3>& positions,
                                const std::string& source, const core::Progress& progress) {
    const SliceStackGrid grid = sliceStackGrid(stack.geometry(), positions, source);
    core::Volume out(grid.geometry, stack.type());
    switch (stack.type()) {
        case core::VoxelType::UInt8:
            resampleTyped<std::uint8_t>(stack, positions, grid, out, progress);
            break;
        case core::VoxelType::Int16:
            resampleTyped<std::int16_t>(stack, positions, grid, out, progress);
            break;
        case core::VoxelType::UInt16:
            resampleTyped<std::uint16_t>(stack, positions, grid, out, progress);
            break;
        case core::VoxelType::Float32:
            resampleTyped<float>(stack, positions, grid, out, progress);
            break;
    }
    out.mapping = stack.mapping;
    out.modality = stack.modality;
    out.description = stack.description;
    out.format = stack.format;
    out.warnings = stack.warnings;
    return out;
}

}  // namespace voxlight::io::detail
