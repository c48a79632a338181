// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstring>

#include "core/phantoms.h"

using namespace voxlight;

TEST(Phantoms, DeterministicAcrossCalls) {
    for (const auto& [name, desc] : core::phantomCatalog()) {
        core::PhantomOptions o;
        o.size = 32;
        const core::Volume a = core::makePhantom(name, o), b = core::makePhantom(name, o);
        ASSERT_EQ(a.sizeBytes(), b.sizeBytes());
        EXPECT_EQ(std::memcmp(a.data(), b.data(), a.sizeBytes()), 0) << name;
    }
}

TEST(Phantoms, TorsoHasTheTissuesOfACt) {
    core::PhantomOptions o;
    o.size = 96;
    const core::Volume v = core::makePhantom("torso", o);
    EXPECT_EQ(v.type(), core::VoxelType::Int16);
    EXPECT_EQ(v.mapping.unit, "HU");
    const auto r = v.physicalRange();
    EXPECT_LE(r[0], -1000.0);  // air
    EXPECT_GE(r[1], 1500.0);   // metal stent survives partial-volume averaging at 4 mm voxels
    // Known points: air outside, lung, contrast aorta, vertebral cortex.
    EXPECT_NEAR(v.sampleWorld({0, -190, 0}), -1000.0, 30.0);
    EXPECT_NEAR(v.sampleWorld({-72, -5, 85}), -850.0, 30.0);
    EXPECT_NEAR(v.sampleWorld({24, 46, 100}), 320.0, 30.0);
    EXPECT_NEAR(v.sampleWorld({-130, 0, -150}), 50.0, 30.0);  // muscle wall
}

TEST(Phantoms, SphereLevelSetIsTheAnalyticSphere) {
    core::PhantomOptions o;
    o.size = 48;
    const core::Volume v = core::makePhantom("sphere", o);
    const auto s = core::spherePhantomFacts(v.geometry());
    // Along any ray from the centre, the 0.5 crossing of the trilinear field is at the radius
    // (within the curvature error of a linear ramp across one voxel, well below 0.05 voxel at this
    // radius).
    constexpr double kLevelSetTolVoxels = 0.05;
    for (const glm::dvec3 dir : {glm::dvec3(1, 0, 0), glm::normalize(glm::dvec3(1, 1, 0)),
                                 glm::normalize(glm::dvec3(1, -2, 3))}) {
        double lo = 0.0, hi = s.radius + 3.0;
        for (int it = 0; it < 60; ++it) {
            const double mid = 0.5 * (lo + hi);
            (v.sampleWorld(s.centre + mid * dir) > 0.5 ? lo : hi) = mid;
        }
        EXPECT_NEAR(lo, s.radius, kLevelSetTolVoxels * v.geometry().spacing.x);
    }
}

TEST(Phantoms, KronanderPlateIsPerfectlyFlat) {
    core::PhantomOptions o;
    o.size = 64;
    const core::Volume v = core::makePhantom("kronander", o);
    // Every voxel of a z-slice inside the plate's footprint, away from sphere and torus, has the
    // same value.
    const auto* p = v.dataAs<std::uint8_t>();
    for (int k = 0; k < 64; ++k) {
        const std::uint8_t ref = p[v.linearIndex(4, 4, k)];
        for (int j = 4; j < 60; ++j)
            for (int i = 4; i < 6; ++i)
                ASSERT_EQ(p[v.linearIndex(i, j, k)], ref) << i << "," << j << "," << k;
    }
}

TEST(Phantoms, BadNameOrSizeIsAnInputError) {
    EXPECT_THROW(core::makePhantom("nope"), InputError);
    core::PhantomOptions o;
    o.size = 4;
    EXPECT_THROW(core::makePhantom("torso", o), InputError);
}

TEST(Phantoms, IdenticalForAnyThreadCount) {
    core::PhantomOptions o;
    o.size = 40;
    auto build = [&](int threads) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                                  std::size_t(threads));
        return core::makePhantom("torso", o);
    };
    const core::Volume one = build(1), two = build(2), four = build(4);
    EXPECT_EQ(std::memcmp(one.data(), two.data(), one.sizeBytes()), 0);
    EXPECT_EQ(std::memcmp(one.data(), four.data(), one.sizeBytes()), 0);
}
