// SPDX-License-Identifier: MIT
// shadows_from_removed in the pipeline: a section-view plane (true), or moving one, reruns no
// visibility stage; a plane that removes matter for the light (false) reruns only the clip-aware
// stages, keeps the unclipped local visibility cached and reports what the update cost.
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "pipeline/pipeline.h"

using namespace voxlight;
using namespace voxlight::pipeline;
using nlohmann::json;

namespace {

io::Scene scene(const json& doc) { return io::parseScene(doc, "test.json", "."); }

json shScene(const std::string& method) {
    return {{"volume", {{"phantom", "torso"}, {"size", 48}}},
            {"transfer_function", "ct-bone"},
            {"method",
             {{"name", method},
              {"params",
               {{"rays", 16}, {"radius", 4}, {"data_reduction", 2}, {"global_resolution", 16}}}}},
            {"lights",
             json::array({{{"type", "point"}, {"position", {0, -400, 0}}, {"intensity", 2e6}}})},
            {"image", {{"width", 24}, {"height", 20}}}};
}

/// A plane facing +y (keeps the posterior half), so the anterior light shines onto its cut face.
json plane(double y, bool shadows) {
    return {{"point", {0, y, 0}}, {"normal", {0, 1, 0}}, {"shadows_from_removed", shadows}};
}

std::set<std::string> ranStages(const RunResult& r) {
    std::set<std::string> s;
    for (const auto& st : r.stages)
        if (st.ran) s.insert(st.name);
    return s;
}

const std::set<std::string> kVisibility = {"block_pyramid", "multires_grid", "local_visibility",
                                           "clip_local_visibility", "global_visibility"};

std::set<std::string> visibilityRan(const RunResult& r) {
    std::set<std::string> s;
    for (const auto& n : ranStages(r))
        if (kVisibility.count(n)) s.insert(n);
    return s;
}

}  // namespace

TEST(ClipShadowsPipeline, SectionViewPlanesRerunNoVisibilityStage) {
    Session session;
    json d = shScene("sh-global");
    const RunResult base = session.run(scene(d));
    EXPECT_EQ(base.stage("clip_local_visibility").reason.rfind("not needed", 0), 0u);
    d["clip_planes"] = json::array({plane(0.0, true)});
    const RunResult cut = session.run(scene(d));
    EXPECT_TRUE(visibilityRan(cut).empty());
    EXPECT_EQ(cut.stage("clip_local_visibility").reason.rfind("not needed", 0), 0u);
    EXPECT_NE(cut.image.pixels, base.image.pixels);
    d["clip_planes"][0]["point"] = {0, 8, 0};  // moving it
    const RunResult moved = session.run(scene(d));
    EXPECT_TRUE(visibilityRan(moved).empty());
    EXPECT_EQ(ranStages(moved), (std::set<std::string>{"framing", "camera", "render"}));
    d["crop_box"] = {
        {"min", {-200, -200, -200}}, {"max", {200, 200, 30}}, {"shadows_from_removed", true}};
    EXPECT_TRUE(visibilityRan(session.run(scene(d))).empty());
}

TEST(ClipShadowsPipeline, RemovingPlanesRerunOnlyTheClipAwareStagesAndReportTheirCost) {
    Session session;
    json d = shScene("sh-global");
    d["clip_planes"] = json::array({plane(0.0, true)});
    const RunResult section = session.run(scene(d));
    // The same plane removing matter for the light: only the clip-aware stages run (the framing
    // depends on the cut's geometry alone; camera and render are frame stages).
    d["clip_planes"][0]["shadows_from_removed"] = false;
    const RunResult gone = session.run(scene(d));
    EXPECT_EQ(ranStages(gone), (std::set<std::string>{"clip_local_visibility", "global_visibility",
                                                      "camera", "render"}));
    EXPECT_NE(gone.image.pixels, section.image.pixels);
    const json& cost = gone.details.at("clip_local_visibility");
    EXPECT_GT(cost["points_traced"].get<std::uint64_t>(), 0u);
    EXPECT_LT(
        cost["points_traced"].get<std::uint64_t>() + cost["points_cleared"].get<std::uint64_t>(),
        cost["points"].get<std::uint64_t>());
    EXPECT_LT(cost["blocks_touched"].get<std::size_t>(), cost["blocks"].get<std::size_t>());
    EXPECT_GE(cost["seconds"].get<double>(), 0.0);
    // Moving it: the unclipped field stays cached.
    d["clip_planes"][0]["point"] = {0, 8, 0};
    EXPECT_EQ(visibilityRan(session.run(scene(d))),
              (std::set<std::string>{"clip_local_visibility", "global_visibility"}));
    // Adding a section-view plane beside it changes neither visibility key.
    d["clip_planes"].push_back(
        {{"point", {0, 0, 20}}, {"normal", {0, 0, -1}}, {"shadows_from_removed", true}});
    EXPECT_TRUE(visibilityRan(session.run(scene(d))).empty());
    // Back to the first position: every visibility artifact is a cache hit.
    d["clip_planes"] = json::array({plane(0.0, false)});
    EXPECT_TRUE(visibilityRan(session.run(scene(d))).empty());
    // A light change runs no visibility stage with a removing plane either.
    d["lights"][0]["position"] = {100, -400, 0};
    EXPECT_TRUE(visibilityRan(session.run(scene(d))).empty());
}

TEST(ClipShadowsPipeline, ShLocalPlansTheClipAwareStageButNoGlobalOne) {
    Session session;
    json d = shScene("sh-local");
    d["method"]["params"].erase("global_resolution");
    d["clip_planes"] = json::array({plane(0.0, false)});
    const RunResult r = session.run(scene(d));
    EXPECT_TRUE(r.stage("clip_local_visibility").ran);
    for (const auto& st : r.stages) EXPECT_NE(st.name, "global_visibility");
    for (float v : r.image.pixels) ASSERT_TRUE(std::isfinite(v) && v >= 0.f);
    d["clip_planes"][0]["shadows_from_removed"] = true;
    EXPECT_TRUE(visibilityRan(session.run(scene(d))).empty());
}

TEST(ClipShadowsPipeline, RitschelSaysItShadesEveryPlaneAsASectionView) {
    // Its field is not clip-aware: a plane asking for false must not pass silently.
    json d = shScene("ritschel");
    d["method"]["params"] = {{"rays", 16}, {"subsample", 4}};
    d["clip_planes"] = json::array({plane(0.0, false)});
    const RunResult r = Session().run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("section view"), std::string::npos) << r.warnings[0];
    d["clip_planes"] = json::array({plane(0.0, true)});
    EXPECT_TRUE(Session().run(scene(d)).warnings.empty());
}
