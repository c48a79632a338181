// SPDX-License-Identifier: MIT
// Round trips through every writable format, and the real volumes' geometry as their headers state
// it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>

#include "core/phantoms.h"
#include "io/volume_io.h"
#include "support/test_support.h"

using namespace voxlight;

namespace {
core::Volume smallTorso() {
    core::PhantomOptions o;
    o.size = 24;
    return core::makePhantom("torso", o);
}
// Headers store geometry in float32 (NIfTI) or decimal text: relative precision ~1e-6 of values up
// to ~500 mm.
constexpr double kHeaderGeometryTol = 1e-4;

void expectSameVolume(const core::Volume& a, const core::Volume& b, bool checkDirection) {
    ASSERT_EQ(a.dims(), b.dims());
    ASSERT_EQ(a.type(), b.type());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.sizeBytes()), 0);
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(a.geometry().spacing[i], b.geometry().spacing[i], kHeaderGeometryTol);
        EXPECT_NEAR(a.geometry().origin[i], b.geometry().origin[i], kHeaderGeometryTol);
        if (checkDirection)
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(a.geometry().direction[c][i], b.geometry().direction[c][i],
                            kHeaderGeometryTol);
    }
    EXPECT_NEAR(a.mapping.slope, b.mapping.slope, 1e-6);
    EXPECT_NEAR(a.mapping.intercept, b.mapping.intercept, 1e-6);
}
}  // namespace

TEST(VolumeIo, RoundTripThroughEveryWritableFormat) {
    test::TempDir tmp;
    const core::Volume v = smallTorso();
    for (const char* name : {"t.nii.gz", "t.nii", "t.vti", "t.mha"}) {
        io::writeVolume(v, tmp / name);
        const core::Volume back = io::readVolume(tmp / name);
        expectSameVolume(v, back, true);
        // No temporary file is left behind.
        for (const auto& e : std::filesystem::directory_iterator(tmp.path()))
            EXPECT_EQ(e.path().filename().string().find(".voxlight-tmp"), std::string::npos)
                << e.path();
    }
}

TEST(VolumeIo, NiftiKeepsObliqueOrientationAndRescale) {
    test::TempDir tmp;
    core::Volume v = smallTorso();
    const double c = std::cos(0.3), s = std::sin(0.3);
    v.geometry().direction =
        glm::dmat3(glm::dvec3(1, 0, 0), glm::dvec3(0, c, s), glm::dvec3(0, -s, c));
    v.geometry().origin = {12.5, -40.25, 7.0};
    v.geometry().spacing = {0.7, 0.8, 2.5};
    v.mapping.slope = 0.5;
    v.mapping.intercept = -1024.0;
    io::writeVolume(v, tmp / "oblique.nii.gz");
    const core::Volume back = io::readVolume(tmp / "oblique.nii.gz");
    expectSameVolume(v, back, true);
    // World position of a voxel agrees: the strongest statement about orientation.
    const glm::dvec3 a = v.geometry().indexToWorld({3, 5, 7}),
                     b = back.geometry().indexToWorld({3, 5, 7});
    EXPECT_NEAR(glm::length(a - b), 0.0, 1e-3);
}

TEST(VolumeIo, RawWithExplicitLayoutIncludingBigEndian) {
    test::TempDir tmp;
    const std::vector<std::uint8_t> bytes = {0x00, 0x01, 0x01, 0x00,
                                             0xff, 0xfe, 0x7f, 0xff};  // 4 int16 BE
    {
        std::ofstream f(tmp / "v.raw", std::ios::binary);
        f.write("HDR", 3);
        f.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    }
    io::ReadOptions o;
    o.raw = io::RawLayout{{2, 2, 1}, core::VoxelType::Int16, {0.5, 0.5, 1.0}, true, 3};
    const core::Volume v = io::readVolume(tmp / "v.raw", o);
    const auto* p = v.dataAs<std::int16_t>();
    EXPECT_EQ(p[0], 1);
    EXPECT_EQ(p[1], 256);
    EXPECT_EQ(p[2], -2);
    EXPECT_EQ(p[3], 32767);
    EXPECT_EQ(v.geometry().spacing.x, 0.5);
}

TEST(VolumeIo, SharedVolumesHaveTheGeometryTheirHeadersState) {
    struct Case {
        const char* path;
        glm::ivec3 dims;
        glm::dvec3 spacing;
    };
    const Case cases[] = {
        {"ct/headsq/quarter.nhdr", {64, 64, 93}, {3.2, 3.2, 1.5}},
        {"ct/bonsai.vti", {256, 256, 256}, {1, 1, 1}},
        {"ct/engine.vti", {256, 256, 128}, {1, 1, 1}},
        {"ct/lidc2-chest.mha", {256, 256, 133}, {1.40625, 1.40625, 2.5}},
        {"mr/HeadMRVolume.mhd", {48, 62, 42}, {4, 4, 4}},
        {"ct/abdomen-totalseg/example_ct.nii.gz", {122, 101, 112}, {3, 3, 3}},
    };
    for (const Case& c : cases) {
        const auto p = test::sharedDataset(c.path);
        if (!p) {
            std::cout << "[  SKIPPED ] " << c.path << " absent (../shared/datasets)\n";
            continue;
        }
        const core::Volume v = io::readVolume(*p);
        EXPECT_EQ(v.dims(), c.dims) << c.path;
        for (int a = 0; a < 3; ++a)
            EXPECT_NEAR(v.geometry().spacing[a], c.spacing[a], 1e-5) << c.path;
    }
}

TEST(VolumeIo, AbdomenInt32NiftiBecomesExactInt16Hu) {
    VL_REQUIRE_SHARED(path, "ct/abdomen-totalseg/example_ct.nii.gz");
    const core::Volume v = io::readVolume(path);
    EXPECT_EQ(v.type(), core::VoxelType::Int16);  // int32 on disk, range −1207..3382 fits exactly
    const auto r = v.physicalRange();
    EXPECT_EQ(r[0], -1207.0);
    EXPECT_EQ(r[1], 3382.0);
}
