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

#include <algorithm>
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
#include "io/slice_stack.h"
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

TEST(DicomSeries, SeriesWithoutAUidThatDifferInWhatElseNamesASeriesAreRefused) {
    // The anonymised CT carries no Series Instance UID; files of another series without one were
    // stacked into the same volume, labelled by whichever sorted first (probe: CT + MR slices read
    // as one 25-slice "MR" volume). Each field that names a series must agree.
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    const auto files = dicomFiles(ct);
    const struct {
        gdcm::Tag tag;
        gdcm::VR vr;
        const char* value;
        std::vector<const char*> words;
    } cases[] = {
        {gdcm::Tag(0x0008, 0x0060),
         gdcm::VR::CS,
         "MR",
         {"odd.dcm", "Modality", "\"MR\" but \"CT\"", "carry no SeriesInstanceUID",
          "put each series in its own folder"}},
        {gdcm::Tag(0x0008, 0x103e),
         gdcm::VR::LO,
         "T2 FLAIR",
         {"odd.dcm", "SeriesDescription", "T2 FLAIR", "carry no SeriesInstanceUID"}},
        {gdcm::Tag(0x0020, 0x0052),
         gdcm::VR::UI,
         "1.2.3.4.5",
         {"odd.dcm", "FrameOfReferenceUID", "1.2.3.4.5"}},
        // A multi-frame file among single-frame slices: was "the decoded image is 512x512 but the
        // header says 512x512".
        {gdcm::Tag(0x0028, 0x0008),
         gdcm::VR::IS,
         "2",
         {"odd.dcm", "NumberOfFrames", "is 2 but 1", "multi-frame file among single-frame"}},
    };
    for (const auto& c : cases) {
        TempDir tmp;
        for (std::size_t i = 0; i < 4; ++i) fs::copy_file(files[i], tmp / files[i].filename());
        writeWithTag(files[4], tmp / "odd.dcm", c.tag, c.value, c.vr);
        try {
            read(tmp.path());
            ADD_FAILURE() << c.words[1] << ": accepted";
        } catch (const InputError& e) {
            for (const char* w : c.words)
                EXPECT_NE(std::string(e.what()).find(w), std::string::npos) << e.what();
        }
    }
}

TEST(DicomSeries, ARescaleBeyondAnyPhysicalQuantityIsRefused) {
    // RescaleSlope 1e30 read the CT as -1024 … 2.9e33 HU, exit 0 (probe).
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    const auto files = dicomFiles(ct);
    TempDir tmp;
    for (std::size_t i = 0; i < 4; ++i)
        writeWithTag(files[i], tmp / files[i].filename(), gdcm::Tag(0x0028, 0x1053), "1e30");
    expectInputError([&] { read(tmp.path()); },
                     {"RescaleSlope", "1e+30", "beyond any physical quantity"});
}

/// Writes copies of the first `positions.size()` CT slices with the given positions.
void writeStack(const fs::path& ct, const fs::path& out, const std::vector<glm::dvec3>& positions) {
    const auto files = dicomFiles(ct);
    for (std::size_t s = 0; s < positions.size(); ++s)
        writeWithPosition(files[s], out / ("s" + std::to_string(s) + ".dcm"), positions[s]);
}

// --- Gantry tilt and variable spacing: resampled onto a regular grid (or refused when strict)
// -------------------------------------------------------------------------------------------------

constexpr double kPi = 3.14159265358979323846;
/// The shared CT's first slice position; the synthetic stacks start there.
const glm::dvec3 kP0{-249.5, -437.5, -800.0};

/// A 15° tilted stack as a gantry tilt makes it: each slice `gap` mm further in z and gap·tan(15°)
/// mm further along `shear` (a unit in-plane direction).
std::vector<glm::dvec3> tiltedPositions(int slices, double gap, const glm::dvec3& shear) {
    std::vector<glm::dvec3> p;
    for (int s = 0; s < slices; ++s)
        p.push_back(kP0 + glm::dvec3(0, 0, gap * s) +
                    gap * s * std::tan(15.0 * kPi / 180.0) * shear);
    return p;
}

ReadOptions strictOptions() {
    ReadOptions o;
    o.strictGeometry = true;
    return o;
}

/// A linear field of patient position (mm), as stored values: trilinear interpolation in the
/// sheared frame reproduces it exactly, so the resampled volume can be checked voxel by voxel.
double linearField(const glm::dvec3& p) {
    const glm::dvec3 d = p - kP0;
    return 2000.0 + 3.0 * d.x + 2.0 * d.y + 4.0 * d.z;
}
/// The field is written rounded to uint16 (≤ 0.5) and the blend is rounded back to uint16 (≤ 0.5).
constexpr double kFieldTol = 1.0 + 1e-6;

/// Synthetic series from the shared CT's first file: `cols`×`rows` uint16 pixels holding
/// linearField at each pixel's patient position (axial: i = +x, j = +y), PixelSpacing
/// [Δrow, Δcol] = `pixelSpacing`, one file per position.
void writeFieldStack(const fs::path& ct, const fs::path& out, const std::vector<glm::dvec3>& pos,
                     int cols, int rows, const glm::dvec2& pixelSpacing) {
    const fs::path templ = dicomFiles(ct).front();
    for (std::size_t s = 0; s < pos.size(); ++s) {
        gdcm::Reader r;
        r.SetFileName(templ.string().c_str());
        ASSERT_TRUE(r.Read());
        gdcm::DataSet& ds = r.GetFile().GetDataSet();
        const auto put = [&](std::uint16_t g, std::uint16_t e, gdcm::VR vr, std::string v) {
            if (v.size() % 2) v += ' ';
            gdcm::DataElement de(gdcm::Tag(g, e));
            de.SetVR(vr);
            de.SetByteValue(v.data(), std::uint32_t(v.size()));
            ds.Replace(de);
        };
        const auto us = [](int v) { return std::string{char(v & 0xff), char(v >> 8)}; };
        std::ostringstream ipp, ps;
        ipp.precision(12);
        ipp << pos[s].x << '\\' << pos[s].y << '\\' << pos[s].z;
        ps.precision(12);
        ps << pixelSpacing[0] << '\\' << pixelSpacing[1];
        std::vector<std::uint16_t> px(std::size_t(cols) * std::size_t(rows));
        for (int b = 0; b < rows; ++b)
            for (int a = 0; a < cols; ++a)
                px[std::size_t(b) * cols + a] = std::uint16_t(std::lround(linearField(
                    pos[s] + glm::dvec3(a * pixelSpacing[1], b * pixelSpacing[0], 0.0))));
        put(0x0020, 0x0032, gdcm::VR::DS, ipp.str());
        put(0x0020, 0x0037, gdcm::VR::DS, "1\\0\\0\\0\\1\\0");
        put(0x0028, 0x0030, gdcm::VR::DS, ps.str());
        put(0x0028, 0x0010, gdcm::VR::US, us(rows));
        put(0x0028, 0x0011, gdcm::VR::US, us(cols));
        put(0x7fe0, 0x0010, gdcm::VR::OW,
            std::string(reinterpret_cast<const char*>(px.data()), px.size() * 2));
        gdcm::Writer w;
        w.SetFile(r.GetFile());
        w.CheckFileMetaInformationOff();
        const fs::path dst = out / ("s" + std::to_string(s) + ".dcm");
        w.SetFileName(dst.string().c_str());
        ASSERT_TRUE(w.Write()) << dst;
    }
}

/// Checks every voxel of a resampled field stack: where the bracketing acquired slices (those with
/// a nonzero weight) cover the voxel's in-plane position, the value is linearField there; elsewhere
/// it is the volume's minimum. The bracketing is found here from the positions themselves.
void expectFieldResampled(const Volume& v, const std::vector<glm::dvec3>& pos, int cols, int rows,
                          const glm::dvec2& pixelSpacing) {
    const auto& g = v.geometry();
    const double intercept = v.mapping.intercept;  // the template's −1024, slope 1
    ASSERT_DOUBLE_EQ(v.mapping.slope, 1.0);
    // Background: the smallest value written into the files (not read back from the volume).
    double background = HUGE_VAL;
    for (const glm::dvec3& p : pos)
        for (int b = 0; b < rows; ++b)
            for (int a = 0; a < cols; ++a)
                background =
                    std::min(background,
                             double(std::lround(linearField(
                                 p + glm::dvec3(a * pixelSpacing[1], b * pixelSpacing[0], 0.0)))) +
                                 intercept);
    std::size_t inside = 0, outside = 0;
    const auto covers = [&](const glm::dvec3& p, std::size_t s) {
        const double x = (p.x - pos[s].x) / pixelSpacing[1], y = (p.y - pos[s].y) / pixelSpacing[0];
        constexpr double kEdge = 1e-6;
        return x > -kEdge && y > -kEdge && x < cols - 1 + kEdge && y < rows - 1 + kEdge;
    };
    for (int c = 0; c < g.dims.z; ++c)
        for (int b = 0; b < g.dims.y; ++b)
            for (int a = 0; a < g.dims.x; ++a) {
                const glm::dvec3 p = g.indexToWorld(glm::dvec3(a, b, c));
                std::size_t k = 0;
                while (k + 2 < pos.size() && pos[k + 1].z <= p.z + 1e-9) ++k;
                const double t = (p.z - pos[k].z) / (pos[k + 1].z - pos[k].z);
                const bool in = (t > 1.0 - 1e-9 || covers(p, k)) && (t < 1e-9 || covers(p, k + 1));
                const double got = v.at(a, b, c);
                if (in) {
                    ++inside;
                    ASSERT_NEAR(got, linearField(p) + intercept, kFieldTol)
                        << "voxel " << a << "," << b << "," << c << " at " << p.x << "," << p.y
                        << "," << p.z;
                } else {
                    ++outside;
                    ASSERT_EQ(got, background) << "voxel " << a << "," << b << "," << c;
                }
            }
    // Not vacuous: a good part of the grid is inside the acquired data (these stacks are small
    // and strongly sheared, so much of the grown bounding box is not).
    EXPECT_GT(inside, (inside + outside) / 4);
}

TEST(DicomSeries, GantryTiltResampledOntoRegularGrid) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    // 6 slices 2 mm apart, tilted 15° so that each is 2·tan 15° = 0.536 mm further in −y (0.67 of
    // a 0.8 mm row): 12 columns × 10 rows of 0.5 × 0.8 mm.
    const int cols = 12, rows = 10;
    const glm::dvec2 ps{0.8, 0.5};
    const std::vector<glm::dvec3> pos = tiltedPositions(6, 2.0, {0, -1, 0});
    writeFieldStack(ct, tmp.path(), pos, cols, rows, ps);
    const Volume v = read(tmp.path());

    // Geometry from the slice positions: i, j, n unchanged; in-plane spacing kept; the last slice
    // is 5·0.536 = 2.68 mm = 3.35 rows further in −y, so the grid starts 4 rows before slice 0
    // (on slice 0's pixel lattice) and spans 4 + 9 + 1 = 14 rows; 6 slices at the 2 mm gap.
    const auto& g = v.geometry();
    const double shiftRows = 5 * 2.0 * std::tan(15.0 * kPi / 180.0) / ps[0];
    const int rowsBefore = int(std::ceil(shiftRows));
    ASSERT_EQ(rowsBefore, 4);
    EXPECT_EQ(g.dims, glm::ivec3(cols, rows + rowsBefore, 6));
    EXPECT_NEAR(g.spacing.x, 0.5, kMmTol);
    EXPECT_NEAR(g.spacing.y, 0.8, kMmTol);
    EXPECT_NEAR(g.spacing.z, 2.0, kMmTol);
    for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r) EXPECT_NEAR(g.direction[c][r], c == r ? 1.0 : 0.0, 1e-12);
    EXPECT_NEAR(g.origin.x, kP0.x, kMmTol);
    EXPECT_NEAR(g.origin.y, kP0.y - rowsBefore * ps[0], kMmTol);
    EXPECT_NEAR(g.origin.z, kP0.z, kMmTol);
    // The first and last grid planes are the first and last slices' planes.
    EXPECT_NEAR(g.indexToWorld({0, 0, g.dims.z - 1}).z, pos.back().z, kMmTol);
    EXPECT_EQ(v.type(), VoxelType::UInt16);  // the stored type is kept
    expectFieldResampled(v, pos, cols, rows, ps);

    // One warning line: what was found, what was done, how to refuse.
    ASSERT_EQ(v.warnings.size(), 1u);
    const std::string& w = v.warnings[0];
    std::cout << "[warning] " << w << "\n";
    EXPECT_EQ(w.find('\n'), std::string::npos);
    for (const char* k : {"gantry tilt of 15 degrees", "resampled its 6 slices", "6 slices at 2 mm",
                          "--strict-geometry"})
        EXPECT_NE(w.find(k), std::string::npos) << "\"" << k << "\" not in: " << w;
    EXPECT_NE(w.find(tmp.path().string()), std::string::npos) << w;
}

TEST(DicomSeries, VariableSpacingResampledAtSmallestGap) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    // Gaps 2, 2, 2, 2.5, 2.5, 2.5 mm: 13.5 mm in steps ≤ the smallest gap (2 mm) = 7 steps of
    // 13.5/7 mm, 8 slices.
    const std::vector<double> z{0.0, 2.0, 4.0, 6.0, 8.5, 11.0, 13.5};
    std::vector<glm::dvec3> pos;
    for (double zz : z) pos.push_back(kP0 + glm::dvec3(0, 0, zz));
    const int cols = 12, rows = 10;
    const glm::dvec2 ps{0.8, 0.5};
    writeFieldStack(ct, tmp.path(), pos, cols, rows, ps);
    const Volume v = read(tmp.path());
    const auto& g = v.geometry();
    EXPECT_EQ(g.dims, glm::ivec3(cols, rows, 8));
    EXPECT_NEAR(g.spacing.z, 13.5 / 7.0, kMmTol);
    EXPECT_NEAR(glm::distance(g.origin, kP0), 0.0, kMmTol);
    expectFieldResampled(v, pos, cols, rows, ps);
    ASSERT_EQ(v.warnings.size(), 1u);
    std::cout << "[warning] " << v.warnings[0] << "\n";
    EXPECT_NE(v.warnings[0].find("slice spacing varying from 2 to 2.5 mm"), std::string::npos)
        << v.warnings[0];
    EXPECT_NE(v.warnings[0].find("8 slices at 1.929 mm"), std::string::npos) << v.warnings[0];
}

TEST(DicomSeries, TiltAndVariableSpacingTogether) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    // Sheared along +x and −y at once (0.3 and 0.2 mm per mm of z) with gaps 1.5, 1.5, 2.5, 2 mm.
    const std::vector<double> z{0.0, 1.5, 3.0, 5.5, 7.5};
    std::vector<glm::dvec3> pos;
    for (double zz : z) pos.push_back(kP0 + glm::dvec3(0.3 * zz, -0.2 * zz, zz));
    const int cols = 9, rows = 11;
    const glm::dvec2 ps{0.6, 0.7};
    writeFieldStack(ct, tmp.path(), pos, cols, rows, ps);
    const Volume v = read(tmp.path());
    const auto& g = v.geometry();
    // x: slices shifted 0 .. 2.25 mm = 0 .. 3.21 columns → 9 + 4 columns from slice 0's first;
    // y: 0 .. −1.5 mm = 2.5 rows back → 3 rows before, 11 + 3; z: 7.5 mm in 5 steps of 1.5 mm.
    EXPECT_EQ(g.dims, glm::ivec3(cols + 4, rows + 3, 6));
    EXPECT_NEAR(g.spacing.z, 1.5, kMmTol);
    EXPECT_NEAR(glm::distance(g.origin, kP0 + glm::dvec3(0, -3 * 0.6, 0)), 0.0, kMmTol);
    expectFieldResampled(v, pos, cols, rows, ps);
    ASSERT_EQ(v.warnings.size(), 1u);
    EXPECT_NE(v.warnings[0].find("gantry tilt of"), std::string::npos) << v.warnings[0];
    EXPECT_NE(v.warnings[0].find("and slice spacing varying from 1.5 to 2.5 mm"), std::string::npos)
        << v.warnings[0];
}

TEST(DicomSeries, StrictGeometryRefusesTiltAndVariableSpacing) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    {
        TempDir tmp;
        writeStack(ct, tmp.path(), tiltedPositions(5, 2.0, {0, 1, 0}));
        expectInputError([&] { read(tmp.path(), strictOptions()); },
                         {tmp.path().string().c_str(), "ImagePositionPatient",
                          "gantry tilt of 15 degrees", "--strict-geometry", "omit"});
    }
    {
        TempDir tmp;
        const std::vector<double> z{0.0, 2.0, 4.0, 6.0, 8.5, 11.0, 13.5};
        std::vector<glm::dvec3> p;
        for (double zz : z) p.push_back(kP0 + glm::dvec3(0, 0, zz));
        writeStack(ct, tmp.path(), p);
        expectInputError([&] { read(tmp.path(), strictOptions()); },
                         {"ImagePositionPatient", "variable slice spacing", "2 to 2.5 mm",
                          "--strict-geometry", "omit"});
    }
}

TEST(DicomSeries, TiltedSharedCtLoadsWithWarningAndKeepsFirstSlice) {
    // The check: the shared CT made into a tilted series by shearing its slice positions.
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    TempDir tmp;
    const std::vector<glm::dvec3> pos = tiltedPositions(5, 2.0, {0, 1, 0});
    writeStack(ct, tmp.path(), pos);
    const Volume v = read(tmp.path());
    const auto& g = v.geometry();
    // +y shear: 4·0.536 mm = 2.2 rows of 0.9765625 mm after the last row: 512 + 3 rows.
    EXPECT_EQ(g.dims, glm::ivec3(512, 515, 5));
    EXPECT_NEAR(glm::distance(g.origin, pos[0]), 0.0, kMmTol);
    EXPECT_NEAR(g.spacing.y, kCtPixelSpacing, kMmTol);
    EXPECT_NEAR(g.spacing.z, 2.0, kMmTol);
    EXPECT_EQ(v.mapping.unit, "HU");
    ASSERT_EQ(v.warnings.size(), 1u);
    EXPECT_NE(v.warnings[0].find("gantry tilt of 15 degrees"), std::string::npos);
    // Grid slice 0 is acquired slice 0 on its own pixel lattice: identical pixels, then background
    // in the rows only later slices reach.
    gdcm::ImageReader r;
    r.SetFileName(dicomFiles(tmp.path())[0].string().c_str());
    ASSERT_TRUE(r.Read());
    std::vector<std::uint16_t> stored(512 * 512);
    ASSERT_TRUE(r.GetImage().GetBuffer(reinterpret_cast<char*>(stored.data())));
    const std::uint16_t* got = v.dataAs<std::uint16_t>();
    std::uint16_t lowest = 0xffff;
    for (std::size_t q = 0; q < v.voxelCount(); ++q) lowest = std::min(lowest, got[q]);
    for (int b = 0; b < 515; ++b)
        for (int a = 0; a < 512; a += 7)
            ASSERT_EQ(got[std::size_t(b) * 512 + a],
                      b < 512 ? stored[std::size_t(b) * 512 + a] : lowest)
                << a << "," << b;
}

TEST(SliceStack, FloatStackResampledExactlyWithoutSharedData) {
    // resampleSliceStack on its own, with an oblique slice orientation (rotated 30° about z): a
    // float field linear in patient position is reproduced to float rounding, and voxels that no
    // bracketing slice covers hold the stack's minimum.
    const double c30 = std::cos(kPi / 6), s30 = std::sin(kPi / 6);
    const glm::dvec3 i(c30, s30, 0), j(-s30, c30, 0), n(0, 0, 1);
    voxlight::core::Geometry sg;
    sg.dims = {7, 5, 4};
    sg.spacing = {0.75, 1.25, 99.0};  // spacing.z and origin are ignored
    sg.direction = glm::dmat3(i, j, n);
    Volume stack(sg, VoxelType::Float32);
    const glm::dvec3 p0(10, -20, 30);
    const std::vector<double> w{0.0, 1.0, 3.0, 4.5};  // variable gaps
    std::vector<glm::dvec3> pos;
    for (double ww : w) pos.push_back(p0 + ww * n + ww * 0.4 * i - ww * 0.3 * j);  // sheared
    const auto field = [](const glm::dvec3& p) { return 0.5 * p.x - 1.5 * p.y + 2.0 * p.z + 7.0; };
    float* d = stack.dataAs<float>();
    for (int k = 0; k < 4; ++k)
        for (int b = 0; b < 5; ++b)
            for (int a = 0; a < 7; ++a)
                d[stack.linearIndex(a, b, k)] = float(field(pos[k] + a * 0.75 * i + b * 1.25 * j));
    const Volume v = voxlight::io::detail::resampleSliceStack(stack, pos, "stack");
    const auto& g = v.geometry();
    EXPECT_EQ(v.type(), VoxelType::Float32);
    EXPECT_NEAR(g.spacing.z, 4.5 / 5.0, 1e-12);  // 5 steps ≤ the smallest gap (1 mm)
    EXPECT_EQ(g.dims.z, 6);
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(glm::distance(g.direction[c], sg.direction[c]), 0, 1e-12);
    // Shear 4.5·0.4/0.75 = 2.4 columns forward, 4.5·0.3/1.25 = 1.08 rows back.
    EXPECT_EQ(g.dims.x, 7 + 3);
    EXPECT_EQ(g.dims.y, 5 + 2);
    EXPECT_NEAR(glm::distance(g.origin, p0 - 2 * 1.25 * j), 0.0, 1e-9);
    float lowest = d[0];
    for (std::size_t q = 0; q < stack.voxelCount(); ++q) lowest = std::min(lowest, d[q]);
    /// Float32 storage of values ≈ 100: relative rounding 6e-8, a few ulps through the blend.
    constexpr double kFloatFieldTol = 1e-4;
    int inside = 0, outside = 0;
    for (int c = 0; c < g.dims.z; ++c)
        for (int b = 0; b < g.dims.y; ++b)
            for (int a = 0; a < g.dims.x; ++a) {
                const glm::dvec3 p = g.indexToWorld(glm::dvec3(a, b, c));
                const double wp = glm::dot(p - p0, n);
                std::size_t k = 0;
                while (k + 2 < pos.size() && w[k + 1] <= wp + 1e-9) ++k;
                const double t = (wp - w[k]) / (w[k + 1] - w[k]);
                const auto covers = [&](std::size_t s) {
                    const double x = glm::dot(p - pos[s], i) / 0.75;
                    const double y = glm::dot(p - pos[s], j) / 1.25;
                    return x > -1e-6 && y > -1e-6 && x < 6 + 1e-6 && y < 4 + 1e-6;
                };
                const bool in = (t > 1 - 1e-9 || covers(k)) && (t < 1e-9 || covers(k + 1));
                if (in) {
                    ++inside;
                    ASSERT_NEAR(v.at(a, b, c), field(p), kFloatFieldTol)
                        << a << "," << b << "," << c;
                } else {
                    ++outside;
                    ASSERT_EQ(v.at(a, b, c), lowest) << a << "," << b << "," << c;
                }
            }
    EXPECT_GT(inside, 100);
    EXPECT_GT(outside, 10);

    // Progress ends at 1 under its own stage name; a raised cancel flag stops the resampling.
    std::atomic<bool> cancel{false};
    std::vector<double> seen;
    const Progress p(
        [&](const std::string& stage, double f) {
            EXPECT_EQ(stage, "dicom resample");
            seen.push_back(f);
        },
        &cancel);
    (void)voxlight::io::detail::resampleSliceStack(stack, pos, "stack", p);
    ASSERT_FALSE(seen.empty());
    EXPECT_DOUBLE_EQ(seen.back(), 1.0);
    cancel = true;
    EXPECT_THROW((void)voxlight::io::detail::resampleSliceStack(stack, pos, "stack", p),
                 voxlight::CancelledError);
}

TEST(DicomSeries, RegularSeriesUntouchedAndSilent) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/dicom");
    const Volume lax = read(ct);
    const Volume strict = read(ct, strictOptions());
    EXPECT_TRUE(lax.warnings.empty());
    EXPECT_EQ(lax.geometry().dims, strict.geometry().dims);
    EXPECT_EQ(lax.geometry().origin, strict.geometry().origin);
    EXPECT_EQ(lax.geometry().spacing, strict.geometry().spacing);
    ASSERT_EQ(lax.sizeBytes(), strict.sizeBytes());
    EXPECT_EQ(std::memcmp(lax.data(), strict.data(), lax.sizeBytes()), 0);
    // A synthetic regular stack keeps its written pixels exactly (no resampling on the way).
    TempDir tmp;
    std::vector<glm::dvec3> pos;
    for (int s = 0; s < 4; ++s) pos.push_back(kP0 + glm::dvec3(0, 0, 2.0 * s));
    writeFieldStack(ct, tmp.path(), pos, 6, 5, {1.0, 1.0});
    const Volume v = read(tmp.path());
    EXPECT_TRUE(v.warnings.empty());
    EXPECT_EQ(v.dims(), glm::ivec3(6, 5, 4));
    for (int c = 0; c < 4; ++c)
        for (int b = 0; b < 5; ++b)
            for (int a = 0; a < 6; ++a)
                ASSERT_EQ(v.dataAs<std::uint16_t>()[v.linearIndex(a, b, c)],
                          std::uint16_t(std::lround(linearField(pos[c] + glm::dvec3(a, b, 0)))));
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
