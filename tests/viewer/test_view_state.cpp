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
    viewer::zoom(c, 2.0);
    EXPECT_NEAR(glm::length(c.eye - c.target), 200.0, 1e-9);
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
        {R"({"orbit": [1, 2]})", "script"},           {R"([{"orbit": [1]}])", "[0].orbit"},
        {R"([{"zoom": "in"}])", "[0].zoom"},          {R"([{"view": "Q"}])", "[0].view"},
        {R"([{"orbit": [1, 2], "zoom": 1}])", "[0]"}, {R"([{"zoom": 1}, {"spin": 1}])", "[1].spin"},
        {R"([{"pathtrace": 0.5}])", "[0].pathtrace"}};
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
