// SPDX-License-Identifier: MIT
// Malformed files: one clear InputError naming the file, never a crash or a half-filled volume.
// These run under ASan/UBSan in CI (the `asan` preset).
#include <gtest/gtest.h>

#include <fstream>

#include "core/phantoms.h"
#include "io/volume_io.h"
#include "support/test_support.h"

using namespace voxlight;
namespace fs = std::filesystem;

namespace {

void writeText(const fs::path& p, const std::string& text) {
    std::ofstream f(p, std::ios::binary);
    f << text;
}

/// Expects readVolume to throw an InputError whose message names `mustName` and contains every word
/// in `words`.
void expectInputError(const fs::path& path, const std::string& mustName,
                      std::vector<std::string> words, const io::ReadOptions& options = {}) {
    try {
        (void)io::readVolume(path, options);
        ADD_FAILURE() << path << " was accepted";
    } catch (const InputError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(mustName), std::string::npos) << msg;
        for (const auto& w : words)
            EXPECT_NE(msg.find(w), std::string::npos) << "'" << w << "' missing: " << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << "one line: " << msg;
    }
}

}  // namespace

TEST(BadInput, MissingFile) {
    test::TempDir tmp;
    expectInputError(tmp / "nope.nii.gz", "nope.nii.gz", {"does not exist"});
}

TEST(BadInput, TruncatedNiftiGz) {
    test::TempDir tmp;
    core::PhantomOptions o;
    o.size = 48;
    io::writeVolume(core::makePhantom("torso", o), tmp / "full.nii.gz");
    const auto size = fs::file_size(tmp / "full.nii.gz");
    fs::copy_file(tmp / "full.nii.gz", tmp / "cut.nii.gz");
    fs::resize_file(tmp / "cut.nii.gz", size / 2);
    expectInputError(tmp / "cut.nii.gz", "cut.nii.gz", {"could not be read"});
    // Cut inside the header too.
    fs::resize_file(tmp / "cut.nii.gz", 100);
    expectInputError(tmp / "cut.nii.gz", "cut.nii.gz", {});
}

TEST(BadInput, TruncatedUncompressedNifti) {
    test::TempDir tmp;
    core::PhantomOptions o;
    o.size = 32;
    io::writeVolume(core::makePhantom("torso", o), tmp / "full.nii");
    fs::resize_file(tmp / "full.nii", fs::file_size(tmp / "full.nii") - 1000);
    expectInputError(tmp / "full.nii", "full.nii", {});
}

TEST(BadInput, MetaImageWithShortRawFile) {
    test::TempDir tmp;
    writeText(tmp / "v.mhd",
              "ObjectType = Image\nNDims = 3\nDimSize = 64 64 64\nElementType = MET_SHORT\n"
              "ElementSpacing = 1 1 1\nElementByteOrderMSB = False\nElementDataFile = v.raw\n");
    writeText(tmp / "v.raw", std::string(1000, '\0'));
    expectInputError(tmp / "v.mhd", "v.raw", {"truncated", "524288"});
    fs::remove(tmp / "v.raw");
    expectInputError(tmp / "v.mhd", "v.mhd", {"ElementDataFile"});
}

TEST(BadInput, NrrdWithAbsurdDims) {
    test::TempDir tmp;
    // 10^21 per axis: 10^63 voxels. Must be refused from the header, before any allocation.
    writeText(
        tmp / "huge.nhdr",
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 1000000000000000000000 1000000000000000000000 "
        "1000000000000000000000\nendian: little\nencoding: raw\ndata file: huge.raw\n");
    writeText(tmp / "huge.raw", std::string(16, '\0'));
    expectInputError(tmp / "huge.nhdr", "huge.nhdr", {});
    // Large but representable: 100000^3.
    writeText(tmp / "big.nhdr",
              "NRRD0004\ntype: short\ndimension: 3\nsizes: 100000 100000 100000\nendian: "
              "little\nencoding: raw\n"
              "data file: huge.raw\n");
    expectInputError(tmp / "big.nhdr", "big.nhdr", {"dims", "outside the supported range"});
}

TEST(BadInput, NonVolumeFiles) {
    test::TempDir tmp;
    writeText(tmp / "notes.txt", "this is not a volume\n");
    expectInputError(tmp / "notes.txt", "notes.txt",
                     {"not a volume voxlight can read", "NIfTI", "DICOM"});
    writeText(tmp / "fake.nii", std::string(400, 'x'));
    expectInputError(tmp / "fake.nii", "fake.nii", {"not a volume"});
    writeText(tmp / "fake.vti", "<VTKFile type=\"ImageData\"><broken");
    expectInputError(tmp / "fake.vti", "fake.vti", {});
    writeText(tmp / "empty.mha", "");
    expectInputError(tmp / "empty.mha", "empty.mha", {});
    fs::create_directory(tmp / "emptydir");
    expectInputError(tmp / "emptydir", "emptydir", {"without DICOM"});
}

TEST(BadInput, NonFiniteVoxelsRejectedOrReplaced) {
    test::TempDir tmp;
    core::PhantomOptions o;
    o.size = 16;
    core::Volume v = core::makePhantom("sphere", o);
    v.dataAs<float>()[5] = NAN;
    v.dataAs<float>()[6] = -INFINITY;
    io::writeVolume(v, tmp / "nan.nii.gz");
    expectInputError(tmp / "nan.nii.gz", "nan.nii.gz",
                     {"2 of 4096 voxels are NaN or Inf", "--nonfinite=min"});
    io::ReadOptions opt;
    opt.nonFinite = io::NonFinitePolicy::ReplaceWithMin;
    const core::Volume fixed = io::readVolume(tmp / "nan.nii.gz", opt);
    EXPECT_EQ(fixed.countNonFinite(), 0u);
    EXPECT_EQ(fixed.dataAs<float>()[5], 0.0f);  // the sphere's background
}

TEST(BadInput, RawLayoutLargerThanFile) {
    test::TempDir tmp;
    writeText(tmp / "v.raw", std::string(100, '\0'));
    io::ReadOptions o;
    o.raw = io::RawLayout{{10, 10, 10}, core::VoxelType::UInt8, {1, 1, 1}, false, 0};
    expectInputError(tmp / "v.raw", "v.raw", {"100 bytes", "1000 data bytes"}, o);
    o.raw->spacing = {1, 0, 1};
    writeText(tmp / "w.raw", std::string(1000, '\0'));
    expectInputError(tmp / "w.raw", "w.raw", {"spacing"}, o);
}

TEST(BadInput, WritingToMissingDirectoryLeavesNothing) {
    test::TempDir tmp;
    core::PhantomOptions o;
    o.size = 8;
    EXPECT_THROW(io::writeVolume(core::makePhantom("sphere", o), tmp / "no" / "such" / "v.nii.gz"),
                 InputError);
    EXPECT_THROW(io::writeVolume(core::makePhantom("sphere", o), tmp / "v.xyz"), InputError);
    EXPECT_TRUE(fs::is_empty(tmp.path()));
}
