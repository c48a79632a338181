// SPDX-License-Identifier: MIT
// TF update of the local visibility (updateLocalVisibility): bit for bit the field a full
// computation gives, for edits over a value interval, colour-only edits, LOD reshuffles under a
// budget and edits that move the TF's end points; and it recomputes only what the edit reaches —
// under the march and under the line sweep.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <iostream>

#include "visibility/local_visibility.h"
#include "visibility/vis_test_util.h"

using namespace voxlight;
using namespace voxlight::visibility;

namespace {

/// 112×48×64 voxels at 1.5 × 1 × 1 mm: air, a soft-tissue ellipsoid (40, textured), a dense
/// nodule (120: below the contrast interval, so no step from it to the tissue integrates σt over
/// that interval) near one end and a contrast-filled plate (220) across the other end at z = 32…34 — just
/// past a block face, so blocks two apart in z (z ≤ 15, 17 voxels below) see it within r_s 20.
core::Volume phantom() {
    core::Volume v = test::makeVolume({112, 48, 64}, [](int i, int j, int k) {
        const double x = (i - 55.5) / 56.0, y = (j - 23.5) / 26.0, z = (k - 31.5) / 34.0;
        if (x * x + y * y + z * z > 1.0) return -1000;
        const double bx = (i - 20.0) * 1.5, by = j - 18.0, bz = k - 14.0;
        if (bx * bx + by * by + bz * bz < 49.0) return 120;
        if (i > 76 && k >= 32 && k <= 34) return 220;
        return 40 + (i * 7 + j * 3 + k) % 11;  // texture: blocks are not constant
    });
    v.geometry().spacing = {1.5, 1.0, 1.0};
    return v;
}

/// CT-like TF; `vessel` scales σt of the contrast interval (150…300), `tint` the colours only.
optics::TransferFunction ctTf(float vessel, float tint = 1.f, float airEnd = -1000.f) {
    const glm::vec3 c(0.9f * tint, 0.7f, 0.6f);
    return optics::TransferFunction({{airEnd, c, 0.f, glm::vec3(0.f)},
                                     {-200.f, c, 0.f, glm::vec3(0.f)},
                                     {20.f, c, 0.02f, glm::vec3(0.f)},
                                     {100.f, c, 0.03f, glm::vec3(0.f)},
                                     {150.f, c, 0.03f, glm::vec3(0.f)},
                                     {220.f, c, 0.03f + vessel, glm::vec3(0.f)},
                                     {300.f, c, 0.03f, glm::vec3(0.f)},
                                     {600.f, c, 0.5f, glm::vec3(0.f)},
                                     {2000.f, c, 1.f, glm::vec3(0.f)}},
                                    {40.f, 400.f}, "test-ct");
}

struct Field {
    std::shared_ptr<const BlockPyramid> pyramid;
    LocalVisibilityOptions options;
    LodBudget budget = LodBudget::unlimited();

    std::shared_ptr<const MultiresGrid> grid(const optics::TransferFunction& tf) const {
        return std::make_shared<const MultiresGrid>(
            pyramid, selectLod(*pyramid, tf, optics::TfTable(tf), budget));
    }
    LocalVisibility full(const optics::TransferFunction& tf) const {
        return computeLocalVisibility(grid(tf), optics::TfTable(tf), options);
    }
    LocalVisibility update(const LocalVisibility& prev, const optics::TransferFunction& tf,
                           TfUpdateStats& st) const {
        return updateLocalVisibility(prev, grid(tf), optics::TfTable(tf), options,
                                     core::Progress::none(), &st);
    }
};

Field field(VisibilityAlgorithm algorithm = VisibilityAlgorithm::March) {
    static const auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(phantom()));
    Field f;
    f.pyramid = pyr;
    // The fewest for 4 coefficients (the test is about which blocks, not V), or the sweep's 26
    // lattice steps.
    f.options.rays = algorithm == VisibilityAlgorithm::Sweep ? kSweepRaysCoarse : 8;
    f.options.algorithm = algorithm;
    f.options.coefficients = 4;
    // The sweep's lines run through groups of 4³ blocks (as on a 256³ volume), so an update's
    // subset of blocks walks different stretches of them than the full computation does.
    f.options.sweepGroupBlocks = algorithm == VisibilityAlgorithm::Sweep ? 4 : 0;
    // Rays reach past the next block (20 voxels): blocks two apart see each other, three do not.
    // The sweep's lines read 2·max|v_a| + 1 = 3 voxels further (local_visibility.h), which would
    // take its reach along x (1.5 mm voxels: 20/1.5 + 2 + 3 > 16) past the next block: 16 keeps
    // the same block pattern.
    f.options.radiusVoxels = algorithm == VisibilityAlgorithm::Sweep ? 16.0 : 20.0;
    return f;
}

/// Same selection and bit-identical coefficients in every stored block.
void expectIdentical(const LocalVisibility& a, const LocalVisibility& b) {
    const MultiresGrid& g = a.grid();
    ASSERT_EQ(g.pyramid().blockCount(), b.grid().pyramid().blockCount());
    for (std::size_t blk = 0; blk < g.pyramid().blockCount(); ++blk) {
        ASSERT_EQ(g.level(blk), b.grid().level(blk)) << "block " << blk;
        if (g.level(blk) == kNone) continue;
        const std::size_t n = std::size_t(levelResolution(g.level(blk)));
        const std::size_t floats = n * n * n * std::size_t(a.coefficients());
        ASSERT_EQ(std::memcmp(a.blockData(blk), b.blockData(blk), floats * sizeof(float)), 0)
            << "block " << blk << " at level " << g.level(blk);
        for (int face = 0; face < 6; ++face) {  // and its boundary layers
            const float* la = a.layerData(blk, face);
            ASSERT_EQ(la == nullptr, b.layerData(blk, face) == nullptr) << "block " << blk;
            if (la) {
                ASSERT_EQ(std::memcmp(la, b.layerData(blk, face),
                                      n * n * std::size_t(a.coefficients()) * sizeof(float)),
                          0)
                    << "block " << blk << " layer " << face;
            }
        }
    }
}

/// The edits below, under the march and under the line sweep.
class TfUpdateBy : public ::testing::TestWithParam<VisibilityAlgorithm> {};

}  // namespace

INSTANTIATE_TEST_SUITE_P(Integrators, TfUpdateBy,
                         ::testing::Values(VisibilityAlgorithm::March, VisibilityAlgorithm::Sweep),
                         [](const auto& info) {
                             return info.param == VisibilityAlgorithm::Sweep ? "Sweep" : "March";
                         });

TEST_P(TfUpdateBy, AnEditOverAValueIntervalEqualsAFullComputationAndRecomputesOnlyNearIt) {
    const Field f = field(GetParam());
    const LocalVisibility before = f.full(ctTf(0.f));
    TfUpdateStats st;
    const LocalVisibility after = f.update(before, ctTf(0.4f), st);
    expectIdentical(after, f.full(ctTf(0.4f)));
    EXPECT_TRUE(st.incremental) << st.reason;
    // The edit's σt differs only inside (150, 300), widened by the table's cells.
    EXPECT_LT(st.changed.lo, 151.f);
    EXPECT_GT(st.changed.lo, 140.f);
    EXPECT_GT(st.changed.hi, 299.f);
    EXPECT_LT(st.changed.hi, 310.f);
    EXPECT_EQ(st.blocksLevelChanged, 0u);  // unlimited budget: every stored block at 16³
    // Sources: the vessel's blocks and their neighbours (a step between two blocks integrates σt
    // over the values between its ends); the nodule's end of the body is out of reach.
    EXPECT_GT(st.blocksRecomputed, 0u);
    EXPECT_LT(st.blocksRecomputed, st.blocks);
    EXPECT_LT(st.pointsRecomputed, st.points);
    std::cout << "recomputed " << st.blocksRecomputed << " of " << st.blocks << " blocks, "
              << st.pointsRecomputed << " of " << st.points << " points\n";
}

TEST_P(TfUpdateBy, AStepAcrossABlockFaceIntegratesTheValuesBetweenItsEnds) {
    // Tissue (40) meets bone (700) exactly on a block face: neither block holds a value in the
    // edited interval (150…300), but a ray step from one to the other integrates σt over the
    // values between its ends, so the edit changes V on both sides and both blocks are sources.
    Field f;
    f.pyramid = std::make_shared<const BlockPyramid>(BlockPyramid::build(test::makeVolume(
        {48, 16, 16}, [](int i, int, int) { return i < 16   ? 40
                                                   : i < 32 ? 700
                                                            : -1000; })));
    f.options.algorithm = GetParam();
    f.options.rays = GetParam() == VisibilityAlgorithm::Sweep ? kSweepRaysCoarse : 8;
    f.options.coefficients = 4;
    f.options.radiusVoxels = 4.0;
    const LocalVisibility before = f.full(ctTf(0.f));
    const LocalVisibility expected = f.full(ctTf(2.f));
    // The edit does change the field next to the face (else the test proves nothing).
    float a[4], b[4];
    before.sample(glm::vec3(15.f, 8.f, 8.f), a);
    expected.sample(glm::vec3(15.f, 8.f, 8.f), b);
    EXPECT_GT(std::abs(a[0] - b[0]), 1e-3f);
    TfUpdateStats st;
    const LocalVisibility after = f.update(before, ctTf(2.f), st);
    EXPECT_TRUE(st.incremental) << st.reason;
    EXPECT_GE(st.blocksRecomputed, 2u);
    expectIdentical(after, expected);
}

TEST_P(TfUpdateBy, AColourOnlyEditChangesNoValueAndTracesNothing) {
    Field f = field(GetParam());
    // At full resolution, and under a budget (coarse blocks on the volume's faces: their boundary
    // layers are copied too).
    for (const double reduction : {1.0, 8.0}) {
        if (reduction > 1.0)
            f.budget = LodBudget::fromReduction(reduction, f.pyramid->geometry().voxelCount());
        const LocalVisibility before = f.full(ctTf(0.2f));
        TfUpdateStats st;
        const LocalVisibility after = f.update(before, ctTf(0.2f, 0.5f), st);
        EXPECT_TRUE(st.changed.empty());
        EXPECT_EQ(st.blocksRecomputed, 0u);
        EXPECT_EQ(after.raysTraced(), 0u);
        EXPECT_EQ(after.layerPoints() > 0, reduction > 1.0);
        expectIdentical(after, f.full(ctTf(0.2f, 0.5f)));
    }
}

TEST_P(TfUpdateBy, UnderABudgetBlocksThatChangeLevelAreRecomputedAndTheFieldStillMatches) {
    Field f = field(GetParam());
    f.budget = LodBudget::fromReduction(8.0, f.pyramid->geometry().voxelCount());
    const LocalVisibility before = f.full(ctTf(0.f));
    TfUpdateStats st;
    const LocalVisibility after = f.update(before, ctTf(1.5f), st);
    EXPECT_TRUE(st.incremental);
    EXPECT_GT(st.blocksLevelChanged, 0u) << "the edit should move the LOD selection";
    EXPECT_GT(after.layerPoints(), 0u) << "coarse blocks on the volume's faces have layers";
    expectIdentical(after, f.full(ctTf(1.5f)));
}

TEST_P(TfUpdateBy, MovingAnEndPointRecomputesEverythingAndStillMatches) {
    const Field f = field(GetParam());
    const LocalVisibility before = f.full(ctTf(0.f));
    TfUpdateStats st;
    const LocalVisibility after = f.update(before, ctTf(0.f, 1.f, -1100.f), st);
    EXPECT_EQ(st.changed.lo, -INFINITY);
    EXPECT_EQ(st.changed.hi, INFINITY);
    EXPECT_EQ(st.blocksRecomputed, st.blocks);
    expectIdentical(after, f.full(ctTf(0.f, 1.f, -1100.f)));
}

TEST(TfUpdate, AnotherVolumeOrOtherRaysComputeInFullAndSayWhy) {
    const auto small = [] {
        return std::make_shared<const BlockPyramid>(BlockPyramid::build(
            test::makeVolume({32, 32, 32}, [](int i, int j, int k) { return (i + j + k) * 10; })));
    };
    Field f = field();
    f.pyramid = small();
    const LocalVisibility before = f.full(ctTf(0.f));
    Field other = f;
    other.pyramid = small();  // equal content, another object: not known to be the same volume
    TfUpdateStats st;
    expectIdentical(other.update(before, ctTf(0.4f), st), other.full(ctTf(0.4f)));
    EXPECT_FALSE(st.incremental);
    EXPECT_NE(st.reason.find("another volume"), std::string::npos) << st.reason;
    Field moreRays = f;
    moreRays.options.rays = 12;
    moreRays.update(before, ctTf(0.4f), st);
    EXPECT_FALSE(st.incremental);
    EXPECT_NE(st.reason.find("rays"), std::string::npos) << st.reason;
    Field swept = f;
    swept.options.algorithm = VisibilityAlgorithm::Sweep;
    swept.options.rays = kSweepRaysCoarse;
    swept.update(before, ctTf(0.4f), st);
    EXPECT_FALSE(st.incremental);
    EXPECT_NE(st.reason.find("rays"), std::string::npos) << st.reason;  // 8 march rays vs 26
}
