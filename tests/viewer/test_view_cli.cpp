// SPDX-License-Identifier: MIT
// `voxlight view` end to end: the scripted screenshot's image area equals `voxlight render`'s image
// of the same scene (one renderer, shown pixel for pixel), and bad input fails before any window.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include "io/image.h"
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
}  // namespace

TEST(ViewCli, ScreenshotImageAreaEqualsTheCpuRender) {
    // Headless: under the display we have, else under xvfb-run (tools/setup.sh installs it).
    std::string prefix;
    if (!std::getenv("DISPLAY")) {
        if (!onPath("xvfb-run"))
            GTEST_SKIP() << "no DISPLAY and no xvfb-run: cannot open an OpenGL window here "
                            "(tools/setup.sh installs xvfb)";
        prefix = "xvfb-run -a -s '-screen 0 1280x800x24' ";
    }
    test::TempDir tmp;
    std::ofstream(tmp / "scene.json") << R"({
        "volume": {"phantom": "torso", "size": 64}, "transfer_function": "ct-bone",
        "method": "gradient", "camera": {"azimuth": 30, "elevation": 15},
        "image": {"width": 240, "height": 200}})";
    const Result cpu = runShell(std::string(VOXLIGHT_BINARY) + " render -q " +
                                    quoted(tmp / "scene.json") + " -o " + quoted(tmp / "cpu.png"),
                                tmp.path());
    ASSERT_EQ(cpu.code, 0) << cpu.err;
    const Result view =
        runShell(prefix + VOXLIGHT_BINARY + " view -q " + quoted(tmp / "scene.json") +
                     " --screenshot " + quoted(tmp / "shot.png") + " --frames 5",
                 tmp.path());
    if (view.code != 0 && view.err.find("OpenGL 4.5 window") != std::string::npos)
        GTEST_SKIP() << "no OpenGL 4.5 window on this machine: " << view.err;
    ASSERT_EQ(view.code, 0) << view.err;
    const io::ImageRGBA a = io::readImage(tmp / "cpu.png");
    const io::ImageRGBA s = io::readImage(tmp / "shot.png");
    ASSERT_EQ(s.width, a.width + kPanelWidth);
    ASSERT_EQ(s.height, a.height);
    // The orientation letters sit at the middle of each edge, 12 px in (viewer.cpp drawImage):
    // left out of the comparison, and they must be there.
    const auto inLabel = [&](int x, int y) {
        const int cx = a.width / 2, cy = a.height / 2;
        const auto near = [](int p, int q, int r) { return std::abs(p - q) <= r; };
        return (near(y, cy, kLabelHalfHeight) &&
                (near(x, 12, kLabelHalfWidth) || near(x, a.width - 12, kLabelHalfWidth))) ||
               (near(x, cx, kLabelHalfWidth) &&
                (near(y, 12, kLabelHalfHeight) || near(y, a.height - 12, kLabelHalfHeight)));
    };
    float worst = 0.f;
    int labelPixels = 0;
    for (int y = 0; y < a.height; ++y)
        for (int x = 0; x < a.width; ++x)
            for (int c = 0; c < 3; ++c) {
                const float d = std::abs(a.at(x, y)[c] - s.at(x, y)[c]) * 255.f;
                if (inLabel(x, y))
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

TEST(ViewCli, BadInputIsOneLineAndExitCodeTwo) {
    test::TempDir tmp;
    std::ofstream(tmp / "missing-volume.json") << R"({"volume": "nowhere.nii.gz"})";
    std::ofstream(tmp / "corrupt.json") << R"({"volume": {"phantom": "torso"}, "camera": )";
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"view " + quoted(tmp / "missing-volume.json"), "nowhere.nii.gz"},
        {"view " + quoted(tmp / "corrupt.json"), "corrupt.json"},
        {"view " + quoted(tmp / "absent.json"), "absent.json"},
        {"view " + quoted(tmp / "corrupt.json") + " --screenshot " + quoted(tmp / "x.jpg"),
         "--screenshot"},
        {"view --screenshot " + quoted(tmp / "x.png"), "--screenshot"},
    };
    for (const auto& [args, word] : cases) {
        const Result r = runShell(std::string(VOXLIGHT_BINARY) + " " + args, tmp.path());
        EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << "\n" << r.err;
        EXPECT_NE(r.err.find(word), std::string::npos) << args << "\n" << r.err;
    }
    EXPECT_FALSE(fs::exists(tmp / "x.png"));
}
