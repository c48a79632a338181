// SPDX-License-Identifier: MIT
// The two tables of central differences (dense VoxelGradients, sparse BrickedGradients) hold the
// same values, and the gradient mode renders the same image with either, and with none.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "grid/brick_grid.h"
#include "render/ray_caster.h"
#include "render_test_util.h"

namespace voxlight {
namespace {

using test::boneRampTf;
using test::smallTorso;

render::RenderOptions withTable(render::GradientTable t) {
    render::RenderOptions o;
    o.mode = render::Mode::Gradient;
    o.gradientTable = t;
    return o;
}

/// Dense-table cell (lower corner (i, j, k)) as the marcher's CellSampler locates it.
struct DenseCell {
    std::size_t offset;
};
struct IndexCell {
    int i, j, k;
};

// Every cell the bricked table holds has the dense table's 8 corner entries; every cell within
// one skip cell of a non-empty one is held (where shading can ask); and some are not (or the
// table would not be sparse).
TEST(GradientTables, BrickedHoldsTheDenseValuesNearTheVisibleCells) {
    const core::Volume v = smallTorso(72);  // 5 bricks per axis, the last one partial
    const grid::BrickGrid grid = grid::BrickGrid::build(v);
    const auto tf = boneRampTf();
    const render::RayCaster caster(v, grid, tf, withTable(render::GradientTable::Bricked));
    const render::BrickedGradients* b = caster.brickedGradients();
    ASSERT_NE(b, nullptr);
    EXPECT_EQ(caster.voxelGradients(), nullptr);
    const render::VoxelGradients dense = render::VoxelGradients::build(v);
    ASSERT_FALSE(dense.empty());
    const grid::BrickMajorants& m = caster.majorants();
    const glm::ivec3 n = v.dims();
    const std::size_t sy = std::size_t(n.x), sz = std::size_t(n.x) * n.y;
    const int cs = m.cellSize();
    int held = 0, missing = 0;
    for (int k = 0; k <= n.z - 2; ++k)
        for (int j = 0; j <= n.y - 2; ++j)
            for (int i = 0; i <= n.x - 2; ++i) {
                const render::GradientEntry* q = b->corner(IndexCell{i, j, k});
                const std::size_t cell = m.index(i / cs, j / cs, k / cs);
                if (m.skipDistances()[cell] <= 1) {
                    ASSERT_NE(q, nullptr) << i << "," << j << "," << k;
                }
                if (!q) {
                    ++missing;
                    continue;
                }
                ++held;
                const std::size_t o = std::size_t(i) + sy * j + sz * k;
                ASSERT_EQ(dense.corner(DenseCell{o}), dense.d.data() + o);
                for (int c = 0; c < 8; ++c) {
                    const std::size_t db =
                        (c & 1 ? b->di : 0) + (c & 2 ? b->dj : 0) + (c & 4 ? b->dk : 0);
                    const std::size_t dd = (c & 1 ? 1 : 0) + (c & 2 ? sy : 0) + (c & 4 ? sz : 0);
                    ASSERT_EQ(q[db], dense.d[o + dd])
                        << i << "," << j << "," << k << " corner " << c;
                }
            }
    EXPECT_GT(held, 1000);
    EXPECT_GT(missing, 1000);
    EXPECT_LT(b->d.size(), dense.d.size());
}

// Same image with the dense table, the bricked one, and none (six taps per gradient), to float
// rounding: interpolating the differences and differencing the interpolated field agree.
TEST(GradientTables, SameImageWithEitherTableOrNone) {
    // Rounding of the two gradient forms (float, values up to ~2000 HU/voxel) moves a pixel by
    // far less than this; a wrong corner or stride moves shading by tenths.
    constexpr double kTol = 2e-4;
    const core::Volume v = smallTorso(56);
    const auto tf = boneRampTf();
    core::Volume asFloat(v.geometry(), core::VoxelType::Float32);
    v.visit([&](const auto& view) {
        float* out = asFloat.dataAs<float>();
        for (std::uint64_t i = 0; i < v.voxelCount(); ++i)
            out[i] = view.slope * float(view.data[i]) + view.intercept;
    });
    const render::Camera cam = test::orthoCamera(v, 30, 20, 0.0, 48);
    for (float step : {0.5f, 6.f}) {
        auto render = [&](const core::Volume& vol, render::GradientTable t,
                          render::RenderStats* stats = nullptr) {
            render::RenderOptions o = withTable(t);
            o.stepVoxels = step;
            return test::renderWith(vol, tf, cam, o, stats);
        };
        const io::ImageRGBA dense = render(v, render::GradientTable::Dense);
        const io::ImageRGBA bricked = render(v, render::GradientTable::Bricked);
        // No table: the same physical values as float32 (tables hold integer differences only).
        const io::ImageRGBA none = render(asFloat, render::GradientTable::Auto);
        double maxBricked = 0.0, maxNone = 0.0, maxValue = 0.0;
        for (std::size_t i = 0; i < dense.pixels.size(); ++i) {
            maxBricked =
                std::max(maxBricked, double(std::abs(dense.pixels[i] - bricked.pixels[i])));
            maxNone = std::max(maxNone, double(std::abs(dense.pixels[i] - none.pixels[i])));
            maxValue = std::max(maxValue, double(dense.pixels[i]));
        }
        EXPECT_GT(maxValue, 0.1) << "the image should show something";
        EXPECT_LT(maxBricked, kTol) << "step " << step;
        EXPECT_LT(maxNone, kTol) << "step " << step;
    }
}

// A small object in a large volume, at a 24-voxel step without pre-integration: the sample that
// ends a shaded segment lies up to six skip cells past the cube, in bricks the table does not
// hold (pre-integrated coarse segments are refined down to the surface, and never get there); the
// marcher
// falls back to six taps there (seen in the sample count) and the image stays the dense one.
TEST(GradientTables, BrickedMissFallsBackToSixTaps) {
    constexpr double kTol = 2e-4;  // as above
    core::Geometry geom;
    geom.dims = {96, 96, 96};
    core::Volume v(geom, core::VoxelType::UInt8);
    auto* data = v.dataAs<std::uint8_t>();
    for (int k = 0; k < 96; ++k)  // a transparent ramp (below the TF), so gradients are not 0
        for (int j = 0; j < 96; ++j)
            for (int i = 0; i < 96; ++i)
                data[i + 96 * (j + 96 * k)] = std::uint8_t((i + j + 2 * k) / 5);
    for (int k = 24; k <= 40; ++k)  // a solid 17³ cube in one corner of the volume
        for (int j = 24; j <= 40; ++j)
            for (int i = 24; i <= 40; ++i) data[i + 96 * (j + 96 * k)] = 200;
    const optics::TransferFunction tf(
        {test::tfPoint(0, 0), test::tfPoint(90, 0), test::tfPoint(110, 0.5f)}, {100, 100});
    const render::Camera cam = test::orthoCamera(v, 20, 35, 0.0, 40);
    render::RenderOptions o = withTable(render::GradientTable::Dense);
    o.stepVoxels = 24.f;
    o.preintegrated = false;  // midpoint segments are not refined: they end far past the object
    render::RenderStats denseStats, brickedStats;
    const io::ImageRGBA dense = test::renderWith(v, tf, cam, o, &denseStats);
    o.gradientTable = render::GradientTable::Bricked;
    const io::ImageRGBA bricked = test::renderWith(v, tf, cam, o, &brickedStats);
    EXPECT_GT(brickedStats.samples, denseStats.samples) << "the fallback should have run";
    double maxDiff = 0.0, maxValue = 0.0;
    for (std::size_t i = 0; i < dense.pixels.size(); ++i) {
        maxDiff = std::max(maxDiff, double(std::abs(dense.pixels[i] - bricked.pixels[i])));
        maxValue = std::max(maxValue, double(dense.pixels[i]));
    }
    EXPECT_GT(maxValue, 0.1) << "the image should show the object";
    EXPECT_LT(maxDiff, kTol);
}

}  // namespace
}  // namespace voxlight
