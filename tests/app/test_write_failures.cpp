// SPDX-License-Identifier: MIT
// Writes that fail: a full disk, a rename refused at commit, standard output that cannot be
// written, names the file system cannot hold, outputs over a command's own inputs. Each is one
// line and exit 2 (or 130 for Ctrl-C), and leaves the files that were there as they were.
//
// The full-disk and immutable-file cases need root (a tmpfs mount, chattr): they skip elsewhere.
#include <gtest/gtest.h>
#include <sys/mount.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "support/test_support.h"

using namespace voxlight;
namespace fs = std::filesystem;

namespace {
using Result = test::ShellResult;

std::string quoted(const fs::path& p) { return "'" + p.string() + "'"; }

/// Runs voxlight with `args` in folder `dir`.
Result run(const std::string& args, const fs::path& dir) {
    return test::runShell("cd " + quoted(dir) + " && " + VOXLIGHT_BINARY + " " + args, dir);
}

std::string contents(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::size_t lineCount(const std::string& s) {
    return std::size_t(std::count(s.begin(), s.end(), '\n'));
}

/// Files whose names say they are some writer's temporaries (ours, the image layer's, VTK's).
std::vector<std::string> temporariesIn(const fs::path& dir) {
    std::vector<std::string> found;
    for (const auto& e : fs::recursive_directory_iterator(dir)) {
        const std::string name = e.path().filename().string();
        if (name.rfind(".voxlight", 0) == 0 || name.find(".tmp") != std::string::npos)
            found.push_back(name);
    }
    return found;
}

/// A tmpfs of `bytes` mounted at `at` for the test's length (root only).
class SmallDisk {
  public:
    SmallDisk(const fs::path& at, std::size_t bytes) : at_(at) {
        fs::create_directories(at);
        const std::string options = "size=" + std::to_string(bytes);
        mounted_ =
            ::geteuid() == 0 && ::mount("tmpfs", at.c_str(), "tmpfs", 0, options.c_str()) == 0;
    }
    ~SmallDisk() {
        if (mounted_) ::umount2(at_.c_str(), MNT_DETACH);
    }
    bool mounted() const { return mounted_; }

  private:
    fs::path at_;
    bool mounted_ = false;
};

/// An old output that every failed run below must leave as it was.
constexpr const char* kOld = "OLD CONTENT\n";
}  // namespace

TEST(WriteFailures, AFullDiskFailsTheRunInOneLineAndKeepsTheOldFile) {
    test::TempDir tmp;
    ASSERT_EQ(run("phantom torso --size 48 -q -o " + quoted(tmp / "t.nii.gz"), tmp.path()).code, 0);
    const std::string render =
        "render " + quoted(tmp / "t.nii.gz") + " -q --set image.width=256 --set image.height=256 ";
    ASSERT_EQ(run(render + "-o " + quoted(tmp / "r1.png"), tmp.path()).code, 0);
    ASSERT_EQ(run(render + "--view left -o " + quoted(tmp / "r2.png"), tmp.path()).code, 0);
    // 16 KiB: the old file takes a 4-KiB page, and none of the outputs below fits in the rest.
    // Each writer failed differently before: OpenImageIO's PNG/BMP and tinygltf reported success
    // over a short file, VTK's MetaImage printed a line and reported success, libjpeg exit()ed.
    const fs::path full = tmp / "full";
    struct Case {
        std::string file, command;
    };
    const std::vector<Case> cases = {
        {"a.png", render + "-o {}"},
        {"a.bmp", render + "-o {}"},
        {"a.jpg", render + "-o {}"},
        {"m.png", "compare " + quoted(tmp / "r1.png") + " " + quoted(tmp / "r2.png") + " --map {}"},
        {"t.mha", "phantom torso --size 64 -q -o {}"},
        {"m.glb", "iso " + quoted(tmp / "t.nii.gz") + " -q -o {}"},
        {"a.exr", render + "-o " + quoted(tmp / "ok.png") + " --exr {}"},
    };
    for (const Case& c : cases) {
        SmallDisk disk(full, 16 << 10);
        if (!disk.mounted()) GTEST_SKIP() << "needs root to mount a small tmpfs";
        std::ofstream(full / c.file) << kOld;
        std::string command = c.command;
        command.replace(command.find("{}"), 2, quoted(full / c.file));
        const Result r = run(command, tmp.path());
        EXPECT_EQ(r.code, 2) << c.file << ": " << r.err;
        EXPECT_EQ(lineCount(r.err), 1u) << c.file << ": " << r.err;
        EXPECT_NE(r.err.find("no space left"), std::string::npos) << c.file << ": " << r.err;
        EXPECT_NE(r.err.find(c.file), std::string::npos) << c.file << ": " << r.err;
        EXPECT_EQ(r.err.find(".voxlight"), std::string::npos) << c.file << ": " << r.err;
        EXPECT_EQ(contents(full / c.file), kOld) << c.file;
        EXPECT_TRUE(temporariesIn(full).empty()) << c.file << ": " << temporariesIn(full).front();
    }
}

TEST(WriteFailures, ReplayOnAFullDiskNamesTheFrameAndLeavesNoFolder) {
    test::TempDir tmp;
    ASSERT_EQ(run("phantom torso --size 48 -q -o " + quoted(tmp / "t.nii.gz"), tmp.path()).code, 0);
    std::ofstream(tmp / "scene.json") << R"({"volume": "t.nii.gz", "method": "gradient",
        "image": {"width": 96, "height": 96}})";
    std::ofstream(tmp / "s.json") << R"({"format": "voxlight-session", "version": 2,
        "scene": "scene.json", "keyframes": [{"time": 0, "camera": {"azimuth": -30}},
        {"time": 4, "camera": {"azimuth": 60}}]})";
    SmallDisk disk(tmp / "full", 24 << 10);
    if (!disk.mounted()) GTEST_SKIP() << "needs root to mount a small tmpfs";
    const Result r =
        run("replay s.json -q --fps 2 --out " + quoted(tmp / "full" / "rp"), tmp.path());
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(lineCount(r.err), 1u) << r.err;
    EXPECT_NE(r.err.find("no space left"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("frame_000"), std::string::npos) << r.err;
    // The folder this run made goes with its frames: no truncated or empty frame stays.
    EXPECT_FALSE(fs::exists(tmp / "full" / "rp"));
    EXPECT_TRUE(temporariesIn(tmp / "full").empty());
}

TEST(WriteFailures, ARenameRefusedAtCommitLeavesEveryOldFileAsItWas) {
    // render -o a.png --stats s.json with s.json immutable: a.png was renamed into place, then
    // the rollback deleted it, and the old a.png was gone for good.
    test::TempDir tmp;
    ASSERT_EQ(run("phantom sphere --size 16 -q -o " + quoted(tmp / "v.nii.gz"), tmp.path()).code,
              0);
    std::ofstream(tmp / "a.png") << kOld;
    std::ofstream(tmp / "s.json") << kOld;
    if (::geteuid() != 0 ||
        test::runShell("chattr +i " + quoted(tmp / "s.json"), tmp.path()).code != 0)
        GTEST_SKIP() << "needs root and a file system with the immutable attribute";
    struct Unlock {
        fs::path file;
        ~Unlock() { test::runShell("chattr -i '" + file.string() + "'", file.parent_path()); }
    } unlock{tmp / "s.json"};
    const Result r = run("render " + quoted(tmp / "v.nii.gz") + " -q --set image.width=32 " +
                             "--set image.height=32 -o a.png --stats s.json",
                         tmp.path());
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(lineCount(r.err), 1u) << r.err;
    EXPECT_NE(r.err.find("--stats"), std::string::npos) << r.err;
    EXPECT_EQ(contents(tmp / "a.png"), kOld);
    EXPECT_EQ(contents(tmp / "s.json"), kOld);
    EXPECT_TRUE(temporariesIn(tmp.path()).empty()) << temporariesIn(tmp.path()).front();
}

TEST(WriteFailures, StandardOutputThatCannotBeWrittenIsExitTwo) {
    // `scene --init ct.nii.gz > scene.json` on a full disk gave an empty scene.json and exit 0.
    test::TempDir tmp;
    ASSERT_EQ(run("phantom sphere --size 16 -q -o " + quoted(tmp / "v.nii.gz"), tmp.path()).code,
              0);
    for (const std::string cmd : {"scene --init v.nii.gz", "info --json v.nii.gz"}) {
        const Result r = run(cmd + " > /dev/full", tmp.path());
        EXPECT_EQ(r.code, 2) << cmd << ": " << r.err;
        EXPECT_EQ(lineCount(r.err), 1u) << cmd << ": " << r.err;
        EXPECT_NE(r.err.find("standard output"), std::string::npos) << cmd << ": " << r.err;
    }
    EXPECT_EQ(run("scene --init v.nii.gz > /dev/null", tmp.path()).code, 0);
}

TEST(WriteFailures, ANameTheFileSystemCannotHoldIsRefusedBeforeTheWork) {
    test::TempDir tmp;
    ASSERT_EQ(run("phantom sphere --size 16 -q -o " + quoted(tmp / "v.nii.gz"), tmp.path()).code,
              0);
    const std::string render = "render v.nii.gz -q --set image.width=32 --set image.height=32 ";
    const Result tooLong = run(render + "-o " + std::string(260, 'c') + ".png", tmp.path());
    EXPECT_EQ(tooLong.code, 2) << tooLong.err;
    EXPECT_NE(tooLong.err.find("bytes long"), std::string::npos) << tooLong.err;
    // 250 bytes is a legal name: it failed after the work when the temporaries' names wrapped
    // it (".voxlight-partial-PID-N-" + name + the image layer's ".tmpPID_N").
    const std::string legal = std::string(246, 'c') + ".png";
    const Result r =
        run(render + "-o " + legal + " --exr " + std::string(246, 'c') + ".exr", tmp.path());
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(fs::exists(tmp / legal));
    const Result phantom =
        run("phantom sphere --size 16 -q -o " + std::string(243, 'p') + ".nii.gz", tmp.path());
    EXPECT_EQ(phantom.code, 0) << phantom.err;
    // A long name with an early dot: the temporary had kept everything from the first dot.
    const std::string dotted = "a." + std::string(244, 'c') + ".png";
    const Result early = run(render + "-o " + dotted, tmp.path());
    EXPECT_EQ(early.code, 0) << early.err;
    EXPECT_TRUE(fs::exists(tmp / dotted));
    EXPECT_TRUE(temporariesIn(tmp.path()).empty()) << temporariesIn(tmp.path()).front();
}

TEST(WriteFailures, OutputsOverACommandsOwnInputsAreRefused) {
    test::TempDir tmp;
    ASSERT_EQ(run("phantom sphere --size 16 -q -o " + quoted(tmp / "v.nii.gz"), tmp.path()).code,
              0);
    const std::string scene = R"({"volume": "v.nii.gz", "image": {"width": 16, "height": 16}})";
    std::ofstream(tmp / "scene.json") << scene;
    std::ofstream(tmp / "s.json") << R"({"format": "voxlight-session", "version": 2,
        "scene": "scene.json", "keyframes": [{"time": 0}]})";
    // replay --stats over the session's scene file replaced it with the stats (exit 0).
    const Result replay = run("replay s.json -q --out frames --stats scene.json", tmp.path());
    EXPECT_EQ(replay.code, 2) << replay.err;
    EXPECT_NE(replay.err.find("scene file"), std::string::npos) << replay.err;
    EXPECT_EQ(contents(tmp / "scene.json"), scene);
    EXPECT_FALSE(fs::exists(tmp / "frames"));
    // A sweep file kept as DIR/reference.json was replaced by the first run's reference.json.
    fs::create_directories(tmp / "sw");
    const std::string sweep =
        R"({"name": "t", "scene": {"volume": {"phantom": "sphere", "size": 16},
        "image": {"width": 16, "height": 16}}, "runs": [{"method": "gradient"}]})";
    std::ofstream(tmp / "sw" / "reference.json") << sweep;
    const Result sw = run("sweep sw/reference.json -q --out sw", tmp.path());
    EXPECT_EQ(sw.code, 2) << sw.err;
    EXPECT_NE(sw.err.find("replaces the sweep file"), std::string::npos) << sw.err;
    EXPECT_EQ(contents(tmp / "sw" / "reference.json"), sweep);
    // view --record over its own --script replaced the script with the session (refused before
    // any window opens: no display needed).
    const std::string steps = R"([{"orbit": [30, 0]}])";
    std::ofstream(tmp / "steps.json") << steps;
    const Result view =
        run("view scene.json --script steps.json --record steps.json -q", tmp.path());
    EXPECT_EQ(view.code, 2) << view.err;
    EXPECT_NE(view.err.find("--script"), std::string::npos) << view.err;
    EXPECT_EQ(contents(tmp / "steps.json"), steps);
}

TEST(WriteFailures, AReplacedOutputKeepsItsModeAndASymlinkIsWrittenThrough) {
    // The temporary-and-rename scheme turned a 0600 output into 0644 and replaced a symlink
    // (latest.png → renders/one.png) by a plain file.
    test::TempDir tmp;
    ASSERT_EQ(run("phantom sphere --size 16 -q -o " + quoted(tmp / "v.nii.gz"), tmp.path()).code,
              0);
    fs::create_directories(tmp / "renders");
    std::ofstream(tmp / "renders" / "one.png") << kOld;
    fs::create_symlink(fs::path("renders") / "one.png", tmp / "latest.png");
    std::ofstream(tmp / "s.json") << kOld;
    fs::permissions(tmp / "s.json", fs::perms::owner_read | fs::perms::owner_write);
    const Result r =
        run("render v.nii.gz -q --set image.width=16 --set image.height=16 "
            "-o latest.png --stats s.json",
            tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(fs::is_symlink(tmp / "latest.png"));
    EXPECT_NE(contents(tmp / "renders" / "one.png"), kOld);  // the PNG, through the link
    EXPECT_EQ(contents(tmp / "renders" / "one.png").substr(1, 3), "PNG");
    EXPECT_EQ(fs::status(tmp / "s.json").permissions() & fs::perms::all,
              fs::perms::owner_read | fs::perms::owner_write);
    EXPECT_TRUE(temporariesIn(tmp.path()).empty()) << temporariesIn(tmp.path()).front();
}

TEST(WriteFailures, AWriteErrorTheImageLibraryDoesNotReportIsCaughtByReadingBack) {
    // A file size limit (as a disk quota) leaves free space: OpenImageIO's PNG and BMP writers
    // reported success over a short file, VTK's MetaImage printed a line and reported success.
    test::TempDir tmp;
    ASSERT_EQ(run("phantom sphere --size 16 -q -o v.nii.gz", tmp.path()).code, 0);
    std::ofstream(tmp / "big.png") << kOld;
    for (const std::string command :
         {"render v.nii.gz -q --set image.width=256 --set image.height=256 -o big.png",
          "render v.nii.gz -q --set image.width=256 --set image.height=256 -o big.bmp",
          "phantom torso --size 64 -q -o big.mha"}) {
        // ulimit -f 2: 2 KiB per file; SIGXFSZ ignored, so a write past it fails with EFBIG.
        const Result r =
            test::runShell("cd " + quoted(tmp.path()) + " && trap '' XFSZ && ulimit -f 2 && " +
                               VOXLIGHT_BINARY + " " + command,
                           tmp.path());
        EXPECT_EQ(r.code, 2) << command << ": " << r.err;
        EXPECT_EQ(lineCount(r.err), 1u) << command << ": " << r.err;
        EXPECT_EQ(r.err.find(".voxlight"), std::string::npos) << command << ": " << r.err;
    }
    EXPECT_EQ(contents(tmp / "big.png"), kOld);
    EXPECT_FALSE(fs::exists(tmp / "big.bmp"));
    EXPECT_FALSE(fs::exists(tmp / "big.mha"));
    EXPECT_TRUE(temporariesIn(tmp.path()).empty()) << temporariesIn(tmp.path()).front();
}

TEST(WriteFailures, AFifoOrADanglingLinkAsAnOutput) {
    test::TempDir tmp;
    ASSERT_EQ(run("phantom sphere --size 16 -q -o v.nii.gz", tmp.path()).code, 0);
    const std::string render = "render v.nii.gz -q --set image.width=16 --set image.height=16 ";
    // A FIFO was replaced by a regular file (nothing reached the reader): refused.
    ASSERT_EQ(test::runShell("mkfifo " + quoted(tmp / "f.png"), tmp.path()).code, 0);
    const Result fifo = run(render + "-o f.png", tmp.path());
    EXPECT_EQ(fifo.code, 2) << fifo.err;
    EXPECT_NE(fifo.err.find("FIFO"), std::string::npos) << fifo.err;
    // A dangling link is replaced by the file, with ordinary permissions (its "unknown" mode had
    // been copied: 07777, set-id bits and all).
    fs::create_symlink("/nonexistent/x.png", tmp / "d.png");
    const Result dangling = run(render + "-o d.png", tmp.path());
    EXPECT_EQ(dangling.code, 0) << dangling.err;
    EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(tmp / "d.png")));
    const fs::perms p = fs::status(tmp / "d.png").permissions();
    EXPECT_EQ(p & (fs::perms::set_uid | fs::perms::set_gid | fs::perms::sticky_bit |
                   fs::perms::others_write),
              fs::perms::none);
}

TEST(WriteFailures, AFileSystemThatCountsNoBlocksIsNeverFull) {
    // An unlimited tmpfs (size=0) reports 0 blocks in all: every output there failed "no space
    // left" for one commit.
    test::TempDir tmp;
    SmallDisk disk(tmp / "unlimited", 0);
    if (!disk.mounted()) GTEST_SKIP() << "needs root to mount a tmpfs";
    const Result r = run("phantom sphere --size 16 -q -o unlimited/v.nii.gz", tmp.path());
    EXPECT_EQ(r.code, 0) << r.err;
    const Result png =
        run("render unlimited/v.nii.gz -q --set image.width=16 "
            "--set image.height=16 -o unlimited/a.png",
            tmp.path());
    EXPECT_EQ(png.code, 0) << png.err;
}
