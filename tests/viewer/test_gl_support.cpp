// SPDX-License-Identifier: MIT
// Which scenes the GLSL ray caster takes (no window needed: the rule reads the pipeline's
// prepared caster inputs), what pipeline::Session::prepare hands it (the CPU image stage's own
// inputs), and the worker's prepare-only requests.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "pipeline/pipeline.h"
#include "render/sh_field_grid.h"
#include "render/sh_shading.h"
#include "viewer/gl_support.h"
#include "viewer/render_worker.h"
#include "viewer/sh_grids.h"

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

TEST(GlSupport, ShVisibilityMethodsAreRenderedOnTheGpu) {
    EXPECT_EQ(reasonFor(torsoDoc("sh-local")), "");
    EXPECT_EQ(reasonFor(torsoDoc("sh-global")), "");
    EXPECT_EQ(reasonFor(torsoDoc("ritschel")), "");
    EXPECT_EQ(reasonFor(torsoDoc({{"name", "sh-local"}, {"params", {{"near_shadow", true}}}})), "");
    EXPECT_EQ(reasonFor(torsoDoc({{"name", "sh-global"}, {"params", {{"near_shadow", true}}}})),
              "");
    // Directional and environment lights are summed on the CPU: any number of them (without the
    // near shadow, which traces each directional light on its own).
    json many = torsoDoc({{"name", "sh-global"}, {"params", {{"near_shadow", false}}}});
    many["lights"] = json::array();
    for (int i = 0; i <= viewer::kMaxGlLights; ++i)
        many["lights"].push_back({{"type", "directional"}, {"direction", {0.1 * i, 1, 0}}});
    for (int i = 0; i < viewer::kMaxGlShPointLights; ++i)
        many["lights"].push_back({{"type", "point"}, {"position", {0, -300, 10 * i}}});
    EXPECT_EQ(reasonFor(many), "");
}

TEST(GlSupport, OtherScenesSayWhyTheCpuDrawsThem) {
    // Methods the shader does not evaluate: MIP (a ray-caster method) and the path tracer
    // (prepare() has nothing for it).
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
    // The near shadow (sh-local, sh-global) traces each directional light on its own: at most 8.
    for (const char* method : {"sh-local", "sh-global"}) {
        json near = torsoDoc({{"name", method}, {"params", {{"near_shadow", true}}}});
        near["lights"] = json::array();
        for (int i = 0; i <= viewer::kMaxGlLights; ++i)
            near["lights"].push_back({{"type", "directional"}, {"direction", {0.1 * i, 1, 0}}});
        EXPECT_NE(reasonFor(near).find("9 directional and environment lights with near_shadow"),
                  std::string::npos)
            << method;
    }
    json shPoints = torsoDoc("sh-local");
    shPoints["lights"] = json::array();
    for (int i = 0; i <= viewer::kMaxGlShPointLights; ++i)
        shPoints["lights"].push_back({{"type", "point"}, {"position", {0, -300, 10 * i}}});
    EXPECT_NE(reasonFor(shPoints).find("9 point lights: the GLSL SH shading holds at most 8"),
              std::string::npos);
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

// The SH methods' setup carries the very fields their image stage shades from: a model built
// from them renders the run's image bit for bit (sh-global with a plane that removes matter for
// the light: the global field, the clip-aware local one and the cut faces' band).
TEST(GlSupport, PreparedShFieldsAreWhatTheImageStageShadesFrom) {
    for (const char* method : {"sh-local", "sh-global", "ritschel"}) {
        SCOPED_TRACE(method);
        json doc = torsoDoc({{"name", method}, {"params", {{"rays", 8}}}});
        doc["clip_planes"] = {
            {{"point", {0, 0, 0}}, {"normal", {0, 1, 0}}, {"shadows_from_removed", false}}};
        const io::Scene scene = io::parseScene(doc, "test", "/");
        pipeline::Session session;
        const pipeline::RunResult run = session.run(scene);
        const std::optional<pipeline::CasterSetup> setup = session.prepare(scene);
        ASSERT_TRUE(setup);
        const pipeline::CasterSetup::ShFields& f = setup->sh;
        const render::RayCaster caster(setup->volume, setup->tf, setup->options, setup->tables);
        std::unique_ptr<render::ShadingModel> model;
        if (std::string(method) == "ritschel") {
            ASSERT_TRUE(f.hierarchical);
            model = render::makeShVisibilityModel(caster, *setup->camera, f.hierarchical);
        } else if (std::string(method) == "sh-local") {
            ASSERT_TRUE(f.local);
            EXPECT_FALSE(f.global);
            model = render::makeShVisibilityModel(caster, *setup->camera, f.local);
        } else {
            ASSERT_TRUE(f.global && f.local);
            EXPECT_GT(f.cutBandMm, 0.f);
            model = render::makeShVisibilityModel(caster, *setup->camera, f.global, f.local,
                                                  f.cutBandMm);
        }
        EXPECT_EQ(caster.render(*setup->camera, *model).pixels, run.image.pixels);
    }
}

// The resampled grid holds the field's own value at each grid point (within half precision), at
// one point per voxel within the budget and fewer beyond it; the cache resamples a field once.
TEST(ShGrids, ResampledFieldHoldsTheFieldAtItsPointsAndIsMadeOncePerField) {
    const io::Scene scene =
        io::parseScene(torsoDoc({{"name", "sh-global"}, {"params", {{"rays", 8}}}}), "test", "/");
    pipeline::Session session;
    const std::optional<pipeline::CasterSetup> setup = session.prepare(scene);
    ASSERT_TRUE(setup && setup->sh.global && setup->sh.local);
    const glm::ivec3 dims = setup->volume->dims();
    const render::ShFieldGrid grid = render::resampleShField(*setup->sh.global, dims);
    EXPECT_EQ(grid.res, (dims - 1) * render::kShFieldGridOversample + 1);
    EXPECT_EQ(grid.step, glm::vec3(1.f / float(render::kShFieldGridOversample)));
    EXPECT_EQ(grid.coefficients, 4);
    ASSERT_EQ(grid.textures(), 1);
    // Half floats: 11 significant bits, |V_i| ≤ √(4π) ≈ 3.54.
    constexpr float kHalfTol = 3.6f / 2048.f;
    float v[16];
    for (const glm::ivec3 g : {glm::ivec3(0), dims, grid.res - 1, glm::ivec3(3, 17, 9)}) {
        setup->sh.global->sample(grid.position(g), v);
        for (int i = 0; i < 4; ++i) EXPECT_NEAR(grid.at(g, i), v[i], kHalfTol) << g.x << g.y << g.z;
    }
    // One point per voxel within its budget; half of that: fewer points, still spanning the
    // voxel centres from the first to the last.
    const std::size_t full = std::size_t(dims.x) * dims.y * dims.z * 4 * 2;
    EXPECT_EQ(render::resampleShField(*setup->sh.global, dims, full).res, dims);
    // Two points per voxel only where every side fits a GPU's 3D textures.
    EXPECT_EQ(render::shFieldGridResolution({1100, 8, 8}, 4), glm::ivec3(2199, 15, 15));
    EXPECT_EQ(render::shFieldGridResolution({1100, 8, 8}, 4, render::kShFieldGridBudgetBytes,
                                            viewer::ShGridCache::kMaxTextureSide),
              glm::ivec3(1100, 8, 8));
    const render::ShFieldGrid half = render::resampleShField(*setup->sh.global, dims, full / 2);
    // The budget counts the coefficients; the local field's spacing (sh-global's near shadow
    // reads it) comes on top, 2 bytes per point.
    ASSERT_EQ(half.spacing.size(), std::size_t(half.res.x) * half.res.y * half.res.z);
    EXPECT_LE(half.bytes() - half.spacing.size() * sizeof(std::uint16_t), full / 2);
    EXPECT_LT(half.res.x, dims.x);
    EXPECT_FLOAT_EQ(half.position(half.res - 1).x, float(dims.x - 1));
    const glm::ivec3 g(1, 2, 3);
    setup->sh.global->sample(half.position(g), v);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(half.at(g, i), v[i], kHalfTol);

    viewer::ShGridCache cache;
    const viewer::ShGrids a = cache.get(*setup);
    ASSERT_TRUE(a.field && a.local);
    EXPECT_EQ(cache.resampled(), 2u);
    // A camera change: the same fields, nothing resampled.
    json moved = torsoDoc({{"name", "sh-global"}, {"params", {{"rays", 8}}}});
    moved["camera"]["azimuth"] = 100;
    const std::optional<pipeline::CasterSetup> again =
        session.prepare(io::parseScene(moved, "test", "/"));
    ASSERT_TRUE(again);
    const viewer::ShGrids b = cache.get(*again);
    EXPECT_EQ(b.field, a.field);
    EXPECT_EQ(cache.resampled(), 2u);
    // Switching to sh-local: its field is sh-global's local one, resampled already.
    const std::optional<pipeline::CasterSetup> local = session.prepare(
        io::parseScene(torsoDoc({{"name", "sh-local"}, {"params", {{"rays", 8}}}}), "test", "/"));
    ASSERT_TRUE(local);
    EXPECT_EQ(cache.get(*local).field, a.local);
    EXPECT_EQ(cache.resampled(), 2u);
}

TEST(ShGrids, ACancelledResamplingResumesAndFinishesUnderRepeatedCancels) {
    // The viewer's worker cancels a resampling when a newer state arrives (up to seconds per
    // field on a 256³ volume). A camera drag cancels every attempt, and the fields stay the same:
    // each attempt must keep what it filled (at least one chunk) and the next resume there, so
    // the grid is finished after at most ⌈res.z / chunk⌉ attempts, never cached half-made, and
    // equal to an uninterrupted resampling.
    const io::Scene scene =
        io::parseScene(torsoDoc({{"name", "sh-local"}, {"params", {{"rays", 8}}}}), "test", "/");
    pipeline::Session session;
    const std::optional<pipeline::CasterSetup> setup = session.prepare(scene);
    ASSERT_TRUE(setup && setup->sh.local);
    std::atomic<bool> cancel{true};
    std::vector<double> reported;
    const core::Progress cancelled([&](const std::string&, double f) { reported.push_back(f); },
                                   &cancel);
    const render::ShFieldGrid whole = render::resampleShField(
        *setup->sh.local, setup->volume->dims(), render::kShFieldGridBudgetBytes,
        viewer::ShGridCache::kMaxTextureSide);
    const int most =
        (whole.res.z + render::kShFieldResampleChunk - 1) / render::kShFieldResampleChunk;
    ASSERT_GT(most, 2) << "the test needs several chunks";
    viewer::ShGridCache cache;
    int attempts = 0;
    viewer::ShGrids g;
    for (; attempts < most + 1 && !g.field; ++attempts) {
        try {
            g = cache.get(*setup, cancelled);
        } catch (const CancelledError&) {
            EXPECT_EQ(cache.resampled(), 0u);  // nothing half-made is cached
        }
    }
    ASSERT_TRUE(g.field) << "still cancelled after " << attempts << " attempts";
    EXPECT_EQ(attempts, most);  // one chunk per attempt, the last one finishing
    EXPECT_EQ(cache.resampled(), 1u);
    EXPECT_EQ(g.field->texels, whole.texels);  // the same grid as an uninterrupted resampling
    EXPECT_EQ(cache.get(*setup, cancelled).field, g.field);  // kept: nothing to cancel
    // Uncancelled, it reports its progress from 0 to 1.
    cancel = false;
    viewer::ShGridCache fresh;
    ASSERT_TRUE(fresh.get(*setup, cancelled).field);
    ASSERT_GE(reported.size(), 2u);
    EXPECT_EQ(reported.front(), 0.0);
    EXPECT_EQ(reported.back(), 1.0);
}
