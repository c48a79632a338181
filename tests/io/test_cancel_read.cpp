// SPDX-License-Identifier: MIT
// Ctrl-C during a volume read: every reader stops soon after the cancel flag is raised, inside
// VTK's read loop (NIfTI, NRRD raw, VTI: their progress events abort the reader) or by killing
// the child process that runs a reader VTK cannot interrupt (MetaImage: MetaIO reads every voxel
// in one call; NRRD gzip: one gzread). The child's read, when nobody cancels, gives the same
// volume and the same errors as the in-process read.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <zlib.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>

#include "core/error.h"
#include "io/volume_io.h"
#include "support/test_support.h"

using namespace voxlight;
namespace fs = std::filesystem;

namespace {

/// Seconds from raising the flag to the read's CancelledError, at most. A bound on a hang, not a
/// speed target: a reader honours the flag at its next step (2 % of a NIfTI's or raw NRRD's rows,
/// one VTI data block, or the 50 ms poll of a contained reader's child), milliseconds even under
/// ASan; the 32–64 MB reads below take longer than that to run to their end on a loaded machine,
/// and a reader that ignored the flag would never return from the FIFO case.
constexpr double kCancelBound = 2.0;
/// Edge of the generated volumes: 256³ int16 = 32 MiB of voxels.
constexpr int kEdge = 256;

using Clock = std::chrono::steady_clock;

/// 12-bit noise (deflate shrinks it little, so compressed files are long to read too).
core::Volume noiseVolume() {
    core::Geometry g;
    g.dims = glm::ivec3(kEdge);
    g.spacing = glm::dvec3(0.8, 0.8, 1.5);
    core::Volume v(g, core::VoxelType::Int16);
    std::mt19937 rng(11);
    auto* p = v.dataAs<std::int16_t>();
    for (std::size_t i = 0; i < std::size_t(v.voxelCount()); ++i)
        p[i] = std::int16_t(rng() & 0xfff);
    return v;
}

/// NRRD of `v` with `encoding` raw or gzip, written by hand (voxlight writes no NRRD).
void writeNrrd(const core::Volume& v, const fs::path& path, const std::string& encoding) {
    {
        std::ofstream f(path, std::ios::binary);
        f << "NRRD0004\ntype: short\ndimension: 3\nsizes: " << v.dims().x << " " << v.dims().y
          << " " << v.dims().z << "\nencoding: " << encoding
          << "\nendian: little\nspacings: 0.8 0.8 1.5\n\n";
        if (encoding == "raw") f.write(static_cast<const char*>(v.data()), v.sizeBytes());
    }
    if (encoding == "gzip") {
        gzFile gz = gzopen(path.c_str(), "ab1");
        ASSERT_NE(gz, nullptr);
        ASSERT_EQ(gzwrite(gz, v.data(), unsigned(v.sizeBytes())), int(v.sizeBytes()));
        gzclose(gz);
    }
}

/// Bytes this process has read through read(2) so far (/proc/self/io rchar).
std::uint64_t bytesReadByThisProcess() {
    std::ifstream io("/proc/self/io");
    std::string key;
    std::uint64_t value = 0;
    while (io >> key >> value)
        if (key == "rchar:") return value;
    return 0;
}

struct Outcome {
    bool cancelled = false;
    std::string other;        ///< what else happened (a volume, another exception)
    double afterFlag = 0.0;   ///< seconds from the flag to the end of the read
    double flaggedAt = -1;    ///< the progress fraction that raised the flag
    std::uint64_t bytes = 0;  ///< bytes this process read meanwhile
};

/// Reads `path` with a cancel flag that the first progress report of at least `raiseAt` raises
/// (from inside the reader's data loop when `raiseAt` > 0).
Outcome readAndCancel(const fs::path& path, double raiseAt) {
    std::atomic<bool> flag{false};
    Clock::time_point raised;
    Outcome out;
    const core::Progress progress(
        [&](const std::string&, double f) {
            if (!flag && f >= raiseAt) {
                out.flaggedAt = f;
                raised = Clock::now();
                flag = true;
            }
        },
        &flag);
    const std::uint64_t before = bytesReadByThisProcess();
    try {
        const core::Volume v = io::readVolume(path, {}, progress);
        out.other = "read to the end (" + std::to_string(v.voxelCount()) + " voxels)";
    } catch (const CancelledError&) {
        out.cancelled = true;
    } catch (const std::exception& e) {
        out.other = e.what();
    }
    out.bytes = bytesReadByThisProcess() - before;
    if (flag) out.afterFlag = std::chrono::duration<double>(Clock::now() - raised).count();
    return out;
}

/// No child process is left, running or unreaped.
void expectNoChildLeft() {
    errno = 0;
    EXPECT_EQ(::waitpid(-1, nullptr, WNOHANG), -1);
    EXPECT_EQ(errno, ECHILD);
}

class CancelRead : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        dir_ = new test::TempDir;
        core::Volume v = noiseVolume();
        for (const char* name : {"v.nii", "v.nii.gz", "v.vti", "v.mha"})
            io::writeVolume(v, *dir_ / name);
        writeNrrd(v, *dir_ / "raw.nrrd", "raw");
        writeNrrd(v, *dir_ / "gzip.nrrd", "gzip");
        volume_ = new core::Volume(std::move(v));
    }
    static void TearDownTestSuite() {
        delete volume_;
        delete dir_;
    }
    static fs::path file(const char* name) { return *dir_ / name; }
    static const core::Volume& volume() { return *volume_; }

  private:
    static inline test::TempDir* dir_ = nullptr;
    static inline core::Volume* volume_ = nullptr;
};

}  // namespace

TEST_F(CancelRead, AbortableReadersStopInsideTheirDataLoop) {
    // The flag is raised by a progress event the reader sends from its data loop (10 % read): it
    // stops at its next step, so that at least half of the file is never read. (Counted against a
    // whole read of the same file: voxlight's own header checks read parts of it before VTK.)
    for (const char* name : {"v.nii", "v.nii.gz", "v.vti", "raw.nrrd"}) {
        const fs::path path = file(name);
        const std::uint64_t before = bytesReadByThisProcess();
        (void)io::readVolume(path);
        const std::uint64_t whole = bytesReadByThisProcess() - before;
        const Outcome o = readAndCancel(path, 0.1);
        EXPECT_TRUE(o.cancelled) << name << ": " << o.other;
        EXPECT_GT(o.flaggedAt, 0.0) << name << ": the flag was raised from inside the read";
        EXPECT_LT(o.afterFlag, kCancelBound) << name;
        EXPECT_GT(whole - std::min(whole, o.bytes), fs::file_size(path) / 2)
            << name << ": read on after the flag (" << o.bytes << " of " << whole << " bytes)";
    }
    expectNoChildLeft();
}

TEST_F(CancelRead, ContainedReadersAreKilledAndLeaveNoChild) {
    // MetaImage and NRRD gzip read in a child process; the flag, raised as soon as the read
    // starts, kills it.
    for (const char* name : {"v.mha", "gzip.nrrd"}) {
        const Outcome o = readAndCancel(file(name), 0.0);
        EXPECT_TRUE(o.cancelled) << name << ": " << o.other;
        EXPECT_LT(o.afterFlag, kCancelBound) << name;
        expectNoChildLeft();
    }
}

TEST_F(CancelRead, ContainedReadsGiveTheVolumeTheInProcessReadGives) {
    std::atomic<bool> neverRaised{false};
    double last = -1;
    bool monotonic = true;
    const core::Progress cancellable(
        [&](const std::string& stage, double f) {
            EXPECT_EQ(stage, "read");
            monotonic = monotonic && f >= last;
            last = f;
        },
        &neverRaised);
    for (const char* name : {"v.mha", "gzip.nrrd"}) {
        last = -1;
        const core::Volume contained = io::readVolume(file(name), {}, cancellable);
        const core::Volume inProcess = io::readVolume(file(name));  // no flag: no child
        ASSERT_EQ(contained.dims(), volume().dims()) << name;
        ASSERT_EQ(contained.type(), volume().type()) << name;
        EXPECT_EQ(std::memcmp(contained.data(), volume().data(), volume().sizeBytes()), 0) << name;
        EXPECT_EQ(std::memcmp(contained.data(), inProcess.data(), volume().sizeBytes()), 0) << name;
        EXPECT_EQ(contained.geometry().spacing, inProcess.geometry().spacing) << name;
        EXPECT_EQ(contained.geometry().origin, inProcess.geometry().origin) << name;
        EXPECT_EQ(contained.format, inProcess.format) << name;
    }
    EXPECT_TRUE(monotonic);
    expectNoChildLeft();
}

TEST(CancelReadErrors, ContainedReadsReportTheErrorsTheInProcessReadReports) {
    test::TempDir tmp;
    // Deflate data that is not deflate: MetaIO prints "Uncompress failed" on std::cerr and returns.
    std::ofstream(tmp / "bad.mha", std::ios::binary)
        << "ObjectType = Image\nNDims = 3\nDimSize = 8 8 8\nElementType = MET_SHORT\n"
           "CompressedData = True\nElementDataFile = LOCAL\n"
        << std::string(600, 'x');
    // gzip data cut short: VTK's NRRD reader reports the short gzread.
    core::Geometry g;
    g.dims = glm::ivec3(16);
    core::Volume small(g, core::VoxelType::Int16);
    std::mt19937 rng(5);  // noise: a gzip stream of some kilobytes, cut inside its deflate data
    for (std::size_t i = 0; i < std::size_t(small.voxelCount()); ++i)
        small.dataAs<std::int16_t>()[i] = std::int16_t(rng() & 0xfff);
    writeNrrd(small, tmp / "short.nrrd", "gzip");
    fs::resize_file(tmp / "short.nrrd", fs::file_size(tmp / "short.nrrd") - 400);
    std::atomic<bool> neverRaised{false};
    const core::Progress cancellable({}, &neverRaised);
    for (const char* name : {"bad.mha", "short.nrrd"}) {
        std::string inProcess, contained;
        try {
            (void)io::readVolume(tmp / name);
        } catch (const InputError& e) {
            inProcess = e.what();
        }
        try {
            (void)io::readVolume(tmp / name, {}, cancellable);
        } catch (const InputError& e) {
            contained = e.what();
        }
        EXPECT_FALSE(inProcess.empty()) << name;
        EXPECT_EQ(contained, inProcess) << name;
    }
    expectNoChildLeft();
}

TEST(CancelReadErrors, AReaderBlockedOnItsDataFileIsStopped) {
    // A MetaImage whose second slice file is a FIFO nobody writes: MetaIO blocks in open(2)
    // forever (as on a hung network share). Raising the flag still ends the read.
    test::TempDir tmp;
    test::writeBlockedMetaImage(tmp.path());
    ASSERT_FALSE(HasFailure());
    std::atomic<bool> flag{false};
    const core::Progress progress({}, &flag);
    Clock::time_point raised;
    std::thread raiser([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
        raised = Clock::now();
        flag = true;
    });
    EXPECT_THROW((void)io::readVolume(tmp / "hang.mhd", {}, progress), CancelledError);
    raiser.join();
    EXPECT_LT(std::chrono::duration<double>(Clock::now() - raised).count(), kCancelBound);
    expectNoChildLeft();
}
