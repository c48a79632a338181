// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>

#include "core/volume.h"

using namespace voxlight;
using core::Geometry;
using core::Volume;
using core::VoxelType;

namespace {
// Trilinear interpolation reproduces any trilinear function exactly; float rounding of products of
// values < 1e3.
constexpr float kTrilinearTol = 1e-3f;

Geometry rotatedGeometry() {
    Geometry g;
    g.dims = {7, 5, 4};
    g.spacing = {0.5, 0.75, 2.0};
    g.origin = {10.0, -20.0, 5.0};
    // 30° about z, then the k axis pointing inferior: a proper orthonormal frame with det −1 is
    // allowed too.
    const double c = std::cos(M_PI / 6), s = std::sin(M_PI / 6);
    g.direction = glm::dmat3(glm::dvec3(c, s, 0), glm::dvec3(-s, c, 0), glm::dvec3(0, 0, -1));
    return g;
}
}  // namespace

TEST(Geometry, IndexWorldRoundTrip) {
    const Geometry g = rotatedGeometry();
    for (const glm::dvec3 ijk :
         {glm::dvec3(0, 0, 0), glm::dvec3(6, 4, 3), glm::dvec3(1.25, 3.5, 2.75)}) {
        const glm::dvec3 back = g.worldToIndex(g.indexToWorld(ijk));
        EXPECT_NEAR(glm::length(back - ijk), 0.0, 1e-12);
    }
    // Voxel (1,0,0) lies spacing.x along the first direction column.
    const glm::dvec3 d = g.indexToWorld({1, 0, 0}) - g.origin;
    EXPECT_NEAR(d.x, 0.5 * std::cos(M_PI / 6), 1e-12);
    EXPECT_NEAR(d.y, 0.5 * std::sin(M_PI / 6), 1e-12);
    EXPECT_EQ(g.orientationCode(), "LPI");
}

TEST(Volume, TrilinearIsExactOnTrilinearFunctionsForEveryType) {
    auto f = [](double x, double y, double z) {
        return 3.0 + 2.0 * x + 1.0 * y + 4.0 * z + 1.0 * x * y * z;
    };
    for (VoxelType t :
         {VoxelType::UInt8, VoxelType::Int16, VoxelType::UInt16, VoxelType::Float32}) {
        Geometry g;
        g.dims = {5, 4, 3};
        Volume v(g, t);
        v.mapping.slope = 2.0;
        v.mapping.intercept = -7.0;
        v.visit([&](const auto& view) {
            using T = std::remove_cv_t<std::remove_pointer_t<decltype(view.data)>>;
            T* p = const_cast<T*>(view.data);
            for (int k = 0; k < 3; ++k)
                for (int j = 0; j < 4; ++j)
                    for (int i = 0; i < 5; ++i) p[v.linearIndex(i, j, k)] = T(f(i, j, k));
        });
        for (const glm::dvec3 q :
             {glm::dvec3(0.5, 0.5, 0.5), glm::dvec3(3.25, 2.75, 1.5), glm::dvec3(4, 3, 2)}) {
            EXPECT_NEAR(v.sampleIndex(q), 2.0 * f(q.x, q.y, q.z) - 7.0, kTrilinearTol)
                << core::toString(t) << " at " << q.x << "," << q.y << "," << q.z;
        }
        // Outside the grid: edge extension (clamped), never garbage.
        EXPECT_NEAR(v.sampleIndex({-3, -3, -3}), 2.0 * f(0, 0, 0) - 7.0, kTrilinearTol);
        EXPECT_NEAR(v.sampleIndex({99, 99, 99}), 2.0 * f(4, 3, 2) - 7.0, kTrilinearTol);
        const auto range = v.physicalRange();
        EXPECT_DOUBLE_EQ(range[0], 2.0 * f(0, 0, 0) - 7.0);
        EXPECT_DOUBLE_EQ(range[1], 2.0 * f(4, 3, 2) - 7.0);
    }
}

TEST(Volume, SingleVoxelAxesSampleWithoutReadingOutOfBounds) {
    Geometry g;
    g.dims = {1, 1, 1};
    Volume v(g, VoxelType::Float32);
    v.dataAs<float>()[0] = 42.f;
    EXPECT_EQ(v.sampleIndex({0.3, -1, 5}), 42.f);
}

TEST(Volume, AbsurdSizesAreRefusedBeforeAllocation) {
    Geometry g;
    g.dims = {core::kMaxDim + 1, 1, 1};
    EXPECT_THROW(Volume(g, VoxelType::UInt8), InputError);
    g.dims = {16384, 16384, 16};
    EXPECT_THROW(Volume(g, VoxelType::UInt8), InputError);
    g.dims = {0, 1, 1};
    EXPECT_THROW(Volume(g, VoxelType::UInt8), InputError);
}

TEST(Volume, NonFiniteVoxelsAreCountedAndIgnoredByRange) {
    Geometry g;
    g.dims = {4, 1, 1};
    Volume v(g, VoxelType::Float32);
    float* p = v.dataAs<float>();
    p[0] = 1.f;
    p[1] = NAN;
    p[2] = INFINITY;
    p[3] = -2.f;
    EXPECT_EQ(v.countNonFinite(), 2u);
    const auto r = v.physicalRange();
    EXPECT_EQ(r[0], -2.0);
    EXPECT_EQ(r[1], 1.0);
}

TEST(Volume, MemoryOfLargeCtIsItsVoxelsOnly) {
    // 512×512×880 int16 must fit in well under 2 GiB: storage is exactly 2 bytes per voxel.
    Geometry g;
    g.dims = {512, 512, 880};
    EXPECT_EQ(g.voxelCount() * core::voxelBytes(VoxelType::Int16), 461373440u);
}

TEST(Volume, ASkewedOrientationIsBadInputNotAnInternalFault) {
    // A damaged NIfTI sform (fuzz_nifti_gz) gave a direction matrix that is not a rotation; the
    // volume refuses it as input, which the CLI reports in one line with exit code 2.
    core::Geometry g;
    g.dims = {4, 4, 4};
    g.direction = glm::dmat3(1.0);
    g.direction[1] = glm::dvec3(0.5, 1.0, 0.0);  // second axis sheared toward the first
    try {
        core::Volume v(g, core::VoxelType::UInt8);
        FAIL() << "a sheared direction matrix must be refused";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "orientation");
    }
}

TEST(Volume, TheSpacingLimitsPassAsAFloatHeaderStoresThem) {
    // NIfTI's pixdim is float32: 1e-4 reads back as 9.99999974e-5 and was refused as "0.0001 is
    // outside 0.0001..10000 mm".
    auto make = [](double spacing) {
        core::Geometry g;
        g.dims = {4, 4, 4};
        g.spacing = glm::dvec3(spacing);
        return core::Volume(g, core::VoxelType::Float32);
    };
    EXPECT_NO_THROW(make(double(float(core::kMinSpacingMm))));
    EXPECT_NO_THROW(make(double(float(core::kMaxSpacingMm))));
    EXPECT_THROW(make(0.99 * core::kMinSpacingMm), InputError);
    EXPECT_THROW(make(1.01 * core::kMaxSpacingMm), InputError);
}

TEST(Volume, AVolumeTooFarFromTheOriginForSinglePrecisionIsRefused) {
    // A 16³ sphere at 1 mm with its origin at 1e8–1e9 mm rendered black (pvrt, iso-lattice) or
    // unlit (the SH methods) with exit code 0: the methods' float positions lose the voxel there.
    auto make = [](glm::dvec3 origin, double spacing) {
        core::Geometry g;
        g.dims = {16, 16, 16};
        g.spacing = glm::dvec3(spacing);
        g.origin = origin;
        return core::Volume(g, core::VoxelType::Float32);
    };
    EXPECT_NO_THROW(make(glm::dvec3(-1e5, 0, 0), 1.0));        // 1e5 spacings: ≤ 0.1 % (volume.h)
    EXPECT_NO_THROW(make(glm::dvec3(-250, -250, 1200), 0.5));  // a CT's patient coordinates
    for (const auto& [origin, spacing] :
         {std::pair{glm::dvec3(1e7, 1e7, 1e7), 1.0}, std::pair{glm::dvec3(0, 0, -2e5), 1.0},
          std::pair{glm::dvec3(20, 0, 0), 1e-4}}) {
        try {
            make(origin, spacing);
            ADD_FAILURE() << "origin " << origin.x << ", " << origin.y << ", " << origin.z << " at "
                          << spacing << " mm must be refused";
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), "origin");
            EXPECT_NE(std::string(e.what()).find("nearer 0"), std::string::npos) << e.what();
        }
    }
    // The far corner counts too (the origin near 0, the voxels running away from it).
    EXPECT_THROW(make(glm::dvec3(131070, 0, 0), 1.0), InputError);
}
