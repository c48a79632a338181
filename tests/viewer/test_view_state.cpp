// SPDX-License-Identifier: MIT
// The viewer's camera and TF edits (view_state.h), checked through the renderer: continuing from a
// rendered camera as an explicit look-at camera must not move the picture.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "pipeline/pipeline.h"
#include "viewer/loaded_scene.h"
#include "viewer/render_worker.h"
#include "viewer/view_state.h"

using namespace voxlight;
using nlohmann::json;

namespace {
json torsoDoc(int size, int image) {
    return {{"volume", {{"phantom", "torso"}, {"size", size}}},
            {"transfer_function", "ct-bone"},
            {"method", "gradient"},
            {"camera", {{"azimuth", 30}, {"elevation", 15}}},
            {"image", {{"width", image}, {"height", image}}}};
}
/// Largest per-channel difference of two display images, in 8-bit levels.
int maxLevelDiff(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
    int d = 0;
    for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, std::abs(int(a[i]) - int(b[i])));
    return d;
}
}  // namespace

TEST(ViewState, ALookAtCameraFromTheRenderedOneShowsTheSamePicture) {
    const io::Scene fitted = io::parseScene(torsoDoc(48, 96), "test", "/");
    pipeline::Session session;
    const pipeline::RunResult a = session.run(fitted);
    ASSERT_TRUE(a.details.contains("camera"));
    // Any pivot: it only places the target (the orbit centre) along the same view axis.
    const viewer::LookAt c = viewer::lookAtFromRendered(a.details["camera"], glm::dvec3(5.0));
    json doc = torsoDoc(48, 96);
    doc["camera"] = viewer::cameraJson(c, doc["camera"]);
    const pipeline::RunResult b = session.run(io::parseScene(doc, "test", "/"));
    // Same rays up to the round trip of eye/forward through the target (1e-12 mm): the display
    // images may differ by one level where a sample falls on a TF breakpoint.
    constexpr int kSameRaysLevels = 1;
    EXPECT_LE(
        maxLevelDiff(viewer::displayBytes(fitted, a.image), viewer::displayBytes(fitted, b.image)),
        kSameRaysLevels);
}

TEST(ViewState, OrbitTurnsAboutTheTargetAndKeepsTheDistance) {
    viewer::LookAt c;
    c.target = {10.0, 20.0, 30.0};
    c.eye = c.target + glm::dvec3(0.0, -500.0, 0.0);  // anterior view
    c.up = {0.0, 0.0, 1.0};
    viewer::orbit(c, 90.0, 0.0);
    // Yaw +90° about superior takes the eye from anterior (−y) to the patient's left (+x in
    // LPS), as camera azimuth +90° does.
    EXPECT_NEAR(c.eye.x - c.target.x, 500.0, 1e-9);
    EXPECT_NEAR(c.eye.y - c.target.y, 0.0, 1e-9);
    EXPECT_NEAR(glm::length(c.eye - c.target), 500.0, 1e-9);
    // Pitch stops 1° short of the pole; up stays orthogonal to the view.
    viewer::orbit(c, 0.0, 120.0);
    const glm::dvec3 f = glm::normalize(c.target - c.eye);
    EXPECT_NEAR(std::asin((c.eye - c.target).z / 500.0) * 180.0 / M_PI, 89.0, 1e-6);
    EXPECT_NEAR(glm::dot(f, c.up), 0.0, 1e-12);
    EXPECT_NEAR(glm::length(c.eye - c.target), 500.0, 1e-9);
}

TEST(ViewState, PanMovesEyeAndTargetTogetherAndZoomKeepsTheTarget) {
    viewer::LookAt c;
    c.target = {0.0, 0.0, 0.0};
    c.eye = {0.0, -400.0, 0.0};
    c.fovYDeg = 30.0;
    const glm::dvec3 before = c.eye - c.target;
    viewer::pan(c, 100.0, 0.0, 400);
    EXPECT_EQ(c.eye - c.target, before);
    // 100 of 400 pixels = a quarter of the view height at the target, 2·400·tan 15°.
    EXPECT_NEAR(std::abs(c.target.x), 0.25 * 2.0 * 400.0 * std::tan(M_PI / 12.0), 1e-9);
    EXPECT_TRUE(viewer::zoom(c, 2.0));
    EXPECT_NEAR(glm::length(c.eye - c.target), 200.0, 1e-9);
}

TEST(ViewState, AZoomPastWhatASceneRendersLeavesTheViewAsItWas) {
    // Orthographic: a factor of ∞ (1.1^100000) made the height 0 — "fit" to the scene, the whole
    // volume again — and 1.1^1000 a height of 1e-40 mm (one flat colour); a factor of 0 was
    // dropped silently while a smaller zoom-out was refused by the scene.
    viewer::LookAt o;
    o.perspective = false;
    o.eye = {0.0, -400.0, 0.0};
    o.orthoHeight = 200.0;
    for (const double factor : {std::pow(1.1, 100000.0), std::pow(1.1, 1000.0), 0.0,
                                std::pow(1.1, -1e9), 1e6, 1e-5, std::nan("")}) {
        EXPECT_FALSE(viewer::zoom(o, factor)) << factor;
        EXPECT_EQ(o.orthoHeight, 200.0) << factor;
    }
    EXPECT_TRUE(viewer::zoom(o, 1e5));  // 2 µm: still a view
    EXPECT_NEAR(o.orthoHeight, 2e-3, 1e-15);
    viewer::LookAt p;
    p.eye = {0.0, -400.0, 0.0};
    for (const double factor : {std::pow(1.1, 300.0), 1e-4, std::pow(1.1, 1e6)}) {
        EXPECT_FALSE(viewer::zoom(p, factor)) << factor;
        EXPECT_EQ(p.eye, glm::dvec3(0.0, -400.0, 0.0)) << factor;
    }
    // Every accepted view is one the scene takes.
    json doc = torsoDoc(32, 32);
    doc["camera"] = viewer::cameraJson(o, json());
    EXPECT_NO_THROW(io::parseScene(doc, "test", "/"));
    doc["camera"]["ortho_height"] = 1e-40;
    EXPECT_THROW(io::parseScene(doc, "test", "/"), InputError);
}

TEST(ViewState, WindowDragAndTfJsonRoundTrip) {
    const optics::Window w = viewer::dragWindow({100.f, 400.f}, 200.0, 400.0);
    EXPECT_FLOAT_EQ(w.width, 800.f);  // 200 px right doubles the width
    EXPECT_FLOAT_EQ(w.level, 500.f);  // 400 px down raises the level by one (starting) width
    // The editor's TF written as scene JSON reads back as the same points.
    json doc = torsoDoc(32, 32);
    const optics::TransferFunction tf(
        {{-100.f, {1.f, 0.5f, 0.25f}, 0.f}, {300.f, {1.f, 1.f, 1.f}, 0.05f}}, {100.f, 400.f});
    doc["transfer_function"] = viewer::transferFunctionJson(tf);
    const io::Scene s = io::parseScene(doc, "test", "/");
    ASSERT_EQ(s.transferFunction.points.size(), 2u);
    EXPECT_DOUBLE_EQ(s.transferFunction.points[1].extinction, double(0.05f));
    EXPECT_DOUBLE_EQ(s.transferFunction.points[0].color.g, 0.5);
    ASSERT_TRUE(s.transferFunction.window.has_value());
    EXPECT_DOUBLE_EQ(s.transferFunction.window->y, 400.0);
}

TEST(ViewState, CoarseSceneIsAQuarterOfTheSizeWithALongerStep) {
    const io::Scene full = io::parseScene(torsoDoc(32, 512), "test", "/");
    const io::Scene coarse = viewer::coarseScene(full, 4, 2.0, 0.01);
    EXPECT_EQ(coarse.image.width, 128);
    EXPECT_EQ(coarse.image.height, 128);
    EXPECT_DOUBLE_EQ(coarse.render.stepVoxels, 2.0 * full.render.stepVoxels);
    EXPECT_DOUBLE_EQ(coarse.render.termination, 0.01);
}

TEST(LoadedScene, SummaryHistogramAndTheScenesTfForTheVolume) {
    const io::Scene s = io::parseScene(torsoDoc(40, 32), "test", "/");
    const viewer::LoadedScene l = viewer::prepareScene(s, core::Progress::none());
    EXPECT_EQ(l.summary.dims, glm::ivec3(40));
    EXPECT_EQ(l.summary.orientation, "LPS");
    EXPECT_LT(l.summary.range[0], l.summary.range[1]);
    // A small volume is binned whole: every voxel once.
    std::uint64_t sum = 0;
    for (auto c : l.histogram.counts) sum += c;
    EXPECT_EQ(sum, l.volume->voxelCount());
    EXPECT_EQ(l.histogram.total, l.volume->voxelCount());
    const std::vector<float> bins = l.histogram.logNormalized();
    EXPECT_FLOAT_EQ(*std::max_element(bins.begin(), bins.end()), 1.f);
    // The editor starts from the TF the renderer uses (the preset, fitted to this volume).
    EXPECT_EQ(l.tf.name(), "ct-bone");
    EXPECT_EQ(l.document["transfer_function"]["preset"], "ct-bone");
}

TEST(LoadedScene, AVolumeWithoutATfGetsTheModalityPresetByName) {
    json doc = torsoDoc(24, 32);
    doc.erase("transfer_function");
    const viewer::LoadedScene l =
        viewer::prepareScene(io::parseScene(doc, "test", "/"), core::Progress::none());
    // Named in the document, so that edits start from a scene that parses again.
    ASSERT_TRUE(l.document["transfer_function"].contains("preset"));
    EXPECT_EQ(l.document["transfer_function"]["preset"].get<std::string>(), l.tf.name());
}

TEST(LoadedScene, AFileThatFailsToLoadIsAnInputErrorNamingIt) {
    json doc = torsoDoc(24, 32);
    doc["volume"] = "/nonexistent/ct.nii.gz";
    try {
        viewer::prepareScene(io::parseScene(doc, "test", "/"), core::Progress::none());
        FAIL() << "loaded a volume that does not exist";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent/ct.nii.gz"), std::string::npos)
            << e.what();
    }
}

TEST(ViewScript, StepsParseAndBadStepsNameTheirIndexAndKey) {
    const auto steps =
        viewer::parseScript(json::parse(R"([{"orbit": [40, -5]}, {"pan": [1, 2]}, {"zoom": -1.5},
                        {"window": [3, 4]}, {"view": "L"}, {"view": "superior"},
                        {"pathtrace": 32}])"),
                            "steps.json");
    ASSERT_EQ(steps.size(), 7u);
    EXPECT_EQ(steps[6].kind, viewer::ScriptStep::Kind::PathTrace);
    EXPECT_EQ(steps[6].a, 32.0);
    EXPECT_EQ(steps[0].kind, viewer::ScriptStep::Kind::Orbit);
    EXPECT_EQ(steps[0].b, -5.0);
    EXPECT_EQ(steps[2].a, -1.5);
    EXPECT_EQ(steps[4].view, "left");
    EXPECT_EQ(steps[5].view, "superior");
    const std::vector<std::pair<const char*, const char*>> bad = {
        {R"({"orbit": [1, 2]})", "script"},
        {R"([{"orbit": [1]}])", "[0].orbit"},
        {R"([{"zoom": "in"}])", "[0].zoom"},
        {R"([{"view": "Q"}])", "[0].view"},
        {R"([{"orbit": [1, 2], "zoom": 1}])", "[0]"},
        {R"([{"zoom": 1}, {"spin": 1}])", "[1].spin"},
        {R"([{"pathtrace": 0.5}])", "[0].pathtrace"},
        {R"([{"drop": []}])", "[0].drop"},
        {R"([{"drop": "ct.mha"}])", "[0].drop"},
        {R"([{"drop": ["a.mha", ""]}])", "[0].drop"},
        {R"([{"drop": [3]}])", "[0].drop"}};
    const auto drop =
        viewer::parseScript(json::parse(R"([{"drop": ["a.mha", "b dir/c.nii"]}])"), "steps.json");
    ASSERT_EQ(drop.size(), 1u);
    EXPECT_EQ(drop[0].kind, viewer::ScriptStep::Kind::Drop);
    EXPECT_EQ(drop[0].paths, (std::vector<std::string>{"a.mha", "b dir/c.nii"}));
    for (const auto& [text, field] : bad) {
        try {
            viewer::parseScript(json::parse(text), "steps.json");
            ADD_FAILURE() << text;
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), field) << text;
            EXPECT_EQ(e.source(), "steps.json");
        }
    }
}

// The local/global switch keeps the shared params (the same local field) and sh-global's own
// ones for the way back; other methods are left alone.
TEST(ViewState, ShVisibilitySwitchKeepsTheLocalFieldsParams) {
    json doc = {{"method",
                 {{"name", "sh-global"},
                  {"params", {{"rays", 64}, {"coefficients", 9}, {"global_resolution", 32}}}}}};
    json stash;
    EXPECT_FALSE(viewer::switchShVisibility(doc, true, stash));  // already global
    ASSERT_TRUE(viewer::switchShVisibility(doc, false, stash));
    EXPECT_EQ(doc["method"]["name"], "sh-local");
    EXPECT_EQ(doc["method"]["params"], json({{"rays", 64}, {"coefficients", 9}}));
    ASSERT_TRUE(viewer::switchShVisibility(doc, true, stash));
    EXPECT_EQ(doc["method"]["name"], "sh-global");
    EXPECT_EQ(doc["method"]["params"]["global_resolution"], 32);
    json gradient = {{"method", {{"name", "gradient"}, {"params", json::object()}}}};
    EXPECT_FALSE(viewer::switchShVisibility(gradient, false, stash));
    EXPECT_EQ(gradient["method"]["name"], "gradient");
    const auto steps = viewer::parseScript(json::parse(R"([{"shading": "local"}])"), "s.json");
    ASSERT_EQ(steps.size(), 1u);
    EXPECT_EQ(steps[0].kind, viewer::ScriptStep::Kind::Shading);
    EXPECT_EQ(steps[0].view, "local");
    EXPECT_THROW(viewer::parseScript(json::parse(R"([{"shading": "far"}])"), "s.json"), InputError);
}

// An effects list follows the switch (sh-local refuses global_shadows, sh-global needs it), and
// the path tracer's "render this view" takes any method's list as it can.
TEST(ViewState, EffectsFollowTheShSwitchAndThePathTracersView) {
    json doc = {{"method", "sh-local"}, {"effects", {"local_shadows"}}};
    json stash;
    ASSERT_TRUE(viewer::switchShVisibility(doc, true, stash));
    EXPECT_EQ(doc["effects"], json({"local_shadows", "global_shadows"}));
    ASSERT_TRUE(viewer::switchShVisibility(doc, false, stash));
    EXPECT_EQ(doc["effects"], json({"local_shadows"}));
    json none = {{"method", "sh-local"}};
    ASSERT_TRUE(viewer::switchShVisibility(none, true, stash));
    EXPECT_FALSE(none.contains("effects")) << "no list: the methods' defaults";
    EXPECT_EQ(viewer::pathTraceEffects(json({"specular"})), json::array());
    EXPECT_EQ(viewer::pathTraceEffects(json({"local_shadows"})), json({"global_shadows"}));
    EXPECT_EQ(
        viewer::pathTraceEffects(json({"multiple_scattering", "local_shadows", "global_shadows"})),
        json({"multiple_scattering", "global_shadows"}));
    EXPECT_TRUE(viewer::pathTraceEffects(json()).is_null());
}

TEST(ViewScript, ClipPlaneAndLightStepsParse) {
    const auto steps = viewer::parseScript(json::parse(R"([
        {"clip_add": {"normal": [0, 2, 0], "offset": -5, "shadows_from_removed": true}},
        {"clip_add": {"normal": "camera"}},
        {"clip_move": {"index": 1, "by": 7.5}},
        {"clip_drag": {"index": 0, "by": [3, -40], "frames": 20}},
        {"clip_edit": {"index": 0, "flip": true, "enabled": false}},
        {"clip_remove": 1},
        {"light_add": {"type": "point", "azimuth": 10, "elevation": -20, "distance": 300,
                       "color": [1, 0.9, 0.8], "intensity": 5}},
        {"light_edit": {"index": 0, "position": [1, 2, 3]}},
        {"light_turn": {"index": 0, "azimuth": 30}},
        {"light_remove": 0}, {"gizmo": false}])"),
                                           "steps.json");
    using Kind = viewer::ScriptStep::Kind;
    ASSERT_EQ(steps.size(), 11u);
    EXPECT_EQ(steps[0].kind, Kind::ClipAdd);
    EXPECT_EQ(steps[0].vec, glm::dvec3(0, 2, 0));
    EXPECT_EQ(steps[0].a, -5.0);
    EXPECT_EQ(steps[0].shadowsFromRemoved, true);
    EXPECT_TRUE(steps[1].facingCamera);
    EXPECT_FALSE(steps[1].shadowsFromRemoved.has_value());
    EXPECT_EQ(steps[2].index, 1);
    EXPECT_EQ(steps[2].a, 7.5);
    EXPECT_EQ(steps[3].kind, Kind::ClipDrag);
    EXPECT_EQ(steps[3].b, -40.0);
    EXPECT_EQ(steps[3].frames, 20);
    EXPECT_TRUE(steps[4].flip);
    EXPECT_EQ(steps[4].enabled, false);
    EXPECT_EQ(steps[5].kind, Kind::ClipRemove);
    EXPECT_EQ(steps[5].index, 1);
    EXPECT_EQ(steps[6].lightType, "point");
    EXPECT_EQ(steps[6].distance, 300.0);
    EXPECT_EQ(steps[6].color, glm::dvec3(1, 0.9, 0.8));
    EXPECT_EQ(steps[7].position, glm::dvec3(1, 2, 3));
    EXPECT_EQ(steps[8].kind, Kind::LightTurn);
    EXPECT_EQ(steps[8].a, 30.0);
    EXPECT_EQ(steps[8].b, 0.0);
    EXPECT_EQ(steps[9].kind, Kind::LightRemove);
    EXPECT_EQ(steps[10].kind, Kind::Gizmo);
    EXPECT_EQ(steps[10].a, 0.0);
    EXPECT_EQ(steps[3].field, "[3].clip_drag");
}

TEST(ViewScript, DragStepsParse) {
    const auto steps = viewer::parseScript(json::parse(R"([
        {"drag": {"kind": "window", "by": [30, -20], "frames": 40}},
        {"drag": {"kind": "orbit", "by": [5, 0]}}])"),
                                           "steps.json");
    using Kind = viewer::ScriptStep::Kind;
    ASSERT_EQ(steps.size(), 2u);
    EXPECT_EQ(steps[0].kind, Kind::Drag);
    EXPECT_EQ(steps[0].dragMotion, Kind::Window);
    EXPECT_EQ(steps[0].a, 30.0);
    EXPECT_EQ(steps[0].b, -20.0);
    EXPECT_EQ(steps[0].frames, 40);
    EXPECT_EQ(steps[1].dragMotion, Kind::Orbit);
    EXPECT_EQ(steps[1].frames, 1);
    for (const auto& [text, field] : std::vector<std::pair<const char*, const char*>>{
             {R"([{"drag": {"by": [1, 2]}}])", "[0].drag"},
             {R"([{"drag": {"kind": "zoom", "by": [1, 2]}}])", "[0].drag.kind"},
             {R"([{"drag": {"kind": "pan", "by": [1]}}])", "[0].drag.by"},
             {R"([{"drag": {"kind": "pan", "by": [1, 2], "frames": 0}}])", "[0].drag.frames"}}) {
        try {
            viewer::parseScript(json::parse(text), "steps.json");
            ADD_FAILURE() << text;
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), field) << text << ": " << e.what();
        }
    }
}

TEST(ViewScript, BadClipPlaneAndLightStepsNameTheField) {
    const std::vector<std::pair<const char*, const char*>> bad = {
        {R"([{"clip_add": {}}])", "[0].clip_add"},
        {R"([{"clip_add": {"normal": [0, 0, 0]}}])", "[0].clip_add.normal"},
        {R"([{"clip_add": {"normal": "viewer"}}])", "[0].clip_add.normal"},
        {R"([{"clip_add": {"normal": [0, 1]}}])", "[0].clip_add.normal"},
        {R"([{"clip_add": {"normal": [0, 0, 1], "ofset": 3}}])", "[0].clip_add.ofset"},
        {R"([{"clip_add": {"normal": [0, 0, 1], "shadows_from_removed": 1}}])",
         "[0].clip_add.shadows_from_removed"},
        {R"([{"clip_add": [0, 0, 1]}])", "[0].clip_add"},
        {R"([{"clip_move": {"index": 0}}])", "[0].clip_move"},
        {R"([{"clip_move": {"index": -1, "by": 2}}])", "[0].clip_move.index"},
        {R"([{"clip_move": {"index": 0.5, "by": 2}}])", "[0].clip_move.index"},
        {R"([{"clip_move": {"index": 0, "by": "far"}}])", "[0].clip_move.by"},
        {R"([{"clip_drag": {"index": 0, "by": 5}}])", "[0].clip_drag.by"},
        {R"([{"clip_drag": {"index": 0, "by": [0, 5], "frames": 0}}])", "[0].clip_drag.frames"},
        {R"([{"clip_edit": {"index": 0}}])", "[0].clip_edit"},
        {R"([{"clip_edit": {"index": 0, "flip": false}}])", "[0].clip_edit.flip"},
        {R"([{"clip_edit": {"index": 0, "enabled": "no"}}])", "[0].clip_edit.enabled"},
        {R"([{"clip_remove": "0"}])", "[0].clip_remove"},
        {R"([{"light_add": {"azimuth": 3}}])", "[0].light_add"},
        {R"([{"light_add": {"type": "area"}}])", "[0].light_add.type"},
        {R"([{"light_add": {"type": "environment"}}])", "[0].light_add.path"},
        {R"([{"light_add": {"type": "directional", "distance": 3}}])", "[0].light_add.distance"},
        {R"([{"light_add": {"type": "point", "distance": 0}}])", "[0].light_add.distance"},
        {R"([{"light_add": {"type": "directional", "elevation": 95}}])", "[0].light_add.elevation"},
        {R"([{"light_add": {"type": "directional", "color": [1, -1, 1]}}])", "[0].light_add.color"},
        {R"([{"light_add": {"type": "directional", "intensity": -2}}])", "[0].light_add.intensity"},
        {R"([{"light_edit": {"index": 0}}])", "[0].light_edit"},
        {R"([{"light_edit": {"index": 0, "direction": [0, 0, 1]}}])", "[0].light_edit.direction"},
        {R"([{"light_turn": {"index": 0}}])", "[0].light_turn"},
        {R"([{"light_turn": {"index": 0, "azimuth": null}}])", "[0].light_turn.azimuth"},
        {R"([{"gizmo": "off"}])", "[0].gizmo"},
        {R"([{"clip": {"add": [0, 0, 1]}}])", "[0].clip"}};
    for (const auto& [text, field] : bad) {
        try {
            viewer::parseScript(json::parse(text), "steps.json");
            ADD_FAILURE() << text;
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), field) << text << ": " << e.what();
            EXPECT_EQ(e.source(), "steps.json");
        }
    }
}

TEST(ViewState, LightAnglesFollowTheCameraConventionAndRoundTrip) {
    // Azimuth 0 is anterior (−y), 90 the patient's left (+x), elevation 90 superior (+z).
    EXPECT_NEAR(glm::length(viewer::towardLight(0, 0) - glm::dvec3(0, -1, 0)), 0.0, 1e-12);
    EXPECT_NEAR(glm::length(viewer::towardLight(90, 0) - glm::dvec3(1, 0, 0)), 0.0, 1e-12);
    EXPECT_NEAR(glm::length(viewer::towardLight(0, 90) - glm::dvec3(0, 0, 1)), 0.0, 1e-12);
    for (double az : {-170.0, -45.0, 0.0, 30.0, 135.0, 180.0})
        for (double el : {-80.0, -10.0, 0.0, 45.0, 89.0}) {
            const glm::dvec2 a = viewer::lightAngles(viewer::towardLight(az, el));
            EXPECT_NEAR(a.x, az, 1e-9) << az << " " << el;
            EXPECT_NEAR(a.y, el, 1e-9) << az << " " << el;
        }
    // A directional light travels away from where it comes from; a point light keeps its
    // distance from the pivot; turning adds to the angles.
    const glm::dvec3 pivot(10, 20, 30);
    io::LightDesc d = viewer::newLight("directional", pivot, 100, "", "t", "f");
    viewer::setLightAngles(d, {60, 20}, pivot);
    EXPECT_NEAR(glm::length(d.direction + viewer::towardLight(60, 20)), 0.0, 1e-12);
    viewer::turnLight(d, 30, -10, pivot);
    EXPECT_NEAR(viewer::lightAnglesOf(d, pivot).x, 90.0, 1e-9);
    EXPECT_NEAR(viewer::lightAnglesOf(d, pivot).y, 10.0, 1e-9);
    io::LightDesc p = viewer::newLight("point", pivot, 250, "", "t", "f");
    EXPECT_NEAR(glm::length(p.position - pivot), 250.0, 1e-9);
    EXPECT_NEAR(p.intensity, 250.0 * 250.0, 1e-9);  // irradiance 1 at the pivot
    viewer::turnLight(p, -100, 200, pivot);         // elevation stops 1° short of the pole
    EXPECT_NEAR(glm::length(p.position - pivot), 250.0, 1e-9);
    EXPECT_NEAR(viewer::lightAnglesOf(p, pivot).y, 89.0, 1e-9);
    EXPECT_THROW(viewer::newLight("environment", pivot, 1, "", "t", "f"), InputError);
    try {
        viewer::newLight("environment", pivot, 1, "/nonexistent/sky.hdr", "steps.json", "[0].x");
        ADD_FAILURE() << "a missing environment map was accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "[0].x.path");
    }
    // The lights list parses back as the same lights.
    json doc = torsoDoc(24, 32);
    doc["lights"] = viewer::lightsJson({d, p});
    const io::Scene s = io::parseScene(doc, "test", "/");
    ASSERT_EQ(s.lights.size(), 2u);
    EXPECT_NEAR(glm::length(s.lights[0].direction - d.direction), 0.0, 1e-12);
    EXPECT_NEAR(glm::length(s.lights[1].position - p.position), 0.0, 1e-9);
}

TEST(ViewState, ClipPlanesMoveFlipAndOutlineTheBox) {
    const glm::dvec3 centre(0.0);
    io::ClipPlaneDesc p = viewer::clipPlaneThrough({0, 0, 2}, centre, 5.0, "t", "f");
    EXPECT_EQ(p.normal, glm::dvec3(0, 0, 1));
    EXPECT_EQ(p.point, glm::dvec3(0, 0, 5));
    viewer::moveClipPlane(p, -3.0);
    EXPECT_EQ(p.point, glm::dvec3(0, 0, 2));
    viewer::flipClipPlane(p);
    EXPECT_EQ(p.normal, glm::dvec3(0, 0, -1));
    EXPECT_EQ(p.point, glm::dvec3(0, 0, 2));
    EXPECT_THROW(viewer::clipPlaneThrough({0, 0, 0}, centre, 0, "t", "f"), InputError);
    // Disabled planes are not in the scene.
    const json planes = viewer::clipPlanesJson({{p, true}, {p, false}});
    ASSERT_EQ(planes.size(), 1u);
    EXPECT_EQ(planes[0]["normal"][2], -1.0);
    // A box of voxel centres [-10, 10]³: an axial plane cuts it in a square, an oblique one
    // through the centre perpendicular to a diagonal in a regular hexagon.
    core::Geometry g;
    g.dims = {21, 21, 21};
    g.origin = glm::dvec3(-10.0);
    const std::vector<glm::dvec3> square = viewer::clipOutline(p, g);
    ASSERT_EQ(square.size(), 4u);
    for (const glm::dvec3& q : square) {
        EXPECT_NEAR(q.z, 2.0, 1e-12);
        EXPECT_NEAR(std::abs(q.x), 10.0, 1e-12);
        EXPECT_NEAR(std::abs(q.y), 10.0, 1e-12);
    }
    for (std::size_t i = 0; i < 4; ++i)  // in order around it: neighbours share a side
        EXPECT_NEAR(glm::length(square[i] - square[(i + 1) % 4]), 20.0, 1e-12);
    const io::ClipPlaneDesc diagonal = viewer::clipPlaneThrough({1, 1, 1}, centre, 0, "t", "f");
    const std::vector<glm::dvec3> hexagon = viewer::clipOutline(diagonal, g);
    ASSERT_EQ(hexagon.size(), 6u);
    for (std::size_t i = 0; i < 6; ++i)
        EXPECT_NEAR(glm::length(hexagon[i] - hexagon[(i + 1) % 6]), 10.0 * std::sqrt(2.0), 1e-9);
    EXPECT_TRUE(
        viewer::clipOutline(viewer::clipPlaneThrough({1, 0, 0}, centre, 11, "t", "f"), g).empty());
}

TEST(ViewState, AGizmoDragMovesThePlaneAsFarAsItsHandleFollowsTheCursor) {
    viewer::LookAt c;
    c.eye = {200.0, -300.0, 80.0};
    c.target = {0.0, 0.0, 0.0};
    const render::Camera cam = viewer::projectionCamera(c, 320, 240);
    // An oblique plane through the target: dragging 25 pixels along the image direction of its
    // normal moves its handle's image 25 pixels (the image map is smooth: small drags are
    // almost linear).
    const io::ClipPlaneDesc p = viewer::clipPlaneThrough({1, 0.3, 0.2}, c.target, 0, "t", "f");
    double x0, y0, x1, y1;
    ASSERT_TRUE(cam.project(p.point, x0, y0));
    ASSERT_TRUE(cam.project(p.point + 1.0 * p.normal, x1, y1));
    const glm::dvec2 u = glm::normalize(glm::dvec2(x1 - x0, y1 - y0));
    const double mm = viewer::clipDragMm(p, p.point, cam, 25 * u.x, 25 * u.y);
    EXPECT_GT(mm, 0.0);
    double x2, y2;
    ASSERT_TRUE(cam.project(p.point + mm * p.normal, x2, y2));
    constexpr double kLinearTolPixels = 0.5;  // perspective: the 20-pixel probe is not exact
    EXPECT_NEAR(std::hypot(x2 - x0, y2 - y0), 25.0, kLinearTolPixels);
    // Across the normal's image direction nothing moves.
    EXPECT_NEAR(viewer::clipDragMm(p, p.point, cam, -25 * u.y, 25 * u.x), 0.0, 1e-9);
    // A plane facing the camera: dragging up moves it away from the eye.
    const io::ClipPlaneDesc facing = viewer::clipPlaneThrough(cam.forward(), c.target, 0, "t", "f");
    EXPECT_GT(viewer::clipDragMm(facing, facing.point, cam, 0, -10), 0.0);
    EXPECT_LT(viewer::clipDragMm(facing, facing.point, cam, 0, 10), 0.0);
}
