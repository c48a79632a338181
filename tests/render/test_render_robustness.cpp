// SPDX-License-Identifier: MIT
// Bad input gives a defined image or a clear error, never NaN pixels.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "render_test_util.h"

using namespace voxlight;
using namespace voxlight::test;

namespace {
const render::Mode kAllModes[] = {render::Mode::EmissionAbsorption, render::Mode::Gradient,
                                  render::Mode::Mip, render::Mode::MinIp, render::Mode::Isosurface};

render::Camera defaultCamera(const core::Volume& v, int w, int h) {
    const auto b = v.geometry().worldBounds();
    return render::Camera(render::CameraSpec{}, b[0], b[1], w, h);
}
}  // namespace

TEST(Robustness, NonFiniteVoxelsNeverGiveNonFinitePixels) {
    core::Volume v = spherePhantom(32);
    float* d = v.dataAs<float>();
    const float bad[] = {std::numeric_limits<float>::quiet_NaN(),
                         std::numeric_limits<float>::infinity(),
                         -std::numeric_limits<float>::infinity()};
    for (std::size_t i = 0; i < v.voxelCount(); i += 37) d[i] = bad[(i / 37) % 3];
    const render::Camera cam = defaultCamera(v, 32, 32);
    for (render::Mode m : kAllModes) {
        render::RenderOptions o;
        o.mode = m;
        const core::ImageRGBA img = renderWith(v, stepTf(0.5f), cam, o);
        EXPECT_TRUE(allFinite(img)) << render::toString(m);
    }
}

TEST(Robustness, TransparentTfGivesTheBackgroundAndOpaqueTfAFiniteImage) {
    const core::Volume v = spherePhantom(32);
    const render::Camera cam = defaultCamera(v, 24, 24);
    render::RenderOptions o;
    o.background = {0.2f, 0.3f, 0.4f};
    const optics::TransferFunction empty({tfPoint(0, 0), tfPoint(1, 0)}, {0.5f, 1});
    const core::ImageRGBA e = renderWith(v, empty, cam, o);
    for (int y = 0; y < 24; ++y)
        for (int x = 0; x < 24; ++x) {
            EXPECT_EQ(e.at(x, y)[2], 0.4f);
            EXPECT_EQ(e.at(x, y)[3], 0.f);
        }
    const optics::TransferFunction opaque({tfPoint(0, 1e6f), tfPoint(1, 1e6f)}, {0.5f, 1});
    for (render::Mode m : kAllModes) {
        o.mode = m;
        const core::ImageRGBA img = renderWith(v, opaque, cam, o);
        EXPECT_TRUE(allFinite(img)) << render::toString(m);
        EXPECT_EQ(img.at(12, 12)[3], 1.f) << render::toString(m);
    }
}

TEST(Robustness, CameraInsideTheVolumeRendersFromInside) {
    core::PhantomOptions po;
    po.size = 40;
    const core::Volume v = core::makePhantom("torso", po);
    render::CameraSpec s;
    s.eye = glm::dvec3(0, -20, 0);    // inside the body
    s.target = glm::dvec3(0, 80, 0);  // looking at the spine
    s.fovYDeg = 90;
    const auto b = v.geometry().worldBounds();
    const render::Camera cam(s, b[0], b[1], 24, 24);
    render::RenderOptions o;
    const auto bone = optics::TransferFunction(
        {tfPoint(150, 0), tfPoint(400, 1.f), tfPoint(1000, 3.f)}, {500, 1000});
    const core::ImageRGBA img = renderWith(v, bone, cam, o);
    EXPECT_TRUE(allFinite(img));
    EXPECT_GT(img.at(12, 12)[3], 0.9f) << "the vertebra ahead is opaque";
}

TEST(Robustness, AbsurdImageSizesAndStepsAreClearErrors) {
    const core::Volume v = spherePhantom(16);
    const auto b = v.geometry().worldBounds();
    EXPECT_THROW(render::Camera(render::CameraSpec{}, b[0], b[1], 0, 10), InputError);
    const render::Camera huge(render::CameraSpec{}, b[0], b[1], 16384, 16384);
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const auto tf = stepTf(1);
    const render::RayCaster caster(v, g, tf, render::RenderOptions{});
    EXPECT_THROW(caster.render(huge), InputError);
    render::RenderOptions bad;
    bad.stepVoxels = 0;
    EXPECT_THROW(render::RayCaster(v, g, tf, bad), InputError);
    bad.stepVoxels = NAN;
    EXPECT_THROW(render::RayCaster(v, g, tf, bad), InputError);
}

// A single slice is the slab ±0.5 voxel thick on its axis (5 mm slices here): empty-space
// skipping must keep all of it (a clip to the cells' box [0, 0] once left a 0.02-voxel sliver).
TEST(Robustness, SingleSliceSkippingDoesNotChangeTheImage) {
    const core::Volume v = singleSlice(4.0);
    const optics::TransferFunction tf({tfPoint(0, 0), tfPoint(255, 0.2f)}, {128, 256});
    const auto b = v.geometry().worldBounds();
    for (const double elevation : {60.0, 0.0}) {  // oblique, and rays parallel to the slice
        render::CameraSpec s;
        s.elevationDeg = elevation;
        const render::Camera cam(s, b[0], b[1], 16, 16);
        for (render::Mode m :
             {render::Mode::EmissionAbsorption, render::Mode::Gradient, render::Mode::Isosurface}) {
            render::RenderOptions o;
            o.mode = m;
            const core::ImageRGBA a = renderWith(v, tf, cam, o);
            o.emptySpaceSkipping = false;
            const core::ImageRGBA c = renderWith(v, tf, cam, o);
            double maxDiff = 0;
            for (std::size_t i = 0; i < a.pixels.size(); ++i)
                maxDiff = std::max(maxDiff, double(std::abs(a.pixels[i] - c.pixels[i])));
            EXPECT_LT(maxDiff, 1e-4) << render::toString(m) << " elevation " << elevation;
        }
    }
}

TEST(Robustness, DegenerateSingleSliceVolumeRenders) {
    const core::Volume v = singleSlice(1.0);
    const render::Camera cam = defaultCamera(v, 16, 16);
    const optics::TransferFunction tf({tfPoint(0, 0), tfPoint(255, 1.f)}, {128, 256});
    for (render::Mode m : kAllModes) {
        render::RenderOptions o;
        o.mode = m;
        EXPECT_TRUE(allFinite(renderWith(v, tf, cam, o))) << render::toString(m);
    }
}

// Progress comes from the calling thread only, rises to 1, and a cancel request stops the frame
// with CancelledError (tiles run in one parallel loop; the workers stop taking tiles).
TEST(Robustness, RenderReportsProgressAndCancels) {
    const core::Volume v = spherePhantom(48);
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const auto tf = stepTf(1.f);
    render::RenderOptions o;
    o.threads = 2;
    o.tileSize = 4;
    const render::RayCaster caster(v, g, tf, o);
    const render::Camera cam = defaultCamera(v, 64, 64);
    const std::thread::id self = std::this_thread::get_id();
    std::vector<double> seen;
    bool otherThread = false;
    std::atomic<bool> cancel = false;
    const core::Progress p(
        [&](const std::string& stage, double f) {
            EXPECT_EQ(stage, "render");
            otherThread |= std::this_thread::get_id() != self;
            seen.push_back(f);
        },
        &cancel);
    (void)caster.render(cam, p);
    EXPECT_FALSE(otherThread);
    ASSERT_GE(seen.size(), 3u);
    EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
    EXPECT_EQ(seen.front(), 0.0);
    EXPECT_EQ(seen.back(), 1.0);

    // Cancelled after the caller's first chunk: the frame throws, and the tiles rendered stop
    // well short of all of them (workers take no new chunk). Worker threads wait in their first
    // tile until the cancel is raised (or kGateTimeout passes), so a caller descheduled on a
    // loaded machine cannot let them finish the frame before it reports: the test checks the
    // mechanism, not the scheduler.
    struct CountingModel final : render::ShadingModel {
        mutable std::atomic<int> tiles{0};
        std::atomic<bool> gate{true};
        const std::atomic<bool>* cancel = nullptr;
        std::thread::id caller;
        std::string name() const override { return "counting"; }
        void renderTile(const render::RayCaster&, const render::Camera&, int, int, int, int,
                        core::ImageRGBA&, render::RenderStats&) const override {
            constexpr auto kGateTimeout = std::chrono::seconds(10);
            const auto start = std::chrono::steady_clock::now();
            while (gate && std::this_thread::get_id() != caller && !*cancel &&
                   std::chrono::steady_clock::now() - start < kGateTimeout)
                std::this_thread::yield();
            ++tiles;
        }
    };
    CountingModel counting;
    counting.cancel = &cancel;
    counting.caller = self;
    const render::Camera big = defaultCamera(v, 256, 256);  // 4096 tiles of 4²
    int calls = 0;
    const core::Progress cancelling(
        [&](const std::string&, double) {
            if (++calls == 2) cancel = true;  // after the first chunk of tiles
        },
        &cancel);
    EXPECT_THROW((void)caster.render(big, counting, cancelling), CancelledError);
    EXPECT_LT(counting.tiles.load(), 4096 / 2);
    cancel = false;
    counting.gate = false;
    (void)caster.render(big, counting, core::Progress::none());
    EXPECT_GE(counting.tiles.load(), 4096);
}
