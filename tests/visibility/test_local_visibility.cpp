// SPDX-License-Identifier: MIT
// Local visibility V^L against closed forms: empty space, a homogeneous slab; determinism and
// robustness under opaque TFs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "sh/sphere_samples.h"
#include "visibility/hierarchical_visibility.h"
#include "visibility/local_visibility.h"
#include "visibility/vis_test_util.h"

using namespace voxlight;
using namespace voxlight::visibility;

namespace {

const double kSqrt4Pi = std::sqrt(4.0 * std::numbers::pi);

}  // namespace

TEST(VisibilityDirections, IntegrateTheFirstCoefficientsExactlyWithPositiveWeights) {
    // Float sums of ≤ 4096 terms of size ≤ 4π/N·|Y| ≤ 1: rounding stays below 1e-9 in double.
    constexpr double kExactTol = 1e-9;
    for (int c : {1, 4, 9, 16})
        for (int rays : {2 * c, 16, 32, 33, 64, 100, 256, 1024}) {
            if (rays < kMinRaysPerCoefficient * c) continue;
            const sh::SphereSamples s = visibilityDirections(rays, c);  // throws on a weight ≤ 0
            std::vector<double> sum(static_cast<std::size_t>(c), 0.0), y(sum.size());
            for (std::size_t k = 0; k < s.size(); ++k) {
                sh::evalShUnitDouble(sh::shBandForCount(c), s.directions[k], y);
                for (int i = 0; i < c; ++i) sum[std::size_t(i)] += s.weights[k] * y[std::size_t(i)];
            }
            EXPECT_NEAR(sum[0], kSqrt4Pi, kExactTol) << c << " coefficients, " << rays << " rays";
            for (int i = 1; i < c; ++i) EXPECT_NEAR(sum[std::size_t(i)], 0.0, kExactTol) << i;
        }
    EXPECT_THROW(visibilityDirections(20, 16), InputError);  // fewer than 2 rays per coefficient
    EXPECT_THROW(visibilityDirections(32, 5), InputError);
}

TEST(LocalVisibility, EmptySpaceSeesEverything) {
    // Value 0 everywhere: σt(0) = 0 exactly, but the TF's table may leak σt within one cell of 0,
    // so every block is stored and computed.
    const core::Volume v = test::makeVolume({32, 32, 32}, [](int, int, int) { return 0; });
    const auto grid = test::fullGrid(v, test::rampTf(1.f));
    for (int c : {1, 4, 9, 16}) {
        LocalVisibilityOptions o;
        o.coefficients = c;
        o.rays = 2 * c + 8;
        const LocalVisibility vis =
            computeLocalVisibility(grid, optics::TfTable(test::rampTf(1.f)), o);
        ASSERT_GT(vis.raysTraced(), 0u);
        // Float storage of √(4π) ≈ 3.5 and of sums that cancel to 0: a few 1e-7.
        constexpr float kFloatTol = 2e-6f;
        for (glm::vec3 p :
             {glm::vec3(0.f), glm::vec3(15.5f, 3.f, 31.f), glm::vec3(7.f, 22.f, 13.f)}) {
            float out[16];
            vis.sample(p, out);
            EXPECT_NEAR(out[0], kSqrt4Pi, kFloatTol);
            for (int i = 1; i < c; ++i) EXPECT_NEAR(out[i], 0.f, kFloatTol) << i;
        }
    }
}

TEST(LocalVisibility, InsideAHomogeneousSlabMatchesTheProjectedClosedForm) {
    // Slab of value 1000 (σt = σ0) for voxel layers z ∈ [20, 39] in a 40×40×60 volume of 0 (σt = 0);
    // the test point's rays stay inside it across x and y. Trilinear interpolation ramps σt over one voxel at each face symmetrically, which
    // integrates like sharp faces at z = 19.5 and 39.5.
    constexpr float kSigma = 0.05f;  // 1/mm, 1 mm voxels
    const core::Volume v = test::makeVolume(
        {40, 40, 60}, [](int, int, int k) { return k >= 20 && k <= 39 ? 1000 : 0; });
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const auto grid = test::fullGrid(v, tf);
    LocalVisibilityOptions o;
    o.coefficients = 16;
    o.rays = 32;
    o.radiusVoxels = 16.0;
    const LocalVisibility vis = computeLocalVisibility(grid, optics::TfTable(tf), o);
    // A grid point 4 voxels below the top face: upward rays leave the slab, downward rays are cut
    // by the radius.
    const glm::vec3 x(20.f, 20.f, 35.f);
    const sh::SphereSamples dirs = visibilityDirections(o.rays, o.coefficients);
    const auto expected = sh::projectFunction(3, dirs, [&](const glm::dvec3& w) {
        double d = 16.0;  // r_s
        if (w.z > 0) d = std::min(d, (39.5 - x.z) / w.z);
        if (w.z < 0) d = std::min(d, (19.5 - x.z) / w.z);
        return std::exp(-double(kSigma) * d);
    });
    float got[16];
    vis.sample(x, got);
    // The midpoint rule (1-voxel steps) on σt with two kinks per face errs by ≤ σ0·Δ/8 per kink
    // in τ, so |ΔT| ≤ σ0/4 per ray and |ΔV_i| ≤ (σ0/4)·Σ_k w_k |Y_i(ω_k)| ≤ (σ0/4)·√(4π)
    // (Cauchy–Schwarz with Σ w = 4π, Σ w Y_i² = 1): 0.044 at σ0 = 0.05.
    const double kSlabTol = kSigma / 4.0 * kSqrt4Pi;
    for (int i = 0; i < 16; ++i) EXPECT_NEAR(got[i], expected[std::size_t(i)], kSlabTol) << i;
    // The closed form is far from empty space, and its upward bias (Y_1^0 ∝ z) is large against
    // the tolerance: a wrong sign or a missing slab would fail.
    EXPECT_LT(expected[0], kSqrt4Pi - 10 * kSlabTol);
    EXPECT_GT(expected[2], 5 * kSlabTol);
}

TEST(LocalVisibility, IdenticalForAnyThreadCount) {
    const core::Volume v = test::makeVolume({48, 40, 36}, [](int i, int j, int k) {
        return int(500 + 400 * std::sin(0.3 * i + 0.2 * j) * std::cos(0.25 * k));
    });
    const optics::TransferFunction tf = test::rampTf(0.2f);
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const optics::TfTable table(tf);
    const auto grid = std::make_shared<const MultiresGrid>(
        pyr, selectLod(*pyr, tf, table, LodBudget::fromReduction(6.0, v.voxelCount())));
    LocalVisibilityOptions o;
    o.coefficients = 9;
    o.rays = 24;
    o.threads = 1;
    const LocalVisibility a = computeLocalVisibility(grid, table, o);
    o.threads = 2;
    const LocalVisibility b = computeLocalVisibility(grid, table, o);
    ASSERT_EQ(a.bytes(), b.bytes());
    for (std::size_t blk = 0; blk < pyr->blockCount(); ++blk) {
        if (grid->level(blk) == kNone) continue;
        const std::size_t n = std::size_t(std::pow(levelResolution(grid->level(blk)), 3)) * 9;
        EXPECT_EQ(std::memcmp(a.blockData(blk), b.blockData(blk), n * sizeof(float)), 0) << blk;
    }
}

TEST(LocalVisibility, FullyOpaqueTfGivesFiniteNonNegativeOcclusion) {
    const core::Volume v = test::makeVolume({32, 32, 32}, [](int i, int, int) { return 200 + i; });
    const optics::TransferFunction opaque({{0.f, glm::vec3(1.f), 1e4f, glm::vec3(0.f)},
                                           {1000.f, glm::vec3(1.f), 1e4f, glm::vec3(0.f)}},
                                          {500.f, 1000.f});
    const auto grid = test::fullGrid(v, opaque);
    LocalVisibilityOptions o;
    o.coefficients = 4;
    const LocalVisibility vis = computeLocalVisibility(grid, optics::TfTable(opaque), o);
    float out[4];
    for (glm::vec3 p : {glm::vec3(16.f), glm::vec3(0.f), glm::vec3(31.f, 0.f, 31.f)}) {
        vis.sample(p, out);
        for (float x : out) EXPECT_TRUE(std::isfinite(x));
        // Rays from a corner see out of the volume in some directions; interior rays see nothing.
        EXPECT_GE(out[0], 0.f);
    }
    vis.sample(glm::vec3(16.f), out);
    EXPECT_NEAR(out[0], 0.f, 1e-6f);
}

TEST(LocalVisibility, RaysRespectAnisotropicSpacingAndAnObliqueGrid) {
    // A slab of σt = σ0 in index layers k ∈ [10, 19] of a grid with spacing (0.8, 1.0, 1.5) mm
    // whose axes are rotated 30° about world z: the slab's faces are the index planes k = 9.5 and
    // 19.5 (as in the slab test), crossed by a ray of world direction ω at a rate of
    // (Dᵀω)_z / 1.5 index units per mm.
    constexpr float kSigma = 0.05f;
    core::Volume v = test::makeVolume(
        {40, 40, 30}, [](int, int, int k) { return k >= 10 && k <= 19 ? 1000 : 0; });
    core::Geometry& g = v.geometry();
    g.spacing = {0.8, 1.0, 1.5};
    const double a = 30.0 * std::numbers::pi / 180.0;
    g.direction = glm::dmat3(std::cos(a), std::sin(a), 0, -std::sin(a), std::cos(a), 0, 0, 0, 1);
    g.origin = {5.0, -3.0, 2.0};
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const auto grid = test::fullGrid(v, tf);
    const optics::TfTable table(tf);
    const glm::vec3 x(20.f, 20.f, 16.f);           // 3.5 index layers (5.25 mm) below the top face
    const double radius = 16.0, R = radius * 0.8;  // r_s in units of the smallest spacing, mm
    // Midpoint rule at 0.8 mm steps on σt with kinks at the faces: |Δτ| ≤ σ0·Δ/4 (slab test).
    constexpr double kRayTol = kSigma * 0.8 / 4.0;
    int farFromIsotropic = 0;
    for (const glm::dvec3 w : {glm::dvec3(0, 0, 1), glm::dvec3(0, 0, -1), glm::dvec3(0.6, 0.0, 0.8),
                               glm::dvec3(-0.48, 0.6, 0.64), glm::dvec3(0.8, -0.6, 0.0)}) {
        const double rate = (glm::transpose(g.direction) * w).z / g.spacing.z;  // index z per mm
        double d = R;
        if (rate > 0) d = std::min(d, (19.5 - x.z) / rate);
        if (rate < 0) d = std::min(d, (9.5 - x.z) / rate);
        const double expected = std::exp(-double(kSigma) * d);
        EXPECT_NEAR(rayTransmittance(*grid, table, x, w, radius), expected, kRayTol)
            << w.x << "," << w.y << "," << w.z;
        // What a march that ignored spacing and orientation (1 mm voxels, identity axes) would get.
        double dIso = radius;
        if (w.z > 0) dIso = std::min(dIso, (19.5 - x.z) / w.z);
        if (w.z < 0) dIso = std::min(dIso, (9.5 - x.z) / w.z);
        if (std::abs(std::exp(-double(kSigma) * dIso) - expected) > 5 * kRayTol) ++farFromIsotropic;
    }
    EXPECT_GE(farFromIsotropic, 2);  // the test can tell the difference
}

TEST(LocalVisibility, ADenseSurfaceOnABlockFaceAttenuatesAsTheContinuousModel) {
    // Bone-like σt (2/mm above value 510) for k ≤ 15, a partial-volume voxel (600) at k = 16, air
    // above: the surface (value 500) lies at k = 16.17, just past the face between two blocks of
    // 16 (k = 15.5). Trilinear samples near the face read both blocks' voxels, so (i) the block
    // above must be stored although its own voxels are mostly transparent, and (ii) a ray from
    // under the surface must integrate σt as the continuous model does (value trilinear, then
    // the TF) — not drop the part past the block face (which gave T = 1 from k = 15), nor read
    // pre-classified σt at step midpoints (a surface moved by up to half a voxel). Ritschel's
    // brute-force march (level-0 steps only) must agree too.
    const core::Volume v = test::makeVolume({16, 16, 48}, [](int, int, int k) {
        return k <= 15 ? 1000 : k == 16 ? 600 : 0;
    });
    const optics::TransferFunction tf({{0.f, glm::vec3(1.f), 0.f, glm::vec3(0.f)},
                                       {490.f, glm::vec3(1.f), 0.f, glm::vec3(0.f)},
                                       {510.f, glm::vec3(1.f), 2.f, glm::vec3(0.f)},
                                       {1000.f, glm::vec3(1.f), 2.f, glm::vec3(0.f)}},
                                      {500.f, 1000.f});
    const auto grid = test::fullGrid(v, tf);
    const optics::TfTable table(tf);
    EXPECT_NE(grid->level(grid->ownerBlock(glm::vec3(8.f, 8.f, 20.f))), kNone);
    EXPECT_EQ(grid->level(grid->ownerBlock(glm::vec3(8.f, 8.f, 40.f))), kNone);
    const OpacityPyramid opacity = OpacityPyramid::build(grid->pyramid(), tf, table);
    // Brute force: value linear between voxel centres along z, σt from the TF, 10⁵ midpoint steps.
    auto voxel = [](int k) { return k <= 15 ? 1000.0 : k == 16 ? 600.0 : 0.0; };
    auto exact = [&](double z0, const glm::dvec3& w, double length) {
        constexpr int kSteps = 100000;
        double tau = 0.0;
        for (int s = 0; s < kSteps; ++s) {
            const double z = z0 + w.z * (s + 0.5) * length / kSteps;
            const int k = int(std::floor(z));
            const double value = voxel(k) + (z - k) * (voxel(k + 1) - voxel(k));
            tau += double(tf.eval(float(value)).extinction) * length / kSteps;
        }
        return std::exp(-tau);
    };
    // Pre-integrated steps are exact while the value is linear along the step; it kinks where the
    // ray crosses a voxel plane, and a step across the surface is split into sub-steps of optical
    // depth ≤ kRefineDepth. Measured: ≤ 0.0058 (unsplit: above 0.01); the old midpoint steps were off
    // by up to 0.63.
    constexpr double kPreIntegratedTol = 0.01;
    const double radius = 8.0;
    for (const double z : {13.0, 14.0, 15.0, 15.25, 15.5, 16.0}) {
        for (const glm::dvec3 w : {glm::dvec3(0, 0, 1), glm::normalize(glm::dvec3(0.6, 0, 0.8)),
                                   glm::normalize(glm::dvec3(0.9, 0.2, 0.3))}) {
            const glm::vec3 x(8.f, 8.f, float(z));
            const double expected = exact(z, w, radius);
            EXPECT_NEAR(rayTransmittance(*grid, table, x, w, radius), expected, kPreIntegratedTol)
                << "sh-local: z " << z << " w " << w.x << "," << w.y << "," << w.z;
            EXPECT_NEAR(hierarchicalTransmittance(opacity, x, w, radius, false), expected,
                        kPreIntegratedTol)
                << "ritschel: z " << z << " w " << w.x << "," << w.y << "," << w.z;
        }
    }
}

TEST(LocalVisibility, TheFastMarchReproducesTheReferenceMarchAtEveryPointAndDirection) {
    // computeLocalVisibility's march skips the TF table on steps inside a transparent tail and
    // reads each point's origin value once for all its rays; rayTransmittanceReference marches
    // through the table at every step. Volume: textured soft tissue (transparent: the lower
    // tail), bone slabs with partial-volume faces (dense: sub-steps), a metal rod (above the TF's
    // upper tail end: transparent again) and air, under a budget so that blocks sit at mixed
    // levels (steps of 1, 2 and 4 voxels).
    const core::Volume v = test::makeVolume({48, 40, 44}, [](int i, int j, int k) {
        if ((i - 30) * (i - 30) + (k - 20) * (k - 20) < 9) return 3000;  // metal rod along y
        if (k >= 10 && k <= 13) return 900 + 37 * ((i + 2 * j) % 5);     // bone slab
        if (std::abs(i - 2 * j + 3) < 2) return 500 + 10 * k;            // oblique sheet
        if (k > 36) return -1000;                                        // air
        return 40 + (i * 7 + j * 3 + k) % 11;                            // soft tissue
    });
    const glm::vec3 c(1.f);
    const optics::TransferFunction tf({{-1000.f, c, 0.f, glm::vec3(0.f)},
                                       {100.f, c, 0.f, glm::vec3(0.f)},
                                       {400.f, c, 0.2f, glm::vec3(0.f)},
                                       {1000.f, c, 3.f, glm::vec3(0.f)},
                                       {2000.f, c, 0.5f, glm::vec3(0.f)},
                                       {2200.f, c, 0.f, glm::vec3(0.f)},
                                       {3071.f, c, 0.f, glm::vec3(0.f)}},
                                      {400.f, 1000.f}, "two-tails");
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const optics::TfTable table(tf);
    ASSERT_GT(table.zeroBelow(), -1000.f);  // both tails exist
    ASSERT_LT(table.zeroAbove(), 3000.f);
    const auto grid = std::make_shared<const MultiresGrid>(
        pyr, selectLod(*pyr, tf, table, LodBudget::fromReduction(3.0, v.voxelCount())));
    int levels[kLevels] = {};  // blocks per level (kNone not counted)
    for (std::size_t b = 0; b < pyr->blockCount(); ++b)
        if (grid->level(b) != kNone) ++levels[grid->level(b)];
    ASSERT_GT(levels[0], 0);
    ASSERT_GT(levels[1] + levels[2], 0);
    LocalVisibilityOptions o;
    o.coefficients = 4;
    o.rays = 32;
    o.radiusVoxels = 12.0;
    const LocalVisibility vis = computeLocalVisibility(grid, table, o);
    const sh::SphereSamples dirs = visibilityDirections(o.rays, o.coefficients);
    std::vector<double> y(16);
    // The fast march and the reference differ only where a value lies within float rounding of a
    // tail's end (σt ≤ 1e-6 of a node's there); what remains is the field's float transmittance
    // (e^−τ in float, 1e-7) and float storage, ×√(4π) by the projection: 1e-5 bounds all of it.
    constexpr double kFastPathTol = 1e-5;
    // A single ray in double: the same march, so only the tails' rounding can differ.
    constexpr double kRayTol = 1e-9;
    const glm::vec3 top(grid->dims() - 1);
    int compared = 0, occluded = 0;
    for (std::size_t b = 0; b < pyr->blockCount(); ++b) {
        const int l = grid->level(b);
        if (l == kNone) continue;
        const int n = levelResolution(l);
        const float* data = vis.blockData(b);
        for (int k = 0; k < n; ++k)
            for (int j = 0; j < n; ++j)
                for (int i = 0; i < n; ++i, data += o.coefficients) {
                    if ((i + 3 * j + 5 * k) % 7 != 0) continue;  // a sixth of the points
                    const glm::vec3 x = glm::min(grid->samplePosition(b, l, i, j, k), top);
                    if (!visibilityNeeded(*grid, x, float(levelSpacing(l)))) continue;
                    double expected[4] = {};
                    for (std::size_t r = 0; r < dirs.size(); ++r) {
                        const double t =
                            rayTransmittanceReference(*grid, table, x, dirs.directions[r], 12.0);
                        ASSERT_NEAR(rayTransmittance(*grid, table, x, dirs.directions[r], 12.0), t,
                                    kRayTol)
                            << "block " << b << " point " << x.x << "," << x.y << "," << x.z;
                        occluded += t < 0.5;
                        sh::evalShUnitDouble(1, dirs.directions[r], y);
                        for (int q = 0; q < 4; ++q)
                            expected[q] += dirs.weights[r] * t * y[std::size_t(q)];
                    }
                    for (int q = 0; q < 4; ++q)
                        ASSERT_NEAR(data[q], expected[q], kFastPathTol)
                            << "block " << b << " level " << l << " point " << x.x << "," << x.y
                            << "," << x.z << " coefficient " << q;
                    ++compared;
                }
    }
    EXPECT_GT(compared, 1000);
    EXPECT_GT(occluded, 1000);  // the volume is not nearly empty for the rays
}

TEST(LocalVisibility, MarchedRaysInAHomogeneousBoxStopExactlyAtItsFaces) {
    // Matter up to every face of an odd-sized box: from points near faces, edges and corners, in
    // axis, diagonal and Fibonacci directions, a ray of radius R has transmittance
    // exp(−σ0·min(R, d)), d the distance to the face along it — with level-0 steps and with the
    // coarse steps of a reduced LOD (the march's last step is shortened to the box exit).
    constexpr float kSigma = 0.05f;
    const core::Volume v = test::makeVolume({37, 29, 23}, [](int, int, int) { return 1000; });
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const optics::TfTable table(tf);
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const glm::dvec3 hi(36.0, 28.0, 22.0);
    const std::vector<glm::dvec3> dirs = test::boxTestDirections();
    constexpr double kBoxTol = 1e-4;  // σt is constant: float rounding only
    for (const double reduction : {1.0, 8.0})
        for (const double radius : {6.0, 100.0}) {
            const auto grid = std::make_shared<const MultiresGrid>(
                pyr,
                selectLod(*pyr, tf, table, LodBudget::fromReduction(reduction, v.voxelCount())));
            for (const glm::dvec3 o : {glm::dvec3(0.0), glm::dvec3(36.0, 28.0, 22.0),
                                       glm::dvec3(35.5, 0.25, 11.0), glm::dvec3(1.0, 27.0, 21.5),
                                       glm::dvec3(18.0, 14.0, 0.5), glm::dvec3(33.7, 26.1, 19.9)})
                for (const glm::dvec3& w : dirs) {
                    EXPECT_NEAR(rayTransmittance(*grid, table, glm::vec3(o), w, radius),
                                std::exp(-double(kSigma) * test::boxExitDistance(o, w, hi, radius)),
                                kBoxTol)
                        << "1:" << reduction << " R " << radius << " from " << o.x << "," << o.y
                        << "," << o.z << " along " << w.x << "," << w.y << "," << w.z;
                }
        }
}

TEST(LocalVisibility, OnTheVolumesFacesACoarseBlockReadsItsBoundaryLayer) {
    // Matter up to every face of the box (a scan range cutting through the body): on a face the
    // outward half of the directions leaves at once, a voxel inside V drops steeply. At every
    // level 1…4 the field on the face must give the projected closed form — the level-0 samples
    // lie on the faces, a coarse block's outermost ones (s − 1)/2 voxels inside, so without the
    // boundary layers the face would read those (checked: 5× the tolerance away, and darker).
    constexpr float kSigma = 0.3f;  // 1/mm, 1 mm voxels: ≈ 0.26 of V_0 lost over half a voxel
    constexpr double kRadius = 6.0;
    const glm::ivec3 dims(32, 32, 32);
    const core::Volume v = test::makeVolume(dims, [](int, int, int) { return 1000; });
    const optics::TransferFunction tf = test::rampTf(kSigma);
    const optics::TfTable table(tf);
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    const glm::dvec3 hi(dims - 1);
    LocalVisibilityOptions o;
    o.coefficients = 4;
    o.rays = 32;
    o.radiusVoxels = kRadius;
    const sh::SphereSamples dirs = visibilityDirections(o.rays, o.coefficients);
    auto closedForm = [&](const glm::dvec3& x) {
        return sh::projectFunction(1, dirs, [&](const glm::dvec3& w) {
            return std::exp(-double(kSigma) * test::boxExitDistance(x, w, hi, kRadius));
        });
    };
    // σt is constant and every ray ends at R or the box (the march's last step is shortened to
    // it, MarchedRaysInAHomogeneousBoxStopExactlyAtItsFaces): float rounding of ≤ 32 rays only.
    constexpr double kFaceTol = 1e-4 * 32;
    // A point on each face, farther than R from the other faces: there the layer's points, at the
    // block's sample positions along the face, all hold the same value.
    const glm::dvec3 onFaces[6] = {{0.0, 15.3, 16.6},  {31.0, 15.3, 16.6}, {15.3, 0.0, 16.6},
                                   {15.3, 31.0, 16.6}, {15.3, 16.6, 0.0},  {15.3, 16.6, 31.0}};
    for (int level = 1; level < kLevels; ++level) {
        const LocalVisibility field =
            computeLocalVisibility(test::uniformGrid(pyr, level), table, o);
        // 2 × 2 × 2 blocks, each with a layer on its three faces on the volume's box.
        const std::size_t n = std::size_t(levelResolution(level));
        EXPECT_EQ(field.layerPoints(), 8 * 3 * n * n) << "level " << level;
        const float inset = 0.5f * float(levelSpacing(level)) - 0.5f;  // (s − 1)/2
        for (int f = 0; f < 6; ++f) {
            const glm::dvec3 x = onFaces[f];
            const auto want = closedForm(x);
            float got[4];
            field.sample(glm::vec3(x), got);
            for (int i = 0; i < 4; ++i)
                EXPECT_NEAR(got[i], want[std::size_t(i)], kFaceTol)
                    << "level " << level << ", face " << f << ", coefficient " << i;
            // What the clamped interpolation read before: the outermost samples.
            glm::vec3 first(x);
            const int a = f >> 1;
            first[a] = (f & 1) ? float(hi[a]) - inset : inset;
            float inner[4];
            field.sample(first, inner);
            EXPECT_LT(inner[0], want[0] - 5 * kFaceTol) << "level " << level << ", face " << f;
            // Halfway between the face and those samples the two blend linearly.
            glm::vec3 mid(x);
            mid[a] = 0.5f * (float(x[a]) + first[a]);
            float half[4];
            field.sample(mid, half);
            for (int i = 0; i < 4; ++i)
                EXPECT_NEAR(half[i], 0.5f * (got[i] + inner[i]), 1e-5f)
                    << "level " << level << ", face " << f << ", coefficient " << i;
        }
    }
    // Level 0 has samples on the faces: no layers, and the same closed form there.
    const LocalVisibility fine = computeLocalVisibility(test::uniformGrid(pyr, 0), table, o);
    EXPECT_EQ(fine.layerPoints(), 0u);
    float got[4];
    fine.sample(glm::vec3(onFaces[2]), got);
    EXPECT_NEAR(got[0], closedForm(onFaces[2])[0], kFaceTol);
}

TEST(LocalVisibility, BoundaryLayersAreIdenticalForAnyThreadCountAndUnderTheSweep) {
    // The layers' points are marched alone under either integrator, in a fixed order per point.
    const core::Volume v = test::makeVolume({40, 24, 20}, [](int i, int j, int k) {
        return (i * 37 + j * 11 + k * 5) % 17 < 9 ? 1000 : 200;
    });
    const optics::TransferFunction tf = test::rampTf(0.2f);
    const optics::TfTable table(tf);
    auto pyr = std::make_shared<const BlockPyramid>(BlockPyramid::build(v));
    for (const VisibilityAlgorithm alg : {VisibilityAlgorithm::March, VisibilityAlgorithm::Sweep}) {
        LocalVisibilityOptions o;
        o.coefficients = 4;
        o.algorithm = alg;
        o.rays = alg == VisibilityAlgorithm::Sweep ? kSweepRaysCoarse : 16;
        o.radiusVoxels = 8.0;
        const auto grid = test::uniformGrid(pyr, 1);
        o.threads = 1;
        const LocalVisibility one = computeLocalVisibility(grid, table, o);
        o.threads = 2;
        const LocalVisibility two = computeLocalVisibility(grid, table, o);
        ASSERT_GT(one.layerPoints(), 0u);
        for (std::size_t b = 0; b < pyr->blockCount(); ++b)
            for (int face = 0; face < 6; ++face) {
                const float* a = one.layerData(b, face);
                ASSERT_EQ(a == nullptr, two.layerData(b, face) == nullptr);
                if (a) {
                    ASSERT_EQ(std::memcmp(a, two.layerData(b, face), 8 * 8 * 4 * sizeof(float)), 0);
                }
            }
    }
}
