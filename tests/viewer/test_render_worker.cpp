// SPDX-License-Identifier: MIT
// The background renderer: coarse then full, the full image equal to the CLI's, and a newer state
// cancelling a full pass in progress (the UI never waits for either).
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "core/phantoms.h"
#include "io/volume_io.h"
#include "pipeline/pipeline.h"
#include "support/test_support.h"
#include "viewer/loaded_scene.h"
#include "viewer/render_worker.h"
#include "viewer/view_state.h"

using namespace voxlight;
using nlohmann::json;

namespace {
io::Scene torso(int size, int image, double azimuth = 30.0) {
    return io::parseScene({{"volume", {{"phantom", "torso"}, {"size", size}}},
                           {"transfer_function", "ct-bone"},
                           {"camera", {{"azimuth", azimuth}, {"elevation", 15}}},
                           {"image", {{"width", image}, {"height", image}}}},
                          "test", "/");
}
/// Waits (polling, as the UI does each frame) for the worker's next image.
std::optional<viewer::RenderedImage> next(viewer::RenderWorker& w, double seconds = 120.0) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
        if (auto r = w.take()) return r;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return std::nullopt;
}
}  // namespace

TEST(RenderWorker, CoarseFirstThenTheFullImageTheCliWouldWrite) {
    const io::Scene scene = torso(48, 128);
    viewer::RenderWorker worker;
    worker.submit({scene, 1, false});
    auto coarse = next(worker);
    ASSERT_TRUE(coarse);
    ASSERT_TRUE(coarse->error.empty()) << coarse->error;
    EXPECT_TRUE(coarse->coarse);
    EXPECT_EQ(coarse->width, 32);
    auto full = next(worker);
    ASSERT_TRUE(full);
    EXPECT_FALSE(full->coarse);
    EXPECT_EQ(full->width, 128);
    EXPECT_TRUE(full->camera.contains("eye"));
    // The same pipeline as `voxlight render`: bit-identical display bytes.
    const pipeline::RunResult r = pipeline::renderScene(scene);
    EXPECT_EQ(full->rgba, viewer::displayBytes(scene, r.image));
    // The same state again (the drag ended) goes straight to the full pass.
    worker.submit({scene, 1, false});
    auto again = next(worker);
    ASSERT_TRUE(again);
    EXPECT_FALSE(again->coarse);
}

TEST(RenderWorker, InteractingRendersCoarseOnly) {
    viewer::RenderWorker worker;
    worker.submit({torso(32, 64), 1, true});
    auto coarse = next(worker);
    ASSERT_TRUE(coarse);
    EXPECT_TRUE(coarse->coarse);
    // Nothing further until the state is submitted as settled.
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    EXPECT_FALSE(worker.take().has_value());
    EXPECT_FALSE(worker.status().busy);
}

TEST(RenderWorker, ANewStateCancelsTheFullPassInProgress) {
    viewer::RenderWorker worker;
    // Large enough that the full pass runs for a while on two cores.
    worker.submit({torso(96, 640), 1, false});
    auto coarse = next(worker);
    ASSERT_TRUE(coarse && coarse->coarse);
    // Wait for the full pass to start, then move on to a new state.
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!(worker.status().busy && !worker.status().coarse) &&
           std::chrono::steady_clock::now() < end)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    worker.submit({torso(96, 640, 60.0), 2, false});
    // What arrives next is the new state's (coarse, then full); state 1's full image never does.
    for (int i = 0; i < 2; ++i) {
        auto r = next(worker);
        ASSERT_TRUE(r);
        EXPECT_EQ(r->generation, 2u);
        EXPECT_EQ(r->coarse, i == 0);
    }
    EXPECT_EQ(worker.cancelled(), 1u);
}

// Kronander's interleaved update: after a TF change the SH shading of the last fields shows at
// once (coarse and full), the new fields are computed on the field thread, and the state is then
// rendered again with them — equal to the CLI's image of the new state.
TEST(RenderWorker, AfterATfChangeTheOldShadingShowsAtOnceAndTheNewFollows) {
    auto shScene = [](const char* tf, double azimuth) {
        return io::parseScene(
            {{"volume", {{"phantom", "torso"}, {"size", 48}}},
             {"transfer_function", tf},
             {"method", {{"name", "sh-local"}, {"params", {{"rays", 24}, {"data_reduction", 2}}}}},
             {"lights",
              json::array(
                  {{{"type", "directional"}, {"direction", {-1, -1, -1}}, {"intensity", 3}}})},
             {"camera", {{"azimuth", azimuth}, {"elevation", 15}}},
             {"image", {{"width", 64}, {"height", 64}}}},
            "test", "/");
    };
    viewer::RenderWorker worker;
    worker.submit({shScene("ct-bone", 30), 1, false});
    for (;;) {  // the first state computes its fields in its own passes: never stale
        auto r = next(worker);
        ASSERT_TRUE(r);
        ASSERT_TRUE(r->error.empty()) << r->error;
        EXPECT_FALSE(r->staleShading);
        if (!r->coarse) break;
    }
    const io::Scene soft = shScene("ct-soft-tissue", 30);
    worker.submit({soft, 2, false});
    bool sawStale = false, sawUpdating = false;
    std::optional<viewer::RenderedImage> current;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(180);
    while (std::chrono::steady_clock::now() < end) {
        sawUpdating = sawUpdating || worker.status().updatingFields;
        if (auto r = worker.take()) {
            ASSERT_TRUE(r->error.empty()) << r->error;
            EXPECT_EQ(r->generation, 2u);
            sawStale = sawStale || r->staleShading;
            if (!r->coarse && !r->staleShading) {
                current = std::move(r);
                break;
            }
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_TRUE(sawStale);
    EXPECT_TRUE(sawUpdating);
    ASSERT_TRUE(current);
    EXPECT_EQ(current->rgba, viewer::displayBytes(soft, pipeline::renderScene(soft).image));
    EXPECT_FALSE(worker.status().updatingFields);
}

// The volume is read once per load: the one the viewer reads for its info panel and histogram
// (prepareScene) is handed to the worker's session (adoptVolume), whose runs then never compute
// load_volume and hold the very same voxels. Without the hand-over the first pass reads the
// file itself (the control: the check can fail).
TEST(RenderWorker, TheVolumeTheViewerLoadedIsThePipelinesReadOnce) {
    test::TempDir tmp;
    core::PhantomOptions po;
    po.size = 32;
    io::writeVolume(core::makePhantom("torso", po), tmp / "ct.mha");
    const io::Scene scene = io::parseScene({{"volume", (tmp / "ct.mha").string()},
                                            {"transfer_function", "ct-bone"},
                                            {"image", {{"width", 64}, {"height", 64}}}},
                                           "test", "/");
    const viewer::LoadedScene loaded = viewer::prepareScene(scene, core::Progress::none());
    const auto loadsVolume = [](const viewer::RenderedImage& r) {
        return std::find(r.computedStages.begin(), r.computedStages.end(), "load_volume") !=
               r.computedStages.end();
    };
    // The passes up to the full one (take() keeps only the newest: the coarse one may be gone).
    const auto passes = [&](viewer::RenderWorker& w) {
        std::vector<viewer::RenderedImage> out;
        for (;;) {
            auto r = next(w);
            if (!r) {
                ADD_FAILURE() << "no full pass";
                return out;
            }
            EXPECT_TRUE(r->error.empty()) << r->error;
            const bool full = !r->coarse;
            out.push_back(std::move(*r));
            if (full) return out;
        }
    };
    // The volume the worker's pipeline holds, from a prepare-only request (null if none came).
    const auto preparedVolume = [&](viewer::RenderWorker& w) -> const core::Volume* {
        viewer::RenderRequest prepare{loaded.scene, 2, false};
        prepare.prepareOnly = true;
        w.submit(std::move(prepare));
        const auto p = next(w);
        return p && p->setup ? p->setup->volume.get() : nullptr;
    };
    {
        // Without adoptVolume the pipeline reads the file itself: its volume is another object.
        // (Not judged by the passes' stage lists: the coarse pass that read it may have been
        // replaced by the full one before next() took it, on a loaded machine.)
        viewer::RenderWorker control;
        control.submit({loaded.scene, 1, false});
        (void)passes(control);
        const core::Volume* own = preparedVolume(control);
        ASSERT_NE(own, nullptr);
        EXPECT_NE(own, loaded.volume.get());
    }
    viewer::RenderWorker worker;
    worker.adoptVolume(loaded.scene, loaded.volume);
    worker.submit({loaded.scene, 1, false});
    const std::vector<viewer::RenderedImage> seen = passes(worker);
    ASSERT_FALSE(seen.empty());
    EXPECT_FALSE(seen.back().rgba.empty());
    for (const auto& r : seen) {
        EXPECT_FALSE(loadsVolume(r)) << (r.coarse ? "coarse" : "full");
        EXPECT_FALSE(r.computedStages.empty());  // it did compute the others (camera, render)
    }
    EXPECT_EQ(preparedVolume(worker), loaded.volume.get());
}
