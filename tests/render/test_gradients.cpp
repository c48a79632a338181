// SPDX-License-Identifier: MIT
// The two tables of central differences (dense VoxelGradients, sparse BrickedGradients) hold the
// same values, and the gradient mode renders the same image with either, and with none.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/rng.h"
#include "grid/brick_grid.h"
#include "render/dvr_march.h"
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

/// A uint8 blob (value 200 at the centre falling to 0 at radius r) on a grid of any shape.
core::Volume blob(glm::ivec3 dims, glm::dvec3 centre, double radius) {
    core::Geometry geom;
    geom.dims = dims;
    core::Volume v(geom, core::VoxelType::UInt8);
    auto* data = v.dataAs<std::uint8_t>();
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i) {
                const double r = glm::length(glm::dvec3(i, j, k) - centre);
                data[i + dims.x * (j + dims.y * k)] =
                    std::uint8_t(std::clamp(200.0 * (1.0 - r / radius), 0.0, 200.0));
            }
    return v;
}

const optics::TransferFunction& blobTf() {
    static const optics::TransferFunction tf(
        {test::tfPoint(0, 0), test::tfPoint(90, 0), test::tfPoint(120, 0.4f)}, {100, 100});
    return tf;
}

/// Every cell the bricked table holds has the dense table's 8 corner entries; every cell within
/// one skip cell of a non-empty one is held (where shading can ask); and, when `sparse`, some are
/// not.
void expectBrickedHoldsTheDenseValues(const core::Volume& v, const optics::TransferFunction& tf,
                                      bool sparse, const std::string& what) {
    const grid::BrickGrid grid = grid::BrickGrid::build(v);
    const render::RayCaster caster(v, grid, tf, withTable(render::GradientTable::Bricked));
    const render::BrickedGradients* b = caster.brickedGradients();
    ASSERT_NE(b, nullptr) << what;
    EXPECT_EQ(caster.voxelGradients(), nullptr) << what;
    const render::VoxelGradients dense = render::VoxelGradients::build(v);
    ASSERT_FALSE(dense.empty()) << what;
    const grid::BrickMajorants& m = caster.majorants();
    const glm::ivec3 n = v.dims();
    const std::size_t sy = std::size_t(n.x), sz = std::size_t(n.x) * n.y;
    const int cs = m.cellSize();
    int held = 0, missing = 0;
    // Lower corners of cells, as CellSampler clamps them (n − 2, or 0 on a single-voxel axis).
    for (int k = 0; k <= std::max(n.z - 2, 0); ++k)
        for (int j = 0; j <= std::max(n.y - 2, 0); ++j)
            for (int i = 0; i <= std::max(n.x - 2, 0); ++i) {
                const render::GradientEntry* q = b->corner(IndexCell{i, j, k});
                const std::size_t cell = m.index(i / cs, j / cs, k / cs);
                if (m.skipDistances()[cell] <= 1) {
                    ASSERT_NE(q, nullptr) << what << " " << i << "," << j << "," << k;
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
                    const std::size_t dd =
                        (c & 1 ? dense.di : 0) + (c & 2 ? dense.dj : 0) + (c & 4 ? dense.dk : 0);
                    ASSERT_EQ(q[db], dense.d[o + dd])
                        << what << " " << i << "," << j << "," << k << " corner " << c;
                }
            }
    EXPECT_GT(held, 100) << what;
    if (sparse) {
        EXPECT_GT(missing, 100) << what;
        EXPECT_LT(b->d.size(), dense.d.size()) << what;
    }
}

TEST(GradientTables, BrickedHoldsTheDenseValuesNearTheVisibleCells) {
    // Cubic with a partial last brick; not cubic (x, y, z counts differ; 33 = 2·16 + 1); one slice.
    expectBrickedHoldsTheDenseValues(smallTorso(72), boneRampTf(), true, "torso 72^3");
    expectBrickedHoldsTheDenseValues(blob({72, 40, 33}, {20, 28, 24}, 14), blobTf(), true,
                                     "blob 72x40x33");
    expectBrickedHoldsTheDenseValues(blob({40, 36, 1}, {12, 20, 0}, 10), blobTf(), false,
                                     "one slice 40x36x1");
}

// Past the entry limit the bricks with a non-empty cell are kept first.
TEST(GradientTables, EntryLimitKeepsTheBricksWithVisibleCellsFirst) {
    const core::Volume v = blob({96, 96, 96}, {40, 40, 40}, 30);
    const grid::BrickGrid grid = grid::BrickGrid::build(v);
    const render::RayCaster caster(v, grid, blobTf(), withTable(render::GradientTable::Dense));
    const grid::BrickMajorants& m = caster.majorants();
    const render::BrickedGradients all = render::BrickedGradients::build(v, m);
    const std::size_t limit = 3 * render::BrickedGradients::kBrickEntries;
    const render::BrickedGradients few = render::BrickedGradients::build(v, m, limit);
    ASSERT_GT(all.d.size(), limit);
    EXPECT_EQ(few.d.size(), limit);
    int kept = 0;
    for (std::size_t b = 0; b < few.slot.size(); ++b) {
        if (few.slot[b] < 0) continue;
        ++kept;
        const int bx = int(b % 6), by = int(b / 6 % 6), bz = int(b / 36);
        bool nonEmpty = false;
        for (int z = 4 * bz; z < 4 * bz + 4; ++z)
            for (int y = 4 * by; y < 4 * by + 4; ++y)
                for (int x = 4 * bx; x < 4 * bx + 4; ++x)
                    nonEmpty |= m.skipDistances()[m.index(x, y, z)] == 0;
        EXPECT_TRUE(nonEmpty) << "brick " << bx << "," << by << "," << bz;
    }
    EXPECT_EQ(kept, 3);
}

// The table's interpolated differences equal the field's six-tap central difference (the
// marcher's fallback) at any point, edges included, for both tables, to float rounding.
TEST(GradientTables, InterpolatedDifferencesEqualTheSixTapCentralDifference) {
    const core::Volume v = blob({37, 29, 21}, {10, 12, 8}, 16);
    const grid::BrickGrid grid = grid::BrickGrid::build(v);
    const render::RayCaster caster(v, grid, blobTf(), withTable(render::GradientTable::Bricked));
    const render::BrickedGradients* bricked = caster.brickedGradients();
    ASSERT_NE(bricked, nullptr);
    const render::VoxelGradients dense = render::VoxelGradients::build(v);
    const glm::mat3 m = caster.gradientMatrix();
    const core::VolumeView<std::uint8_t> view = v.view<std::uint8_t>();
    const render::detail::CellSampler<core::VolumeView<std::uint8_t>, true> sampler(view);
    const glm::vec3 hi = glm::vec3(v.dims() - 1);
    core::CounterRng rng(3);
    int checkedBricked = 0;
    for (int n = 0; n < 4000; ++n) {
        glm::vec3 p(rng.uniform() * hi.x, rng.uniform() * hi.y, rng.uniform() * hi.z);
        if (n % 5 == 0) p.x = (n / 5) % 2 ? hi.x : 0.f;  // on the faces of the grid
        if (n % 7 == 0) p.z = (n / 7) % 2 ? hi.z : 0.f;
        const auto cell = sampler.locate(p);
        const glm::vec3 six = render::detail::gradientAt(view, p, m);
        const float tol = 1e-5f * (1.f + glm::length(six));
        const glm::vec3 fromDense =
            render::detail::gradientAtCell(dense.corner(cell), dense.slope, cell.fx, cell.fy,
                                           cell.fz, dense.di, dense.dj, dense.dk, m);
        EXPECT_LT(glm::length(fromDense - six), tol) << p.x << "," << p.y << "," << p.z;
        if (const render::GradientEntry* q = bricked->corner(cell)) {
            const glm::vec3 fromBricked =
                render::detail::gradientAtCell(q, bricked->slope, cell.fx, cell.fy, cell.fz,
                                               bricked->di, bricked->dj, bricked->dk, m);
            EXPECT_LT(glm::length(fromBricked - six), tol) << p.x << "," << p.y << "," << p.z;
            ++checkedBricked;
        }
    }
    EXPECT_GT(checkedBricked, 1000);
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
        const core::ImageRGBA dense = render(v, render::GradientTable::Dense);
        const core::ImageRGBA bricked = render(v, render::GradientTable::Bricked);
        // No table: the same physical values as float32 (tables hold integer differences only).
        const core::ImageRGBA none = render(asFloat, render::GradientTable::Auto);
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
    render::RenderOptions o = withTable(render::GradientTable::Bricked);
    {
        const grid::BrickGrid grid = grid::BrickGrid::build(v);
        ASSERT_NE(render::RayCaster(v, grid, tf, o).brickedGradients(), nullptr);
    }
    o.gradientTable = render::GradientTable::Dense;
    o.stepVoxels = 24.f;
    o.preintegrated = false;  // midpoint segments are not refined: they end far past the object
    render::RenderStats denseStats, brickedStats;
    const core::ImageRGBA dense = test::renderWith(v, tf, cam, o, &denseStats);
    o.gradientTable = render::GradientTable::Bricked;
    const core::ImageRGBA bricked = test::renderWith(v, tf, cam, o, &brickedStats);
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
