// SPDX-License-Identifier: MIT
// The pathtrace method in the pipeline: its plan (what it reuses from the ray caster's stages and
// what it does not need), its params read strictly, multiple scattering as an effect, and what a
// light change reruns.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
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

namespace {
/// Over the pixels `a` covers and R, G, B: Σ(a − b)², Σ b², Σ a and the count of values.
struct Differences {
    double squared = 0.0, reference = 0.0, sum = 0.0;
    std::size_t values = 0, pixels = 0;
};
Differences differences(const core::ImageRGBA& a, const core::ImageRGBA& b) {
    Differences d;
    d.pixels = a.pixels.size() / 4;
    for (std::size_t p = 0; p < d.pixels; ++p) {
        if (!(a.pixels[p * 4 + 3] > 0.f)) continue;
        for (int c = 0; c < 3; ++c) {
            const double x = a.pixels[p * 4 + c], y = b.pixels[p * 4 + c];
            d.squared += (x - y) * (x - y);
            d.reference += y * y;
            d.sum += x;
            ++d.values;
        }
    }
    return d;
}
}  // namespace

TEST(PathTraceMethod, ItsErrorEstimatesPredictTheDifferenceOfTwoIndependentRenders) {
    // Two renders that differ only in seed differ by noise alone: their mean squared difference
    // is twice the variance each predicts. Independent truth for the estimates the target stop
    // and the accuracy sweeps' floor use. A saturated colour under multiple scattering (each
    // bounce multiplies by the albedo again) makes R, G and B differ: an estimate of the
    // luminance's error instead of the RGB error is 1.7× too low here.
    const json orange = {0.95, 0.25, 0.05};
    json d = {
        {"volume", {{"phantom", "sphere"}, {"size", 32}}},
        {"transfer_function",
         {{"points",
           {{{"value", 0.0}, {"color", orange}, {"extinction", 0}},
            {{"value", 0.49}, {"color", orange}, {"extinction", 0}},
            {{"value", 0.51}, {"color", orange}, {"extinction", 0.3}},
            {{"value", 1.0}, {"color", orange}, {"extinction", 0.3}}}},
          {"window", {{"level", 0.5}, {"width", 1.0}}}}},
        {"method", {{"name", "pathtrace"}, {"params", {{"spp", 32}, {"antialias", false}}}}},
        {"lights",
         json::array(
             {{{"type", "directional"}, {"direction", {0.5, 0.6, -0.62}}, {"intensity", 6}}})},
        {"effects", {"global_shadows", "multiple_scattering"}},
        {"image", {{"width", 32}, {"height", 32}}}};
    const RunResult a = Session().run(scene(d));
    d["render"] = {{"seed", 2}};
    const RunResult b = Session().run(scene(d));
    const Differences diff = differences(a.image, b.image);
    ASSERT_GT(diff.values, 300u);
    // The relative error: √(mean variance) / mean value over covered pixels and RGB.
    const double relative = a.details["pathtrace"]["relative_std_error"].get<double>();
    const double measuredRelative =
        std::sqrt(diff.squared / double(diff.values) / 2.0) / (diff.sum / double(diff.values));
    // nrmse's terms: √(Σ variance / Σ mean²).
    const double nrmse = a.details["pathtrace"]["expected_nrmse"].get<double>();
    const double measuredNrmse = std::sqrt(diff.squared / diff.reference / 2.0);
    ASSERT_GT(relative, 0.0);
    ASSERT_GT(nrmse, 0.0);
    // The ratios' own sampling noise over ~1000 values × 32 spp is a few %; 20 % catches a wrong
    // formula (a missing √n, luminance instead of RGB, the mean instead of the RMS) without
    // flaking.
    constexpr double kEstimateTolerance = 0.2;
    EXPECT_NEAR(measuredRelative / relative, 1.0, kEstimateTolerance)
        << "measured " << measuredRelative << ", estimated " << relative;
    EXPECT_NEAR(measuredNrmse / nrmse, 1.0, kEstimateTolerance)
        << "measured " << measuredNrmse << ", estimated " << nrmse;
    // The two estimates differ by the image's own RMS / mean over the covered values.
    double square = 0.0;
    for (std::size_t p = 0; p < a.image.pixels.size() / 4; ++p)
        if (a.image.pixels[p * 4 + 3] > 0.f)
            for (int c = 0; c < 3; ++c)
                square += double(a.image.pixels[p * 4 + c]) * a.image.pixels[p * 4 + c];
    const double rmsOverMean =
        std::sqrt(square / double(diff.values)) / (diff.sum / double(diff.values));
    EXPECT_NEAR(relative / nrmse, rmsOverMean, 1e-4 * rmsOverMean);
}

TEST(PathTraceMethod, StopsAtTheTargetErrorAndSaysWhenItDoesNot) {
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    d["method"]["params"] = {{"spp", 4096}, {"target_error", 0.05}};
    const RunResult r = Session().run(scene(d));
    const json& pt = r.details["pathtrace"];
    EXPECT_TRUE(pt["target_reached"].get<bool>());
    EXPECT_LE(pt["relative_std_error"].get<double>(), 0.05);
    EXPECT_LT(pt["spp"].get<int>(), 4096);
    EXPECT_GE(pt["spp"].get<int>(), 16) << "kMinSamplesForErrorStop";
    EXPECT_TRUE(r.warnings.empty());
    d["method"]["params"] = {{"spp", 4}, {"target_error", 0.001}};
    const RunResult s = Session().run(scene(d));
    EXPECT_FALSE(s.details["pathtrace"]["target_reached"].get<bool>());
    ASSERT_EQ(s.warnings.size(), 1u);
    EXPECT_NE(s.warnings[0].find("method.params.spp"), std::string::npos) << s.warnings[0];
}

TEST(PathTraceMethod, OneSampleHasNoErrorEstimateNotAZeroOne) {
    // At 1 spp the error image held rounding noise (mean 5e-11) that read as "exact", while the
    // stats said null (probe): unknown is NaN, and 2 spp gives finite errors again.
    json d = tracedScene();
    d["method"]["params"] = {{"spp", 1}, {"denoise", false}};
    const RunResult one = Session().run(scene(d));
    const json& e = one.details["pathtrace"]["relative_std_error"];
    EXPECT_TRUE(e.is_null() || std::isnan(e.get<double>())) << e;  // null in the stats file
    for (std::size_t i = 0; i < one.images.at("std_error").pixels.size(); i += 4)
        ASSERT_TRUE(std::isnan(one.images.at("std_error").pixels[i])) << i;
    d["method"]["params"]["spp"] = 2;
    const RunResult two = Session().run(scene(d));
    for (float v : two.images.at("std_error").pixels) ASSERT_TRUE(std::isfinite(v));
}

TEST(PathTraceMethod, ReferenceModeIsACachedStageThatKeepsItsStatsAndErrorImage) {
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    d["method"]["params"] = {{"reference", true}, {"target_error", 0.05}};
    Session session;
    const RunResult a = session.run(scene(d));
    EXPECT_TRUE(a.stage("reference").ran);
    EXPECT_EQ(a.params["antialias"], false) << "references sample pixel centres, as the methods do";
    ASSERT_EQ(a.images.count("std_error"), 1u);
    EXPECT_EQ(a.images.at("std_error").width, 16);
    const RunResult b = session.run(scene(d));
    EXPECT_FALSE(b.stage("reference").ran);
    EXPECT_EQ(b.stage("reference").reason.rfind("cached", 0), 0u) << b.stage("reference").reason;
    EXPECT_EQ(b.details["pathtrace"], a.details["pathtrace"]);
    EXPECT_EQ(b.image.pixels, a.image.pixels);
    EXPECT_EQ(b.images.at("std_error").pixels, a.images.at("std_error").pixels);
}

// A sweep measures path-traced variants against the reference of the same scene and seed: had
// they drawn the same random numbers, a variant's error would shrink by the samples it shares.
TEST(PathTraceMethod, AReferenceDrawsOtherRandomNumbersThanARenderOfTheSameSeed) {
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    d["method"]["params"] = {{"reference", true}, {"spp", 8}};
    const RunResult ref = Session().run(scene(d));
    // The same samples as the reference would take: no jitter, no adaptivity, the same count.
    d["method"]["params"] = {{"spp", 8}, {"antialias", false}, {"adaptive", false}};
    const RunResult plain = Session().run(scene(d));
    // Independent estimates differ by about √2 times their standard error: per pixel where the
    // error is non-zero, the squared difference over the summed variances averages 1; shared
    // samples give 0. Bound at a quarter (256 pixels: far from either).
    constexpr double kIndependentRatio = 0.25;
    double ratio = 0.0;
    int n = 0;
    const auto& ea = ref.images.at("std_error").pixels;
    const auto& eb = plain.images.at("std_error").pixels;
    for (std::size_t i = 0; i < ref.image.pixels.size(); i += 4) {
        const double var = double(ea[i]) * ea[i] + double(eb[i]) * eb[i];
        if (!(var > 0.0)) continue;
        const double diff = double(ref.image.pixels[i]) - plain.image.pixels[i];
        ratio += diff * diff / var;
        ++n;
    }
    ASSERT_GT(n, 16) << "the scene must have noisy pixels";
    EXPECT_GT(ratio / n, kIndependentRatio);
}

TEST(PathTraceMethod, AReferenceSurvivesTheDiskCacheBitForBit) {
    const auto dir = std::filesystem::temp_directory_path() / "voxlight-test-reference-cache";
    std::filesystem::remove_all(dir);
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    d["method"]["params"] = {{"reference", true}, {"spp", 8}};
    RunResult a, b;
    {
        Session s;
        s.cache().setDirectory(dir);
        a = s.run(scene(d));
    }
    {
        Session s;
        s.cache().setDirectory(dir);
        b = s.run(scene(d));
    }
    EXPECT_EQ(b.stage("reference").reason.find("(disk)") != std::string::npos, true)
        << b.stage("reference").reason;
    EXPECT_EQ(b.image.pixels, a.image.pixels);
    EXPECT_EQ(b.images.at("std_error").pixels, a.images.at("std_error").pixels);
    EXPECT_EQ(b.details["pathtrace"], a.details["pathtrace"]);
    EXPECT_EQ(b.warnings, a.warnings) << "the not-reached warning comes back from the disk too";
    std::filesystem::remove_all(dir);
}

TEST(PathTraceMethod, DepthOfFieldFromTheSceneWithAutofocusAndAWarningElsewhere) {
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    d["camera"] = {{"aperture", 20.0}};
    const RunResult r = Session().run(scene(d));
    EXPECT_EQ(r.details["camera"]["aperture_mm"], 20.0);
    EXPECT_TRUE(r.details["camera"]["autofocus"].get<bool>());
    EXPECT_GT(r.details["camera"]["focus_distance_mm"].get<double>(), 0.0);
    d["camera"]["focus_distance"] = 300.0;
    const RunResult f = Session().run(scene(d));
    EXPECT_EQ(f.details["camera"]["focus_distance_mm"], 300.0);
    EXPECT_FALSE(f.details["camera"]["autofocus"].get<bool>());
    d["method"] = {{"name", "gradient"}};
    d.erase("effects");
    // The path tracer's light (12: its phase function divides by 4π) washes the gradient image
    // out, which is said too; at 1 only the lens is.
    d["lights"][0]["intensity"] = 1.0;
    const RunResult g = Session().run(scene(d));
    ASSERT_EQ(g.warnings.size(), 1u);
    EXPECT_NE(g.warnings[0].find("camera.aperture"), std::string::npos) << g.warnings[0];
    d["camera"]["focus_distance"] = "near";
    try {
        (void)scene(d);
        FAIL() << "focus_distance must be a distance or \"auto\"";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "camera.focus_distance");
    }
    d["camera"]["focus_distance"] = "auto";
    EXPECT_FALSE(scene(d).camera.focusMm.has_value());
}

TEST(PathTraceMethod, DenoisesTheDisplayImageOnlyAndNeverAReference) {
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    // Default ("auto"): a denoised display image beside the raw estimate, said in the details.
    const RunResult a = Session().run(scene(d));
    ASSERT_EQ(a.images.count("denoised"), 1u);
    EXPECT_EQ(a.details["denoise"]["applied"], true);
    EXPECT_GT(a.details["denoise"]["mean_strength"].get<double>(), 0.0) << "4 spp is noisy";
    EXPECT_EQ(a.params["denoise"], "auto");
    EXPECT_NE(a.images.at("denoised").pixels, a.image.pixels);
    // Off: the same raw image and error image, nothing denoised.
    d["method"]["params"]["denoise"] = false;
    const RunResult off = Session().run(scene(d));
    EXPECT_EQ(off.images.count("denoised"), 0u);
    EXPECT_EQ(off.details["denoise"]["applied"], false);
    EXPECT_EQ(off.image.pixels, a.image.pixels) << "the main image stays the raw estimate";
    EXPECT_EQ(off.images.at("std_error").pixels, a.images.at("std_error").pixels);
    // Reference mode: never denoised (its image is a plain trace of its own random stream:
    // AReferenceDrawsOtherRandomNumbersThanARenderOfTheSameSeed).
    d["method"]["params"] = {{"reference", true}, {"spp", 8}};
    const RunResult ref = Session().run(scene(d));
    EXPECT_EQ(ref.images.count("denoised"), 0u);
    EXPECT_EQ(ref.details["denoise"]["applied"], false);
    EXPECT_FALSE(ref.params.contains("denoise")) << "the reference's cache key is unchanged";
    d["method"]["params"] = {
        {"spp", 8}, {"antialias", false}, {"adaptive", false}, {"target_error", 0.01}};
    const RunResult plain = Session().run(scene(d));
    EXPECT_EQ(plain.images.count("denoised"), 1u);
    // Wrong values and types, and denoise asked of a reference: one error naming the field.
    for (const json& params :
         {json{{"denoise", "yes"}}, json{{"denoise", 1}},
          json{{"reference", true}, {"denoise", true}},
          json{{"denoise", false}, {"denoise_target", 0.02}}, json{{"denoise_target", "0.02"}}}) {
        d["method"]["params"] = params;
        try {
            Session().plan(scene(d));
            FAIL() << params.dump();
        } catch (const InputError& e) {
            EXPECT_EQ(e.field().rfind("method.params.denoise", 0), 0u) << e.what();
        }
    }
}

TEST(PathTraceMethod, SamplesAdaptivelyUnlessAReference) {
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    d["method"]["params"] = {{"spp", 24}};
    const RunResult a = Session().run(scene(d));
    EXPECT_EQ(a.details["pathtrace"]["adaptive"], true);
    EXPECT_GT(a.details["pathtrace"]["pixel_spp_max"].get<int>(), 24);
    d["method"]["params"]["adaptive"] = false;
    const RunResult u = Session().run(scene(d));
    EXPECT_EQ(u.details["pathtrace"]["adaptive"], false);
    EXPECT_EQ(u.details["pathtrace"]["pixel_spp_max"], 24);
    EXPECT_EQ(u.details["pathtrace"]["pixel_spp_min"], 24);
    d["method"]["params"] = {{"reference", true}, {"spp", 24}};
    EXPECT_EQ(Session().run(scene(d)).details["pathtrace"]["adaptive"], false);
    for (const json& params :
         {json{{"reference", true}, {"adaptive", true}}, json{{"adaptive", "yes"}}}) {
        d["method"]["params"] = params;
        try {
            Session().plan(scene(d));
            FAIL() << params.dump();
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), "method.params.adaptive") << e.what();
        }
    }
}

TEST(PathTraceMethod, ScatteringAndGradientFactorAreReadStrictly) {
    json d = tracedScene();
    // Default: the phase function, no surface events.
    EXPECT_EQ(Session().run(scene(d)).details["pathtrace"]["surface_events"], 0);
    d["method"]["params"]["scattering"] = "hybrid";
    d["method"]["params"]["gradient_factor"] = 1.0;
    const RunResult r = Session().run(scene(d));
    EXPECT_GT(r.details["pathtrace"]["surface_events"].get<double>(), 0.0);
    for (float v : r.image.pixels) ASSERT_TRUE(std::isfinite(v) && v >= 0.f);
    auto field = [&](const json& params) {
        json e = tracedScene();
        e["method"]["params"] = params;
        try {
            Session().plan(scene(e));
        } catch (const InputError& err) {
            return err.field();
        }
        return std::string("accepted");
    };
    EXPECT_EQ(field({{"scattering", "surface"}}), "method.params.scattering");
    EXPECT_EQ(field({{"scattering", 1}}), "method.params.scattering");
    EXPECT_EQ(field({{"gradient_factor", 0.5}}), "method.params.gradient_factor");  // phase
    EXPECT_EQ(field({{"scattering", "brdf"}, {"gradient_factor", 0.5}}),
              "method.params.gradient_factor");
    EXPECT_EQ(field({{"scattering", "hybrid"}, {"gradient_factor", 1.5}}),
              "method.params.gradient_factor");
    EXPECT_EQ(field({{"scattering", "hybrid"}, {"gradient_factor", 0.0}}), "accepted");
}

TEST(PathTraceMethod, AnEmptyImageSaysWhyAsTheCastersMethodsDo) {
    // It said nothing: a black image from a camera looking away, or a TF that shows nothing.
    json d = tracedScene();
    d["effects"] = {"global_shadows"};
    EXPECT_TRUE(Session().run(scene(d)).warnings.empty());
    d["camera"] = {{"target", {1e6, 0, 0}}};
    const RunResult away = Session().run(scene(d));
    ASSERT_EQ(away.warnings.size(), 1u);
    EXPECT_NE(away.warnings[0].find("no camera ray meets"), std::string::npos) << away.warnings[0];
    d.erase("camera");
    d["transfer_function"] = {{"preset", "ct-bone"}, {"extinction_scale", 0}};
    const RunResult clear = Session().run(scene(d));
    ASSERT_EQ(clear.warnings.size(), 1u);
    EXPECT_NE(clear.warnings[0].find("is transparent"), std::string::npos) << clear.warnings[0];
}
