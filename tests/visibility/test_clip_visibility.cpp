// SPDX-License-Identifier: MIT
// The clip-aware local visibility update (shadows_from_removed false) against brute force: the
// ordinary local visibility of a volume whose removed matter was zeroed. Plus: only points within
// r_s of a cut face are traced again, the rest is the unclipped field bit for bit.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>

#include "visibility/local_visibility.h"
#include "visibility/vis_test_util.h"

using namespace voxlight;
using namespace voxlight::visibility;

namespace {

const double kSqrt4Pi = std::sqrt(4.0 * std::numbers::pi);
constexpr float kSigma = 0.05f;  // 1/mm, 1 mm voxels
constexpr int kCoefficients = 16;
constexpr int kRays = 32;
constexpr double kRadius = 8.0;  // voxels
/// The removed half-space is x < kCutX (index = world mm: unit spacing, origin 0).
constexpr double kCutX = 19.5;

LocalVisibilityOptions options() {
    LocalVisibilityOptions o;
    o.coefficients = kCoefficients;
    o.rays = kRays;
    o.radiusVoxels = kRadius;
    return o;
}

/// Homogeneous matter (σt = σ0) everywhere in 40×32×32 voxels, its local visibility on the grid
/// `grid` makes, that field clipped at the plane x = kCutX (x < kCutX removed for the light), and
/// brute force: the field of the volume with the removed matter zeroed.
struct CutCase {
    LocalVisibility base, clipped, truth;
    ClipUpdateStats stats;
};
template <class Grid>
CutCase cutCase(Grid&& grid) {
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const optics::TfTable table(tf);
    const glm::ivec3 dims(40, 32, 32);
    const core::Volume full = test::makeVolume(dims, [](int, int, int) { return 1000; });
    const core::Volume zeroed =
        test::makeVolume(dims, [](int i, int, int) { return i < kCutX ? 0 : 1000; });
    CutCase c;
    c.base = computeLocalVisibility(grid(full, tf), table, options());
    const std::vector<core::HalfSpace> kept = {{{kCutX, 0.0, 0.0}, {1.0, 0.0, 0.0}}};
    c.clipped = clipAwareLocalVisibility(c.base, table, kept, 0, core::Progress::none(), &c.stats);
    c.truth = computeLocalVisibility(grid(zeroed, tf), table, options());
    return c;
}

/// The clipped field against brute force at `points`: the zeroed volume ramps σt linearly over
/// the voxel layer 19..20, which integrates like the sharp cut at 19.5 along any ray crossing
/// it; the midpoint rule (1-voxel steps) on the ramp's two kinks errs by ≤ σ0·Δ/8 per kink in τ,
/// so |ΔV_i| ≤ (σ0/4)·√(4π) (as the slab test of test_local_visibility.cpp): 0.044 at σ0 = 0.05.
/// (Coarse steps meet the ramp at other points, with the same bound per kink.) Also that the cut
/// matters at some point: the clipped field differs from the unclipped one there.
void expectClippedAsZeroed(const CutCase& c, const std::vector<glm::vec3>& points) {
    const double kCutTol = kSigma / 4.0 * kSqrt4Pi;
    bool differsFromUnclipped = false;
    for (const glm::vec3& p : points) {
        float got[16], want[16], before[16];
        c.clipped.sample(p, got);
        c.truth.sample(p, want);
        c.base.sample(p, before);
        for (int i = 0; i < kCoefficients; ++i)
            EXPECT_NEAR(got[i], want[i], kCutTol)
                << "at " << p.x << "," << p.y << "," << p.z << ", coefficient " << i;
        differsFromUnclipped = differsFromUnclipped || std::abs(got[0] - before[0]) > 10 * kCutTol;
    }
    EXPECT_TRUE(differsFromUnclipped) << "the cut must matter at this σ0";
}

}  // namespace

TEST(ClipAwareVisibility, EqualsTheLocalVisibilityOfTheVolumeWithTheRemovedMatterZeroed) {
    // Homogeneous matter (σt = σ0) everywhere; the plane x = 19.5 removes x < 19.5 for the light.
    const CutCase c = cutCase([](const core::Volume& v, const optics::TransferFunction& tf) {
        return test::fullGrid(v, tf);
    });
    std::vector<glm::vec3> points;
    for (const float x : {12.f, 17.f, 20.f, 21.f, 23.f, 26.f, 31.f})
        for (const glm::vec3 p : {glm::vec3(x, 16.f, 16.f), glm::vec3(x, 3.f, 28.f)})
            points.push_back(p);
    expectClippedAsZeroed(c, points);
    const ClipUpdateStats& st = c.stats;
    const glm::ivec3 dims(40, 32, 32);
    // Only the points within r_s of the plane were traced again: x ∈ (11.5, 27.5) of 0..39.
    EXPECT_GT(st.pointsTraced, 0u);
    EXPECT_LE(st.pointsTraced, std::uint64_t(16) * dims.y * dims.z);
    // x ≤ 11: rays never reach the kept side; and beyond them some points (126 here) whose every
    // ray the plane cuts off entirely — also empty space's value without a ray, counted since
    // Stop 52 (they had been counted neither traced nor cleared).
    EXPECT_GT(st.pointsCleared, std::uint64_t(12) * dims.y * dims.z);
    EXPECT_LT(st.pointsCleared, std::uint64_t(13) * dims.y * dims.z);
    EXPECT_EQ(st.points, std::uint64_t(48) * 32 * 32);  // 3×2×2 blocks of 16³
    // Rays are marched only where a face cuts them (or, outside a face, only their kept parts):
    // a point on the kept side at distance d from the plane has about (1 − d/R)/2 of its rays
    // cut, so well under half of the traced points' rays are marched (the field has 4× fewer).
    EXPECT_GT(st.raysTraced, 0u);
    EXPECT_LT(st.raysTraced, st.pointsTraced * kRays / 2);
}

TEST(ClipAwareVisibility, HeterogeneousMatterUnderEitherIntegratorEqualsTheZeroedVolume) {
    // Varying matter, so a cut ray's depth in its removed part differs from ray to ray: the
    // update marches only the rays the plane cuts near the kept side (adding their change to the
    // unclipped value) and the kept parts alone outside it; both against brute force, with the
    // unclipped field from the march and from the line sweep (whose own ray depths the
    // difference carries).
    constexpr float kPeak = 0.08f;  // σt at value 1000
    const optics::TransferFunction tf = test::rampTf(kPeak);
    const optics::TfTable table(tf);
    const glm::ivec3 dims(40, 32, 32);
    auto wavy = [](int i, int j, int k) {
        return int(500.0 + 450.0 * std::sin(0.4 * i) * std::cos(0.3 * j + 0.2 * k));
    };
    const core::Volume full = test::makeVolume(dims, wavy);
    const core::Volume zeroed =
        test::makeVolume(dims, [&](int i, int j, int k) { return i < kCutX ? 0 : wavy(i, j, k); });
    const std::vector<core::HalfSpace> kept = {{{kCutX, 0.0, 0.0}, {1.0, 0.0, 0.0}}};
    for (const VisibilityAlgorithm algorithm :
         {VisibilityAlgorithm::March, VisibilityAlgorithm::Sweep}) {
        LocalVisibilityOptions o = options();
        o.algorithm = algorithm;
        if (algorithm == VisibilityAlgorithm::Sweep) o.rays = 26, o.coefficients = 4;
        const LocalVisibility base = computeLocalVisibility(test::fullGrid(full, tf), table, o);
        ClipUpdateStats st;
        const LocalVisibility clipped =
            clipAwareLocalVisibility(base, table, kept, 0, core::Progress::none(), &st);
        const LocalVisibility truth = computeLocalVisibility(test::fullGrid(zeroed, tf), table, o);
        // The cut's ramp bound as above, at the peak σt.
        const double kCutTol = kPeak / 4.0 * kSqrt4Pi;
        double worst = 0.0;
        for (int x = 8; x <= 31; ++x)
            for (const glm::vec3 p :
                 {glm::vec3(float(x), 16.f, 16.f), glm::vec3(float(x), 5.f, 27.f),
                  glm::vec3(float(x), 24.f, 9.f)}) {
                float got[16], want[16];
                clipped.sample(p, got);
                truth.sample(p, want);
                for (int i = 0; i < o.coefficients; ++i) {
                    EXPECT_NEAR(got[i], want[i], kCutTol)
                        << int(algorithm) << " at " << x << "," << p.y << "," << p.z << " c" << i;
                    worst = std::max(worst, double(std::abs(got[i] - want[i])));
                }
            }
        EXPECT_GT(st.pointsTraced, 0u);
        EXPECT_LT(st.raysTraced, st.pointsTraced * std::uint64_t(o.rays) / 2);
        std::printf("%s: worst |ΔV_i| %.4f (bound %.4f), %llu rays for %llu points\n",
                    algorithm == VisibilityAlgorithm::March ? "march" : "sweep", worst, kCutTol,
                    static_cast<unsigned long long>(st.raysTraced),
                    static_cast<unsigned long long>(st.pointsTraced));
    }
}

TEST(ClipAwareVisibility, AFieldOfManyRaysIsUpdatedToo) {
    // The scene's rays go up to 4096: the update's per-ray arrays must hold any count (a fixed
    // 128 stopped an update of a field with more rays with an internal error). Small, as it runs
    // under the sanitizers too.
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const optics::TfTable table(tf);
    const glm::ivec3 dims(20, 12, 12);
    const core::Volume full = test::makeVolume(dims, [](int, int, int) { return 1000; });
    const core::Volume zeroed =
        test::makeVolume(dims, [](int i, int, int) { return i < 9.5 ? 0 : 1000; });
    LocalVisibilityOptions o = options();
    o.rays = 160;
    o.coefficients = 4;
    o.radiusVoxels = 6.0;
    const LocalVisibility base = computeLocalVisibility(test::fullGrid(full, tf), table, o);
    const std::vector<core::HalfSpace> kept = {{{9.5, 0.0, 0.0}, {1.0, 0.0, 0.0}}};
    const LocalVisibility clipped = clipAwareLocalVisibility(base, table, kept);
    const LocalVisibility truth = computeLocalVisibility(test::fullGrid(zeroed, tf), table, o);
    for (const float x : {5.f, 9.f, 10.f, 12.f, 15.f}) {
        float got[16], want[16];
        clipped.sample({x, 6.f, 6.f}, got);
        truth.sample({x, 6.f, 6.f}, want);
        for (int i = 0; i < 4; ++i) EXPECT_NEAR(got[i], want[i], kSigma / 4.0 * kSqrt4Pi) << x;
    }
}

TEST(ClipAwareVisibility, EdgePointsPastTheVolumeOfASweptCoarseFieldAreComputedAfresh) {
    // A slab of dense matter just inside the +x face of a volume whose x size (46) is no multiple
    // of the blocks; blocks at level 1 and 2, the line sweep. Points of the partial edge blocks
    // past the volume are clamped onto it and store a copy of another point's value
    // (sweepBlocks), so the update cannot start from it: cut at x = 44 (keeping x > 44), nothing
    // is left for the light, and the field must be empty space's there (a first version added
    // the cut rays' change to the copied value: V_0 1.9 instead of √(4π) ≈ 3.54).
    const optics::TransferFunction tf = test::rampTf(2.f);
    const optics::TfTable table(tf);
    const glm::ivec3 dims(46, 32, 32);
    const core::Volume slab =
        test::makeVolume(dims, [](int i, int, int) { return i == 42 || i == 43 ? 1000 : 0; });
    const std::vector<core::HalfSpace> kept = {{{44.0, 0.0, 0.0}, {1.0, 0.0, 0.0}}};
    for (const int level : {1, 2}) {
        LocalVisibilityOptions o;
        o.algorithm = VisibilityAlgorithm::Sweep;
        o.rays = 26;
        o.coefficients = 4;
        o.radiusVoxels = 8.0;
        auto pyramid = std::make_shared<const BlockPyramid>(BlockPyramid::build(slab));
        const LocalVisibility base =
            computeLocalVisibility(test::uniformGrid(pyramid, level), table, o);
        const LocalVisibility clipped = clipAwareLocalVisibility(base, table, kept);
        for (const float x : {44.f, 44.5f, 45.f})
            for (const glm::vec3 p : {glm::vec3(x, 16.f, 16.f), glm::vec3(x, 3.f, 29.f)}) {
                float got[16];
                clipped.sample(p, got);
                // Empty space: V = 1 on every ray projects onto (√(4π), 0, …) up to the lattice
                // weights' own projection error (≤ 5e-4 seen; their correction is in float).
                constexpr double kProjectionTol = 1e-3;
                EXPECT_NEAR(got[0], kSqrt4Pi, kProjectionTol) << "level " << level << " x " << x;
                for (int i = 1; i < 4; ++i)
                    EXPECT_NEAR(got[i], 0.0, kProjectionTol) << level << " " << x;
            }
    }
}

TEST(ClipAwareVisibility, PointsFarFromEveryFaceKeepTheUnclippedValuesBitForBit) {
    const optics::TransferFunction tf = test::rampTf(0.2f);
    const optics::TfTable table(tf);
    const core::Volume v = test::makeVolume({48, 40, 36}, [](int i, int j, int k) {
        return int(500 + 400 * std::sin(0.3 * i + 0.2 * j) * std::cos(0.25 * k));
    });
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const auto grid = std::make_shared<const MultiresGrid>(
        pyr, selectLod(*pyr, tf, table, LodBudget::fromReduction(4.0, v.voxelCount())));
    LocalVisibilityOptions o;
    o.coefficients = 4;
    o.rays = 16;
    const LocalVisibility base = computeLocalVisibility(grid, table, o);
    // No half-space: the same field.
    const LocalVisibility same = clipAwareLocalVisibility(base, table, {});
    ASSERT_EQ(same.bytes(), base.bytes());
    // An oblique plane near one corner: far blocks are untouched, and the result is the same for
    // any thread count.
    const std::vector<core::HalfSpace> kept = {
        {{40.0, 0.0, 0.0}, glm::normalize(glm::dvec3(-1.0, -0.3, 0.2))}};
    ClipUpdateStats st;
    const LocalVisibility one =
        clipAwareLocalVisibility(base, table, kept, 1, core::Progress::none(), &st);
    const LocalVisibility two = clipAwareLocalVisibility(base, table, kept, 2);
    EXPECT_GT(st.blocksTouched, 0u);
    EXPECT_LT(st.blocksTouched, st.blocks);
    EXPECT_LT(st.pointsTraced + st.pointsCleared, st.points);
    const double R = o.radiusVoxels;
    for (std::size_t b = 0; b < pyr->blockCount(); ++b) {
        const int l = grid->level(b);
        if (l == kNone) continue;
        const int n = levelResolution(l);
        const std::size_t floats = std::size_t(n) * n * n * 4;
        EXPECT_EQ(std::memcmp(same.blockData(b), base.blockData(b), floats * sizeof(float)), 0);
        EXPECT_EQ(std::memcmp(one.blockData(b), two.blockData(b), floats * sizeof(float)), 0);
        for (int k = 0; k < n; ++k)
            for (int j = 0; j < n; ++j)
                for (int i = 0; i < n; ++i) {
                    const glm::vec3 x =
                        glm::min(grid->samplePosition(b, l, i, j, k), glm::vec3(v.dims() - 1));
                    if (kept[0].distance(glm::dvec3(x)) < R) continue;
                    const std::size_t at = ((std::size_t(k) * n + j) * n + i) * 4;
                    for (int c = 0; c < 4; ++c)
                        ASSERT_EQ(one.blockData(b)[at + c], base.blockData(b)[at + c]);
                }
    }
}

TEST(ClipAwareVisibility, CoarseBlocksBoundaryLayersAreClippedToo) {
    // The brute force above on a grid of 8³ blocks: on the volume's face y = 0 the field reads
    // the blocks' boundary layers (local_visibility.h), which the update must clip as well.
    const CutCase c = cutCase([](const core::Volume& v, const optics::TransferFunction&) {
        return test::uniformGrid(std::make_shared<const BlockPyramid>(BlockPyramid::build(v)), 1);
    });
    ASSERT_GT(c.base.layerPoints(), 0u);
    std::vector<glm::vec3> points;  // on the face: the layers alone
    for (const float x : {12.f, 17.f, 20.f, 21.f, 23.f, 26.f, 31.f})
        points.emplace_back(x, 0.f, 16.f);
    expectClippedAsZeroed(c, points);
}
