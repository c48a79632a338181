// SPDX-License-Identifier: MIT
// DICOM series reader: geometry and values of the shared series checked against independent truth
// (the manifest's numbers, each file's own Image Position string and its pixels decoded separately
// with gdcm::ImageReader), and refusals of bad folders built in a TempDir from copies of the shared
// files.
#include <gdcmDataElement.h>
#include <gdcmDataSet.h>
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmTag.h>
#include <gdcmWriter.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "io/dicom_series.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using voxlight::InputError;
using voxlight::core::Modality;
using voxlight::core::Progress;
using voxlight::core::Volume;
using voxlight::core::VoxelType;
using voxlight::io::ReadOptions;
using voxlight::io::detail::looksLikeDicom;
using voxlight::io::detail::readDicomSeries;
using voxlight::test::TempDir;

namespace {

/// Positions and spacings in the shared headers are exact binary fractions or short decimals; 1e-6
/// mm is rounding.
constexpr double kMmTol = 1e-6;
/// Pixel spacing 0.9765625 = 500/512 mm, exact in binary.
constexpr double kCtPixelSpacing = 0.9765625;

std::vector<fs::path> dicomFiles(const fs::path& dir) {
    std::vector<fs::path> out;
    for (const auto& e : fs::directory_iterator(dir))
        if (e.is_regular_file() && e.path().extension() != ".txt") out.push_back(e.path());
    std::sort(out.begin(), out.end());
    return out;
}

/// Raw tag string of a file, read with gdcm::Reader (independent of the code under test).
std::string rawTag(const fs::path& file, const gdcm::Tag& tag) {
    gdcm::Reader r;
    r.SetFileName(file.string().c_str());
    if (!r.Read()) ADD_FAILURE() << "gdcm::Reader failed on " << file;
    const gdcm::DataSet& ds = r.GetFile().GetDataSet();
    if (!ds.FindDataElement(tag)) return {};
    const gdcm::ByteValue* bv = ds.GetDataElement(tag).GetByteValue();
    return bv ? std::string(bv->GetPointer(), bv->GetLength()) : std::string();
}

glm::dvec3 rawPosition(const fs::path& file) {
    const std::string s = rawTag(file, gdcm::Tag(0x0020, 0x0032));
    glm::dvec3 p(0.0);
    EXPECT_EQ(std::sscanf(s.c_str(), "%lf\\%lf\\%lf", &p.x, &p.y, &p.z), 3) << s;
    return p;
}

/// Copies `src` to `dst` with one tag replaced (DS/IS strings, or a US value when `us` is set).
void writeWithTag(const fs::path& src, const fs::path& dst, const gdcm::Tag& tag,
                  const std::string& value, gdcm::VR vr = gdcm::VR::DS) {
    gdcm::Reader r;
    r.SetFileName(src.string().c_str());
    ASSERT_TRUE(r.Read()) << src;
    gdcm::DataElement de(tag);
    de.SetVR(vr);
    std::string v = value;
    if (v.size() % 2) v += ' ';  // DICOM values have even length
    de.SetByteValue(v.data(), std::uint32_t(v.size()));
    r.GetFile().GetDataSet().Replace(de);
    gdcm::Writer w;
    w.SetFile(r.GetFile());
    w.CheckFileMetaInformationOff();
    w.SetFileName(dst.string().c_str());
    ASSERT_TRUE(w.Write()) << dst;
}

void writeWithPosition(const fs::path& src, const fs::path& dst, const glm::dvec3& p) {
    std::ostringstream os;
    os.precision(12);
    os << p.x << '\\' << p.y << '\\' << p.z;
    writeWithTag(src, dst, gdcm::Tag(0x0020, 0x0032), os.str());
}

void writeWithUShort(const fs::path& src, const fs::path& dst, const gdcm::Tag& tag,
                     std::uint16_t value) {
    const char bytes[2] = {char(value & 0xff), char(value >> 8)};
    writeWithTag(src, dst, tag, std::string(bytes, 2), gdcm::VR::US);
}

void copyAll(const fs::path& from, const fs::path& to) {
    for (const auto& f : dicomFiles(from)) fs::copy_file(f, to / f.filename());
}

/// Runs `f`, expects an InputError whose message holds every key word; prints the message for the
/// record.
void expectInputError(const std::function<void()>& f, std::initializer_list<const char*> keys) {
    try {
        f();
        ADD_FAILURE() << "expected InputError, got none";
    } catch (const InputError& e) {
        const std::string msg = e.what();
        std::cout << "[InputError] " << msg << "\n";
        for (const char* k : keys)
            EXPECT_NE(msg.find(k), std::string::npos) << "\"" << k << "\" not in: " << msg;
    }
}

Volume read(const fs::path& p, const ReadOptions& o = {}) {
    return readDicomSeries(p, o, Progress::none());
}

}  // namespace

// --- Shared series: geometry and values
// --------------------------------------------------------------------------

TEST(DicomSeries, AbdomenCtGeometryAndHu) {
    VL_REQUIRE_SHARED(dir, "ct/abdomen-totalseg/dicom");
    const Volume v = read(dir);
    const auto& g = v.geometry();
    EXPECT_EQ(g.dims, glm::ivec3(512, 512, 20));
    EXPECT_NEAR(g.spacing.x, kCtPixelSpacing, kMmTol);
    EXPECT_NEAR(g.spacing.y, kCtPixelSpacing, kMmTol);
    EXPECT_NEAR(g.spacing.z, 2.0, kMmTol);  // from positions; SliceThickness says 3
    // Files run from z = −766.5 down to −804.5; the first slice after sorting along +z is the
    // lowest.
    EXPECT_NEAR(g.origin.x, -249.51171875, kMmTol);
    EXPECT_NEAR(g.origin.y, -437.51171875, kMmTol);
    EXPECT_NEAR(g.origin.z, -804.5, kMmTol);
    for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r) EXPECT_NEAR(g.direction[c][r], c == r ? 1.0 : 0.0, 1e-12);
    EXPECT_EQ(v.type(), VoxelType::UInt16);
    EXPECT_EQ(v.modality, Modality::CT);
    EXPECT_EQ(v.mapping.unit, "HU");
    EXPECT_DOUBLE_EQ(v.mapping.slope, 1.0);
    EXPECT_DOUBLE_EQ(v.mapping.intercept, -1024.0);
    EXPECT_EQ(v.description, "CT Body 3.0");

    // HU plausibility: outside the reconstruction circle stored 0 → −1024; bone reaches well above
    // +500.
    const auto range = v.physicalRange();
    EXPECT_NEAR(range[0], -1024.0, 1.0);
    EXPECT_GT(range[1], 500.0);
    EXPECT_LT(range[1], 3100.0);
    EXPECT_FLOAT_EQ(v.at(0, 0, 0), -1024.f);
    // The centre of the body (soft tissue) is within soft-tissue HU.
    float centre = 0.f;
    for (int k = 0; k < 20; ++k) centre += v.at(256, 300, k) / 20.f;
    EXPECT_GT(centre, -200.f);
    EXPECT_LT(centre, 300.f);
}

TEST(DicomSeries, AbdomenSlicesMatchEachFileDecodedIndependently) {
    VL_REQUIRE_SHARED(dir, "ct/abdomen-totalseg/dicom");
    const Volume v = read(dir);
    const auto files = dicomFiles(dir);
    ASSERT_EQ(files.size(), 20u);
    const std::size_t sliceBytes = 512 * 512 * sizeof(std::uint16_t);
    for (std::size_t f : {std::size_t(0), std::size_t(7), std::size_t(19)}) {
        // Where the file's own position string puts it in the volume: on the k axis at an integer
        // index.
        const glm::dvec3 ijk = v.geometry().worldToIndex(rawPosition(files[f]));
        EXPECT_NEAR(ijk.x, 0.0, 1e-9);
        EXPECT_NEAR(ijk.y, 0.0, 1e-9);
        const int k = int(std::lround(ijk.z));
        EXPECT_NEAR(ijk.z, double(k), 1e-9);
        EXPECT_EQ(k, 19 - int(f)) << "files are named in order of decreasing z";

        gdcm::ImageReader r;
        r.SetFileName(files[f].string().c_str());
        ASSERT_TRUE(r.Read());
        ASSERT_EQ(r.GetImage().GetBufferLength(), sliceBytes);
        std::vector<char> pixels(sliceBytes);
        ASSERT_TRUE(r.GetImage().GetBuffer(pixels.data()));
        const auto* slice = static_cast<const char*>(v.data()) + v.linearIndex(0, 0, k) * 2;
        EXPECT_EQ(std::memcmp(slice, pixels.data(), sliceBytes), 0)
            << "slice " << k << " vs " << files[f];
    }
}

TEST(DicomSeries, Jpeg2000IsPixelIdenticalToUncompressed) {
    VL_REQUIRE_SHARED(raw, "ct/abdomen-totalseg/dicom");
    VL_REQUIRE_SHARED(j2k, "ct/abdomen-totalseg/dicom-jpeg2000");
    const Volume a = read(raw);
    const Volume b = read(j2k);
    EXPECT_EQ(a.dims(), b.dims());
    EXPECT_EQ(a.geometry().origin, b.geometry().origin);
    EXPECT_EQ(a.geometry().spacing, b.geometry().spacing);
    EXPECT_EQ(a.geometry().direction, b.geometry().direction);
    EXPECT_EQ(a.type(), b.type());
    EXPECT_EQ(a.mapping.intercept, b.mapping.intercept);
    ASSERT_EQ(a.sizeBytes(), b.sizeBytes());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.sizeBytes()), 0);
}

TEST(DicomSeries, T1BrainGeometry) {
    VL_REQUIRE_SHARED(dir, "mr/t1-brain-dicom-120");
    const Volume v = read(dir);
    const auto& g = v.geometry();
    EXPECT_EQ(g.dims, glm::ivec3(512, 512, 120));
    EXPECT_NEAR(g.spacing.x, 0.41015625, kMmTol);
    EXPECT_NEAR(g.spacing.y, 0.41015625, kMmTol);
    EXPECT_NEAR(g.spacing.z, 1.5, 1e-4);  // positions carry ~11 significant digits
    EXPECT_EQ(v.modality, Modality::MR);
    EXPECT_EQ(v.mapping.unit, "");
    EXPECT_EQ(v.description, "t1_mpr_tra_gk_v4");
    // The first and last files are the two ends of the stack (in either order).
    const auto files = dicomFiles(dir);
    const glm::dvec3 a = rawPosition(files.front()), b = rawPosition(files.back());
    const glm::dvec3 lastSlice = g.indexToWorld({0.0, 0.0, 119.0});
    const bool forward = glm::length(g.origin - a) < 1e-3;
    EXPECT_LT(glm::length(g.origin - (forward ? a : b)), 1e-3);
    EXPECT_LT(glm::length(lastSlice - (forward ? b : a)), 1e-3);
    EXPECT_GT(v.physicalRange()[1], 100.0);
}

TEST(DicomSeries, ForearmThreeSlicesIgnoringTextFiles) {
    VL_REQUIRE_SHARED(dir, "mr/forearm-dicom-3slices");
    ASSERT_TRUE(fs::exists(dir / "LICENSE.txt"));
    const Volume v = read(dir);
    const auto& g = v.geometry();
    EXPECT_EQ(g.dims, glm::ivec3(512, 512, 3));
    EXPECT_NEAR(g.spacing.z, 12.0, kMmTol);
    // Files say z = 12, 0, −12; sorted along +z the origin is the −12 slice.
    EXPECT_NEAR(g.origin.z, -12.0, kMmTol);
    EXPECT_NEAR(g.origin.x, -250.0, kMmTol);
    EXPECT_EQ(v.modality, Modality::MR);
    EXPECT_EQ(v.description, "AX SCOUT");
    // One file of the folder reads the series it belongs to.
    EXPECT_EQ(read(dir / "1-2.dcm").dims(), glm::ivec3(512, 512, 3));
}

TEST(DicomSeries, ProgressAndCancel) {
    VL_REQUIRE_SHARED(dir, "mr/forearm-dicom-3slices");
    std::vector<double> seen;
    std::atomic<bool> cancel{false};
    Progress p(
        [&](const std::string& stage, double f) {
            EXPECT_EQ(stage, "dicom");
            seen.push_back(f);
        },
        &cancel);
    (void)readDicomSeries(dir, {}, p);
    ASSERT_FALSE(seen.empty());
    EXPECT_DOUBLE_EQ(seen.back(), 1.0);
    EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
    cancel = true;
    EXPECT_THROW((void)readDicomSeries(dir, {}, p), voxlight::CancelledError);
}

TEST(DicomSeries, LooksLikeDicom) {
    VL_REQUIRE_SHARED(dir, "mr/forearm-dicom-3slices");
    VL_REQUIRE_SHARED(j2k, "ct/abdomen-totalseg/dicom-jpeg2000");
    EXPECT_TRUE(looksLikeDicom(dir));
    EXPECT_TRUE(looksLikeDicom(dir / "1-1.dcm"));
    EXPECT_TRUE(looksLikeDicom(j2k));  // files without extension
    EXPECT_FALSE(looksLikeDicom(dir / "LICENSE.txt"));
    TempDir tmp;
    EXPECT_FALSE(looksLikeDicom(tmp.path()));
    EXPECT_FALSE(looksLikeDicom(tmp / "absent"));
}

// --- Several series
// ------------------------------------------------------------------------------------------------

TEST(DicomSeries, MixedSeriesRefusedAndSelectable) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    VL_REQUIRE_SHARED(mr, "mr/forearm-dicom-3slices");
    TempDir tmp;
    copyAll(ct, tmp.path());
    copyAll(mr, tmp.path());
    const std::string mrUid = [&] {
        std::string s = rawTag(mr / "1-1.dcm", gdcm::Tag(0x0020, 0x000e));
        while (!s.empty() && (s.back() == '\0' || s.back() == ' ')) s.pop_back();
        return s;
    }();
    expectInputError([&] { read(tmp.path()); },
                     {"2 series", mrUid.c_str(), "AX SCOUT", "3 slices", "CT Body 3.0", "20 slices",
                      "choose one with --series UID"});

    ReadOptions o;
    o.dicomSeriesUid = mrUid;
    EXPECT_EQ(read(tmp.path(), o).dims().z, 3);
    o.dicomSeriesUid = "none";  // the anonymised CT has an empty Series Instance UID
    EXPECT_EQ(read(tmp.path(), o).dims().z, 20);
    o.dicomSeriesUid = "1.2.3.4";
    expectInputError([&] { read(tmp.path(), o); }, {"1.2.3.4", "not in the folder", "AX SCOUT"});
}

// --- Bad folders
// ------------------------------------------------------------------------------------------------

TEST(DicomSeries, MissingSliceRefused) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    copyAll(ct, tmp.path());
    const auto files = dicomFiles(tmp.path());
    fs::remove(files[10]);  // z = −786.5, between −784.5 and −788.5
    expectInputError([&] { read(tmp.path()); },
                     {"missing slice", "-784.5", "-788.5", "4 mm", "1 slice missing"});
}

TEST(DicomSeries, TruncatedFileRefused) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    {
        // Pixel data cut in half: the header scan passes, decoding must fail with the file's name.
        TempDir tmp;
        copyAll(ct, tmp.path());
        const fs::path victim = dicomFiles(tmp.path())[5];
        fs::resize_file(victim, fs::file_size(victim) / 2);
        expectInputError([&] { read(tmp.path()); },
                         {victim.filename().string().c_str(), "PixelData"});
    }
    {
        // Header cut inside the data set.
        TempDir tmp;
        copyAll(ct, tmp.path());
        const fs::path victim = dicomFiles(tmp.path())[5];
        fs::resize_file(victim, 400);
        expectInputError([&] { read(tmp.path()); }, {victim.filename().string().c_str()});
    }
}

TEST(DicomSeries, TruncatedAnywhereIsInputErrorNeverAbort) {
    // Debian's GDCM asserts (aborts) on some truncated headers; the reader must turn every cut into
    // an InputError.
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    VL_REQUIRE_SHARED(j2k, "ct/abdomen-totalseg/dicom-jpeg2000");
    VL_REQUIRE_SHARED(t1, "mr/t1-brain-dicom-120");
    for (const fs::path& src : {dicomFiles(ct)[0], dicomFiles(j2k)[0], dicomFiles(t1)[0]}) {
        const auto size = fs::file_size(src);
        std::vector<std::uintmax_t> cuts;
        for (std::uintmax_t c = 129; c < std::min<std::uintmax_t>(size, 6000); c += 31)
            cuts.push_back(c);
        for (std::uintmax_t c = 6000; c < size; c += size / 17) cuts.push_back(c);
        for (std::uintmax_t c : cuts) {
            TempDir tmp;
            const fs::path f = tmp / "cut.dcm";
            fs::copy_file(src, f);
            fs::resize_file(f, c);
            bool threw = false;
            try {
                (void)read(tmp.path());
            } catch (const InputError&) {
                threw = true;
            }
            EXPECT_TRUE(threw) << src.filename() << " cut at " << c << " of " << size
                               << " bytes was accepted";
        }
    }
}

TEST(DicomSeries, NonDicomAndEmptyRefused) {
    TempDir tmp;
    expectInputError([&] { read(tmp.path()); }, {"no DICOM files", "empty"});
    {
        std::ofstream f(tmp / "slice.dcm");
        f << "this is not DICOM, only a text file with a .dcm name\n";
    }
    expectInputError([&] { read(tmp / "slice.dcm"); }, {"slice.dcm", "not a DICOM file"});
    expectInputError([&] { read(tmp.path()); }, {"no DICOM files", "1 other file"});
    expectInputError([&] { read(tmp / "absent"); }, {"does not exist"});
}

TEST(DicomSeries, DuplicatePositionRefused) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    copyAll(ct, tmp.path());
    const auto files = dicomFiles(tmp.path());
    fs::copy_file(files[3], tmp / "copy-of-slice.dcm");
    expectInputError([&] { read(tmp.path()); }, {"same position", "copy-of-slice.dcm"});
}

TEST(DicomSeries, InconsistentColumnsRefused) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    const auto files = dicomFiles(ct);
    for (std::size_t i = 0; i < 4; ++i) fs::copy_file(files[i], tmp / files[i].filename());
    writeWithUShort(files[4], tmp / "odd.dcm", gdcm::Tag(0x0028, 0x0011), 256);
    expectInputError([&] { read(tmp.path()); }, {"odd.dcm", "Columns", "256", "512"});
}

/// Writes copies of the first `positions.size()` CT slices with the given positions.
void writeStack(const fs::path& ct, const fs::path& out, const std::vector<glm::dvec3>& positions) {
    const auto files = dicomFiles(ct);
    for (std::size_t s = 0; s < positions.size(); ++s)
        writeWithPosition(files[s], out / ("s" + std::to_string(s) + ".dcm"), positions[s]);
}

TEST(DicomSeries, GantryTiltRefused) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    // Each slice 2 mm further in z and 2·tan(15°) mm further in y: a 15° tilted stack.
    const double tilt = 15.0 * 3.14159265358979323846 / 180.0;
    std::vector<glm::dvec3> p;
    for (int s = 0; s < 5; ++s)
        p.push_back({-249.5, -437.5 + 2.0 * s * std::tan(tilt), -800.0 + 2.0 * s});
    writeStack(ct, tmp.path(), p);
    expectInputError([&] { read(tmp.path()); },
                     {"gantry tilt of 15 degrees is not supported", "reslice"});
}

TEST(DicomSeries, VariableSpacingRefused) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    // Gaps 2, 2, 2, 2.5, 2.5, 2.5 mm: neither uniform nor a multiple of the typical gap.
    const std::vector<double> z{0.0, 2.0, 4.0, 6.0, 8.5, 11.0, 13.5};
    std::vector<glm::dvec3> p;
    for (double zz : z) p.push_back({-249.5, -437.5, -800.0 + zz});
    writeStack(ct, tmp.path(), p);
    expectInputError([&] { read(tmp.path()); },
                     {"variable slice spacing", "2 to 2.5 mm", "does not resample"});
}

TEST(DicomSeries, SmallPositionJitterAccepted) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    // Positions rounded to 0.1 mm-ish noise (≤ 5 % of the 2 mm spacing) and 0.05 mm sideways:
    // within tolerance.
    const std::vector<double> jitter{0.0, 0.05, -0.05, 0.04, 0.0};
    std::vector<glm::dvec3> p;
    for (int s = 0; s < 5; ++s)
        p.push_back({-249.5 + (s == 2 ? 0.05 : 0.0), -437.5, -800.0 + 2.0 * s + jitter[s]});
    writeStack(ct, tmp.path(), p);
    const Volume v = read(tmp.path());
    EXPECT_EQ(v.dims().z, 5);
    EXPECT_NEAR(v.geometry().spacing.z, 2.0, 1e-9);
}

TEST(DicomSeries, PerSliceRescaleBecomesFloatPhysicalValues) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    const auto files = dicomFiles(ct);
    // Slices 0..2 keep intercept −1024; slice 3 gets −1000 (z of files decreases, so it becomes k =
    // 0).
    for (std::size_t i = 0; i < 3; ++i) fs::copy_file(files[i], tmp / files[i].filename());
    writeWithTag(files[3], tmp / "rescaled.dcm", gdcm::Tag(0x0028, 0x1052), "-1000");
    const Volume v = read(tmp.path());
    ASSERT_EQ(v.type(), VoxelType::Float32);
    EXPECT_DOUBLE_EQ(v.mapping.slope, 1.0);
    EXPECT_DOUBLE_EQ(v.mapping.intercept, 0.0);
    EXPECT_EQ(v.mapping.unit, "HU");

    gdcm::ImageReader r;
    r.SetFileName(files[3].string().c_str());
    ASSERT_TRUE(r.Read());
    std::vector<std::uint16_t> stored(512 * 512);
    ASSERT_TRUE(r.GetImage().GetBuffer(reinterpret_cast<char*>(stored.data())));
    for (int i : {0, 1000, 131000, 200000})
        EXPECT_FLOAT_EQ(v.dataAs<float>()[i], float(stored[i]) - 1000.f) << "voxel " << i;
    EXPECT_FLOAT_EQ(v.at(0, 0, 1), -1024.f);
}
