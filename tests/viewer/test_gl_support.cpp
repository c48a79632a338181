// SPDX-License-Identifier: MIT
// Which scenes the GLSL ray caster takes (no window needed: the rule reads the pipeline's
// prepared caster inputs), what pipeline::Session::prepare hands it (the CPU image stage's own
// inputs), and the worker's prepare-only requests.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "pipeline/pipeline.h"
#include "viewer/gl_support.h"
#include "viewer/render_worker.h"

using namespace voxlight;
using nlohmann::json;

namespace {
json torsoDoc(const json& method) {
    return {{"volume", {{"phantom", "torso"}, {"size", 32}}},
            {"transfer_function", "ct-bone"},
            {"method", method},
            {"camera", {{"azimuth", 30}, {"elevation", 15}}},
            {"image", {{"width", 64}, {"height", 48}}}};
}
/// The reason for the scene `doc`, from what the pipeline prepares for it.
std::string reasonFor(const json& doc) {
    const io::Scene scene = io::parseScene(doc, "test", "/");
    pipeline::Session session;
    const std::optional<pipeline::CasterSetup> setup = session.prepare(scene);
    return viewer::glUnsupportedReason(scene.method.name, setup ? &*setup : nullptr);
}
}  // namespace

TEST(GlSupport, GradientAndEmissionAbsorptionAreRenderedOnTheGpu) {
    EXPECT_EQ(reasonFor(torsoDoc("gradient")), "");
    EXPECT_EQ(reasonFor(torsoDoc("emission-absorption")), "");
    json withLights = torsoDoc("gradient");
    withLights["lights"] = json::array();
    for (int i = 0; i < viewer::kMaxGlLights; ++i)
        withLights["lights"].push_back({{"type", "point"}, {"position", {0, -300, 10 * i}}});
    withLights["clip_planes"] = {{{"point", {0, 0, 0}}, {"normal", {0, 1, 0}}}};
    EXPECT_EQ(reasonFor(withLights), "");
}

TEST(GlSupport, OtherScenesSayWhyTheCpuDrawsThem) {
    // Methods the shader does not evaluate: SH visibility (a ray-caster method) and the path
    // tracer (prepare() has nothing for it).
    EXPECT_NE(reasonFor(torsoDoc("sh-local")).find("method 'sh-local' is rendered on the CPU"),
              std::string::npos);
    EXPECT_NE(reasonFor(torsoDoc("pathtrace")).find("method 'pathtrace' is rendered on the CPU"),
              std::string::npos);
    EXPECT_NE(reasonFor(torsoDoc("mip")).find("method 'mip'"), std::string::npos);
    json many = torsoDoc("gradient");
    many["lights"] = json::array();
    for (int i = 0; i <= viewer::kMaxGlLights; ++i)
        many["lights"].push_back({{"type", "directional"}, {"direction", {0.1 * i, 1, 0}}});
    EXPECT_NE(reasonFor(many).find("9 lights: the GLSL ray caster holds at most 8"),
              std::string::npos);
    json coarse = torsoDoc({{"name", "gradient"}, {"params", {{"step", 2.0}}}});
    EXPECT_NE(reasonFor(coarse).find("a step over one voxel"), std::string::npos);
    json forward = torsoDoc({{"name", "gradient"}, {"params", {{"central_differences", false}}}});
    EXPECT_NE(reasonFor(forward).find("forward-difference"), std::string::npos);
    EXPECT_THROW(viewer::rendererChoiceFromString("vulkan"), InputError);
    EXPECT_EQ(viewer::rendererChoiceFromString("gpu"), viewer::RendererChoice::Gpu);
}

// prepare() runs the stages before the image stage and hands over what it reads: the fitted
// camera is the one the full run reports, and a ray caster built from the setup renders the
// run's image bit for bit.
TEST(GlSupport, PreparedSetupIsWhatTheImageStageReads) {
    const io::Scene scene = io::parseScene(torsoDoc("gradient"), "test", "/");
    pipeline::Session session;
    const pipeline::RunResult run = session.run(scene);
    const std::optional<pipeline::CasterSetup> setup = session.prepare(scene);
    ASSERT_TRUE(setup);
    EXPECT_EQ(setup->method, "gradient");
    EXPECT_EQ(pipeline::cameraDetails(*setup->camera), run.details["camera"]);
    const render::RayCaster caster(setup->volume, setup->tf, setup->options, setup->tables);
    const core::ImageRGBA image = caster.render(*setup->camera);
    EXPECT_EQ(image.pixels, run.image.pixels);
}

TEST(RenderWorker, PrepareOnlyRequestsReturnTheSetupWithoutPixels) {
    viewer::RenderWorker worker;
    viewer::RenderRequest request{io::parseScene(torsoDoc("gradient"), "test", "/"), 7, false};
    request.prepareOnly = true;
    worker.submit(std::move(request));
    std::optional<viewer::RenderedImage> r;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (!r && std::chrono::steady_clock::now() < end) {
        r = worker.take();
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    ASSERT_TRUE(r);
    EXPECT_TRUE(r->error.empty()) << r->error;
    EXPECT_TRUE(r->prepared);
    EXPECT_EQ(r->generation, 7u);
    EXPECT_TRUE(r->rgba.empty());
    ASSERT_TRUE(r->setup);
    EXPECT_EQ(r->width, 64);
    EXPECT_EQ(r->height, 48);
    EXPECT_TRUE(r->camera.contains("forward"));
}
