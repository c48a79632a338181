// SPDX-License-Identifier: MIT
// `voxlight replay` end to end: frames equal `voxlight render` of the same states bit for bit,
// the stats say what each frame reused, bad input is one line and exit code 2 with --out left as
// it was, --video without ffmpeg is skipped with a message, and Ctrl-C keeps only whole frames.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <vector>

#include "io/image.h"
#include "session/session.h"
#include "support/test_support.h"

using namespace voxlight;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {
using Result = test::ShellResult;
using test::runShell;

/// The path single-quoted for the shell (appended piecewise: GCC 12 warns falsely on '+' here).
std::string q(const fs::path& p) {
    std::string s = "'";
    s += p.string();
    s += "'";
    return s;
}

Result run(const std::string& args, const fs::path& dir) {
    return runShell(std::string(VOXLIGHT_BINARY) + " " + args, dir);
}

std::size_t nonEmptyLines(const std::string& s) {
    std::size_t n = 0;
    std::istringstream is(s);
    for (std::string l; std::getline(is, l);) n += !l.empty();
    return n;
}

/// A small session: a 24³ torso under ct-bone, the camera orbiting 0 → 90° while a clip plane
/// moves in, then the TF changes to ct-angio.
json smallSession() {
    return {{"format", "voxlight-session"},
            {"version", 1},
            {"scene",
             {{"volume", {{"phantom", "torso"}, {"size", 24}}},
              {"transfer_function", "ct-bone"},
              {"lights", {{{"type", "directional"}, {"direction", {0.3, 1, -0.5}}}}},
              {"image", {{"width", 24}, {"height", 20}}}}},
            {"keyframes",
             {{{"time", 0.0},
               {"camera", {{"azimuth", 0}, {"elevation", 10}}},
               {"clip_planes", {{{"point", {0, -150, 0}}, {"normal", {0, 1, 0}}}}}},
              {{"time", 1.0}, {"camera", {{"azimuth", 90}, {"elevation", 30}}}},
              {{"time", 2.0},
               {"clip_planes", {{{"point", {0, 0, 0}}, {"normal", {0, 1, 0}}}}},
               {"transfer_function", "ct-angio"}}}}};
}

void writeJson(const fs::path& p, const json& j) { std::ofstream(p) << j.dump(2); }

std::vector<std::string> listing(const fs::path& dir) {
    std::vector<std::string> names;
    if (!fs::exists(dir)) return names;
    for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

}  // namespace

TEST(Replay, FramesEqualDirectRendersOfTheSameStates) {
    test::TempDir tmp;
    writeJson(tmp / "s.json", smallSession());
    Result r = run("replay " + q(tmp / "s.json") + " --out " + q(tmp / "frames") +
                       " --fps 4 -q --stats " + q(tmp / "stats.json"),
                   tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    const session::Session s = session::loadSession(tmp / "s.json");
    const std::vector<double> times = session::frameTimes(s, 4.0);
    ASSERT_EQ(times.size(), 9u);
    EXPECT_EQ(listing(tmp / "frames").size(), 9u);
    // A keyframe, two interpolated frames (the orbit; the plane moving in) and the last keyframe.
    for (std::size_t i : {0u, 1u, 6u, 8u}) {
        const fs::path scene = tmp / ("state" + std::to_string(i) + ".json");
        writeJson(scene, s.documentAtTime(times[i]));
        const fs::path direct = tmp / ("direct" + std::to_string(i) + ".png");
        r = run("render -q " + q(scene) + " -o " + q(direct), tmp.path());
        ASSERT_EQ(r.code, 0) << r.err;
        char name[32];
        std::snprintf(name, sizeof name, "frame_%05zu.png", i);
        const core::ImageRGBA a = io::readImage(tmp / "frames" / name), b = io::readImage(direct);
        ASSERT_EQ(a.width, 24);
        ASSERT_EQ(a.height, 20);
        EXPECT_EQ(a.pixels, b.pixels) << "frame " << i;
    }
    // Frames 1..3 change only the camera: the volume, TF, skip cells, gradients, lights and
    // framing stages come from the first frame's run.
    const json stats = json::parse(std::ifstream(tmp / "stats.json"));
    ASSERT_EQ(stats["frames"].size(), 9u);
    const auto ran = [&](std::size_t i, const std::string& stage) {
        const json& r = stats["frames"][i]["ran"];
        return std::find(r.begin(), r.end(), stage) != r.end();
    };
    EXPECT_TRUE(ran(0, "gradients"));
    for (std::size_t i = 1; i <= 3; ++i)
        EXPECT_EQ(stats["frames"][i]["ran"], json({"camera", "render"})) << "frame " << i;
    const json& cached = stats["frames"][2]["cached"];
    for (const char* st :
         {"load_volume", "transfer_function", "skip_cells", "gradients", "framing"})
        EXPECT_NE(std::find(cached.begin(), cached.end(), st), cached.end()) << st;
    // The last keyframe changes the TF: its tables are rebuilt.
    EXPECT_TRUE(ran(8, "transfer_function"));
}

TEST(Replay, AnyMethodThroughSetMatchesRender) {
    // The path tracer (4 spp, 16×16) and MIP, both chosen by --set, keyframes only.
    test::TempDir tmp;
    writeJson(tmp / "s.json", smallSession());
    const session::Session s = session::loadSession(tmp / "s.json");
    for (const std::string method : {"pathtrace", "mip"}) {
        std::string sets = " --set method=" + method;
        if (method == "pathtrace") sets += " --set method.params.spp=4";
        const fs::path out = tmp / method;
        Result r =
            run("replay -q " + q(tmp / "s.json") + " --out " + q(out) + " --size 16x16" + sets,
                tmp.path());
        ASSERT_EQ(r.code, 0) << r.err;
        ASSERT_EQ(listing(out).size(), 3u);
        writeJson(tmp / "k1.json", s.documentAt(1));
        r = run("render -q " + q(tmp / "k1.json") + " -o " + q(tmp / "k1.png") + sets +
                    " --set image.width=16 --set image.height=16",
                tmp.path());
        ASSERT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(io::readImage(out / "frame_00001.png").pixels,
                  io::readImage(tmp / "k1.png").pixels)
            << method;
    }
}

TEST(Replay, BadInputIsOneLineExitTwoAndLeavesOutAsItWas) {
    test::TempDir tmp;
    json missing = smallSession();
    missing["scene"]["volume"] = "no-such-ct.nii.gz";
    writeJson(tmp / "missing-volume.json", missing);
    // A volume that exists but does not read: found in the first frame's load, before any write.
    std::ofstream(tmp / "junk.nii") << "not a nifti";
    json junk = smallSession();
    junk["scene"]["volume"] = "junk.nii";
    writeJson(tmp / "junk-volume.json", junk);
    // A scene file (by path) naming a missing volume.
    json sceneFile = smallSession()["scene"];
    sceneFile["volume"] = "gone/ct.nii.gz";
    writeJson(tmp / "scene.json", sceneFile);
    json byPath = smallSession();
    byPath["scene"] = "scene.json";
    writeJson(tmp / "missing-via-scene.json", byPath);
    const std::string full = smallSession().dump(2);
    std::ofstream(tmp / "truncated.json") << full.substr(0, full.size() * 2 / 3);
    std::ofstream(tmp / "corrupt.json", std::ios::binary)
        << std::string("\x1f\x8b\x08\0garbage", 11);
    json wrongType = smallSession();
    wrongType["keyframes"][1]["time"] = "1s";
    writeJson(tmp / "wrong-type.json", wrongType);
    json backwards = smallSession();
    backwards["keyframes"][2]["time"] = 0.5;
    writeJson(tmp / "backwards.json", backwards);
    // A keyframe's bad part: named with the keyframe (it read as the scene's own key).
    json badPart = smallSession();
    badPart["keyframes"][2]["transfer_function"] = "bogus";
    writeJson(tmp / "bad-part.json", badPart);
    writeJson(tmp / "good.json", smallSession());
    std::ofstream(tmp / "a-file") << "x";
    // Bad input only a frame's stages find, after frames 0 and 1 are written: an environment map
    // that does not read, an isovalue outside the data (named with its keyframe).
    std::ofstream(tmp / "sky.hdr") << "not an image";
    json badMap = smallSession();
    badMap["keyframes"][2]["lights"] =
        json::array({{{"type", "environment"}, {"path", "sky.hdr"}}});
    writeJson(tmp / "bad-map.json", badMap);
    json badIso = smallSession();
    badIso["version"] = 2;
    badIso["keyframes"][2]["method"] = {{"name", "iso-lattice"}, {"params", {{"iso_value", 1e6}}}};
    writeJson(tmp / "bad-iso.json", badIso);

    struct Case {
        std::string args, expect;
    };
    const std::vector<Case> cases = {
        {q(tmp / "missing-volume.json"), "no-such-ct.nii.gz"},
        {q(tmp / "missing-via-scene.json"), "gone/ct.nii.gz"},
        {q(tmp / "junk-volume.json"), "junk.nii"},
        {q(tmp / "truncated.json"), "not valid JSON"},
        {q(tmp / "corrupt.json"), "not valid JSON"},
        {q(tmp / "wrong-type.json"), "keyframes[1].time"},
        {q(tmp / "backwards.json"), "keyframes[2].time"},
        {q(tmp / "no-such-session.json"), "cannot be opened"},
        {q(tmp / "good.json") + " --set method=nosuch", "nosuch"},
        {q(tmp / "good.json") + " --set camera.fov_y=wide",
         "--set camera.fov_y=wide: camera.fov_y"},
        // Found by the pipeline's method parameters, after the scenes parsed: the override named.
        {q(tmp / "good.json") + " --set method=sh-local --set method.params.rays=abc",
         "--set method.params.rays=abc: method.params.rays"},
        {q(tmp / "good.json") + " --set volume=no-such.nii.gz",
         "--set volume=no-such.nii.gz: volume: names"},
        {q(tmp / "good.json") + " --size 16by16", "--size"},
        // Past the image's limit: --size named (it read as a "--set image.width" never typed).
        {q(tmp / "good.json") + " --size 99999x16", "--size: '99999x16' is larger"},
        {q(tmp / "good.json") + " --size 100000x16", "--size: '100000x16' is larger"},
        {q(tmp / "good.json") + " --size 0x16", "a side of 0 pixels"},
        // std::regex recursed once per character: 50,000 digits overflowed the stack.
        {q(tmp / "good.json") + " --size " + std::string(50000, '1') + "x16", "is larger"},
        {q(tmp / "bad-part.json"), "keyframes[2].transfer_function.preset"},
        {q(tmp / "good.json") + " --fps -2", "--fps"},
        {q(tmp / "good.json") + " --fps 0", "--fps"},
        {q(tmp / "good.json") + " --video v.gif", "--video"},
        {q(tmp / "bad-map.json"), "keyframes[2].lights[0].path: '"},  // and the file itself
        {q(tmp / "bad-map.json"), "sky.hdr' file: cannot be read"},
        {q(tmp / "bad-iso.json"), "keyframes[2].method.params.iso_value"},
    };
    for (const Case& c : cases) {
        // A fresh --out (must not be created) and an existing one (must stay as it was).
        for (const bool existing : {false, true}) {
            const fs::path out = tmp / (existing ? "existing" : "fresh");
            if (existing) {
                fs::create_directories(out);
                std::ofstream(out / "keep.txt") << "mine";
            }
            const Result r = run("replay -q " + c.args + " --out " + q(out), tmp.path());
            EXPECT_EQ(r.code, 2) << c.args << ": " << r.err;
            EXPECT_EQ(nonEmptyLines(r.err), 1u) << r.err;
            EXPECT_EQ(r.err.rfind("voxlight: error: ", 0), 0u) << r.err;
            EXPECT_NE(r.err.find(c.expect), std::string::npos) << c.expect << " in " << r.err;
            EXPECT_EQ(listing(out),
                      existing ? std::vector<std::string>{"keep.txt"} : std::vector<std::string>{})
                << c.args;
        }
    }
    const Result r =
        run("replay -q " + q(tmp / "good.json") + " --out " + q(tmp / "a-file"), tmp.path());
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
    // A folder where a frame goes was renamed to a hidden name, exit 0 (probe): refused, kept.
    const fs::path taken = tmp / "taken";
    fs::create_directories(taken / "frame_00001.png");
    std::ofstream(taken / "frame_00001.png" / "important.txt") << "mine";
    const Result d = run("replay -q " + q(tmp / "good.json") + " --out " + q(taken), tmp.path());
    EXPECT_EQ(d.code, 2) << d.err;
    EXPECT_EQ(nonEmptyLines(d.err), 1u) << d.err;
    EXPECT_NE(d.err.find("frame_00001.png' is a directory"), std::string::npos) << d.err;
    EXPECT_EQ(listing(taken), std::vector<std::string>{"frame_00001.png"});
    EXPECT_TRUE(fs::exists(taken / "frame_00001.png" / "important.txt"));
}

TEST(Replay, VideoWithoutFfmpegIsSkippedWithAMessage) {
    test::TempDir tmp;
    writeJson(tmp / "s.json", smallSession());
    // PATH without ffmpeg (the binary is named by its full path).
    const Result r =
        runShell("PATH=/nonexistent " + std::string(VOXLIGHT_BINARY) + " replay -q " +
                     q(tmp / "s.json") + " --out " + q(tmp / "f") + " --video " + q(tmp / "v.mp4"),
                 tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("--video skipped: ffmpeg is not on PATH"), std::string::npos) << r.err;
    EXPECT_EQ(nonEmptyLines(r.err), 1u) << r.err;
    EXPECT_EQ(listing(tmp / "f").size(), 3u);
    EXPECT_FALSE(fs::exists(tmp / "v.mp4"));
}

TEST(Replay, VideoWithFfmpeg) {
    if (std::system("command -v ffmpeg >/dev/null 2>&1") != 0)
        GTEST_SKIP() << "ffmpeg is not on PATH (optional: apt-get install ffmpeg)";
    test::TempDir tmp;
    writeJson(tmp / "s.json", smallSession());
    const Result r = run("replay -q " + q(tmp / "s.json") + " --out " + q(tmp / "f") +
                             " --fps 4 --video " + q(tmp / "v.mp4"),
                         tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_TRUE(fs::exists(tmp / "v.mp4"));
    EXPECT_GT(fs::file_size(tmp / "v.mp4"), 100u);
    EXPECT_EQ(listing(tmp.path()).size(), 3u) << "s.json, f, v.mp4: no temporary left";
}

TEST(Replay, CtrlCKeepsOnlyWholeFrames) {
    // 81 frames of a 48³ torso at 96²; SIGINT once the third frame exists. Exit 130 with one
    // line, and every file in --out is a whole frame (no temporary, each readable). A machine
    // fast enough to finish first is accepted (exit 0, all frames).
    test::TempDir tmp;
    json s = smallSession();
    s["scene"]["volume"]["size"] = 48;
    s["scene"]["image"] = {{"width", 96}, {"height", 96}};
    writeJson(tmp / "s.json", s);
    const fs::path out = tmp / "f";
    const Result r = runShell(std::string(VOXLIGHT_BINARY) + " replay -q " + q(tmp / "s.json") +
                                  " --out " + q(out) + " --fps 40 2>" + q(tmp / "err.txt") +
                                  " & pid=$!; n=0; while [ ! -e " + q(out / "frame_00002.png") +
                                  " ] && [ $n -lt 1200 ]; do sleep 0.05; n=$((n+1)); done;" +
                                  " kill -INT $pid; wait $pid; echo $?",
                              tmp.path());
    const int code = std::stoi(r.out);
    std::ifstream ef(tmp / "err.txt");
    const std::string err((std::istreambuf_iterator<char>(ef)), {});
    const std::vector<std::string> files = listing(out);
    const std::regex frame("frame_[0-9]{5}\\.png");
    for (const auto& f : files) {
        EXPECT_TRUE(std::regex_match(f, frame)) << f;
        EXPECT_EQ(io::readImage(out / f).width, 96) << f;
    }
    std::printf("replay ended with %d after %zu frames\n", code, files.size());
    if (code == 130) {
        EXPECT_EQ(nonEmptyLines(err), 1u) << err;
        EXPECT_NE(err.find("cancelled after " + std::to_string(files.size()) + " of 81 frames"),
                  std::string::npos)
            << err;
        EXPECT_LT(files.size(), 81u);
    } else {
        EXPECT_EQ(code, 0) << err;
        EXPECT_EQ(files.size(), 81u);
    }
}

TEST(Replay, OverMpiRanksWritesTheSameFramesAndStatsAsOneProcess) {
    const fs::path module = fs::path(VOXLIGHT_BINARY).parent_path() / "libvoxlight_mpi.so";
    if (!fs::exists(module) || test::runShell("command -v mpirun", ".").code != 0)
        GTEST_SKIP() << "built without MPI or no mpirun (Debian: libopenmpi-dev, openmpi-bin)";
    test::TempDir tmp;
    writeJson(tmp / "s.json", smallSession());
    Result r = run("replay " + q(tmp / "s.json") + " --out " + q(tmp / "one") +
                       " --fps 4 -q --stats " + q(tmp / "one.json"),
                   tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    // 9 frames over 2 ranks: frames 0-3 on rank 0, 4-8 on rank 1.
    r = test::runShell("mpirun --allow-run-as-root --oversubscribe -n 2 " +
                           std::string(VOXLIGHT_BINARY) + " replay " + q(tmp / "s.json") +
                           " --out " + q(tmp / "two") + " --fps 4 -q --stats " +
                           q(tmp / "two.json"),
                       tmp.path());
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_EQ(listing(tmp / "two"), listing(tmp / "one"));
    for (const auto& name : listing(tmp / "one"))
        EXPECT_EQ(io::readImage(tmp / "two" / name).pixels,
                  io::readImage(tmp / "one" / name).pixels)
            << name;
    const json a = json::parse(std::ifstream(tmp / "one.json"));
    const json b = json::parse(std::ifstream(tmp / "two.json"));
    ASSERT_EQ(b["frames"].size(), a["frames"].size());
    EXPECT_EQ(a["ranks"], 1);
    EXPECT_EQ(b["ranks"], 2);  // two ranks, not two whole replays side by side
    for (std::size_t i = 0; i < a["frames"].size(); ++i) {
        EXPECT_EQ(b["frames"][i]["index"], i);
        EXPECT_EQ(b["frames"][i]["file"], a["frames"][i]["file"]);
    }
    // Rank 1 starts its block from an empty cache: its first frame recomputes what rank 0's
    // first frame did, and the frames after it reuse them as in one process.
    EXPECT_EQ(b["frames"][5]["ran"], a["frames"][5]["ran"]);
}
