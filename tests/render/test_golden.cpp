// SPDX-License-Identifier: MIT
// Golden images, one per mode, on a small torso phantom. Regenerate with tools/make_golden.sh
// (sets VOXLIGHT_UPDATE_GOLDEN=1). On failure the actual and a diff image are written to
// $TMPDIR/voxlight-golden-failures/.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

#include "io/image.h"
#include "optics/presets.h"
#include "render/tonemap.h"
#include "render_test_util.h"
#include "support/test_support.h"

using namespace voxlight;
namespace fs = std::filesystem;

namespace {
// Golden PNGs are 8-bit: compare display values. Different compilers/CPUs may round a few
// samples differently; a real regression moves many pixels by a lot.
constexpr float kPixelTol = 3.f / 255.f;   // per channel
constexpr double kMaxBadFraction = 0.002;  // pixels allowed beyond kPixelTol
constexpr double kMeanTol = 0.5 / 255.0;   // mean absolute difference
constexpr int kGoldenSize = 128;

const core::Volume& torso() {
    static const core::Volume v = [] {
        core::PhantomOptions o;
        o.size = 64;
        return core::makePhantom("torso", o);
    }();
    return v;
}

struct GoldenCase {
    std::string name;
    render::Mode mode;
    std::string preset;
    bool clip = false;
    bool crop = false;
};

void checkGolden(const GoldenCase& c) {
    const core::Volume& v = torso();
    const optics::TransferFunction tf = optics::makePreset(c.preset);
    render::RenderOptions o;
    o.mode = c.mode;
    if (c.clip) o.clipPlanes.push_back({{0, 0, 20}, glm::normalize(glm::dvec3(0.3, 1, -0.2))});
    if (c.crop) o.cropBox = render::CropBox{{-140, -90, -20}, {140, 90, 170}};
    render::CameraSpec s;
    s.azimuthDeg = 25;
    s.elevationDeg = 15;
    const auto b = v.geometry().worldBounds();
    const render::Camera cam(s, b[0], b[1], kGoldenSize, kGoldenSize);
    const core::ImageRGBA img = render::toDisplay(test::renderWith(v, tf, cam, o));
    const fs::path golden = test::sourceDir() / "tests/render/golden" / (c.name + ".png");
    if (std::getenv("VOXLIGHT_UPDATE_GOLDEN")) {
        io::writeImage(img, golden);
        GTEST_SKIP() << "wrote " << golden;
    }
    ASSERT_TRUE(fs::exists(golden)) << golden << " missing: run tools/make_golden.sh";
    const core::ImageRGBA ref = io::readImage(golden);
    ASSERT_EQ(ref.width, img.width);
    ASSERT_EQ(ref.height, img.height);
    core::ImageRGBA diff(img.width, img.height);
    double sum = 0;
    int bad = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            float worst = 0;
            for (int k = 0; k < 3; ++k) {
                const float d = std::abs(img.at(x, y)[k] - ref.at(x, y)[k]);
                worst = std::max(worst, d);
                sum += d / 3;
                diff.at(x, y)[k] = std::min(1.f, 8.f * d);  // amplified
            }
            diff.at(x, y)[3] = 1.f;
            bad += worst > kPixelTol;
        }
    const double mean = sum / (img.width * img.height);
    const double badFraction = double(bad) / (img.width * img.height);
    if (mean > kMeanTol || badFraction > kMaxBadFraction) {
        const fs::path dir = fs::temp_directory_path() / "voxlight-golden-failures";
        fs::create_directories(dir);
        core::ImageRGBA opaque = img;
        for (std::size_t i = 3; i < opaque.pixels.size(); i += 4) opaque.pixels[i] = 1.f;
        io::writeImage(opaque, dir / (c.name + "-actual.png"));
        io::writeImage(diff, dir / (c.name + "-diff.png"));
        ADD_FAILURE() << c.name << ": mean |diff| " << mean * 255 << "/255, " << bad
                      << " pixels beyond " << kPixelTol * 255 << "/255; wrote actual and diff to "
                      << dir;
    }
}
}  // namespace

TEST(Golden, EmissionAbsorption) {
    checkGolden({"ea-soft-tissue", render::Mode::EmissionAbsorption, "ct-soft-tissue"});
}
TEST(Golden, GradientBone) { checkGolden({"gradient-bone", render::Mode::Gradient, "ct-bone"}); }
TEST(Golden, GradientAngioClipped) {
    checkGolden({"gradient-angio-clip", render::Mode::Gradient, "ct-angio", true});
}
TEST(Golden, Mip) { checkGolden({"mip-angio", render::Mode::Mip, "ct-angio"}); }
TEST(Golden, MinIp) {
    checkGolden({"minip-lung-crop", render::Mode::MinIp, "ct-lung", false, true});
}
TEST(Golden, Isosurface) { checkGolden({"iso-bone", render::Mode::Isosurface, "ct-bone"}); }
