// SPDX-License-Identifier: MIT
// Scene → render driver: options from the scene, strict method params, stats JSON.
#include <gtest/gtest.h>

#include "core/phantoms.h"
#include "grid/brick_grid.h"
#include "io/scene.h"
#include "pipeline/pipeline.h"
#include "pipeline/scene_inputs.h"
#include "render/ray_caster.h"

using namespace voxlight;
using nlohmann::json;

namespace {
io::Scene scene(json doc) { return io::parseScene(doc, "test.json", "."); }
json base() {
    return {{"volume", {{"phantom", "sphere"}, {"size", 24}}},
            {"transfer_function", "phantom-step"},
            {"image", {{"width", 16}, {"height", 12}}}};
}
}  // namespace

TEST(SceneRender, RendersAndReportsStagesAndParameters) {
    json d = base();
    d["method"] = {{"name", "gradient"}, {"params", {{"specular", 0.5}}}};
    d["clip_planes"] = json::array({{{"point", {0, 0, 0}}, {"normal", {0, 0, 1}}}});
    const auto r = pipeline::renderScene(scene(d));
    EXPECT_EQ(r.image.width, 16);
    EXPECT_EQ(r.image.height, 12);
    const json s = pipeline::statsJson(r, 1.0);
    ASSERT_TRUE(s["stages"].is_array());
    for (const auto& st : s["stages"]) {
        EXPECT_TRUE(st.contains("name") && st.contains("ran") && st.contains("reason") &&
                    st.contains("seconds"));
    }
    EXPECT_EQ(s["method"]["params"]["specular"], 0.5);
    EXPECT_EQ(s["method"]["params"]["shininess"], 24.0);  // defaults are reported as used
    EXPECT_GT(s["peak_rss_mb"].get<double>(), 0.0);
    EXPECT_EQ(s["total_seconds"], 1.0);
}

TEST(SceneRender, RejectsUnknownParamsUnimplementedMethodsAndUnsupportedLights) {
    json d = base();
    d["method"] = {{"name", "gradient"}, {"params", {{"shinyness", 3}}}};
    try {
        pipeline::Session().plan(scene(d));
        FAIL();
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "method.params.shinyness");
    }
    d = base();
    d["method"] = "radiosity";  // not a method voxlight has
    EXPECT_THROW(pipeline::Session().plan(scene(d)), InputError);
    d = base();
    d["method"] = "no-such-method";
    try {
        pipeline::Session().plan(scene(d));
        FAIL();
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "method.name");
        EXPECT_NE(std::string(e.what()).find("gradient"), std::string::npos) << e.what();
    }
    d = base();
    d["transfer_function"] = "no-such-preset";
    EXPECT_THROW(pipeline::renderScene(scene(d)), InputError);
}

TEST(SceneRender, WindowRemapsPresetsAndSetsMipGrey) {
    json d = base();
    d["volume"] = {{"phantom", "torso"}, {"size", 24}};
    d["transfer_function"] = {{"preset", "ct-bone"}, {"window", {{"level", 600}, {"width", 1000}}}};
    core::PhantomOptions o;
    o.size = 24;
    const core::Volume v = core::makePhantom("torso", o);
    const auto tf = pipeline::buildTransferFunction(scene(d), v);
    EXPECT_FLOAT_EQ(tf.window().level, 600.f);
    EXPECT_FLOAT_EQ(tf.points().back().value, 600.f + (3071.f - 500.f) / 2.f);
}

TEST(SceneRender, DataNearFloatsLimitsTakeAnExplicitWindowAndOtherwiseSaySo) {
    // Values ±3e38: the generic preset's robust range is too wide to window in float. The error
    // used to come even with an explicit window (blaming it); now that window is used as given.
    core::Geometry g;
    g.dims = {8, 8, 8};
    core::Volume v(g, core::VoxelType::Float32);
    for (std::size_t i = 0; i < 512; ++i) v.dataAs<float>()[i] = i % 2 ? 3e38f : -3e38f;
    json d;
    d["volume"] = {{"phantom", "torso"}, {"size", 8}};  // parsed only; v is the volume
    d["transfer_function"] = {{"preset", "generic"}};
    try {
        (void)pipeline::buildTransferFunction(scene(d), v);
        ADD_FAILURE() << "windowed ±3e38";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "transfer_function.window");
    }
    d["transfer_function"]["window"] = {{"level", 0}, {"width", 1}};
    const auto tf = pipeline::buildTransferFunction(scene(d), v);
    EXPECT_FLOAT_EQ(tf.window().width, 1.f);
}

TEST(SceneRender, TerminationThresholdTradesSamplesForAnErrorBelowTheThreshold) {
    // A looser termination stops rays earlier: fewer samples, and each pixel differs from the
    // strict render by at most what the remaining transmittance could still add (≤ threshold
    // times the largest scattered radiance, here ≤ ambient + diffuse + specular = 1.25).
    json d = base();
    d["volume"] = {{"phantom", "torso"}, {"size", 64}};
    d["transfer_function"] = "ct-bone";
    d["image"] = {{"width", 48}, {"height", 48}};
    d["render"] = {{"termination", 0.0}};
    const auto strict = pipeline::renderScene(scene(d));
    d["render"] = {{"termination", 0.02}};
    const auto loose = pipeline::renderScene(scene(d));
    EXPECT_LT(loose.details["counters"]["samples"].get<std::uint64_t>(),
              strict.details["counters"]["samples"].get<std::uint64_t>());
    constexpr float kMaxRadiance = 1.25f;
    float worst = 0.f;
    for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 48; ++x)
            for (int c = 0; c < 4; ++c)
                worst =
                    std::max(worst, std::abs(loose.image.at(x, y)[c] - strict.image.at(x, y)[c]));
    EXPECT_LE(worst, 0.02f * kMaxRadiance + 1e-5f);
    EXPECT_GT(worst, 0.f) << "the loose threshold should change something";
    d["render"] = {{"termination", 0.7}};
    EXPECT_THROW(scene(d), InputError);
    d["render"] = {{"termination", "often"}};
    EXPECT_THROW(scene(d), InputError);
}

TEST(SceneRender, RepeatedFramesReportEveryFrameAndTheSameImage) {
    json d = base();
    const auto once = pipeline::renderScene(scene(d));
    const auto thrice = pipeline::renderScene(scene(d), {.frames = 3});
    ASSERT_TRUE(thrice.details.contains("frame_seconds"));
    EXPECT_EQ(thrice.details["frame_seconds"].size(), 3u);
    EXPECT_FALSE(once.details.contains("frame_seconds"));
    EXPECT_EQ(once.image.pixels, thrice.image.pixels);
    for (const char* counter : {"rays", "samples", "skip_cells_visible"})
        EXPECT_EQ(once.details["counters"][counter], thrice.details["counters"][counter])
            << counter << ": stats are one frame's, not the sum";
    EXPECT_THROW(pipeline::renderScene(scene(d), {.frames = 0}), InputError);
    EXPECT_THROW(pipeline::renderScene(scene(d), {.frames = pipeline::kMaxFrames + 1}), InputError);
}

TEST(SceneRender, UnknownPresetIsRefusedBeforeTheVolumeIsLoaded) {
    json d = base();
    d["transfer_function"] = "ct-lungs";
    d["volume"] = {{"path", "/nonexistent/volume.nii.gz"}};  // never reached
    try {
        (void)pipeline::Session().plan(scene(d));
        FAIL() << "unknown preset accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("transfer_function.preset"), std::string::npos)
            << e.what();
    }
}

TEST(SceneRender, ThePipelineImageIsTheRayCastersOwnBitForBit) {
    // The seam adds no arithmetic: the same volume, TF, camera and default options rendered by a
    // RayCaster built directly (tables built by its own constructor) give the identical film.
    json d = base();
    d["volume"] = {{"phantom", "torso"}, {"size", 32}};
    d["transfer_function"] = "ct-bone";
    d["camera"] = {{"eye", {300, -400, 150}}, {"target", {0, 0, 0}}, {"fov_y", 35}};
    const io::Scene s = scene(d);
    const pipeline::RunResult r = pipeline::renderScene(s);

    core::PhantomOptions o;
    o.size = 32;
    const core::Volume v = core::makePhantom("torso", o);
    const optics::TransferFunction tf = pipeline::buildTransferFunction(s, v);
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    render::RenderOptions opt;  // the gradient method's defaults
    opt.seed = s.render.seed;
    const render::RayCaster caster(v, g, tf, opt);
    const auto b = v.geometry().worldBounds();
    const render::Camera cam(pipeline::buildCameraSpec(s.camera), b[0], b[1], s.image.width,
                             s.image.height);
    const core::ImageRGBA direct = caster.render(cam);
    EXPECT_EQ(r.image.pixels, direct.pixels);
    float coverage = 0.f;
    for (std::size_t i = 3; i < direct.pixels.size(); i += 4) coverage += direct.pixels[i];
    EXPECT_GT(coverage, 10.f) << "the view must show the bones, or the comparison proves little";
}
