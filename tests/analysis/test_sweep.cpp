// SPDX-License-Identifier: MIT
// voxlight sweep's engine (analysis/sweep.h): parsing and its errors, expansion of the axes, the
// errors of variants against the path-traced reference (zero for the reference itself, falling
// with samples for the path tracer), the cost a variant is charged, the CSV. The CLI's own test
// (exit codes, files written) is Cli.Sweep* in tests/app/test_cli.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include "analysis/sweep.h"
#include "core/error.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::analysis;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

/// A 32³ torso under a directional light, 32² pixels: every method renders it in well under a
/// second; the reference traces 256 samples per pixel of single scattering.
json tinyScene() {
    return json::parse(R"({
      "volume": {"phantom": "torso", "size": 32},
      "transfer_function": "ct-bone",
      "camera": {"view": "anterior"},
      "lights": [{"type": "directional", "direction": [0.45, 0.55, -0.7], "intensity": 8}],
      "image": {"width": 32, "height": 32}
    })");
}

json tinySweep(const json& runs) {
    return {{"name", "tiny"},
            {"scene", tinyScene()},
            {"reference", {{"params", {{"spp", 256}}}, {"effects", {"global_shadows"}}}},
            {"runs", runs}};
}

SweepSpec parse(const json& doc) { return parseSweep(doc, "sweep.json", "."); }

/// The InputError's field for `doc`, or "" when it parses.
std::string errorField(const json& doc) {
    try {
        const SweepSpec spec = parse(doc);
        pipeline::Session session;
        validateSweep(spec, expandSweep(spec), session);
    } catch (const InputError& e) {
        EXPECT_EQ(e.source(), "sweep.json");
        return e.field();
    }
    return "";
}

std::size_t columns(const std::string& line) {
    std::size_t n = 1;
    bool quoted = false;
    for (char c : line) {
        if (c == '"') quoted = !quoted;
        if (c == ',' && !quoted) ++n;
    }
    return n;
}

}  // namespace

TEST(Sweep, BadSweepsNameTheirKey) {
    const json good = tinySweep(json::parse(R"([{"method": "gradient"}])"));
    EXPECT_EQ(errorField(good), "");
    struct Case {
        std::string what;
        std::function<void(json&)> edit;
        std::string field;
    };
    const std::vector<Case> cases = {
        {"no runs", [](json& d) { d.erase("runs"); }, "runs"},
        {"empty runs", [](json& d) { d["runs"] = json::array(); }, "runs"},
        {"unknown key", [](json& d) { d["run"] = 1; }, "run"},
        {"no scene", [](json& d) { d.erase("scene"); }, "scene"},
        {"scene a number", [](json& d) { d["scene"] = 3; }, "scene"},
        {"missing scene file", [](json& d) { d["scene"] = "no-such-scene.json"; }, "scene"},
        {"frames 0", [](json& d) { d["frames"] = 0; }, "frames"},
        {"frames a string", [](json& d) { d["frames"] = "3"; }, "frames"},
        {"run not an object", [](json& d) { d["runs"][0] = "gradient"; }, "runs[0]"},
        {"method missing", [](json& d) { d["runs"][0].erase("method"); }, "runs[0].method"},
        {"unknown run key", [](json& d) { d["runs"][0]["param"] = json::object(); },
         "runs[0].param"},
        {"axes not an object", [](json& d) { d["runs"][0]["axes"] = json::array(); },
         "runs[0].axes"},
        {"axis not a list",
         [](json& d) {
             d["runs"][0]["axes"] = {{"rays", 16}};
         },
         "runs[0].axes.rays"},
        {"empty axis",
         [](json& d) {
             d["runs"][0]["axes"] = {{"rays", json::array()}};
         },
         "runs[0].axes.rays"},
        // A value given twice rendered twice: two rows of one variant (32 and 32.0 are one value).
        {"axis value twice",
         [](json& d) {
             d["runs"][0]["axes"] = {{"rays", {16, 32, 32.0}}};
         },
         "runs[0].axes.rays[2]"},
        {"bad combine", [](json& d) { d["runs"][0]["combine"] = "all"; }, "runs[0].combine"},
        {"same label twice",
         [](json& d) {
             d["runs"].push_back({{"method", "gradient"}});
         },
         "runs[1].label"},
        // --only splits its list at commas: such a label could never be chosen.
        {"label with a comma", [](json& d) { d["runs"][0]["label"] = "rays,16"; }, "runs[0].label"},
        {"effects not strings", [](json& d) { d["runs"][0]["effects"] = {1}; },
         "runs[0].effects[0]"},
        {"reference params not an object", [](json& d) { d["reference"]["params"] = 1; },
         "reference.params"},
        // An ordinary render as the reference was accepted without a word (probe).
        {"reference mode off",
         [](json& d) {
             d["reference"]["params"] = {{"reference", false}};
         },
         "reference.params.reference"},
        {"bad override", [](json& d) { d["overrides"] = {"image.width"}; }, "overrides"},
        // A scene error is the scene's or its override's, not the first reference's parsed.
        {"override with a bad value", [](json& d) { d["overrides"] = {"image.width=abc"}; },
         "overrides: image.width=abc: image.width"},
        {"unknown scene key", [](json& d) { d["scene"]["bogus"] = 1; }, "scene: bogus"},
        // Checked by planning every variant: the method's strict params and the scene.
        {"unknown method", [](json& d) { d["runs"][0]["method"] = "raytrace"; },
         "runs[0] (raytrace): method.name"},
        {"unknown param on an axis",
         [](json& d) {
             d["runs"][0] = {{"method", "sh-local"}, {"axes", {{"rayz", {16}}}}};
         },
         "runs[0].axes.rayz=16: method.params.rayz"},
        {"param value out of range",
         [](json& d) {
             d["runs"][0] = {{"method", "sh-local"}, {"axes", {{"coefficients", {4, 5}}}}};
         },
         "runs[0].axes.coefficients=5: method.params.coefficients"},
        {"bad reference param",
         [](json& d) {
             d["reference"]["params"] = {{"spp", -1}};
         },
         "reference: method.params.spp"},
    };
    for (const Case& c : cases) {
        json d = good;
        c.edit(d);
        const std::string field = errorField(d);
        // The plan's own field may be more specific; it begins with the expected key.
        EXPECT_EQ(field.substr(0, c.field.size()), c.field) << c.what << ": got '" << field << "'";
    }
}

TEST(Sweep, OneAtATimeVariesEachAxisFromTheBaseAndGridTakesEveryCombination) {
    const SweepSpec spec = parse(tinySweep(json::parse(R"([
        {"method": "sh-local", "params": {"rays": 32, "coefficients": 4},
         "axes": {"rays": [16, 64], "coefficients": [1, 9, 16]}},
        {"method": "ritschel", "label": "ritschel-grid", "combine": "grid",
         "axes": {"subsample": [1, 2, 4], "coefficients": [4, 16]}},
        {"method": "gradient"}
    ])")));
    const std::vector<SweepItem> items = expandSweep(spec);
    ASSERT_EQ(items.size(), 1u + 2u + 3u + 3u * 2u + 1u);
    EXPECT_EQ(items[0].id, "sh-local-base");
    EXPECT_EQ(items[0].params, json({{"rays", 32}, {"coefficients", 4}}));
    std::set<std::string> ids;
    std::set<json> gridParams;
    for (std::size_t i = 0; i < items.size(); ++i) {
        EXPECT_EQ(items[i].index, i);
        EXPECT_TRUE(ids.insert(items[i].id).second) << items[i].id;
        if (items[i].label == "sh-local" && !items[i].axis.empty()) {
            // Only the varied axis differs from the base.
            json expected = items[0].params;
            expected[items[i].axis] = items[i].value;
            EXPECT_EQ(items[i].params, expected) << items[i].id;
        }
        if (items[i].label == "ritschel-grid") gridParams.insert(items[i].params);
    }
    EXPECT_EQ(gridParams.size(), 6u);  // every combination, each once
    EXPECT_EQ(items.back().id, "gradient");
    EXPECT_TRUE(items.back().params.empty());
}

TEST(Sweep, AReferenceThatMissesItsTargetErrorCarriesTheWarning) {
    // Every row is measured against it: a reference stopped at its spp cap above its target
    // error said only "estimated error 12 %" (probe); the render's warning is the sweep's too.
    json d = tinySweep(json::parse(R"([{"method": "gradient"}])"));
    d["reference"]["params"] = {{"reference", true}, {"target_error", 0.001}, {"spp", 4}};
    const SweepSpec spec = parse(d);
    pipeline::Session variants, references;
    SweepRunner runner(spec, variants, references);
    const SweepReference& ref = runner.reference();
    ASSERT_EQ(ref.warnings.size(), 1u);
    EXPECT_NE(ref.warnings[0].find("target_error"), std::string::npos) << ref.warnings[0];
}

TEST(Sweep, TheReferenceAgainstItselfHasNoErrorAndOtherMethodsSome) {
    const SweepSpec spec = parse(tinySweep(json::parse(R"([
        {"method": "pathtrace", "label": "same", "params": {"spp": 256},
         "effects": ["global_shadows"]},
        {"method": "gradient"},
        {"method": "sh-local", "effects": ["local_shadows"]}
    ])")));
    pipeline::Session variants, references;
    SweepRunner runner(spec, variants, references);
    const auto items = expandSweep(spec);
    const SweepReference& ref = runner.reference();
    EXPECT_EQ(ref.spp, 256);
    EXPECT_GT(ref.relativeStdError, 0.0);
    SweepImages images;
    const SweepRow same = runner.run(items[0], core::Progress::none(), &images);
    EXPECT_EQ(same.nrmse, 0.0);
    EXPECT_EQ(same.rmse255, 0.0);
    EXPECT_TRUE(std::isinf(same.psnrDb));
    EXPECT_EQ(same.flip, 0.0);
    EXPECT_EQ(same.detected, 0.0);
    EXPECT_DOUBLE_EQ(same.ssim, 1.0);
    EXPECT_GT(ref.expectedNrmse, 0.0);
    EXPECT_EQ(same.referenceError, ref.expectedNrmse);
    EXPECT_EQ(images.display.width, 32);
    EXPECT_EQ(images.errorMap.width, 32);
    for (std::size_t i : {1u, 2u}) {
        const SweepRow r = runner.run(items[i]);
        EXPECT_TRUE(std::isfinite(r.nrmse)) << items[i].id;
        // Shading without (gradient) or with local-only shadows differs visibly from the traced
        // single scattering: far above the reference's own noise.
        EXPECT_GT(r.nrmse, 3.0 * ref.expectedNrmse) << items[i].id;
        EXPECT_GT(r.flip, 0.0) << items[i].id;
        EXPECT_LT(r.ssim, 1.0) << items[i].id;
        EXPECT_GT(r.frameSeconds, 0.0) << items[i].id;
    }
}

TEST(Sweep, ThePathTracersErrorFallsWithSamples) {
    const SweepSpec spec = parse(tinySweep(json::parse(R"([
        {"method": "pathtrace", "effects": ["global_shadows"], "axes": {"spp": [4, 64]}}
    ])")));
    pipeline::Session variants, references;
    SweepRunner runner(spec, variants, references);
    const auto items = expandSweep(spec);  // base (default spp), 4, 64
    const SweepRow few = runner.run(items[1]), many = runner.run(items[2]);
    // Independent noise: NRMSE ∝ sqrt(1/spp + 1/256) → 64 spp is 0.28 of 4 spp's; 0.5 leaves room
    // for the tiny image's pixel-to-pixel spread.
    constexpr double kFallAtLeast = 0.5;
    EXPECT_LT(many.nrmse, kFallAtLeast * few.nrmse) << few.nrmse << " vs " << many.nrmse;
    EXPECT_LE(many.flip, few.flip);
}

TEST(Sweep, AVariantIsChargedTheFullCostOfWhatItReadsEvenWhenCached) {
    const SweepSpec spec = parse(tinySweep(json::parse(R"([
        {"method": "sh-local", "label": "a", "effects": ["local_shadows"]},
        {"method": "sh-local", "label": "b", "effects": ["local_shadows"]}
    ])")));
    pipeline::Session variants, references;
    SweepRunner runner(spec, variants, references);
    const auto items = expandSweep(spec);
    const SweepRow first = runner.run(items[0]);
    const SweepRow second = runner.run(items[1]);  // every precompute stage served from memory
    EXPECT_GT(first.precomputeSeconds, 0.0);
    EXPECT_EQ(second.precomputeSeconds, first.precomputeSeconds);
    EXPECT_GT(first.memoryMb, 0.0);
    EXPECT_EQ(second.memoryMb, first.memoryMb);
    EXPECT_EQ(second.nrmse, first.nrmse);  // and the same image
}

TEST(Sweep, CsvRowsHaveTheHeadersColumnsAndQuoteParams) {
    SweepRow row;
    row.item.index = 3;
    row.item.id = "sh-local-rays-64";
    row.item.label = "sh-local";
    row.item.method = "sh-local";
    row.item.axis = "rays";
    row.item.value = 64;
    row.item.params = {{"rays", 64}, {"coefficients", 4}};
    row.psnrDb = std::numeric_limits<double>::infinity();
    const std::string line = sweepCsvRow(row);
    EXPECT_EQ(columns(line), columns(sweepCsvHeader()));
    EXPECT_NE(line.find("\"{\"\"coefficients\"\":4,\"\"rays\"\":64}\""), std::string::npos) << line;
    EXPECT_NE(line.find(",inf,"), std::string::npos) << line;
}

TEST(Sweep, ARunWithItsOwnReferenceIsMeasuredAgainstIt) {
    // The isosurface methods are not the volume's optical model: their reference is the same
    // isosurface with paths traced from every hit point (Wyman Fig. 11's), not the path tracer.
    const SweepSpec spec = parse(tinySweep(json::parse(R"([
        {"method": "gradient"},
        {"method": "iso-lattice", "label": "iso", "params": {"iso_value": 300, "samples": 8},
         "reference": {"method": "iso-lattice",
                       "params": {"iso_value": 300, "shading": "paths", "samples": 8}},
         "axes": {"shading": ["paths", "lattice"]}}
    ])")));
    ASSERT_EQ(spec.references.size(), 2u);
    EXPECT_EQ(spec.references[1].method, "iso-lattice");
    pipeline::Session variants, references;
    SweepRunner runner(spec, variants, references);
    const auto items = expandSweep(spec);  // gradient, iso base, iso paths, iso lattice
    ASSERT_EQ(items.size(), 4u);
    EXPECT_EQ(items[0].reference, 0u);
    EXPECT_EQ(items[2].reference, 1u);
    const SweepRow paths = runner.run(items[2]);
    EXPECT_EQ(paths.nrmse, 0.0);                    // the reference's own render, deterministic
    EXPECT_TRUE(std::isnan(paths.referenceError));  // only the path tracer estimates its own
    const SweepRow lattice = runner.run(items[3]);
    EXPECT_GT(lattice.nrmse, 0.0);
    EXPECT_LT(lattice.nrmse, 1.0);
    const std::string line = sweepCsvRow(lattice);
    EXPECT_EQ(line.substr(line.rfind(',')), ",1");
    EXPECT_GT(runner.run(items[0]).referenceError, 0.0);  // gradient: the path tracer's
}
