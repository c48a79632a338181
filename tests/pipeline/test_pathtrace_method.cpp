// SPDX-License-Identifier: MIT
// The pathtrace method in the pipeline: its plan (what it reuses from the ray caster's stages and
// what it does not need), its params read strictly, multiple scattering as an effect, and what a
// light change reruns.
#include <gtest/gtest.h>

#include <set>

#include "pipeline/pipeline.h"
#include "pipeline/scene_inputs.h"

using namespace voxlight;
using namespace voxlight::pipeline;
using nlohmann::json;

namespace {
io::Scene scene(const json& doc) { return io::parseScene(doc, "test.json", "."); }

json tracedScene() {
    return {
        {"volume", {{"phantom", "torso"}, {"size", 32}}},
        {"transfer_function", "ct-bone"},
        {"method", {{"name", "pathtrace"}, {"params", {{"spp", 4}}}}},
        {"lights",
         json::array({{{"type", "directional"}, {"direction", {0, 1, -0.3}}, {"intensity", 12}}})},
        {"image", {{"width", 16}, {"height", 16}}}};
}

std::set<std::string> ranStages(const RunResult& r) {
    std::set<std::string> s;
    for (const auto& st : r.stages)
        if (st.ran) s.insert(st.name);
    return s;
}
}  // namespace

TEST(PathTraceMethod, PlansTheCastersVolumeStagesAndSaysWhatItDoesNotNeed) {
    Session session;
    const RunResult r = session.run(scene(tracedScene()));
    EXPECT_EQ(r.details["pathtrace"]["spp"], 4);
    EXPECT_EQ(r.details["pathtrace"]["majorant_violations"], 0);
    EXPECT_EQ(r.details["pathtrace"]["max_bounces"], 16) << "multiple scattering by default";
    EXPECT_EQ(r.stage("gradients").reason.rfind("not needed", 0), 0u);
    EXPECT_EQ(r.stage("light_sh").reason,
              "not needed: the path tracer samples environment maps directly");
    for (float v : r.image.pixels) ASSERT_TRUE(std::isfinite(v));
    // Moving the light reruns no precompute stage.
    json d = tracedScene();
    d["lights"][0]["direction"] = {1, 0, -0.3};
    EXPECT_EQ(ranStages(session.run(scene(d))),
              (std::set<std::string>{"lights", "camera", "render"}));
}

TEST(PathTraceMethod, SingleScatteringUnlessTheSceneAsksForMultiple) {
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    EXPECT_EQ(Session().run(scene(d)).details["pathtrace"]["max_bounces"], 1);
    d["method"]["params"]["max_bounces"] = 4;
    try {
        Session().plan(scene(d));
        FAIL() << "max_bounces > 1 without multiple_scattering must be refused";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "method.params.max_bounces");
    }
    d["method"]["params"] = {{"sp", 4}};
    try {
        Session().plan(scene(d));
        FAIL();
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "method.params.sp");
        EXPECT_NE(std::string(e.what()).find("spp"), std::string::npos) << e.what();
    }
}
