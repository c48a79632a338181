// SPDX-License-Identifier: MIT
// `voxlight view` end to end: the scripted screenshot's image area equals `voxlight render`'s image
// of the same scene (one renderer, shown pixel for pixel), the GLSL ray caster's image agrees with
// the CPU ray caster's within named tolerances, a scene the GLSL path cannot do falls back to the
// CPU with its reason, and bad input fails before any window.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "io/image.h"
#include "session/session.h"
#include "support/test_support.h"

using namespace voxlight;
namespace fs = std::filesystem;

namespace {
struct Result {
    int code;
    std::string err;
};
Result runShell(const std::string& line, const fs::path& dir) {
    const fs::path errFile = dir / "stderr.txt";
    const int status = std::system((line + " >/dev/null 2>'" + errFile.string() + "'").c_str());
    std::ifstream ef(errFile);
    std::string err((std::istreambuf_iterator<char>(ef)), {});
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, err};
}
std::string quoted(const fs::path& p) { return "'" + p.string() + "'"; }
bool onPath(const char* tool) {
    return std::system((std::string("command -v ") + tool + " >/dev/null 2>&1").c_str()) == 0;
}
/// The viewer's side panel width (viewer/viewer.h kPanelWidth): the image area is left of it.
constexpr int kPanelWidth = 380;
/// The screenshot's image area against the CLI's PNG, in 8-bit levels: the same renderer and the
/// same rounding to 8 bits, the texture drawn 1:1 with nearest filtering and opaque blending, so
/// they should agree exactly; one level allows for the GL's own fixed-point blend arithmetic.
constexpr float kScreenshotTolLevels = 1.f;
/// Half the box around each orientation letter (ImGui's 13 px font, two letters at most).
constexpr int kLabelHalfWidth = 16, kLabelHalfHeight = 10;

/// The command prefix that gives `voxlight view` a display: none under a display, else xvfb-run;
/// nullopt (the test skips) when there is neither.
std::optional<std::string> displayPrefix() {
    if (std::getenv("DISPLAY")) return std::string();
    if (!onPath("xvfb-run")) return std::nullopt;
    return std::string("xvfb-run -a -s '-screen 0 1280x800x24' ");
}

/// Whether (x, y) of a w × h image area lies in the box of an orientation letter (at the middle
/// of each edge, 12 px in: viewer.cpp drawImage).
bool inLabel(int x, int y, int w, int h) {
    const int cx = w / 2, cy = h / 2;
    const auto near = [](int p, int q, int r) { return std::abs(p - q) <= r; };
    return (near(y, cy, kLabelHalfHeight) &&
            (near(x, 12, kLabelHalfWidth) || near(x, w - 12, kLabelHalfWidth))) ||
           (near(x, cx, kLabelHalfWidth) &&
            (near(y, 12, kLabelHalfHeight) || near(y, h - 12, kLabelHalfHeight)));
}

/// `voxlight ARGS` under `display` (displayPrefix()): voxlight's own exit code and stderr.
/// xvfb-run's are its own — after a command that exits within a fraction of a second it can fail
/// to remove its temporary directory ("problem while cleaning up", exit code 5).
Result runViewUnder(const std::string& display, const std::string& args, const test::TempDir& dir) {
    const fs::path rc = dir / "view-rc.txt", err = dir / "view-stderr.txt";
    const Result outer = runShell(display + "sh -c \"" + VOXLIGHT_BINARY + " " + args + " 2>" +
                                      quoted(err) + "; echo \\$? >" + quoted(rc) + "\"",
                                  dir.path());
    std::ifstream rf(rc);
    int code = -1;
    if (!(rf >> code)) return outer;  // the command did not run: xvfb-run's error says why
    std::ifstream ef(err);
    return {code, std::string((std::istreambuf_iterator<char>(ef)), {})};
}

/// `voxlight view` of dir/scene.json running dir/steps.json, recording dir/rec.json, screenshot
/// dir/shot.png, under `display` (displayPrefix()), on the CPU path; `extra` options before the
/// scene.
Result runScriptedView(const std::string& display, const test::TempDir& dir,
                       const std::string& extra = "") {
    return runViewUnder(display,
                        "view -q --renderer cpu " + extra + quoted(dir / "scene.json") +
                            " --script " + quoted(dir / "steps.json") + " --record " +
                            quoted(dir / "rec.json") + " --screenshot " + quoted(dir / "shot.png"),
                        dir);
}
}  // namespace

TEST(ViewCli, ScreenshotImageAreaEqualsTheCpuRender) {
    // Headless: under the display we have, else under xvfb-run (tools/setup.sh installs it).
    const std::optional<std::string> display = displayPrefix();
    if (!display)
        GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here "
                        "(tools/setup.sh installs xvfb)";
    const std::string prefix = *display;
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 240, "height": 200}})";
    const Result cpu = runShell(std::string(VOXLIGHT_BINARY) + " render -q " +
                                    quoted(tmp / "scene.json") + " -o " + quoted(tmp / "cpu.png"),
                                tmp.path());
    ASSERT_EQ(cpu.code, 0) << cpu.err;
    const Result view = runShell(prefix + VOXLIGHT_BINARY + " view -q --renderer cpu " +
                                     quoted(tmp / "scene.json") + " --screenshot " +
                                     quoted(tmp / "shot.png") + " --frames 5",
                                 tmp.path());
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    const io::ImageRGBA a = io::readImage(tmp / "cpu.png");
    const io::ImageRGBA s = io::readImage(tmp / "shot.png");
    ASSERT_EQ(s.width, a.width + kPanelWidth);
    ASSERT_EQ(s.height, a.height);
    // The orientation letters are left out of the comparison, and they must be there.
    float worst = 0.f;
    int labelPixels = 0;
    for (int y = 0; y < a.height; ++y)
        for (int x = 0; x < a.width; ++x)
            for (int c = 0; c < 3; ++c) {
                const float d = std::abs(a.at(x, y)[c] - s.at(x, y)[c]) * 255.f;
                if (inLabel(x, y, a.width, a.height))
                    labelPixels += d > 0.5f;
                else
                    worst = std::max(worst, d);
            }
    EXPECT_LE(worst, kScreenshotTolLevels + 1e-3f);
    EXPECT_GT(labelPixels, 20) << "no orientation letters at the image's edges";
    // The panel is drawn too: text and widgets, not only the clear colour.
    int bright = 0;
    for (int y = 0; y < s.height; ++y)
        for (int x = a.width; x < s.width; ++x) bright += s.at(x, y)[0] > 0.6f;
    EXPECT_GT(bright, 200) << "the side panel looks empty";
    // Written atomically: no temporary left beside it.
    int files = 0;
    for (const auto& e : fs::directory_iterator(tmp.path()))
        files += e.path().extension() == ".png";
    EXPECT_EQ(files, 2);
}

/// The replayed frames dir/NAME/frame_00000.png, … in order.
std::vector<io::ImageRGBA> readFrames(const fs::path& dir) {
    std::vector<io::ImageRGBA> frames;
    for (int i = 0;; ++i) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%05d.png", i);
        if (!fs::exists(dir / name)) break;
        frames.push_back(io::readImage(dir / name));
    }
    return frames;
}

/// Replays dir/rec.json into dir/frames and checks what both scripted-session tests check: `count`
/// frames (one per settled state), each step changing the picture, and the last equal to the
/// screenshot's image area within kScreenshotTolLevels (same renderer, same state).
void expectReplayMatchesScreenshot(const test::TempDir& tmp, std::size_t count) {
    const Result replay =
        runShell(std::string(VOXLIGHT_BINARY) + " replay -q " + quoted(tmp / "rec.json") +
                     " --out " + quoted(tmp / "frames"),
                 tmp.path());
    ASSERT_EQ(replay.code, 0) << replay.err;
    const std::vector<io::ImageRGBA> frames = readFrames(tmp / "frames");
    ASSERT_EQ(frames.size(), count);
    const io::ImageRGBA s = io::readImage(tmp / "shot.png");
    const io::ImageRGBA& f = frames.back();
    ASSERT_EQ(s.width, f.width + kPanelWidth);
    float worst = 0.f;
    for (int y = 0; y < f.height; ++y)
        for (int x = 0; x < f.width; ++x)
            if (!inLabel(x, y, f.width, f.height))
                for (int c = 0; c < 3; ++c)
                    worst = std::max(worst, std::abs(f.at(x, y)[c] - s.at(x, y)[c]) * 255.f);
    EXPECT_LE(worst, kScreenshotTolLevels + 1e-3f);
    for (std::size_t i = 1; i < frames.size(); ++i)
        EXPECT_NE(frames[i].pixels, frames[i - 1].pixels) << "step " << i << " changed nothing";
}

// The issue's scripted UI check: steps run through the mouse's and keys' code paths (orbit,
// window/level drag, a named view, orbit again, wheel zoom) while the viewer records the session;
// `voxlight replay` of it gives one frame per settled state, the last equal to the screenshot's
// image area (same renderer, same state: kScreenshotTolLevels), and the states differ.
TEST(ViewCli, AScriptedExplorationRecordsASessionThatReplaysToTheScreenshot) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "steps.json")
        << R"([{"orbit": [60, 10]}, {"window": [40, -30]}, {"view": "L"}, {"orbit": [-30, 0]},
              {"zoom": 2}])";
    const Result view = runScriptedView(*display, tmp);
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    expectReplayMatchesScreenshot(tmp, 6);  // the first state and one per step
}

// Issue #15's scripted session ("change TF, add and move a clip plane, move a light, save")
// through the viewer's own code paths: a window/level drag, a plane facing the view, moved by the
// panel's slider path and by the gizmo's drag (coarse frames in between), a light added and
// turned, the plane flipped; recorded, then replayed. One frame per settled state, each step
// changes the picture, and the last equals the screenshot's image area (the gizmo hidden by the
// last step, as the G key does).
TEST(ViewCli, ScriptedClipPlaneAndLightEditsRecordASessionThatReplaysToTheScreenshot) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "steps.json") << R"([
        {"window": [40, -30]},
        {"clip_add": {"normal": "camera", "offset": -12}},
        {"clip_move": {"index": 0, "by": 6}},
        {"clip_drag": {"index": 0, "by": [0, -24], "frames": 6}},
        {"light_add": {"type": "directional", "azimuth": -60, "elevation": 20}},
        {"light_turn": {"index": 0, "azimuth": 70, "elevation": 25}},
        {"clip_edit": {"index": 0, "flip": true}},
        {"gizmo": false}])";
    const Result view = runScriptedView(*display, tmp);
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    // The recorded lights and planes are the scene's parts, as replay reads them.
    const nlohmann::json rec = nlohmann::json::parse(std::ifstream(tmp / "rec.json"));
    const nlohmann::json& last = rec["keyframes"].back();
    ASSERT_TRUE(last.contains("clip_planes")) << last.dump();
    // Adding the plane pinned the camera where it was (an explicit eye): a fitted camera would
    // re-frame to what the plane leaves.
    const nlohmann::json& added = rec["keyframes"][2];
    ASSERT_TRUE(added.contains("clip_planes") && added.contains("camera")) << added.dump();
    EXPECT_TRUE(added["camera"].contains("eye")) << added.dump();
    expectReplayMatchesScreenshot(tmp, 8);  // the first state and one per step that changes it
}

// The issue's "logged UI frame ≤ 50 ms during a clip-plane drag": a scripted gizmo drag over many
// frames (one motion per frame, coarse renders meanwhile) with --log; the viewer logs the drag's
// own frame statistics, reported here. No bound is asserted (timings on a shared machine are not
// a test; README's "Where we stand" has the measured ranges). Also checks the gizmo is drawn.
TEST(ViewCli, ClipPlaneDragLogsItsUiFrames) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 256, "height": 256}})";
    constexpr int kDragFrames = 90;
    std::ofstream(tmp / "steps.json") << R"([{"clip_add": {"normal": [0, 1, 0], "offset": -30}},
              {"clip_drag": {"index": 0, "by": [-40, 60], "frames": )"
                                      << kDragFrames << "}}]";
    const Result view = runScriptedView(*display, tmp, "--log ");
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    // The last drag's line: "view: clip-plane drag: N frames, ui frame work mean X ms, max Y ms,
    // Z over 50 ms".
    const std::string key = "view: clip-plane drag: ";
    const std::size_t at = view.err.rfind(key);
    ASSERT_NE(at, std::string::npos) << view.err;
    unsigned long long frames = 0, over = 0;
    double mean = 0, max = 0;
    ASSERT_EQ(std::sscanf(view.err.c_str() + at + key.size(),
                          "%llu frames, ui frame work mean %lf ms, max %lf ms, %llu over", &frames,
                          &mean, &max, &over),
              4)
        << view.err.substr(at);
    EXPECT_EQ(frames, unsigned(kDragFrames));
    std::printf("clip-plane drag, %llu UI frames: mean %.1f ms, max %.1f ms, %llu over 50 ms\n",
                frames, mean, max, over);
    RecordProperty("drag_frames", int(frames));
    RecordProperty("drag_frame_mean_ms", std::to_string(mean));
    RecordProperty("drag_frame_max_ms", std::to_string(max));
    RecordProperty("drag_frames_over_50ms", int(over));
    // Coarse images while dragging, then the full one.
    EXPECT_NE(view.err.find("render coarse"), std::string::npos) << view.err;
    // The gizmo (its outline, handle and arrow in cyan) is over the screenshot's image area, not
    // in the replayed frame of the same state.
    const Result replay =
        runShell(std::string(VOXLIGHT_BINARY) + " replay -q " + quoted(tmp / "rec.json") +
                     " --out " + quoted(tmp / "frames"),
                 tmp.path());
    ASSERT_EQ(replay.code, 0) << replay.err;
    const std::vector<io::ImageRGBA> replayed = readFrames(tmp / "frames");
    ASSERT_FALSE(replayed.empty());
    const io::ImageRGBA& f = replayed.back();
    const io::ImageRGBA s = io::readImage(tmp / "shot.png");
    int gizmo = 0;
    for (int y = 0; y < f.height; ++y)
        for (int x = 0; x < f.width; ++x) {
            const float* a = s.at(x, y);
            gizmo += std::abs(a[2] - f.at(x, y)[2]) * 255.f > 30.f && a[2] > a[0] + 0.2f;
        }
    EXPECT_GT(gizmo, 100) << "no clip-plane gizmo drawn over the image";
}

// A script step naming a plane or light the view does not have fails when it runs: one line
// naming the step's field, exit code 2.
TEST(ViewCli, AScriptStepNamingAMissingPlaneFailsWithOneLine) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 32}, "transfer_function": "ct-bone",
        "image": {"width": 64, "height": 64}})";
    std::ofstream(tmp / "steps.json")
        << R"([{"clip_add": {"normal": [0, 0, 1]}}, {"clip_move": {"index": 1, "by": 3}}])";
    const Result view = runScriptedView(*display, tmp);
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    EXPECT_EQ(view.code, 2) << view.err;
    EXPECT_EQ(std::count(view.err.begin(), view.err.end(), '\n'), 1) << view.err;
    EXPECT_NE(view.err.find("[1].clip_move.index"), std::string::npos) << view.err;
    EXPECT_FALSE(fs::exists(tmp / "shot.png"));
}

// "Render this view with the path tracer" (item 7): after an orbit, the panel's job path-traces the
// view in the background and the image area shows its result — equal to `voxlight replay` of the
// recorded state with method pathtrace at the same spp (the path tracer's image is the same for
// any thread count), and not the live gradient image.
TEST(ViewCli, PathTracingThisViewShowsThePathTracersImageOfIt) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": {"name": "gradient"}, "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "steps.json") << R"([{"orbit": [30, 0]}, {"pathtrace": 4}])";
    const Result view = runScriptedView(*display, tmp);
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    const std::string replay =
        std::string(VOXLIGHT_BINARY) + " replay -q " + quoted(tmp / "rec.json") + " --out ";
    const Result traced = runShell(
        replay + quoted(tmp / "pt") + " --set method.name=pathtrace --set method.params.spp=4",
        tmp.path());
    ASSERT_EQ(traced.code, 0) << traced.err;
    const Result live = runShell(replay + quoted(tmp / "live"), tmp.path());
    ASSERT_EQ(live.code, 0) << live.err;
    const io::ImageRGBA s = io::readImage(tmp / "shot.png");
    const io::ImageRGBA pt = io::readImage(tmp / "pt" / "frame_00001.png");
    const io::ImageRGBA gradient = io::readImage(tmp / "live" / "frame_00001.png");
    ASSERT_EQ(s.width, pt.width + kPanelWidth);
    float worstPt = 0.f, worstLive = 0.f;
    for (int y = 0; y < pt.height; ++y)
        for (int x = 0; x < pt.width; ++x)
            if (!inLabel(x, y, pt.width, pt.height))
                for (int c = 0; c < 3; ++c) {
                    worstPt = std::max(worstPt, std::abs(pt.at(x, y)[c] - s.at(x, y)[c]) * 255.f);
                    worstLive =
                        std::max(worstLive, std::abs(gradient.at(x, y)[c] - s.at(x, y)[c]) * 255.f);
                }
    EXPECT_LE(worstPt, kScreenshotTolLevels + 1e-3f);
    EXPECT_GT(worstLive, 20.f) << "the live gradient image is shown, not the path tracer's";
}

namespace {
/// How the screenshot's image area differs from a CPU render (8-bit levels, RGB, the orientation
/// letters left out).
struct Agreement {
    double meanAbs = 0.0;        ///< mean |difference| over channels
    double fractionOver2 = 0.0;  ///< channels off by more than 2 levels
    double psnr = 0.0;           ///< dB, peak 255
    float worst = 0.f;
};
Agreement compareImageArea(const io::ImageRGBA& cpu, const io::ImageRGBA& shot) {
    Agreement a;
    double sum = 0.0, sq = 0.0;
    std::size_t n = 0, over = 0;
    for (int y = 0; y < cpu.height; ++y)
        for (int x = 0; x < cpu.width; ++x) {
            if (inLabel(x, y, cpu.width, cpu.height)) continue;
            for (int c = 0; c < 3; ++c) {
                const double d = std::abs(double(cpu.at(x, y)[c]) - shot.at(x, y)[c]) * 255.0;
                sum += d;
                sq += d * d;
                over += d > 2.0 + 1e-3;
                a.worst = std::max(a.worst, float(d));
                ++n;
            }
        }
    a.meanAbs = sum / double(n);
    a.fractionOver2 = double(over) / double(n);
    a.psnr = sq > 0.0 ? 10.0 * std::log10(255.0 * 255.0 / (sq / double(n))) : INFINITY;
    return a;
}

// Tolerances of the GLSL image against the CPU ray caster's (same scene, same 8-bit mapping).
// They are not bit-identical: the texture unit interpolates (the trilinear values and the six
// gradient taps) where the CPU interpolates in float with FMA and reads a precomputed int16
// central-difference table (equal up to rounding), the ray set-up runs in float (the CPU's in
// double), the pre-integration table's cumulative integrals are float pairs (the CPU's double),
// and the specular power is pow() (the CPU interpolates a table). That moves a sample by far
// less than a display level except where a ray grazes a steep TF edge. Measured under Mesa
// llvmpipe 22.3 (xvfb; it filters in float): these two scenes mean 0.0002 levels, no channel
// over 2 levels, worst 1, PSNR 84–85 dB; the 256³ torso at 512²: mean 0.0008, 0.0004 % over 2
// levels (one pixel, worst 24), PSNR 74 dB. A hardware GPU filters with fixed-point weights
// (8 bits of fraction on common ones; not measurable on this GPU-less machine): the limits
// leave ×60 headroom on the mean for that and still catch a real mismatch: the GL path without
// its per-pixel jitter gave mean 1.94 and 0.15 levels, 14.7 % and 0.77 % of channels over 2
// levels on these two scenes (PSNR 31 and 53 dB: PSNR alone misses the second). The issue's own
// floor is PSNR ≥ 35 dB.
constexpr double kGlMeanAbsLevels = 0.05;
constexpr double kGlFractionOver2 = 0.001;
constexpr double kGlMinPsnrDb = 35.0;

/// `voxlight view -q --log FLAGS` of dir/scene.json running dir/steps.json, screenshot dir/shot.
Result viewScript(const std::string& display, const test::TempDir& dir, const std::string& flags,
                  const char* shot) {
    return runShell(display + VOXLIGHT_BINARY + " view -q --log " + flags + " " +
                        quoted(dir / "scene.json") + " --script " + quoted(dir / "steps.json") +
                        " --screenshot " + quoted(dir / shot),
                    dir.path());
}

/// The two screenshots' image areas agree within the GLSL tolerances above.
void expectGlAgreesWithCpu(const test::TempDir& dir, const char* cpuShot, const char* glShot) {
    const Agreement a = compareImageArea(io::readImage(dir / cpuShot), io::readImage(dir / glShot));
    EXPECT_LE(a.meanAbs, kGlMeanAbsLevels);
    EXPECT_LE(a.fractionOver2, kGlFractionOver2);
}

/// `voxlight view --renderer gpu` of dir/scene.json against `voxlight render` of it.
struct GlRun {
    bool skipped = false;
    std::string why;
    Agreement agreement;
    std::string err;
};
GlRun runGlAgainstCpu(const test::TempDir& tmp, const std::string& display) {
    GlRun out;
    const Result cpu = runShell(std::string(VOXLIGHT_BINARY) + " render -q " +
                                    quoted(tmp / "scene.json") + " -o " + quoted(tmp / "cpu.png"),
                                tmp.path());
    EXPECT_EQ(cpu.code, 0) << cpu.err;
    // The clip-plane gizmo is drawn over the image: hidden, as G does, for the comparison.
    std::ofstream(tmp / "steps.json") << R"([{"gizmo": false}])";
    const Result view =
        runShell(display + VOXLIGHT_BINARY + " view -q --log --renderer gpu --gl-slice-ms 0 " +
                     quoted(tmp / "scene.json") + " --script " + quoted(tmp / "steps.json") +
                     " --screenshot " + quoted(tmp / "shot.png"),
                 tmp.path());
    out.err = view.err;
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos) {
        out.skipped = true;
        out.why = "no OpenGL 4.5 window on this machine: " + view.err;
        return out;
    }
    EXPECT_EQ(view.code, 0) << view.err;
    if (view.code != 0 || cpu.code != 0) return out;
    const io::ImageRGBA a = io::readImage(tmp / "cpu.png");
    const io::ImageRGBA s = io::readImage(tmp / "shot.png");
    EXPECT_EQ(s.width, a.width + kPanelWidth);
    EXPECT_EQ(s.height, a.height);
    out.agreement = compareImageArea(a, s);
    return out;
}

/// Renders each scene on the GLSL path (not a fallback to the CPU image) and against the CPU ray
/// caster, and holds them to the named GL limits; `what` labels the printed figures. Skips the
/// calling test when no OpenGL 4.5 window can open here.
void expectGlslAgreesWithCpu(std::span<const char* const> scenes, const std::string& display,
                             const char* what) {
    for (const char* scene : scenes) {
        test::TempDir tmp;
        std::ofstream(tmp / "scene.json") << scene;
        const GlRun r = runGlAgainstCpu(tmp, display);
        if (r.skipped) GTEST_SKIP() << r.why;
        EXPECT_NE(r.err.find("renderer gpu (GLSL): --renderer gpu"), std::string::npos) << r.err;
        const Agreement& a = r.agreement;
        std::printf(
            "%s vs CPU: mean %.4f levels, %.4f %% over 2 levels, worst %.0f, PSNR %.1f dB\n", what,
            a.meanAbs, 100.0 * a.fractionOver2, a.worst, a.psnr);
        EXPECT_LE(a.meanAbs, kGlMeanAbsLevels) << scene;
        EXPECT_LE(a.fractionOver2, kGlFractionOver2) << scene;
        EXPECT_GE(a.psnr, kGlMinPsnrDb) << scene;
    }
}
}  // namespace

// Item 3 of the issue: the GLSL ray caster's image of a phantom scene (gradient shading with a
// directional and a point light, a clip plane; then emission–absorption in a crop box) equals the
// CPU ray caster's within the named tolerances.
TEST(ViewCli, GlslImageAgreesWithTheCpuRayCaster) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    const char* scenes[] = {
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
            "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
            "lights": [{"type": "directional", "direction": [0.3, 1, -0.4], "intensity": 0.8},
                       {"type": "point", "position": [-150, -250, 150], "intensity": 40000}],
            "clip_planes": [{"point": [0, 20, 0], "normal": [0, 1, 0]}],
            "image": {"width": 240, "height": 200}})",
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-soft-tissue",
            "method": "emission-absorption", "camera": {"azimuth": -40, "elevation": 25},
            "crop_box": {"min": [-140, -90, -20], "max": [140, 90, 170]},
            "image": {"width": 240, "height": 200, "display": "srgb"}})"};
    expectGlslAgreesWithCpu(scenes, *display, "GLSL");
}

// The GLSL SH shading is held to the gradient path's limits above. On top of that path's
// differences it reads the visibility field resampled as half floats on a grid of two points per
// voxel and axis, interpolated by the texture unit (render/sh_field_grid.h), where the CPU
// samples the field itself: that grid holds the fields' own sample points, so the texture
// reproduces their interpolation (sh-global's product is baked on the local field's points, so
// the same holds for it; until 5 December its product of two interpolations differed between
// points half a voxel apart). Measured (llvmpipe): sh-global mean 0.003 levels, sh-local
// 0.002, ritschel 0.001, none over 2 levels, worst 1, PSNR 73–79 dB. The limits catch a real
// mismatch: a first version read the field resampled cell centred (points between the fields'
// own) and gave mean 0.4–0.9 levels, 5–12 % of channels over 2 levels (PSNR 39–50 dB); the
// issue's floor is PSNR ≥ 35 dB.

// Item 3 of the issue, SH shading: the GLSL image of sh-global (a directional and a point light,
// a plane that removes matter for the light: the local field in the cut face's band), sh-local
// and ritschel (with a window and ambient) agrees with the CPU ray caster's.
TEST(ViewCli, GlslShShadingAgreesWithTheCpuRayCaster) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    const char* scenes[] = {
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
            "method": {"name": "sh-global", "params": {"rays": 32}},
            "camera": {"azimuth": 30, "elevation": 15},
            "lights": [{"type": "directional", "direction": [0.3, 1, -0.4], "intensity": 9},
                       {"type": "point", "position": [-150, -250, 150], "intensity": 400000}],
            "clip_planes": [{"point": [0, 20, 0], "normal": [0, 1, 0],
                             "shadows_from_removed": false}],
            "image": {"width": 240, "height": 200}})",
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
            "method": {"name": "sh-local", "params": {"rays": 32, "coefficients": 9}},
            "camera": {"azimuth": -40, "elevation": 25},
            "image": {"width": 240, "height": 200}})",
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
            "method": {"name": "ritschel", "params": {"rays": 32, "coefficients": 16,
                       "window": "hanning", "ambient": 0.2}},
            "camera": {"azimuth": 120, "elevation": 10},
            "lights": [{"type": "directional", "direction": [-0.5, 0.2, -1], "intensity": 12}],
            "image": {"width": 240, "height": 200}})",
        // sh-local's near shadow where the field is coarse (1:16), under a directional and a
        // point light, traced only inside what a plane keeps for the light.
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
            "method": {"name": "sh-local", "params": {"data_reduction": 16, "near_shadow": true}},
            "camera": {"azimuth": 30, "elevation": 15},
            "lights": [{"type": "directional", "direction": [-0.4, 0.6, 0.7], "intensity": 9},
                       {"type": "point", "position": [-150, -250, 150], "intensity": 400000}],
            "clip_planes": [{"point": [0, 20, 0], "normal": [0, 1, 0],
                             "shadows_from_removed": false}],
            "image": {"width": 240, "height": 200}})",
        // sh-global's near shadow at 1:16 (the global field read at the stretch's end), with the
        // cut face's band: there the end's coefficients blend toward the local field too; and
        // 1.5 voxels traced at every level (near_trace), full resolution included.
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
            "method": {"name": "sh-global", "params": {"data_reduction": 16, "near_trace": 1.5}},
            "camera": {"azimuth": 30, "elevation": 15},
            "lights": [{"type": "directional", "direction": [-0.4, 0.6, 0.7], "intensity": 9},
                       {"type": "point", "position": [-150, -250, 150], "intensity": 400000}],
            "clip_planes": [{"point": [0, 20, 0], "normal": [0, 1, 0],
                             "shadows_from_removed": false}],
            "image": {"width": 240, "height": 200}})"};
    expectGlslAgreesWithCpu(scenes, *display, "GLSL SH");
}

// Under an environment map the near shadow traces the map's dominant direction as a directional
// light (render/sh_shading.h): the GLSL shader takes it from the same light list and agrees.
TEST(ViewCli, GlslShShadingUnderAnEnvironmentAgreesWithTheCpuRayCaster) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    VL_REQUIRE_SHARED(env, "env/courtyard.hdr");
    const std::string scene =
        R"({"volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
            "method": {"name": "sh-local", "params": {"data_reduction": 16}},
            "camera": {"azimuth": 30, "elevation": 15},
            "lights": [{"type": "environment", "intensity": 1, "path": ")" +
        std::filesystem::absolute(env).string() + R"("}], "image": {"width": 240, "height": 200}})";
    const char* scenes[] = {scene.c_str()};
    expectGlslAgreesWithCpu(scenes, *display, "GLSL SH environment");
}

// SH fields are uploaded once per field, not per frame: an orbit and a zoom on the GLSL path
// (three states, three GLSL frames) upload sh-global's field once — and its local field once
// more only when a plane removes matter for the light (the cut faces' band), added here by the
// last step.
TEST(ViewCli, GlslShFieldsAreUploadedOncePerField) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 40}, "transfer_function": "ct-bone",
        "method": {"name": "sh-global", "params": {"rays": 32}},
        "image": {"width": 120, "height": 96}})";
    std::ofstream(tmp / "steps.json") << R"([{"orbit": [60, 10]}, {"zoom": 2},
        {"clip_add": {"normal": [0, 1, 0], "offset": 5, "shadows_from_removed": false}}])";
    const Result view = runShell(
        // Whole GLSL frames: one per state, none replaced by the next before it shows.
        *display + VOXLIGHT_BINARY + " view -q --log --renderer gpu --gl-slice-ms 0 " +
            quoted(tmp / "scene.json") + " --script " + quoted(tmp / "steps.json") +
            " --screenshot " + quoted(tmp / "shot.png"),
        tmp.path());
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    std::vector<int> uploads;
    const std::string key = "SH fields uploaded so far: ";
    for (std::size_t at = view.err.find(key); at != std::string::npos;
         at = view.err.find(key, at + 1))
        uploads.push_back(std::atoi(view.err.c_str() + at + key.size()));
    ASSERT_GE(uploads.size(), 4u) << view.err;
    EXPECT_EQ(uploads.front(), 1) << view.err;
    EXPECT_EQ(uploads[uploads.size() - 2], 1) << view.err;  // after the orbit and the zoom
    // The plane removes matter for the light: a new (clip-aware) local field and a new global
    // field, each uploaded once.
    EXPECT_EQ(uploads.back(), 3) << view.err;
}

// Item 1 of the issue, drag-and-drop: a script step calls GLFW's drop callback itself with a
// path list, and the viewer opens the last path through the file field's code path. A file that
// fails to load shows the error (logged) and the current volume stays — the image is still the
// scene's; a good file then loads and is shown exactly as `voxlight render` draws that volume.
TEST(ViewCli, DroppedFilesOpenThroughTheFileFieldsPath) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 40}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "broken.mha") << "not a volume";
    // The volume to drop: a smaller torso, so its image differs from the scene's.
    const Result ph = runShell(std::string(VOXLIGHT_BINARY) + " phantom torso -o " +
                                   quoted(tmp / "dropped.mha") + " --size 24",
                               tmp.path());
    ASSERT_EQ(ph.code, 0) << ph.err;
    const Result cpu = runShell(std::string(VOXLIGHT_BINARY) + " render -q " +
                                    quoted(tmp / "scene.json") + " -o " + quoted(tmp / "cpu.png"),
                                tmp.path());
    ASSERT_EQ(cpu.code, 0) << cpu.err;
    const auto view = [&](const char* first, const char* last, const std::string& shot) {
        const nlohmann::json steps =
            nlohmann::json::array({{{"drop", {(tmp / first).string(), (tmp / last).string()}}}});
        std::ofstream(tmp / "steps.json") << steps.dump();
        return runShell(*display + VOXLIGHT_BINARY + " view -q --log --renderer cpu " +
                            quoted(tmp / "scene.json") + " --script " + quoted(tmp / "steps.json") +
                            " --screenshot " + quoted(tmp / shot),
                        tmp.path());
    };
    // A bad file: the error, and the scene's own image still shown.
    const Result bad = view("dropped.mha", "broken.mha", "bad.png");
    if (bad.code != 0 && bad.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << bad.err;
    ASSERT_EQ(bad.code, 0) << bad.err;
    EXPECT_NE(bad.err.find("view: could not open " + (tmp / "broken.mha").string()),
              std::string::npos)
        << bad.err;
    EXPECT_EQ(bad.err.find("does not exist"), std::string::npos) << bad.err;  // read, and failed
    const Agreement kept =
        compareImageArea(io::readImage(tmp / "cpu.png"), io::readImage(tmp / "bad.png"));
    EXPECT_LE(kept.worst, kScreenshotTolLevels + 1e-3f);
    // A good one: opened as the file field opens a volume (its modality's default view and TF),
    // so the image is `voxlight render dropped.mha` at the window's image size.
    const Result good = view("broken.mha", "dropped.mha", "good.png");
    ASSERT_EQ(good.code, 0) << good.err;
    EXPECT_EQ(good.err.find("could not open"), std::string::npos) << good.err;
    const Result want = runShell(
        std::string(VOXLIGHT_BINARY) + " render -q " + quoted(tmp / "dropped.mha") +
            " --set image.width=160 --set image.height=128 -o " + quoted(tmp / "dropped.png"),
        tmp.path());
    ASSERT_EQ(want.code, 0) << want.err;
    const Agreement opened =
        compareImageArea(io::readImage(tmp / "dropped.png"), io::readImage(tmp / "good.png"));
    EXPECT_LE(opened.worst, kScreenshotTolLevels + 1e-3f);
    const Agreement changed =
        compareImageArea(io::readImage(tmp / "cpu.png"), io::readImage(tmp / "good.png"));
    EXPECT_GT(changed.worst, 10.f) << "the dropped volume was not shown";
}

// Kronander's interleaved update on the GLSL path: after a TF change (a window/level drag) the
// GL image is shaded from the last fields at once, then again from the new ones when the field
// thread has them; the screenshot waits for those and agrees with the CPU path's of the same
// script.
TEST(ViewCli, AfterATfChangeTheGlslPathShowsTheOldShadingThenTheNew) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": {"name": "sh-local", "params": {"rays": 64}},
        "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "steps.json") << R"([{"window": [60, -40]}])";
    const auto view = [&](const char* renderer, const char* shot) {
        // Whole GLSL frames: the stale one shows before the fresh one replaces it.
        return viewScript(*display, tmp, std::string("--gl-slice-ms 0 --renderer ") + renderer,
                          shot);
    };
    const Result gl = view("gpu", "gl.png");
    if (gl.code != 0 && gl.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << gl.err;
    ASSERT_EQ(gl.code, 0) << gl.err;
    // The window step's state: a frame from the earlier fields, then one from its own.
    const std::size_t stale = gl.err.find("shaded from earlier fields");
    ASSERT_NE(stale, std::string::npos) << gl.err;
    const std::size_t lineStart = gl.err.rfind("view: GLSL frame", stale);
    const std::size_t state = gl.err.find("(state ", lineStart);
    ASSERT_NE(state, std::string::npos);
    const std::string stateTag = gl.err.substr(state, gl.err.find(',', state) - state);
    const std::size_t fresh = gl.err.find(stateTag, stale);
    ASSERT_NE(fresh, std::string::npos) << "no GLSL frame of the state from its own fields\n"
                                        << gl.err;
    EXPECT_EQ(gl.err.substr(fresh, gl.err.find('\n', fresh) - fresh).find("earlier"),
              std::string::npos)
        << gl.err;
    const Result cpu = view("cpu", "cpu.png");
    ASSERT_EQ(cpu.code, 0) << cpu.err;
    expectGlAgreesWithCpu(tmp, "cpu.png", "gl.png");
}

// Item 3 of the issue, "local/global switch without recomputation": switching an sh-global scene
// to local, back and to local again (the panel's switch, script step `shading`) on the GLSL path
// resamples no field after the first state (sh-global's local field is sh-local's) and uploads
// the local field once; the last image agrees with `voxlight render` of the scene as sh-local.
TEST(ViewCli, GlslLocalGlobalSwitchRecomputesNothing) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    const std::string scene = R"({
        "volume": {"phantom": "torso", "size": 40}, "transfer_function": "ct-bone",
        "method": {"name": "sh-global", "params": {"rays": 32, "global_resolution": 20}},
        "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 120, "height": 96}})";
    std::ofstream(tmp / "scene.json") << scene;
    nlohmann::json local = nlohmann::json::parse(scene);
    local["method"] = {{"name", "sh-local"}, {"params", {{"rays", 32}}}};
    std::ofstream(tmp / "local.json") << local.dump();
    std::ofstream(tmp / "steps.json")
        << R"([{"shading": "local"}, {"shading": "global"}, {"shading": "local"}])";
    const Result view = runShell(
        // Whole GLSL frames: one per state, none replaced by the next before it shows.
        *display + VOXLIGHT_BINARY + " view -q --log --renderer gpu --gl-slice-ms 0 " +
            quoted(tmp / "scene.json") + " --script " + quoted(tmp / "steps.json") +
            " --screenshot " + quoted(tmp / "shot.png"),
        tmp.path());
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    std::size_t resampled = 0;
    for (std::size_t at = view.err.find("SH fields resampled"); at != std::string::npos;
         at = view.err.find("SH fields resampled", at + 1))
        ++resampled;
    EXPECT_EQ(resampled, 1u) << view.err;  // global and local together, for the first state
    std::vector<int> uploads;
    const std::string key = "SH fields uploaded so far: ";
    for (std::size_t at = view.err.find(key); at != std::string::npos;
         at = view.err.find(key, at + 1))
        uploads.push_back(std::atoi(view.err.c_str() + at + key.size()));
    EXPECT_EQ(uploads, (std::vector<int>{1, 2, 2, 2})) << view.err;
    const Result cpu = runShell(std::string(VOXLIGHT_BINARY) + " render -q " +
                                    quoted(tmp / "local.json") + " -o " + quoted(tmp / "cpu.png"),
                                tmp.path());
    ASSERT_EQ(cpu.code, 0) << cpu.err;
    const Agreement a =
        compareImageArea(io::readImage(tmp / "cpu.png"), io::readImage(tmp / "shot.png"));
    EXPECT_LE(a.meanAbs, kGlMeanAbsLevels);
    EXPECT_LE(a.fractionOver2, kGlFractionOver2);
}

// Item 6 with item 3's switch: the local/global shading switch is recorded (the session's
// method part, format version 2), so the replay shades every state as the viewer did.
TEST(ViewCli, TheLocalGlobalSwitchIsRecordedAndReplayed) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 40}, "transfer_function": "ct-bone",
        "method": {"name": "sh-global", "params": {"rays": 16, "global_resolution": 20}},
        "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 120, "height": 96}})";
    std::ofstream(tmp / "steps.json")
        << R"([{"shading": "local"}, {"shading": "global"}, {"shading": "local"}])";
    const Result view = runScriptedView(*display, tmp);
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    const nlohmann::json rec = nlohmann::json::parse(std::ifstream(tmp / "rec.json"));
    EXPECT_EQ(rec["version"], 2);
    std::vector<std::string> methods;
    for (const auto& k : rec["keyframes"])
        if (k.contains("method")) methods.push_back(k["method"]["name"].get<std::string>());
    EXPECT_EQ(methods, (std::vector<std::string>{"sh-global", "sh-local", "sh-global", "sh-local"}))
        << rec.dump();
    expectReplayMatchesScreenshot(tmp, 4);  // the first state and one per switch
}

// Item 7 of the issue: an EXR screenshot holds the image's linear radiance — on the CPU path
// exactly what `voxlight render --exr` writes for the same scene (the worker's full pass is the
// CLI's image bit for bit), on the GLSL path the same within the float film's agreement.
TEST(ViewCli, ExrScreenshotIsTheLinearRadianceRenderWrites) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128, "exposure": 1.5}})";
    const Result cpu =
        runShell(std::string(VOXLIGHT_BINARY) + " render -q " + quoted(tmp / "scene.json") +
                     " -o " + quoted(tmp / "cpu.png") + " --exr " + quoted(tmp / "cpu.exr"),
                 tmp.path());
    ASSERT_EQ(cpu.code, 0) << cpu.err;
    const io::ImageRGBA want = io::readImage(tmp / "cpu.exr");
    for (const char* renderer : {"cpu", "gpu"}) {
        SCOPED_TRACE(renderer);
        const fs::path shot = tmp / (std::string("shot-") + renderer + ".exr");
        const Result view =
            runShell(*display + VOXLIGHT_BINARY + " view -q --renderer " + renderer + " " +
                         quoted(tmp / "scene.json") + " --screenshot " + quoted(shot),
                     tmp.path());
        if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
            GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
        ASSERT_EQ(view.code, 0) << view.err;
        io::ImageReadInfo info;
        const io::ImageRGBA got = io::readImage(shot, info);
        EXPECT_TRUE(info.floatingPoint);
        EXPECT_EQ(info.channels, 4);
        ASSERT_EQ(got.width, want.width);
        ASSERT_EQ(got.height, want.height);
        if (std::string(renderer) == "cpu") {
            EXPECT_EQ(got.pixels, want.pixels);
            continue;
        }
        // The GLSL film: radiance agrees as the 8-bit images do (mean well below one level of
        // the display's ~1/255 of the brightest radiance; see kGlMeanAbsLevels).
        double sum = 0.0, peak = 0.0;
        for (std::size_t i = 0; i < want.pixels.size(); ++i) {
            sum += std::abs(double(got.pixels[i]) - want.pixels[i]);
            peak = std::max(peak, double(want.pixels[i]));
        }
        EXPECT_LE(sum / double(want.pixels.size()), kGlMeanAbsLevels * peak / 255.0);
        EXPECT_GT(peak, 0.0);
    }
    // A screenshot name the viewer cannot write fails before any window, with one line.
    const Result bad =
        runShell(std::string(VOXLIGHT_BINARY) + " view " + quoted(tmp / "scene.json") +
                     " --screenshot " + quoted(tmp / "shot.hdr"),
                 tmp.path());
    EXPECT_EQ(bad.code, 2);
    EXPECT_NE(bad.err.find("--screenshot"), std::string::npos) << bad.err;
}

// On the GLSL path the gestures work as on the CPU path (the camera continues from the prepared
// state's): a scripted orbit, window/level drag and zoom, recorded and replayed on the CPU — the
// replay's last frame agrees with the screenshot within the GLSL tolerances.
TEST(ViewCli, AScriptedExplorationOnTheGlslPathReplaysToTheScreenshot) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "steps.json")
        << R"([{"orbit": [60, 10]}, {"window": [40, -30]}, {"zoom": 2}])";
    const Result view = runShell(
        // Whole GLSL frames: one per state, none replaced by the next before it shows.
        *display + VOXLIGHT_BINARY + " view -q --log --renderer gpu --gl-slice-ms 0 " +
            quoted(tmp / "scene.json") + " --script " + quoted(tmp / "steps.json") + " --record " +
            quoted(tmp / "rec.json") + " --screenshot " + quoted(tmp / "shot.png"),
        tmp.path());
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    // One GLSL frame per state: the first and one per step.
    std::size_t glFrames = 0;
    for (std::size_t at = view.err.find("view: GLSL frame 160x128"); at != std::string::npos;
         at = view.err.find("view: GLSL frame 160x128", at + 1))
        ++glFrames;
    EXPECT_GE(glFrames, 4u) << view.err;
    const Result replay =
        runShell(std::string(VOXLIGHT_BINARY) + " replay -q " + quoted(tmp / "rec.json") +
                     " --out " + quoted(tmp / "frames"),
                 tmp.path());
    ASSERT_EQ(replay.code, 0) << replay.err;
    ASSERT_TRUE(fs::exists(tmp / "frames" / "frame_00003.png"));
    ASSERT_FALSE(fs::exists(tmp / "frames" / "frame_00004.png"));
    const io::ImageRGBA last = io::readImage(tmp / "frames" / "frame_00003.png");
    const io::ImageRGBA first = io::readImage(tmp / "frames" / "frame_00000.png");
    const Agreement a = compareImageArea(last, io::readImage(tmp / "shot.png"));
    EXPECT_LE(a.meanAbs, kGlMeanAbsLevels);
    EXPECT_LE(a.fractionOver2, kGlFractionOver2);
    EXPECT_NE(first.pixels, last.pixels) << "the steps changed nothing";
}

// Progressive refinement on the GLSL path: while a clip plane is dragged the GL renders the
// coarse scene (a quarter of the size per side, twice the step, as the CPU path's coarse pass),
// magnified; when the drag ends, the full image of the same state, which agrees with the CPU
// path's screenshot of the same script.
TEST(ViewCli, TheGlslPathRendersCoarseWhileDraggingAndFullWhenReleased) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "steps.json") << R"([{"clip_add": {"normal": [0, 1, 0], "offset": -20}},
              {"clip_drag": {"index": 0, "by": [-20, 30], "frames": 8}}])";
    const auto view = [&](const char* renderer, const char* shot) {
        return viewScript(*display, tmp, std::string("--renderer ") + renderer, shot);
    };
    const Result gl = view("gpu", "gl.png");
    if (gl.code != 0 && gl.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << gl.err;
    ASSERT_EQ(gl.code, 0) << gl.err;
    const std::size_t coarse = gl.err.rfind("view: GLSL frame coarse 40x32");
    ASSERT_NE(coarse, std::string::npos) << "no coarse GLSL frame during the drag\n" << gl.err;
    EXPECT_NE(gl.err.find("view: GLSL frame 160x128", coarse), std::string::npos)
        << "no full GLSL frame after the drag\n"
        << gl.err;
    const Result cpu = view("cpu", "cpu.png");
    ASSERT_EQ(cpu.code, 0) << cpu.err;
    expectGlAgreesWithCpu(tmp, "cpu.png", "gl.png");
}

// A GLSL frame slower than the slice budget is rendered in slices of rows over several UI frames
// (the UI draws between them, the last image shown meanwhile), and its pixels are those of the
// same frame in one pass, bit for bit.
TEST(ViewCli, TheGlslPathSlicesASlowFrameAndDrawsTheSamePixels) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 160, "height": 128}})";
    std::ofstream(tmp / "steps.json") << R"([{"orbit": [40, 10]}])";
    const auto view = [&](const char* sliceMs, const char* shot) {
        return viewScript(*display, tmp, std::string("--renderer gpu --gl-slice-ms ") + sliceMs,
                          shot);
    };
    constexpr double kSliceMs = 0.5;
    const Result sliced = view("0.5", "sliced.png");
    if (sliced.code != 0 && sliced.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << sliced.err;
    ASSERT_EQ(sliced.code, 0) << sliced.err;
    const Result whole = view("0", "whole.png");
    ASSERT_EQ(whole.code, 0) << whole.err;
    // The orbit's frame: "view: GLSL frame 160x128 in S s, N slices (state …".
    const std::string key = "view: GLSL frame 160x128 in ";
    for (const Result* r : {&sliced, &whole}) {
        const std::size_t at = r->err.rfind(key);
        ASSERT_NE(at, std::string::npos) << r->err;
        double seconds = 0;
        int slices = 0;
        ASSERT_EQ(
            std::sscanf(r->err.c_str() + at + key.size(), "%lf s, %d slice", &seconds, &slices), 2)
            << r->err.substr(at);
        // A GL so fast that the frame fits the budget draws it in one slice; 20× the budget
        // leaves room for a frame slower than the last one's per-pixel time predicted.
        if (r == &whole) {
            EXPECT_EQ(slices, 1) << r->err;
        } else if (seconds > 20 * kSliceMs * 1e-3) {
            EXPECT_GT(slices, 1) << r->err;
        }
    }
    // The first frame's uploads (the volume in two slabs of z-slices): in UI frames of their own
    // when slicing, with the frame's draw otherwise.
    const std::string uploads = ", after uploads of ";
    const auto firstFrame = [&](const Result& r) {
        const std::size_t at = r.err.find("view: GLSL frame ");
        return at == std::string::npos ? std::string()
                                       : r.err.substr(at, r.err.find('\n', at) - at);
    };
    EXPECT_NE(firstFrame(sliced).find(uploads), std::string::npos) << sliced.err;
    EXPECT_EQ(firstFrame(whole).find(uploads), std::string::npos) << whole.err;
    // The image area (left of the panel, whose stats differ) bit for bit.
    const io::ImageRGBA a = io::readImage(tmp / "sliced.png"), b = io::readImage(tmp / "whole.png");
    ASSERT_EQ(a.width, b.width);
    ASSERT_EQ(a.height, b.height);
    std::size_t differ = 0;
    for (int y = 0; y < a.height; ++y)
        for (int x = 0; x < a.width - kPanelWidth; ++x)
            for (int c = 0; c < 4; ++c) differ += a.at(x, y)[c] != b.at(x, y)[c];
    EXPECT_EQ(differ, 0u);
}

// A scripted window/level drag ({"drag": {"kind": "window", …, "frames": n}}: the TF change of the
// issue's "UI frame during a TF change") makes n motions through the mouse drag's function, coarse
// images meanwhile; --log says the drag's own UI frames, and it ends where one motion of the
// same total ends: the same picture, the same recorded window.
TEST(ViewCli, AScriptedWindowDragEndsWhereOneMotionDoes) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
        "method": "gradient", "image": {"width": 160, "height": 128}})";
    constexpr int kDragFrames = 30;
    // (After a zoom: the first UI frames, which build the GL's fonts and shaders, are not timed.)
    std::ofstream(tmp / "steps.json")
        << R"([{"zoom": 1}, {"drag": {"kind": "window", "by": [45, -30], "frames": )" << kDragFrames
        << "}}]";
    const Result dragged = runScriptedView(*display, tmp, "--log ");
    if (dragged.code != 0 && dragged.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << dragged.err;
    ASSERT_EQ(dragged.code, 0) << dragged.err;
    const std::string key = "view: window/level drag: ";
    const std::size_t at = dragged.err.rfind(key);
    ASSERT_NE(at, std::string::npos) << dragged.err;
    EXPECT_EQ(std::atoi(dragged.err.c_str() + at + key.size()), kDragFrames) << dragged.err;
    EXPECT_NE(dragged.err.find("render coarse"), std::string::npos) << dragged.err;
    const io::ImageRGBA drag = io::readImage(tmp / "shot.png");
    const nlohmann::json dragRec = nlohmann::json::parse(std::ifstream(tmp / "rec.json"));

    std::ofstream(tmp / "steps.json") << R"([{"zoom": 1}, {"window": [45, -30]}])";
    const Result once = runScriptedView(*display, tmp);
    ASSERT_EQ(once.code, 0) << once.err;
    const io::ImageRGBA one = io::readImage(tmp / "shot.png");
    const nlohmann::json oneRec = nlohmann::json::parse(std::ifstream(tmp / "rec.json"));
    ASSERT_EQ(drag.width, one.width);
    ASSERT_EQ(drag.height, one.height);
    std::size_t differ = 0;
    for (int y = 0; y < drag.height; ++y)
        for (int x = 0; x < drag.width - kPanelWidth; ++x)
            for (int c = 0; c < 4; ++c) differ += drag.at(x, y)[c] != one.at(x, y)[c];
    EXPECT_EQ(differ, 0u);
    ASSERT_TRUE(dragRec.contains("keyframes") && oneRec.contains("keyframes")) << dragRec.dump();
    EXPECT_EQ(dragRec["keyframes"].back()["transfer_function"],
              oneRec["keyframes"].back()["transfer_function"]);
}

// A scene the GLSL path cannot do (here: nine lights, one more than the shader holds) is drawn by
// the CPU ray caster even with --renderer gpu, and the viewer says why on stderr (and in the
// Renderer panel); the image is the CPU's.
TEST(ViewCli, ASceneTheGlslPathCannotDoFallsBackToTheCpuWithItsReason) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::string lights;
    for (int i = 0; i < 9; ++i)
        lights += std::string(i ? ", " : "") + R"({"type": "directional", "direction": [)" +
                  std::to_string(0.1 * i) + R"(, 1, -0.3], "intensity": 0.12})";
    std::ofstream(tmp / "scene.json")
        << R"({"volume": {"phantom": "torso", "size": 48}, "transfer_function": "ct-bone",
               "method": "gradient", "lights": [)"
        << lights << R"(], "image": {"width": 160, "height": 128}})";
    const GlRun r = runGlAgainstCpu(tmp, *display);
    if (r.skipped) GTEST_SKIP() << r.why;
    EXPECT_NE(r.err.find("view: renderer cpu: the scene needs the CPU path: 9 lights"),
              std::string::npos)
        << r.err;
    EXPECT_LE(r.agreement.worst, kScreenshotTolLevels + 1e-3f);
}

// A GL failure never ends the viewer: a volume longer than the GL's 3D textures (16384 voxels
// along i, voxlight's own limit; GL_MAX_3D_TEXTURE_SIZE is 2048 on llvmpipe, 2048–16384 on GPUs)
// makes the GLSL path give up with one line, and the CPU draws the image.
TEST(ViewCli, AGlFailureFallsBackToTheCpuWithOneLine) {
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    constexpr int nx = 16384, ny = 4, nz = 4;
    {
        std::ofstream f(tmp / "long.nrrd", std::ios::binary);
        f << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: " << nx << " " << ny << " " << nz
          << "\nencoding: raw\nspacing: 0.1 1 1\n\n";
        for (int k = 0; k < nz; ++k)
            for (int j = 0; j < ny; ++j)
                for (int i = 0; i < nx; ++i)
                    f.put(char(j >= 1 && j <= 2 && k >= 1 && k <= 2 ? 200 : 0));
    }
    std::ofstream(tmp / "scene.json") << R"({"volume": "long.nrrd",
        "transfer_function": {"points": [{"value": 0, "extinction": 0},
                                         {"value": 255, "color": [1, 0.8, 0.6], "extinction": 0.5}]},
        "method": "gradient", "image": {"width": 160, "height": 128}})";
    const GlRun r = runGlAgainstCpu(tmp, *display);
    if (r.skipped) GTEST_SKIP() << r.why;
    if (r.err.find("the GLSL path failed") == std::string::npos &&
        r.err.find("renderer gpu (GLSL)") != std::string::npos)
        GTEST_SKIP() << "this GL holds 16384-voxel 3D textures: nothing to fall back from";
    EXPECT_NE(r.err.find("view: renderer cpu: the GLSL path failed, the CPU draws: the volume "
                         "(16384x4x4) exceeds this GL's 3D textures"),
              std::string::npos)
        << r.err;
    EXPECT_LE(r.agreement.worst, kScreenshotTolLevels + 1e-3f);
}

TEST(ViewCli, BadInputIsOneLineAndExitCodeTwo) {
    test::TempDir tmp;
    std::ofstream(tmp / "missing-volume.json") << R"({"volume": "nowhere.nii.gz"})";
    std::ofstream(tmp / "corrupt.json") << R"({"volume": {"phantom": "torso"}, "camera": )";
    std::ofstream(tmp / "steps.json") << R"([{"orbit": [1, 2]}, {"spin": 3}])";
    std::ofstream(tmp / "clip-steps.json") << R"([{"clip_move": {"index": 0}}])";
    std::ofstream(tmp / "tiny.json") << R"({"volume": {"phantom": "torso", "size": 16}})";
    const std::vector<std::pair<std::string, std::string>> cases = {
        // A screenshot the renderer refuses, before any window (it failed after a minute or
        // more, naming the screenshot file and not the --set that made the size).
        {"view " + quoted(tmp / "tiny.json") +
             " --set image.width=16384 --set image.height=16384 --screenshot " +
             quoted(tmp / "x.png"),
         "--set image.width=16384"},
        {"view " + quoted(tmp / "missing-volume.json"), "nowhere.nii.gz"},
        {"view " + quoted(tmp / "corrupt.json"), "corrupt.json"},
        {"view " + quoted(tmp / "absent.json"), "absent.json"},
        {"view " + quoted(tmp / "corrupt.json") + " --screenshot " + quoted(tmp / "x.jpg"),
         "--screenshot"},
        {"view --screenshot " + quoted(tmp / "x.png"), "--screenshot"},
        {"view " + quoted(tmp / "corrupt.json") + " --script " + quoted(tmp / "absent.json"),
         "absent.json"},
        {"view " + quoted(tmp / "missing-volume.json") + " --script " + quoted(tmp / "steps.json"),
         "[1].spin"},
        {"view " + quoted(tmp / "missing-volume.json") + " --script " +
             quoted(tmp / "clip-steps.json"),
         "[0].clip_move"},
        {"view " + quoted(tmp / "missing-volume.json") + " --record " + quoted(tmp / "r.txt"),
         "--record"},
    };
    for (const auto& [args, word] : cases) {
        const Result r = runShell(std::string(VOXLIGHT_BINARY) + " " + args, tmp.path());
        EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << "\n" << r.err;
        EXPECT_NE(r.err.find(word), std::string::npos) << args << "\n" << r.err;
    }
    EXPECT_FALSE(fs::exists(tmp / "x.png"));
    // No display is said before the volume loads (it was said after: seconds to minutes on a
    // large series; probe): a volume that would fail to read is not read.
    std::ofstream(tmp / "bad.nii") << "not a NIfTI file";
    std::ofstream(tmp / "bad.json") << R"({"volume": "bad.nii"})";
    const Result r = runShell("env -u DISPLAY -u WAYLAND_DISPLAY " + std::string(VOXLIGHT_BINARY) +
                                  " view " + quoted(tmp / "bad.json"),
                              tmp.path());
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find("xvfb-run"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("bad.nii"), std::string::npos) << r.err;
}

TEST(ViewCli, AStepThatLeavesAViewTheSceneRefusesIsNamedByTheScript) {
    // {"zoom": 300} (1.1³⁰⁰ closer) put the eye on the target: the error named the screenshot
    // and `scene.json: camera.eye`, a key the file does not have.
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({"volume": {"phantom": "sphere", "size": 16},
        "method": "gradient", "image": {"width": 64, "height": 48}})";
    std::ofstream(tmp / "steps.json") << R"([{"orbit": [10, 0]}, {"zoom": 300}])";
    const Result r = runScriptedView(*display, tmp);
    if (r.code != 0 && r.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << r.err;
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find("steps.json: [1].zoom: leaves a view that cannot be rendered"),
              std::string::npos)
        << r.err;
    EXPECT_FALSE(fs::exists(tmp / "shot.png"));
    // --record keeps the states shown before the failing step (it was lost without a word) and
    // the one line says where.
    EXPECT_NE(r.err.find("the session so far is in"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    ASSERT_TRUE(fs::exists(tmp / "rec.json"));
    EXPECT_GE(nlohmann::json::parse(std::ifstream(tmp / "rec.json"))["keyframes"].size(), 2u);
    fs::remove(tmp / "rec.json");
    // Orthographic: 1.1^100000 made the height 0 — read as "fit", the whole volume again, exit 0.
    std::ofstream(tmp / "steps.json") << R"([{"zoom": 100000}])";
    std::ofstream(tmp / "scene.json") << R"({"volume": {"phantom": "sphere", "size": 16},
        "method": "gradient", "image": {"width": 64, "height": 48},
        "camera": {"projection": "orthographic"}})";
    const Result o = runScriptedView(*display, tmp);
    EXPECT_EQ(o.code, 2) << o.err;
    EXPECT_NE(o.err.find("steps.json: [0].zoom: leaves a view that cannot be rendered"),
              std::string::npos)
        << o.err;
    EXPECT_FALSE(fs::exists(tmp / "shot.png"));
    // The local/global switch on a method without it did nothing, silently.
    std::ofstream(tmp / "steps.json") << R"([{"orbit": [10, 0]}, {"shading": "global"}])";
    const Result s = runScriptedView(*display, tmp);
    EXPECT_EQ(s.code, 2) << s.err;
    EXPECT_NE(s.err.find("steps.json: [1].shading: switches sh-local and sh-global; the view's "
                         "method is 'gradient'"),
              std::string::npos)
        << s.err;
    EXPECT_FALSE(fs::exists(tmp / "shot.png"));
}

namespace {
/// `voxlight view --record rec.json` of dir/scene.json on an X server of its own (-displayfd
/// picks a free display); once the viewer has shown its first full image (--log's "render full"
/// line; the first keyframe is recorded when that image was asked for), `stop` runs in the shell
/// with $x the server's pid and $v the viewer's. Returns the viewer's exit code (-1 when it did
/// not end) and its stderr. Both waits are bounded, so a server or viewer that never comes up
/// fails, not hangs.
Result runViewerStoppedBy(const test::TempDir& dir, const std::string& stop) {
    std::ofstream(dir / "stop.sh") << "cd " << quoted(dir.path()) << "\n"
                                   << "Xvfb -displayfd 3 -screen 0 1024x768x24 3>disp.txt "
                                      "2>/dev/null &\n"
                                   << "x=$!\n"
                                   << "for i in $(seq 100); do [ -s disp.txt ] && break; "
                                      "sleep 0.1; done\n"
                                   << "DISPLAY=:$(cat disp.txt) " << VOXLIGHT_BINARY
                                   << " view -q --log --renderer cpu scene.json --record rec.json "
                                      "2>err.txt &\n"
                                   << "v=$!\n"
                                   << "for i in $(seq 600); do grep -q 'render full' err.txt "
                                      "2>/dev/null && break; sleep 0.1; done\n"
                                   << stop << "\n"
                                   << "wait $v; echo $? >rc.txt\n"
                                   << "kill $x 2>/dev/null; wait\n";
    const int status = std::system(("sh " + quoted(dir / "stop.sh")).c_str());
    std::ifstream rf(dir / "rc.txt"), ef(dir / "err.txt");
    int code = -1;
    if (status != 0 || !(rf >> code)) code = -1;
    return {code, std::string((std::istreambuf_iterator<char>(ef)), {})};
}
}  // namespace

TEST(ViewCli, ALostDisplaySavesTheRecordingAndSaysSo) {
    // The X server going away (it quit, the connection to it dropped) ended the viewer inside
    // Xlib with exit code 1 and "XIO: fatal IO error"; the session being recorded was lost. So
    // did a closed terminal (SIGHUP's default); and Ctrl-C under xvfb-run, which stops the X
    // server too, must still read as a cancel.
    if (!onPath("Xvfb")) GTEST_SKIP() << "no Xvfb here (tools/setup.sh installs xvfb)";
    const struct {
        const char* stop;
        int code;
        const char* says;
    } cases[] = {
        {"kill $x", 2, "voxlight: error: display: the connection to the X server was lost"},
        // The interrupt held until the server is gone, so that the viewer's next X call fails
        // with its cancel flag already up (the race xvfb-run's Ctrl-C makes, made certain).
        {"kill -STOP $v; kill -INT $v; kill $x; wait $x; kill -CONT $v", 130,
         "voxlight: cancelled"},
        {"kill -HUP $v", 130, "voxlight: cancelled"},
    };
    for (const auto& c : cases) {
        test::TempDir tmp;
        std::ofstream(tmp / "scene.json") << R"({
            "volume": {"phantom": "torso", "size": 32}, "transfer_function": "ct-bone",
            "method": "gradient", "image": {"width": 160, "height": 120}})";
        const Result r = runViewerStoppedBy(tmp, c.stop);
        EXPECT_EQ(r.code, c.code) << c.stop << "\n" << r.err;
        EXPECT_NE(r.err.find(c.says), std::string::npos) << c.stop << "\n" << r.err;
        EXPECT_NE(r.err.find("the session so far is in rec.json"), std::string::npos)
            << c.stop << "\n"
            << r.err;
        EXPECT_EQ(r.err.find("XIO"), std::string::npos) << c.stop << "\n" << r.err;
        // A whole session, which replay reads; no temporary beside it.
        const session::Session s = session::loadSession(tmp / "rec.json");
        EXPECT_GE(s.keyframes.size(), 1u) << c.stop;
        for (const auto& e : fs::directory_iterator(tmp.path()))
            EXPECT_EQ(e.path().filename().string().rfind(".voxlight", 0), std::string::npos)
                << c.stop << ": " << e.path();
    }
}

TEST(ViewCli, TheRecordedSessionIsWrittenAsEveryOutputIs) {
    // --record went through the session library's own writer: a symlink given as --record was
    // replaced by a regular file of mode 0644 (every other output writes through a link and
    // keeps a replaced file's mode), and an interactive run whose save failed said only "could
    // not be saved", with exit code 0.
    const std::optional<std::string> display = displayPrefix();
    if (!display) GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here";
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 32}, "transfer_function": "ct-bone",
        "method": "gradient", "image": {"width": 96, "height": 80}})";
    std::ofstream(tmp / "steps.json") << R"([{"orbit": [30, 0]}])";
    fs::create_directory(tmp / "kept");
    std::ofstream(tmp / "kept" / "session.json") << "old";
    fs::permissions(tmp / "kept" / "session.json", fs::perms(0640));
    fs::create_symlink(tmp / "kept" / "session.json", tmp / "rec.json");
    const Result view = runScriptedView(*display, tmp);
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    EXPECT_TRUE(fs::is_symlink(tmp / "rec.json"));
    EXPECT_EQ(fs::status(tmp / "kept" / "session.json").permissions() & fs::perms::all,
              fs::perms(0640));
    EXPECT_EQ(session::loadSession(tmp / "kept" / "session.json").keyframes.size(), 2u);
}
