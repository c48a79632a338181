// SPDX-License-Identifier: MIT
// Round trips through every writable format, and the real volumes' geometry as their headers state
// it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <sstream>

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
        if (checkDirection) {
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(a.geometry().direction[c][i], b.geometry().direction[c][i],
                            kHeaderGeometryTol);
        }
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

TEST(VolumeIo, ADicomSeriesUidOnAnyOtherFileIsRefused) {
    // --series / volume.series picks one series of a DICOM folder; given for a NIfTI or raw file
    // it was ignored without a word (probe).
    test::TempDir tmp;
    io::writeVolume(smallTorso(), tmp / "t.nii.gz");
    io::ReadOptions o;
    o.dicomSeriesUid = "1.2.3";
    for (const bool raw : {false, true}) {
        if (raw)
            o.raw = io::RawLayout{{2, 2, 1}, core::VoxelType::UInt8, {1.0, 1.0, 1.0}, false, 0};
        try {
            (void)io::readVolume(tmp / "t.nii.gz", o);
            ADD_FAILURE() << "read with a series UID, raw " << raw;
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), "series");
            EXPECT_NE(std::string(e.what()).find(raw ? "raw file" : "NIfTI file"),
                      std::string::npos)
                << e.what();
        }
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

// ---------------------------------------------------------------------------------------------------
// Orientation: one asymmetric phantom written as NIfTI (sform) and, by hand, as NRRD in RAS, LAS and
// LPS space (attached and detached) and as MetaImage (TransformMatrix) loads to the same image in
// world space.

namespace {
// Geometry chosen so every sform entry is exact in float32 (3-4-5 cosines times multiples of
// 1.25 mm): the comparison can then be tight.
constexpr double kWorldTol = 1e-6;  // mm; float32 sform entries are exact here, doubles elsewhere

core::Volume orientedPhantom() {
    core::Geometry g;
    g.dims = {12, 11, 5};  // first axis > 9: VTK 9.1 reads a shorter one as vector components
    g.spacing = {1.25, 2.5, 0.625};
    // Oblique in the axial plane and left-handed (the third axis is flipped).
    g.direction =
        glm::dmat3(glm::dvec3(0.6, 0.8, 0), glm::dvec3(0, 0, -1), glm::dvec3(0.8, -0.6, 0));
    g.origin = {10.5, -20.25, 30.0};
    core::Volume v(g, core::VoxelType::Int16);
    auto* p = v.dataAs<std::int16_t>();
    for (int k = 0; k < g.dims.z; ++k)
        for (int j = 0; j < g.dims.y; ++j)
            for (int i = 0; i < g.dims.x; ++i)
                p[i + g.dims.x * (j + g.dims.y * k)] = std::int16_t(1 + i + 13 * j + 150 * k);
    return v;
}

std::string vec(const glm::dvec3& v) {
    std::ostringstream os;
    os << std::setprecision(17) << "(" << v.x << "," << v.y << "," << v.z << ")";
    return os.str();
}

/// NRRD header of `v` in `space`, whose axes relate to LPS by the diagonal `lpsToSpace`.
std::string nrrdHeaderFor(const core::Volume& v, const std::string& space,
                          const glm::dvec3& lpsToSpace, const std::string& dataFile) {
    const core::Geometry& g = v.geometry();
    std::ostringstream os;
    os << "NRRD0004\n# written by hand\ntype: short\ndimension: 3\nspace: " << space
       << "\nsizes: " << g.dims.x << " " << g.dims.y << " " << g.dims.z << "\nspace directions:";
    for (int a = 0; a < 3; ++a) os << " " << vec(lpsToSpace * g.direction[a] * g.spacing[a]);
    os << "\nkinds: domain domain domain\nendian: little\nencoding: raw\nspace origin: "
       << vec(lpsToSpace * g.origin) << "\n";
    if (!dataFile.empty()) os << "data file: " << dataFile << "\n";
    return os.str();
}

std::string rawBytes(const core::Volume& v) {
    return std::string(static_cast<const char*>(v.data()), v.sizeBytes());
}

/// Every voxel of `b` sits at the world position of a voxel of `a` holding the same value.
void expectSameWorldImage(const core::Volume& a, const core::Volume& b, const std::string& what) {
    SCOPED_TRACE(what);
    ASSERT_EQ(a.voxelCount(), b.voxelCount());
    ASSERT_EQ(b.type(), core::VoxelType::Int16);
    const auto& ga = a.geometry();
    const auto& gb = b.geometry();
    int bad = 0;
    for (int k = 0; k < gb.dims.z; ++k)
        for (int j = 0; j < gb.dims.y; ++j)
            for (int i = 0; i < gb.dims.x; ++i) {
                const glm::dvec3 p = gb.indexToWorld({i, j, k});
                const glm::ivec3 q(glm::round(ga.worldToIndex(p)));
                const bool inside = glm::all(glm::greaterThanEqual(q, glm::ivec3(0))) &&
                                    glm::all(glm::lessThan(q, ga.dims));
                const double dist = inside ? glm::length(ga.indexToWorld(glm::dvec3(q)) - p) : 1e9;
                const auto va =
                    inside ? a.dataAs<std::int16_t>()[q.x + ga.dims.x * (q.y + ga.dims.y * q.z)]
                           : -1;
                const auto vb = b.dataAs<std::int16_t>()[i + gb.dims.x * (j + gb.dims.y * k)];
                if ((dist > kWorldTol || va != vb) && ++bad <= 3)
                    ADD_FAILURE() << "voxel (" << i << "," << j << "," << k << ") at " << vec(p)
                                  << " holds " << vb << "; nearest reference voxel is " << dist
                                  << " mm away and holds " << va;
            }
    EXPECT_EQ(bad, 0);
}
}  // namespace

TEST(VolumeIo, NrrdAndMetaImageOrientationMatchNifti) {
    test::TempDir tmp;
    const core::Volume v = orientedPhantom();
    io::writeVolume(v, tmp / "ref.nii");
    const core::Volume ref = io::readVolume(tmp / "ref.nii");
    expectSameWorldImage(v, ref, "NIfTI sform");

    const glm::dvec3 ras(-1, -1, 1), las(1, -1, 1), lps(1, 1, 1);
    const auto writeFile = [&](const std::string& name, const std::string& text) {
        std::ofstream(tmp / name, std::ios::binary) << text;
        return tmp / name;
    };
    const struct {
        const char* name;
        const char* space;
        glm::dvec3 flip;
    } cases[] = {{"ras.nrrd", "RAS", ras},
                 {"ras_long.nrrd", "right-anterior-superior", ras},
                 {"las.nrrd", "LAS", las},
                 {"lps.nrrd", "left-posterior-superior", lps},
                 {"scanner.nrrd", "scanner-xyz", lps}};
    for (const auto& c : cases) {
        const auto path =
            writeFile(c.name, nrrdHeaderFor(v, c.space, c.flip, "") + "\n" + rawBytes(v));
        expectSameWorldImage(ref, io::readVolume(path), c.name);
    }
    writeFile("det.raw", rawBytes(v));
    expectSameWorldImage(
        ref, io::readVolume(writeFile("det.nhdr", nrrdHeaderFor(v, "RAS", ras, "det.raw"))),
        "detached RAS");
    expectSameWorldImage(
        ref, io::readVolume(writeFile("detlas.nhdr", nrrdHeaderFor(v, "LAS", las, "det.raw"))),
        "detached LAS");

    // MetaImage as ITK writes it: TransformMatrix rows are the axes' LPS directions, Offset is
    // voxel (0,0,0) in LPS. AnatomicalOrientation only describes the matrix (ITK ignores it).
    std::ostringstream mhd;
    mhd << std::setprecision(17) << "ObjectType = Image\nNDims = 3\nTransformMatrix =";
    for (int a = 0; a < 3; ++a)
        for (int r = 0; r < 3; ++r) mhd << " " << v.geometry().direction[a][r];
    const auto& g = v.geometry();
    mhd << "\nOffset = " << g.origin.x << " " << g.origin.y << " " << g.origin.z
        << "\nAnatomicalOrientation = RSA\nElementSpacing = " << g.spacing.x << " " << g.spacing.y
        << " " << g.spacing.z << "\nDimSize = " << g.dims.x << " " << g.dims.y << " " << g.dims.z
        << "\nElementType = MET_SHORT\nElementByteOrderMSB = False\nElementDataFile = det.raw\n";
    expectSameWorldImage(ref, io::readVolume(writeFile("meta.mhd", mhd.str())), "MetaImage");
}
