// SPDX-License-Identifier: MIT
// The line sweep of local visibility (visibility/local_visibility.h, algorithm Sweep): its lattice
// directions, empty space, a homogeneous slab's closed form, the continuous model by brute force
// at every traced point (against which the march is measured too), and determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <numbers>
#include <string>

#include "core/half_space.h"
#include "core/rng.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "visibility/local_visibility.h"
#include "visibility/vis_test_util.h"

using namespace voxlight;
using namespace voxlight::visibility;

namespace {

const double kSqrt4Pi = std::sqrt(4.0 * std::numbers::pi);

LocalVisibilityOptions sweepOptions(int rays, int coefficients, double radius = 16.0) {
    LocalVisibilityOptions o;
    o.algorithm = VisibilityAlgorithm::Sweep;
    o.rays = rays;
    o.coefficients = coefficients;
    o.radiusVoxels = radius;
    // Groups of 4³ blocks, as on a 256³ volume: the test volumes are small enough that the
    // automatic choice would walk each block alone (TheWorkUnitChangesNoBit compares the two).
    o.sweepGroupBlocks = 4;
    return o;
}

/// Optical depth of the continuous model (σt of the trilinear value) along origin + t·d (d in
/// voxels per mm), t ∈ [0, length] mm clipped to the volume's box, by the midpoint rule at
/// kFineStepMm: the brute-force truth both integrators approximate.
constexpr double kFineStepMm = 0.02;
double fineOpticalDepth(const core::Volume& v, const optics::TfTable& table,
                        const glm::dvec3& origin, const glm::dvec3& dIn, double length) {
    const glm::dvec3 top(v.dims() - 1);
    // Components at rounding level (a rotated grid's lattice directions) are 0, as in the march:
    // a ray along a face of the box would otherwise be clipped to length 0.
    glm::dvec3 d = dIn;
    const double largest = std::max({std::abs(d.x), std::abs(d.y), std::abs(d.z)});
    for (int a = 0; a < 3; ++a)
        if (std::abs(d[a]) <= 1e-9 * largest) d[a] = 0.0;
    for (int a = 0; a < 3; ++a) {
        if (d[a] > 0.0) length = std::min(length, (top[a] - origin[a]) / d[a]);
        if (d[a] < 0.0) length = std::min(length, -origin[a] / d[a]);
    }
    double tau = 0.0;
    v.visit([&](const auto& view) {
        const int n = std::max(1, int(std::ceil(length / kFineStepMm)));
        const double dt = length / n;
        for (int i = 0; i < n; ++i) {
            const glm::dvec3 p = origin + (i + 0.5) * dt * d;
            tau += double(table.extinction(view.sample(float(p.x), float(p.y), float(p.z)))) * dt;
        }
    });
    return tau;
}

/// Largest |V_i − V_i(truth)| over every traced point of `vis` (each compared point's truth: the
/// projection of fineOpticalDepth's transmittance along the field's own directions), and how
/// many points were compared.
struct FieldError {
    double maxV0 = 0.0, meanV0 = 0.0, maxAny = 0.0;
    int compared = 0;
    glm::vec3 worst{0.f};
    int worstLevel = 0;
};
FieldError errorAgainstTruth(const core::Volume& v, const MultiresGrid& grid,
                             const optics::TfTable& table, const LocalVisibility& vis,
                             int onlyLevel) {
    const sh::SphereSamples& dirs = vis.directions();
    const int C = vis.coefficients();
    const core::Geometry& g = v.geometry();
    std::vector<double> y(16);
    FieldError e;
    const glm::vec3 top(grid.dims() - 1);
    for (std::size_t b = 0; b < grid.pyramid().blockCount(); ++b) {
        const int l = grid.level(b);
        if (l == kNone || l != onlyLevel) continue;
        const int n = levelResolution(l);
        const float* data = vis.blockData(b);
        for (int k = 0; k < n; ++k)
            for (int j = 0; j < n; ++j)
                for (int i = 0; i < n; ++i, data += C) {
                    if ((i + 3 * j + 5 * k) % 5 != 0) continue;  // a fifth of the points
                    const glm::vec3 x = grid.samplePosition(b, l, i, j, k);
                    // Points of a partial edge block past the volume are clamped onto it and
                    // marched by both algorithms: left out.
                    if (x != glm::min(x, top)) continue;
                    if (!visibilityNeeded(grid, x, float(levelSpacing(l)))) continue;
                    std::vector<double> truth(std::size_t(C), 0.0);
                    for (std::size_t r = 0; r < dirs.size(); ++r) {
                        const glm::dvec3 d =
                            (glm::transpose(g.direction) * dirs.directions[r]) / g.spacing;
                        const double T = std::exp(
                            -fineOpticalDepth(v, table, glm::dvec3(x), d,
                                              vis.radiusVoxels() * core::minComponent(g.spacing)));
                        sh::evalShUnitDouble(sh::shBandForCount(C), dirs.directions[r], y);
                        for (int q = 0; q < C; ++q)
                            truth[std::size_t(q)] += dirs.weights[r] * T * y[std::size_t(q)];
                    }
                    for (int q = 0; q < C; ++q) {
                        const double d = std::abs(double(data[q]) - truth[std::size_t(q)]);
                        e.maxAny = std::max(e.maxAny, d);
                        if (q == 0) {
                            if (d > e.maxV0) e.worst = x, e.worstLevel = l;
                            e.maxV0 = std::max(e.maxV0, d);
                            e.meanV0 += d;
                        }
                    }
                    ++e.compared;
                }
    }
    if (e.compared) e.meanV0 /= e.compared;
    return e;
}

/// Bone slabs with partial-volume faces, an oblique sheet, textured soft tissue and air (HU at
/// voxel i, j, k of a 48 × 40 × 44 volume) ...
int boneSlabsValue(int i, int j, int k) {
    if (k >= 10 && k <= 13) return 900 + 37 * ((i + 2 * j) % 5);
    if (std::abs(i - 2 * j + 3) < 2) return 500 + 10 * k;
    if (k > 36) return -1000;
    return 40 + (i * 7 + j * 3 + k) % 11;
}

/// ... under a TF that reaches σt 3/mm in bone (dense sub-steps) and is empty below 100 HU.
optics::TransferFunction boneSlabsTf() {
    const glm::vec3 c(1.f);
    return optics::TransferFunction({{-1000.f, c, 0.f, glm::vec3(0.f)},
                                     {100.f, c, 0.f, glm::vec3(0.f)},
                                     {400.f, c, 0.2f, glm::vec3(0.f)},
                                     {1000.f, c, 3.f, glm::vec3(0.f)},
                                     {3071.f, c, 3.f, glm::vec3(0.f)}},
                                    {400.f, 1000.f}, "bone");
}

}  // namespace

TEST(LineSweep, LatticeDirectionsArePrimitiveSymmetricAndIntegrateTheLowBandsExactly) {
    constexpr double kExactTol = 1e-9;  // as VisibilityDirections' test: double sums of ≤ 98 terms
    core::Geometry g;
    g.spacing = {0.8, 0.8, 2.5};  // anisotropic: the world directions are not the steps'
    for (const auto& [rays, coefficients] : {std::pair{26, 4}, {26, 9}, {98, 16}}) {
        const std::vector<glm::ivec3> steps = latticeSteps(rays);
        ASSERT_EQ(int(steps.size()), rays);
        for (const glm::ivec3& v : steps) {
            EXPECT_NE(std::find(steps.begin(), steps.end(), -v), steps.end());
            EXPECT_LE(std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)}), rays == 26 ? 1 : 2);
        }
        const sh::SphereSamples s = latticeDirections(g, rays, coefficients);  // throws if w ≤ 0
        std::vector<double> sum(std::size_t(coefficients), 0.0), y(16);
        double total = 0.0;
        for (std::size_t k = 0; k < s.size(); ++k) {
            EXPECT_GT(s.weights[k], 0.0);
            total += s.weights[k];
            // The world direction of step k.
            const glm::dvec3 w = glm::normalize(glm::dvec3(steps[k]) * g.spacing);
            EXPECT_NEAR(glm::dot(w, s.directions[k]), 1.0, 1e-12);
            sh::evalShUnitDouble(sh::shBandForCount(coefficients), s.directions[k], y);
            for (int i = 0; i < coefficients; ++i)
                sum[std::size_t(i)] += s.weights[k] * y[std::size_t(i)];
        }
        EXPECT_NEAR(total, 4.0 * std::numbers::pi, kExactTol);
        EXPECT_NEAR(sum[0], kSqrt4Pi, kExactTol);
        for (int i = 1; i < coefficients; ++i) EXPECT_NEAR(sum[std::size_t(i)], 0.0, kExactTol);
    }
    EXPECT_THROW(latticeSteps(32), InputError);
    // Voxels 300× longer on one axis crowd the steps into a few world directions: no positive
    // weights exist. An input error that names the march (it was an internal error); 100:1 holds.
    core::Geometry flat;
    flat.spacing = {1.0, 1.0, 100.0};
    EXPECT_NO_THROW(latticeDirections(flat, 26, 4));
    flat.spacing.z = 300.0;
    try {
        (void)latticeDirections(flat, 26, 4);
        ADD_FAILURE() << "300:1 voxels accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "method.params.algorithm");
        EXPECT_NE(std::string(e.what()).find("\"march\""), std::string::npos) << e.what();
    }
    LocalVisibilityOptions o = sweepOptions(32, 4);
    const core::Volume v = test::makeVolume({16, 16, 16}, [](int, int, int) { return 0; });
    EXPECT_THROW(computeLocalVisibility(test::fullGrid(v, test::rampTf(1.f)),
                                        optics::TfTable(test::rampTf(1.f)), o),
                 InputError);
}

TEST(LineSweep, EmptySpaceSeesEverything) {
    const core::Volume v = test::makeVolume({32, 32, 32}, [](int, int, int) { return 0; });
    const auto grid = test::fullGrid(v, test::rampTf(1.f));
    const LocalVisibility vis =
        computeLocalVisibility(grid, optics::TfTable(test::rampTf(1.f)), sweepOptions(26, 9));
    ASSERT_GT(vis.raysTraced(), 0u);
    constexpr float kFloatTol = 2e-6f;  // as LocalVisibility.EmptySpaceSeesEverything
    for (glm::vec3 p : {glm::vec3(0.f), glm::vec3(15.5f, 3.f, 31.f), glm::vec3(7.f, 22.f, 13.f)}) {
        float out[16];
        vis.sample(p, out);
        EXPECT_NEAR(out[0], kSqrt4Pi, kFloatTol);
        for (int i = 1; i < 9; ++i) EXPECT_NEAR(out[i], 0.f, kFloatTol) << i;
    }
}

TEST(LineSweep, InsideAHomogeneousSlabMatchesTheProjectedClosedForm) {
    // LocalVisibility.InsideAHomogeneousSlab… with the sweep's 98 lattice directions.
    constexpr float kSigma = 0.05f;
    const core::Volume v = test::makeVolume(
        {40, 40, 60}, [](int, int, int k) { return k >= 20 && k <= 39 ? 1000 : 0; });
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const LocalVisibility vis =
        computeLocalVisibility(test::fullGrid(v, tf), optics::TfTable(tf), sweepOptions(98, 16));
    const glm::vec3 x(20.f, 20.f, 35.f);
    const auto expected = sh::projectFunction(3, vis.directions(), [&](const glm::dvec3& w) {
        double d = 16.0;
        if (w.z > 0) d = std::min(d, (39.5 - x.z) / w.z);
        if (w.z < 0) d = std::min(d, (19.5 - x.z) / w.z);
        return std::exp(-double(kSigma) * d);
    });
    float got[16];
    vis.sample(x, got);
    // The slab test's bound (pre-integration with two kinks per face: |ΔT| ≤ σ0/4 per ray).
    const double kSlabTol = kSigma / 4.0 * kSqrt4Pi;
    for (int i = 0; i < 16; ++i) EXPECT_NEAR(got[i], expected[std::size_t(i)], kSlabTol) << i;
    EXPECT_LT(expected[0], kSqrt4Pi - 10 * kSlabTol);
    EXPECT_GT(expected[2], 5 * kSlabTol);
}

TEST(LineSweep, RaysEndingJustBeforeTheBoxFaceKeepTheirDepth) {
    // Matter up to the box faces (a CT cut by its field of view): a ray whose end lies in the
    // last, partial lattice step before the face, more than a sub-step past the last computed one,
    // must integrate up to its end like any other (it read the depth of sub-steps never computed,
    // 0: the ray counted as open, V_i off by up to 0.10 here). Only the 98 rays leave such a step
    // (a step component of 2: part of a step before a face; 26 rays leave at most one sub-step).
    // Every stored point of a homogeneous cube, at level 0 and at a coarser level (the shifted
    // lattice), against the projected closed form exp(−σ0·min(R, box exit)).
    constexpr float kSigma = 0.05f;
    const core::Volume v = test::makeVolume({24, 24, 24}, [](int, int, int) { return 1000; });
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const optics::TfTable table(tf);
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    // σt is constant, so pre-integration is exact and only float rounding remains.
    const double kCubeTol = 1e-4 * kSqrt4Pi;
    for (const int rays : {kSweepRaysCoarse, kSweepRaysFine})
        for (const double reduction : {1.0, 8.0}) {
            const auto grid = std::make_shared<const MultiresGrid>(
                pyr,
                selectLod(*pyr, tf, table, LodBudget::fromReduction(reduction, v.voxelCount())));
            const LocalVisibility vis =
                computeLocalVisibility(grid, table, sweepOptions(rays, 4, 8.0));
            const glm::vec3 top(grid->dims() - 1);
            double worst = 0.0;
            int compared = 0, coarse = 0;
            for (std::size_t b = 0; b < pyr->blockCount(); ++b) {
                const int l = grid->level(b);
                if (l == kNone) continue;
                const int n = levelResolution(l);
                const float* data = vis.blockData(b);
                for (int k = 0; k < n; ++k)
                    for (int j = 0; j < n; ++j)
                        for (int i = 0; i < n; ++i, data += 4) {
                            const glm::vec3 x = grid->samplePosition(b, l, i, j, k);
                            if (x != glm::min(x, top)) continue;  // clamped onto the volume
                            const auto expected =
                                sh::projectFunction(1, vis.directions(), [&](const glm::dvec3& w) {
                                    return std::exp(-double(kSigma) *
                                                    test::boxExitDistance(glm::dvec3(x), w,
                                                                          glm::dvec3(23.0), 8.0));
                                });
                            for (int c = 0; c < 4; ++c)
                                worst = std::max(
                                    worst, std::abs(double(data[c]) - expected[std::size_t(c)]));
                            ++compared;
                            coarse += l > 0;
                        }
            }
            std::printf(
                "cube %d rays 1:%g, %d points (%d coarse): largest |V_i - closed form| %.2e\n",
                rays, reduction, compared, coarse, worst);
            ASSERT_GT(compared, 100);
            if (reduction > 1.0) {
                EXPECT_GT(coarse, 100);
            }
            EXPECT_LT(worst, kCubeTol) << rays << " rays 1:" << reduction;
        }
}

TEST(LineSweep, FollowsTheContinuousModelAsCloselyAsTheMarch) {
    // Bone slabs with partial-volume faces (σt up to 3/mm: dense sub-steps), an oblique sheet,
    // textured soft tissue and air, under a budget that puts blocks at mixed levels (level-0
    // blocks are swept, coarser ones marched along the same directions).
    const core::Volume v = test::makeVolume({48, 40, 44}, boneSlabsValue);
    const optics::TransferFunction tf = boneSlabsTf();
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const optics::TfTable table(tf);
    const auto grid = std::make_shared<const MultiresGrid>(
        pyr, selectLod(*pyr, tf, table, LodBudget::fromReduction(3.0, v.voxelCount())));
    int levels[kLevels] = {};  // blocks per level (kNone not counted)
    for (std::size_t b = 0; b < pyr->blockCount(); ++b)
        if (grid->level(b) != kNone) ++levels[grid->level(b)];
    ASSERT_GT(levels[0], 0);
    ASSERT_GT(levels[1] + levels[2], 0);
    const LocalVisibility sweep = computeLocalVisibility(grid, table, sweepOptions(26, 4, 12.0));
    LocalVisibilityOptions mo = sweepOptions(32, 4, 12.0);
    mo.algorithm = VisibilityAlgorithm::March;
    const LocalVisibility march = computeLocalVisibility(grid, table, mo);
    // Both integrate pre-integrated steps with the value linear between their ends (split where
    // deeper than kRefineDepth); the march ends with a partial step pre-integrated to the end's
    // value, the sweep with that fraction of the sub-step's depth (P linear within a sub-step).
    // The sweep's sub-steps end at every voxel plane a line crosses (where the trilinear value
    // kinks) and stay within about a voxel; the march steps 1, 2 or 4 voxels as the LOD says,
    // across voxel planes, and jumps across invisible cells. Measured (V_0, scale √(4π) = 3.54):
    // sweep max 0.021 / 0.027 / 0.005 at levels 0 / 1 / 2, means 0.0027 / 0.0027 / 0.0010 (with
    // a pre-integrated partial end, as the march's: 0.020 / 0.027 / 0.005, 0.0024 / 0.0020 /
    // 0.0003); march max 0.16 / 0.63 / 0.25, means 0.031 / 0.12 / 0.045. kSweepTol (2 % of
    // √(4π)) is 2.6× the sweep's largest error; its mean must stay below a fifth of the march's.
    const double kSweepTol = 0.02 * kSqrt4Pi;
    for (int l = 0; l < 3; ++l) {
        const FieldError es = errorAgainstTruth(v, *grid, table, sweep, l);
        const FieldError em = errorAgainstTruth(v, *grid, table, march, l);
        std::printf(
            "level %d, V_0 against the continuous model: sweep max %.4f mean %.5f, march "
            "max %.4f mean %.5f (%d points)\n",
            l, es.maxV0, es.meanV0, em.maxV0, em.meanV0, es.compared);
        ASSERT_GT(es.compared, l == 2 ? 10 : 500) << l;
        EXPECT_LT(es.maxV0, kSweepTol) << l;
        EXPECT_LT(es.maxAny, kSweepTol) << l;
        EXPECT_LT(es.meanV0, 0.2 * em.meanV0) << l;
    }
}

TEST(LineSweep, FollowsTheContinuousModelOnAnAnisotropicObliqueGrid) {
    // LocalVisibility.RaysRespectAnisotropicSpacing…'s grid (spacing 0.8 × 1.0 × 1.5 mm, axes
    // rotated 30° about world z) with an oblique dense sheet besides the slab: the lattice steps
    // are not the world directions, their lengths differ per axis and R is 16 × 0.8 mm.
    core::Volume v = test::makeVolume({40, 40, 30}, [](int i, int j, int k) {
        if (std::abs(i - j + k - 10) < 2) return 900;
        return k >= 10 && k <= 19 ? 600 : 0;
    });
    core::Geometry& g = v.geometry();
    g.spacing = {0.8, 1.0, 1.5};
    const double a = 30.0 * std::numbers::pi / 180.0;
    g.direction = glm::dmat3(std::cos(a), std::sin(a), 0, -std::sin(a), std::cos(a), 0, 0, 0, 1);
    const optics::TransferFunction tf = test::rampTf(1.f);
    const optics::TfTable table(tf);
    const auto grid = test::fullGrid(v, tf);
    const LocalVisibility sweep = computeLocalVisibility(grid, table, sweepOptions(26, 4));
    const FieldError e = errorAgainstTruth(v, *grid, table, sweep, 0);
    LocalVisibilityOptions mo = sweepOptions(32, 4);
    mo.algorithm = VisibilityAlgorithm::March;
    const FieldError em =
        errorAgainstTruth(v, *grid, table, computeLocalVisibility(grid, table, mo), 0);
    std::printf(
        "anisotropic oblique grid, V_0: sweep max %.4f mean %.5f, march max %.4f mean %.5f "
        "(%d points)\n",
        e.maxV0, e.meanV0, em.maxV0, em.meanV0, e.compared);
    ASSERT_GT(e.compared, 1000);
    // The sheet is dense (σt 0.9/mm on 1.5 mm voxels: τ ≈ 1.4 per voxel), where a step's linear
    // value model errs most. Measured: sweep max 0.059 mean 0.0035 (0.060 / 0.0033 with a
    // pre-integrated partial end), march (at full resolution here, 0.8 mm steps) max 0.048 mean
    // 0.0036; before the sweep's sub-steps were also bounded by
    // the smallest spacing in mm, 0.089 / 0.0045. The sweep must stay within 4 % of √(4π)
    // everywhere and its mean at most the march's.
    EXPECT_LT(e.maxAny, 0.04 * kSqrt4Pi);
    EXPECT_LT(e.meanV0, em.meanV0);
}

TEST(LineSweep, AClipAwareUpdateOfASweptFieldMarchesItsLatticeDirections) {
    // Homogeneous matter; the plane x = 19.5 removes x < 19.5 for the light (test_clip_visibility's
    // case). The points near the plane are marched again along the field's own lattice
    // directions; the result matches the sweep of the volume with that matter zeroed.
    constexpr float kSigma = 0.05f;
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const optics::TfTable table(tf);
    const glm::ivec3 dims(40, 32, 32);
    const core::Volume full = test::makeVolume(dims, [](int, int, int) { return 1000; });
    const core::Volume zeroed =
        test::makeVolume(dims, [](int i, int, int) { return i < 19.5 ? 0 : 1000; });
    const LocalVisibility base =
        computeLocalVisibility(test::fullGrid(full, tf), table, sweepOptions(26, 4));
    const std::vector<core::HalfSpace> kept = {{{19.5, 0.0, 0.0}, {1.0, 0.0, 0.0}}};
    const LocalVisibility clipped = clipAwareLocalVisibility(base, table, kept);
    EXPECT_EQ(clipped.algorithm(), VisibilityAlgorithm::Sweep);
    const LocalVisibility truth =
        computeLocalVisibility(test::fullGrid(zeroed, tf), table, sweepOptions(26, 4));
    // The clip-aware march cuts at the plane exactly, the zeroed volume ramps σt over one voxel
    // layer: ≤ (σ0/4)·√(4π) per coefficient (test_clip_visibility's bound).
    const double kCutTol = kSigma / 4.0 * kSqrt4Pi;
    bool differs = false;
    for (const float x : {12.f, 17.f, 20.f, 21.f, 23.f, 26.f, 31.f}) {
        float got[16], want[16], before[16];
        const glm::vec3 p(x, 16.f, 16.f);
        clipped.sample(p, got);
        truth.sample(p, want);
        base.sample(p, before);
        for (int i = 0; i < 4; ++i) EXPECT_NEAR(got[i], want[i], kCutTol) << x << " " << i;
        differs = differs || std::abs(got[0] - before[0]) > 10 * kCutTol;
    }
    EXPECT_TRUE(differs);
}

/// A smooth wavy volume under a ramp TF at 1:3, which selects blocks at level 0 and coarser.
struct WavyField {
    std::shared_ptr<const BlockPyramid> pyramid;
    optics::TfTable table{test::rampTf(0.2f)};
    std::shared_ptr<const MultiresGrid> grid;
};
WavyField wavyField(const glm::ivec3& dims) {
    const core::Volume v = test::makeVolume(dims, [](int i, int j, int k) {
        return int(500 + 400 * std::sin(0.3 * i + 0.2 * j) * std::cos(0.25 * k));
    });
    const optics::TransferFunction tf = test::rampTf(0.2f);
    WavyField f;
    f.pyramid = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    f.grid = std::make_shared<const MultiresGrid>(
        f.pyramid,
        selectLod(*f.pyramid, tf, f.table, LodBudget::fromReduction(3.0, v.voxelCount())));
    return f;
}

/// Every stored block of `a` and `b` (on `grid`, C coefficients) holds the same bits.
void expectSameBits(const MultiresGrid& grid, const LocalVisibility& a, const LocalVisibility& b,
                    int C, const std::string& what) {
    ASSERT_EQ(a.bytes(), b.bytes());
    for (std::size_t blk = 0; blk < grid.pyramid().blockCount(); ++blk) {
        if (grid.level(blk) == kNone) continue;
        const std::size_t n = std::size_t(std::pow(levelResolution(grid.level(blk)), 3)) * C;
        EXPECT_EQ(std::memcmp(a.blockData(blk), b.blockData(blk), n * sizeof(float)), 0)
            << what << ", block " << blk;
    }
}

TEST(LineSweep, IdenticalForAnyThreadCount) {
    const WavyField f = wavyField({48, 40, 36});
    LocalVisibilityOptions o = sweepOptions(26, 9);
    o.threads = 1;
    const LocalVisibility a = computeLocalVisibility(f.grid, f.table, o);
    o.threads = 2;
    const LocalVisibility b = computeLocalVisibility(f.grid, f.table, o);
    expectSameBits(*f.grid, a, b, 9, "1 against 2 threads");
}

// The sweep reads its voxels from the pyramid's copy: int16 for integral data, float otherwise
// (BlockPyramid::flatVoxels). Both must give the same field bit for bit: the same volume as
// int16 and as float, the float one made non-integral by half a unit at one air voxel whose
// neighbourhood within r_s + 2 voxels is transparent under the TF (so no ray's depth can move).
TEST(LineSweep, TheInt16AndFloatVoxelCopiesGiveTheSameField) {
    const glm::ivec3 dims(48, 40, 44);
    const auto value = boneSlabsValue;
    const core::Volume ints = test::makeVolume(dims, value);
    core::Volume floats(ints.geometry(), core::VoxelType::Float32);
    for (int k = 0; k < dims.z; ++k)
        for (int j = 0; j < dims.y; ++j)
            for (int i = 0; i < dims.x; ++i)
                floats.dataAs<float>()[floats.linearIndex(i, j, k)] = float(value(i, j, k));
    floats.dataAs<float>()[floats.linearIndex(47, 0, 43)] = -1000.5f;
    const optics::TransferFunction tf = boneSlabsTf();
    const optics::TfTable table(tf);
    std::shared_ptr<const MultiresGrid> grids[2];
    const core::Volume* volumes[2] = {&ints, &floats};
    for (int n = 0; n < 2; ++n) {
        auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(*volumes[n]));
        grids[n] = std::make_shared<const MultiresGrid>(
            pyr, selectLod(*pyr, tf, table, LodBudget::fromReduction(3.0, ints.voxelCount())));
    }
    ASSERT_NE(grids[0]->pyramid().flatVoxels().i, nullptr);
    ASSERT_NE(grids[1]->pyramid().flatVoxels().f, nullptr);
    for (std::size_t b = 0; b < grids[0]->pyramid().blockCount(); ++b)
        ASSERT_EQ(grids[0]->level(b), grids[1]->level(b)) << b;
    const LocalVisibilityOptions o = sweepOptions(26, 4, 12.0);
    expectSameBits(*grids[0], computeLocalVisibility(grids[0], table, o),
                   computeLocalVisibility(grids[1], table, o), 4, "int16 against float copy");
}

// A point's optical depths are fixed-point differences along its line, so which points share a
// line (the group of blocks a walk runs through, the blocks a TF update recomputes) changes no
// bit by construction; here checked for every stored point, lines through 1 to 8³ blocks.
TEST(LineSweep, TheWorkUnitChangesNoBit) {
    const WavyField f = wavyField({70, 52, 44});
    int levels = 0;  // the case needs blocks on both lattices and lines through several blocks
    for (std::size_t blk = 0; blk < f.pyramid->blockCount(); ++blk)
        levels |= f.grid->level(blk) == 0 ? 1 : f.grid->level(blk) != kNone ? 2 : 0;
    ASSERT_EQ(levels, 3);
    for (const int rays : {26, 98}) {
        LocalVisibilityOptions o = sweepOptions(rays, 4);
        o.sweepGroupBlocks = 1;
        const LocalVisibility a = computeLocalVisibility(f.grid, f.table, o);
        for (const int g : {2, 4, 8}) {
            o.sweepGroupBlocks = g;
            expectSameBits(*f.grid, a, computeLocalVisibility(f.grid, f.table, o), 4,
                           std::to_string(rays) + " rays, groups of " + std::to_string(g) +
                               "³ blocks against 1");
        }
    }
    LocalVisibilityOptions bad = sweepOptions(26, 4);
    bad.sweepGroupBlocks = 3;
    EXPECT_THROW(computeLocalVisibility(f.grid, f.table, bad), InputError);
}

// No seams at block faces (Kronander §4.1 asks for interpolation across blocks of different LOD
// "without visible seams"; on the T1 MRI's scalp at 1:8 lines along the block faces showed in
// every image until 7 December): the skin of a sphere, its field stored on a pseudo-random mix
// of 16³ and 8³ blocks, against the same field at 16³ everywhere. Within half a voxel of a block
// face the error of V_0 must be no larger than in the blocks' interiors. Before, a finer block
// diagonally past a face shortened the blend between the two coarser blocks across it to one
// voxel (the ramp was the finest spacing among all 26 neighbours), so the step between their
// samples two voxels apart happened within one voxel: 1.7× the interior error in that band.
TEST(LineSweep, NoLargerErrorAtBlockFacesThanInsideBlocks) {
    constexpr int kN = 128;
    constexpr double kRadius = 50.0, kSoft = 1.5;
    const glm::dvec3 centre(63.7, 64.3, 61.9);
    const core::Volume v = test::makeVolume({kN, kN, kN}, [&](int i, int j, int k) {
        const double r = glm::length(glm::dvec3(i, j, k) - centre);
        return int(1000 * std::clamp((kRadius - r) / kSoft + 0.5, 0.0, 1.0));
    });
    const optics::TfTable table(test::rampTf(0.3f));
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    LodSelection mixed;
    mixed.level.resize(pyr->blockCount());
    mixed.significance.assign(pyr->blockCount(), 0.f);
    for (std::size_t b = 0; b < mixed.level.size(); ++b)
        mixed.level[b] = std::int8_t(core::hashCounters(b, 7, 0, 3) % 3 == 0 ? 0 : 1);
    const LocalVisibilityOptions o = sweepOptions(26, 4);
    const LocalVisibility fine = computeLocalVisibility(test::uniformGrid(pyr, 0), table, o);
    const LocalVisibility coarse =
        computeLocalVisibility(std::make_shared<const MultiresGrid>(pyr, mixed), table, o);
    // Points every half voxel along x on lines through the skin; binned by their distance to the
    // nearest block face across x (faces at 16·b − ½).
    double faceError = 0.0, insideError = 0.0;
    int faceCount = 0, insideCount = 0;
    for (int k = 8; k < kN - 8; ++k)
        for (int j = 8; j < kN - 8; ++j)
            for (int h = 0; h < 2 * kN - 1; ++h) {
                const glm::vec3 p(0.5f * float(h), float(j), float(k));
                if (std::abs(glm::length(glm::dvec3(p) - centre) - kRadius) > 1.0) continue;
                const float inBlock = std::fmod(p.x + 0.5f, 16.f);  // 0 and 16: on a face
                const float toFace = std::min(inBlock, 16.f - inBlock);
                float a[4], b[4];
                fine.sample(p, a);
                coarse.sample(p, b);
                const double e = std::abs(double(b[0]) - double(a[0]));
                if (toFace <= 0.5f) {
                    faceError += e;
                    ++faceCount;
                } else if (toFace >= 4.f) {
                    insideError += e;
                    ++insideCount;
                }
            }
    ASSERT_GT(faceCount, 1000);
    ASSERT_GT(insideCount, 1000);
    faceError /= faceCount;
    insideError /= insideCount;
    std::printf("mean |dV_0| within 0.5 voxel of a block face %.4f, 4+ voxels inside %.4f\n",
                faceError, insideError);
    // 1.25: the interior's own error varies by ±15 % with the position on the level-1 lattice
    // (points on its samples against points between them); the old blend gave 1.7.
    constexpr double kFaceErrorRatio = 1.25;
    EXPECT_LE(faceError, kFaceErrorRatio * insideError);
}
