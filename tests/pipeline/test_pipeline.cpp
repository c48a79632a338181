// SPDX-License-Identifier: MIT
// The stage pipeline: what reruns after which change, the memory and disk caches (damage,
// versions, restarts), --explain against what then runs, effects, and the method seam (a toy
// method registered from this file, touching nothing in io/, render/ or app/).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <set>

#include "core/hash.h"
#include "core/phantoms.h"
#include "io/image.h"
#include "io/volume_io.h"
#include "pipeline/pipeline.h"
#include "pipeline/registry.h"
#include "pipeline/scene_inputs.h"
#include "render/ray_caster.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::pipeline;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

io::Scene scene(const json& doc) { return io::parseScene(doc, "test.json", "."); }

json gradientScene() {
    return {
        {"volume", {{"phantom", "torso"}, {"size", 32}}},
        {"transfer_function", "ct-bone"},
        {"method", "gradient"},
        {"lights",
         json::array({{{"type", "point"}, {"position", {0, -300, 100}}, {"intensity", 60000}}})},
        {"image", {{"width", 24}, {"height", 20}}}};
}

std::set<std::string> ranStages(const RunResult& r) {
    std::set<std::string> s;
    for (const auto& st : r.stages)
        if (st.ran) s.insert(st.name);
    return s;
}

std::string category(const std::string& reason) {
    for (const char* c : {"cached", "computed", "not needed"})
        if (reason.rfind(c, 0) == 0) return c;
    return reason;
}

/// explain() must say, stage by stage, what run() then does.
void expectExplainMatches(const std::vector<StageRecord>& explained, const RunResult& ran) {
    ASSERT_EQ(explained.size(), ran.stages.size());
    for (std::size_t i = 0; i < explained.size(); ++i) {
        const StageRecord &e = explained[i], &r = ran.stages[i];
        EXPECT_EQ(e.name, r.name);
        EXPECT_EQ(e.ran, r.ran) << e.name << ": explain '" << e.reason << "', run '" << r.reason
                                << "'";
        EXPECT_EQ(category(e.reason), category(r.reason)) << e.name;
        if (!e.key.empty()) {
            EXPECT_EQ(e.key, r.key) << e.name;
        }
        EXPECT_EQ(e.inputs, r.inputs) << e.name;
    }
}

const std::set<std::string> kFrameStages = {"camera", "render"};

}  // namespace

TEST(Pipeline, SecondRenderOfTheSameSceneRunsNoPrecomputeStage) {
    Session session;
    const io::Scene s = scene(gradientScene());
    const RunResult first = session.run(s);
    EXPECT_TRUE(ranStages(first).count("brick_grid"));
    EXPECT_TRUE(ranStages(first).count("gradients"));
    const RunResult second = session.run(s);
    EXPECT_EQ(ranStages(second), kFrameStages);
    for (const auto& st : second.stages)
        if (st.kind != StageKind::Frame && st.reason.rfind("not needed", 0) != 0) {
            EXPECT_EQ(st.reason.rfind("cached " + st.key.substr(0, 8), 0), 0u) << st.reason;
        }
    EXPECT_EQ(first.image.pixels, second.image.pixels);
}

TEST(Pipeline, LightAndCameraChangesRerunOnlyLightAndFrameStages) {
    Session session;
    json d = gradientScene();
    const RunResult base = session.run(scene(d));
    d["lights"][0]["intensity"] = 30000;
    const RunResult lit = session.run(scene(d));
    EXPECT_EQ(ranStages(lit), (std::set<std::string>{"lights", "camera", "render"}));
    EXPECT_NE(base.image.pixels, lit.image.pixels);
    d["camera"] = {{"azimuth", 75}};
    const RunResult moved = session.run(scene(d));
    EXPECT_EQ(ranStages(moved), kFrameStages);
    EXPECT_NE(lit.image.pixels, moved.image.pixels);
}

TEST(Pipeline, TransferFunctionChangeRerunsTfStagesButNotTheVolumes) {
    Session session;
    json d = gradientScene();
    session.run(scene(d));
    d["transfer_function"] = {{"preset", "ct-bone"}, {"extinction_scale", 2.0}};
    const RunResult r = session.run(scene(d));
    // Brick grid and dense gradients depend on the volume only.
    EXPECT_EQ(ranStages(r), (std::set<std::string>{"transfer_function", "skip_cells", "framing",
                                                   "camera", "render"}));
    d["transfer_function"] = "ct-angio";  // different visible set: the fitted camera follows
    const RunResult angio = session.run(scene(d));
    EXPECT_EQ(ranStages(angio), (std::set<std::string>{"transfer_function", "skip_cells", "framing",
                                                       "camera", "render"}));
    EXPECT_NE(angio.stage("camera").key, r.stage("camera").key)
        << "the fitted camera's key follows the skip cells";
    // MIP's skip cells do not read the TF: a TF change keeps them.
    d["method"] = "mip";
    session.run(scene(d));
    d["transfer_function"] = {{"preset", "ct-bone"}, {"extinction_scale", 3.0}};
    EXPECT_EQ(ranStages(session.run(scene(d))),
              (std::set<std::string>{"transfer_function", "camera", "render"}));
}

TEST(Pipeline, APlacedCameraIsNotRefittedWhenACutOrTheTfChanges) {
    // Eye and target given (the viewer's camera, a session's keyframes): nothing is fitted, so
    // moving a clip plane or editing the TF must not recompute the hull of the visible matter.
    Session session;
    json d = gradientScene();
    d["camera"] = {{"eye", {40, -400, 60}}, {"target", {0, 0, 10}}};
    session.run(scene(d));
    d["clip_planes"] = json::array({{{"point", {0, 0, 0}}, {"normal", {0, 1, 0}}}});
    const RunResult cut = session.run(scene(d));
    EXPECT_EQ(ranStages(cut), kFrameStages);
    EXPECT_EQ(cut.stage("framing").reason.rfind("cached", 0), 0u) << cut.stage("framing").reason;
    d["transfer_function"] = "ct-angio";
    const RunResult angio = session.run(scene(d));
    EXPECT_EQ(ranStages(angio),
              (std::set<std::string>{"transfer_function", "skip_cells", "camera", "render"}));
    // The same picture as a session that fitted nothing before.
    EXPECT_EQ(Session().run(scene(d)).image.pixels, angio.image.pixels);
    // Without a target the eye looks at the visible matter's centre: that is fitted again.
    d["camera"].erase("target");
    session.run(scene(d));
    d["clip_planes"][0]["point"] = {0, 5, 0};
    EXPECT_TRUE(ranStages(session.run(scene(d))).count("framing"));
}

TEST(Pipeline, UnneededStagesSayWhy) {
    Session session;
    json d = gradientScene();
    const RunResult g = session.run(scene(d));
    EXPECT_EQ(g.stage("light_sh").reason, "not needed: no environment light");
    EXPECT_FALSE(g.stage("light_sh").ran);
    d["method"] = "mip";
    const RunResult m = session.run(scene(d));
    EXPECT_FALSE(m.stage("lights").ran);
    EXPECT_EQ(m.stage("lights").reason, "not needed: method 'mip' is unlit");
    EXPECT_EQ(m.stage("gradients").reason.rfind("not needed", 0), 0u);
    d["method"] = {{"name", "gradient"}, {"params", {{"central_differences", false}}}};
    EXPECT_EQ(session.run(scene(d)).stage("gradients").reason.rfind("not needed", 0), 0u);
}

TEST(Pipeline, DiskCacheSurvivesARestartAndRefusesDamagedFiles) {
    test::TempDir tmp;
    const io::Scene s = scene(gradientScene());
    RunResult first;
    {
        Session a;
        a.cache().setDirectory(tmp.path());
        first = a.run(s);
    }
    Session b;  // a new process: empty memory, same directory
    b.cache().setDirectory(tmp.path());
    const auto explained = b.explain(s);
    const RunResult second = b.run(s);
    expectExplainMatches(explained, second);
    int fromDisk = 0;
    for (const auto& st : second.stages) {
        if (st.kind != StageKind::Precompute || st.reason.rfind("not needed", 0) == 0) continue;
        if (st.reason.find("not kept on disk") != std::string::npos) {
            EXPECT_TRUE(st.ran) << st.name;  // a stage cheaper to recompute than to read back
            continue;
        }
        ++fromDisk;
        EXPECT_FALSE(st.ran) << st.name;
        EXPECT_NE(st.reason.find("(disk)"), std::string::npos) << st.name << ": " << st.reason;
    }
    EXPECT_EQ(fromDisk, 3) << "brick_grid, transfer_function, skip_cells";
    EXPECT_NE(second.stage("gradients").reason.find("not kept on disk"), std::string::npos);
    EXPECT_TRUE(second.stage("load_volume").ran) << "the volume itself is read every process";
    EXPECT_EQ(first.image.pixels, second.image.pixels);

    // Damage: a flipped byte, a truncated file, another codec version, another format version.
    const fs::path grid = tmp / ("brick_grid-" + second.stage("brick_grid").key + ".vlcache");
    ASSERT_TRUE(fs::exists(grid));
    const auto size = fs::file_size(grid);
    auto patch = [&](std::streamoff offset, char value) {
        std::fstream f(grid, std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(offset);
        f.put(value);
    };
    struct Damage {
        std::string name, expect;
        std::function<void()> apply;
    };
    const std::vector<Damage> damages = {
        {"flipped byte", "checksum", [&] { patch(std::streamoff(size) - 5, '\x5a'); }},
        {"truncated", "truncated", [&] { fs::resize_file(grid, size - 100); }},
        {"codec version", "version", [&] { patch(20, '\x63'); }},
        {"format version", "cache format", [&] { patch(16, '\x09'); }},
        {"not a cache file", "not a voxlight cache file", [&] { patch(0, 'X'); }},
    };
    for (const auto& dmg : damages) {
        SCOPED_TRACE(dmg.name);
        dmg.apply();
        Session c;
        c.cache().setDirectory(tmp.path());
        // --explain reads headers: all but a damaged payload (found by the checksum on reading)
        // are seen as "computed" before the run.
        if (dmg.name != "flipped byte") {
            for (const auto& e : c.explain(s))
                if (e.name == "brick_grid") {
                    EXPECT_TRUE(e.ran) << e.reason;
                }
        }
        std::vector<std::string> warnings;
        c.cache().setWarn([&](const std::string& w) { warnings.push_back(w); });
        const RunResult r = c.run(s);
        EXPECT_TRUE(r.stage("brick_grid").ran) << r.stage("brick_grid").reason;
        ASSERT_EQ(warnings.size(), 1u);
        EXPECT_NE(warnings[0].find(dmg.expect), std::string::npos) << warnings[0];
        EXPECT_NE(warnings[0].find(grid.filename().string()), std::string::npos) << warnings[0];
        EXPECT_EQ(r.image.pixels, first.image.pixels);
        // Rewritten whole: the next process reads it again.
        Session e;
        e.cache().setDirectory(tmp.path());
        EXPECT_FALSE(e.run(s).stage("brick_grid").ran);
    }
}

TEST(Pipeline, ExplainSaysWhatRunThenDoes) {
    Session session;
    json d = gradientScene();
    for (int step = 0; step < 4; ++step) {
        SCOPED_TRACE(step);
        if (step == 2) d["transfer_function"] = "ct-angio";
        if (step == 3) d["camera"] = {{"elevation", -10}};
        const io::Scene s = scene(d);
        const auto explained = session.explain(s);
        expectExplainMatches(explained, session.run(s));
    }
}

TEST(Pipeline, EffectsAreCheckedAgainstTheMethodAndTurnOffWhatIsNotAsked) {
    Session session;
    json d = gradientScene();
    d["effects"] = json::array();
    const Plan p = session.plan(scene(d));
    EXPECT_EQ(p.params["specular"], 0.0);
    d["effects"] = {"specular"};
    EXPECT_EQ(session.plan(scene(d)).params["specular"], 0.25);
    auto expectBad = [&](const json& doc, const std::string& field, const std::string& words) {
        try {
            session.plan(scene(doc));
            ADD_FAILURE() << "accepted " << doc.dump();
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), field) << e.what();
            EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
        }
    };
    d["effects"] = {"global_shadows"};
    expectBad(d, "effects[0]", "does not simulate");
    d["effects"] = {"specular", "bloom"};
    expectBad(d, "effects[1]", "not an effect");
    d["effects"] = json::array();
    d["method"] = {{"name", "gradient"}, {"params", {{"specular", 0.5}}}};
    expectBad(d, "method.params.specular", "effects");
    // Shadows a visibility method always casts: a list leaving them out was accepted and
    // ignored (sh-global with ["local_shadows"] still shadowed from across the volume).
    d["method"] = "sh-global";
    d["effects"] = {"local_shadows"};
    expectBad(d, "effects", "use sh-local for local shadows only");
    d["method"] = "ritschel";
    d["effects"] = json::array();
    expectBad(d, "effects", "always simulates global_shadows");
    d["method"] = "sh-local";
    expectBad(d, "effects", "leaves out");
    d["method"] = "pathtrace";
    d["effects"] = {"local_shadows"};
    expectBad(d, "effects", "cannot be had without global_shadows");
    // What each method does cast is accepted; the path tracer's [] is single scattering.
    for (const auto& [method, effects] : std::vector<std::pair<std::string, json>>{
             {"sh-local", {"local_shadows"}},
             {"sh-global", {"global_shadows"}},
             {"ritschel", {"local_shadows", "global_shadows"}},
             {"pathtrace", json::array()},
             {"pvrt", {"global_shadows"}}}) {
        d["method"] = method;
        if (method == "pvrt")  // distant lights only
            d["lights"] = {{{"type", "directional"}, {"direction", {0, 1, 0}}}};
        d["effects"] = effects;
        EXPECT_NO_THROW(session.plan(scene(d))) << method;
    }
}

TEST(Pipeline, AWholeNumberWrittenAsAFloatIsAnIntegerParameter) {
    // JSON has one number type: "rays": 64.0 is 64 (refused as "not an integer" until 7 December).
    Session session;
    json d = gradientScene();
    d["method"] = {{"name", "sh-local"}, {"params", {{"rays", 64.0}}}};
    EXPECT_EQ(session.plan(scene(d)).params["rays"], 64);
    for (const json& bad : {json(64.5), json(1e12), json(nullptr)}) {
        d["method"]["params"]["rays"] = bad;
        try {
            session.plan(scene(d));
            ADD_FAILURE() << "accepted rays " << bad.dump();
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), "method.params.rays") << e.what();
            EXPECT_EQ(std::string(e.what()).find("null null"), std::string::npos) << e.what();
        }
    }
}

TEST(Pipeline, AreaLightsShadeAsTheirEquivalentPointLights) {
    // A sphere light of radiance L and radius r gives exactly the irradiance of a point light of
    // intensity L·π r² (facing it, outside it); the gradient mode treats it so, clamped at r.
    Session session;
    json d = gradientScene();
    const double L = 100.0, r = 5.0;
    d["lights"] = json::array({{{"type", "area"},
                                {"shape", "sphere"},
                                {"position", {0, -300, 100}},
                                {"radius", r},
                                {"intensity", L}}});
    const RunResult sphere = session.run(scene(d));
    d["lights"] = json::array({{{"type", "point"},
                                {"position", {0, -300, 100}},
                                {"min_distance", r},
                                {"intensity", L * std::numbers::pi * r * r}}});
    const RunResult point = session.run(scene(d));
    ASSERT_EQ(sphere.image.pixels.size(), point.image.pixels.size());
    double worst = 0;
    for (std::size_t i = 0; i < point.image.pixels.size(); ++i)
        worst = std::max(worst, double(std::abs(sphere.image.pixels[i] - point.image.pixels[i])));
    // Same flattened emitter up to the float rounding of L·π r² (one ulp of ~8e3).
    constexpr double kEquivalentLightTol = 1e-5;
    EXPECT_LE(worst, kEquivalentLightTol);
    // Rect and disk lights render (one-sided, facing the volume) and light something.
    for (const char* shape : {"rect", "disk"}) {
        d["lights"] = json::array({{{"type", "area"},
                                    {"shape", shape},
                                    {"position", {0, -300, 100}},
                                    {"normal", {0, 1, -0.3}},
                                    {"intensity", 50}}});
        if (std::string(shape) == "rect")
            d["lights"][0]["size"] = {20, 20};
        else
            d["lights"][0]["radius"] = 10;
        const RunResult a = session.run(scene(d));
        d["lights"][0]["normal"] = {0, -1, 0.3};  // facing away: only ambient remains
        const RunResult away = session.run(scene(d));
        double lit = 0, unlit = 0;
        for (std::size_t i = 0; i < a.image.pixels.size(); ++i) {
            lit += a.image.pixels[i];
            unlit += away.image.pixels[i];
        }
        EXPECT_GT(lit, unlit * 1.05) << shape;
    }
}

TEST(Pipeline, UniformEnvironmentLightAddsDiffuseTimesPiL) {
    // A uniform environment of radiance L: irradiance π·L on every normal, so the gradient mode's
    // diffuse term grows by diffuse·π·L, which an ambient raised by the same amount reproduces.
    test::TempDir tmp;
    const float L = 0.2f;
    core::ImageRGBA env(32, 16);
    for (std::size_t i = 0; i < env.pixels.size(); ++i) env.pixels[i] = (i % 4 == 3) ? 1.f : L;
    io::writeImage(env, tmp / "uniform.hdr");
    Session session;
    json d = gradientScene();
    const json dark = {{"type", "directional"}, {"direction", {0, 0, -1}}, {"intensity", 0}};
    d["lights"] =
        json::array({dark, {{"type", "environment"}, {"path", (tmp / "uniform.hdr").string()}}});
    const RunResult withEnv = session.run(scene(d));
    EXPECT_TRUE(withEnv.stage("light_sh").ran);
    {
        // Changing the other light re-projects no map.
        json moved = d;
        moved["lights"][0]["direction"] = {0, 1, 0};
        const RunResult m = session.run(scene(moved));
        EXPECT_TRUE(m.stage("lights").ran);
        EXPECT_FALSE(m.stage("light_sh").ran) << m.stage("light_sh").reason;
    }
    d["lights"] = json::array({dark});
    const double ambient = 0.25 + 0.75 * std::numbers::pi * L;
    d["method"] = {{"name", "gradient"}, {"params", {{"ambient", ambient}}}};
    const RunResult flat = session.run(scene(d));
    double worst = 0;
    for (std::size_t i = 0; i < flat.image.pixels.size(); ++i)
        worst = std::max(worst, double(std::abs(withEnv.image.pixels[i] - flat.image.pixels[i])));
    // RGBE stores 0.2 to 8-bit mantissa precision (≤ 0.4 %), and the 9-coefficient sum rounds.
    constexpr double kUniformEnvTol = 4e-3;
    EXPECT_LE(worst, kUniformEnvTol);
}

TEST(Pipeline, AnEnvironmentMapPushedPastTheRadianceLimitBlamesTheLightsIntensity) {
    // A map within EnvironmentLight::kMaxRadiance that colour × intensity push past it: the light's
    // key is at fault (the map's "pixel … is inf" had named the file).
    test::TempDir tmp;
    core::ImageRGBA env(32, 16);
    for (std::size_t i = 0; i < env.pixels.size(); ++i) env.pixels[i] = (i % 4 == 3) ? 1.f : 1e10f;
    io::writeImage(env, tmp / "bright.exr");
    json d = gradientScene();
    d["lights"] = json::array(
        {{{"type", "environment"}, {"path", (tmp / "bright.exr").string()}, {"intensity", 1e12}}});
    Session session;
    try {
        (void)session.run(scene(d));
        ADD_FAILURE() << "radiance 1e22 accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "lights[0].intensity") << e.what();
        EXPECT_NE(std::string(e.what()).find("1e+22"), std::string::npos) << e.what();
    }
    d["lights"][0]["intensity"] = 1e4;  // 1e14: within the limit, rendered
    const RunResult ok = session.run(scene(d));
    for (const float v : ok.image.pixels) ASSERT_TRUE(std::isfinite(v));
}

// ---- The method seam: a toy method registered here ------------------------------------------

namespace {
struct MeanValue {
    double mean = 0;
};

const Codec& meanCodec() {
    static const Codec c{
        1, [](const Artifact& a, ByteWriter& w) { w.pod(a.as<MeanValue>()->mean); },
        [](ByteReader& r) {
            return Artifact::of(std::make_shared<const MeanValue>(MeanValue{r.pod<double>()}), 8);
        }};
    return c;
}

/// "test-toy": an image filled with the volume's mean value (a precompute stage) times `gain`.
Plan planToy(const io::Scene& s, ParamReader& p) {
    Plan plan;
    const double gain = p.number("gain", 1.0, 0.0, 10.0);
    plan.params = p.used;
    Stage load{"load_volume", StageKind::Input, {"volume"}};
    load.key = [](const Run& run) -> std::optional<std::uint64_t> {
        return core::Hasher()
            .add(run.scene().volume.phantom)
            .add(run.scene().volume.phantomSize)
            .value();
    };
    load.compute = [](Run& run) {
        core::PhantomOptions o;
        o.size = run.scene().volume.phantomSize;
        auto v =
            std::make_shared<const core::Volume>(core::makePhantom(run.scene().volume.phantom, o));
        return Artifact::of<core::Volume>(v, v->sizeBytes());
    };
    plan.stages.push_back(load);
    Stage mean{"toy_mean", StageKind::Precompute, {"load_volume"}};
    mean.key = [](const Run& run) {
        return KeyBuilder(run, "toy_mean").stage("load_volume").value();
    };
    mean.compute = [](Run& run) {
        const auto v = run.get<core::Volume>("load_volume");
        double sum = 0;
        const glm::ivec3 n = v->dims();
        for (int k = 0; k < n.z; ++k)
            for (int j = 0; j < n.y; ++j)
                for (int i = 0; i < n.x; ++i) sum += v->at(i, j, k);
        return Artifact::of(
            std::make_shared<const MeanValue>(MeanValue{sum / double(v->voxelCount())}), 8);
    };
    mean.codec = &meanCodec();
    plan.stages.push_back(mean);
    Stage render{"render", StageKind::Frame, {"toy_mean", "method"}};
    render.key = [gain](const Run& run) {
        return KeyBuilder(run, "render").stage("toy_mean").number(gain).value();
    };
    render.compute = [gain, w = s.image.width, h = s.image.height](Run& run) {
        auto img = std::make_shared<core::ImageRGBA>(w, h);
        const float v = float(run.get<MeanValue>("toy_mean")->mean * gain);
        std::fill(img->pixels.begin(), img->pixels.end(), v);
        return Artifact::of<core::ImageRGBA>(img, img->pixels.size() * 4);
    };
    plan.stages.push_back(render);
    return plan;
}

const RegisterMethod kToy(
    {"test-toy", "test only: the volume's mean as a flat image", {}, {"gain"}, planToy});
}  // namespace

TEST(Pipeline, AToyMethodRegistersFromATestWithoutTouchingOtherLayers) {
    EXPECT_NE(MethodRegistry::instance().find("test-toy"), nullptr);
    Session session;
    json d = {{"volume", {{"phantom", "sphere"}, {"size", 16}}},
              {"method", {{"name", "test-toy"}, {"params", {{"gain", 2.0}}}}},
              {"image", {{"width", 3}, {"height", 2}}}};
    const RunResult r = session.run(scene(d));
    EXPECT_EQ(r.method, "test-toy");
    EXPECT_EQ(r.params["gain"], 2.0);
    ASSERT_EQ(r.image.width, 3);
    EXPECT_GT(r.image.pixels[0], 0.f);
    EXPECT_TRUE(r.stage("toy_mean").ran);
    EXPECT_FALSE(session.run(scene(d)).stage("toy_mean").ran);
    d["method"]["params"] = {{"gian", 2.0}};
    try {
        session.plan(scene(d));
        FAIL();
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "method.params.gian");
        EXPECT_NE(std::string(e.what()).find("gain"), std::string::npos);
    }
}

TEST(ArtifactCache, MemoryBudgetEvictsTheLeastRecentlyUsed) {
    ArtifactCache cache(100);
    auto art = [](int v) { return Artifact::of(std::make_shared<const int>(v), 40); };
    cache.putInMemory("a", 1, art(1));
    cache.putInMemory("b", 2, art(2));
    EXPECT_TRUE(cache.findInMemory("a", 1));  // a is now the most recent
    cache.putInMemory("c", 3, art(3));        // 120 > 100: b goes
    EXPECT_TRUE(cache.inMemory("a", 1));
    EXPECT_FALSE(cache.inMemory("b", 2));
    EXPECT_TRUE(cache.inMemory("c", 3));
    EXPECT_EQ(cache.memoryBytes(), 80u);
    cache.putInMemory("big", 4, Artifact::of(std::make_shared<const int>(4), 500));
    EXPECT_TRUE(cache.inMemory("big", 4)) << "the newest entry stays even beyond the budget";
    EXPECT_EQ(cache.memoryEntries(), 1u);
}

TEST(ContentHash, ChangesWithAnyVoxelOrGeometryAndIsStable) {
    core::PhantomOptions o;
    o.size = 24;
    core::Volume v = core::makePhantom("torso", o);
    const std::uint64_t h = core::contentHash(v);
    EXPECT_EQ(h, core::contentHash(core::makePhantom("torso", o)));
    static_cast<std::int16_t*>(v.data())[v.voxelCount() - 1] ^= 1;
    EXPECT_NE(h, core::contentHash(v));
    static_cast<std::int16_t*>(v.data())[v.voxelCount() - 1] ^= 1;
    v.geometry().spacing.x *= 1.0000001;
    EXPECT_NE(h, core::contentHash(v));
}

TEST(Pipeline, AVolumeFilesIdentityCoversItsDetachedDataAndNothingElse) {
    test::TempDir tmp;
    // A detached MetaImage header whose data file has another stem (as scanners write them).
    std::ofstream(tmp / "ct.mhd") << "ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\n"
                                     "ElementType = MET_UCHAR\nElementDataFile = voxels.raw\n";
    const fs::path data = tmp / "voxels.raw";
    std::ofstream(data, std::ios::binary) << std::string(64, '\x10');
    EXPECT_EQ(
        loadSceneVolume(scene({{"volume", (tmp / "ct.mhd").string()}}), core::Progress::none())
            .voxelCount(),
        64u);
    const io::Scene s = scene({{"volume", (tmp / "ct.mhd").string()}});
    const std::uint64_t id = volumeIdentity(s);
    std::ofstream(tmp / "ct.json") << "{}";  // a scene or stats file beside it: not its data
    std::ofstream(tmp / "ct.png") << "png";
    EXPECT_EQ(volumeIdentity(s), id);
    // Replace the data file's content with another of the same size, later mtime.
    const auto size = fs::file_size(data);
    fs::last_write_time(data, fs::last_write_time(data) + std::chrono::seconds(5));
    EXPECT_EQ(fs::file_size(data), size);
    EXPECT_NE(volumeIdentity(s), id);
}

TEST(Pipeline, AnEmptyImageAlwaysComesWithAWarningThatSaysWhy) {
    Session session;
    // A CT bone TF on the 0..1 sphere phantom: nothing is visible, because these are not HU.
    json d = {{"volume", {{"phantom", "sphere"}, {"size", 16}}},
              {"transfer_function", "ct-bone"},
              {"image", {{"width", 16}, {"height", 16}}}};
    RunResult r = session.run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("'ct-bone' expects Hounsfield units"), std::string::npos)
        << r.warnings[0];
    // A TF whose window lies above every value: transparent over all of them.
    d["transfer_function"] = {{"preset", "phantom-step"},
                              {"window", {{"level", 50}, {"width", 1}}}};
    r = session.run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("transparent over all of this volume's values"), std::string::npos)
        << r.warnings[0];
    EXPECT_NE(r.warnings[0].find("phantom-step"), std::string::npos) << r.warnings[0];
    EXPECT_EQ(r.details["warnings"].size(), 1u);
    // The camera looking away from the visible part.
    d["transfer_function"] = "phantom-step";
    d["camera"] = {{"eye", {0, 0, 500}}, {"target", {0, 0, 1000}}};
    r = session.run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("camera looks past it"), std::string::npos) << r.warnings[0];
    // A lens focused a hair from the eye spreads the path tracer's rays past everything: the
    // aim was blamed (probe: aperture 20 mm, focus_distance 0.001 mm).
    d["camera"] = {{"aperture", 20}, {"focus_distance", 0.001}};
    d["method"] = {{"name", "pathtrace"}, {"params", {{"spp", 2}}}};
    r = session.run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("camera.aperture 20 mm focused at focus_distance 0.001 mm"),
              std::string::npos)
        << r.warnings[0];
    d.erase("method");
    // A normal view: no warning.
    d.erase("camera");
    EXPECT_TRUE(session.run(scene(d)).warnings.empty());
    // Clip planes that remove the whole isosurface: iso-lattice blamed the TF.
    d["method"] = "iso-lattice";
    d["clip_planes"] = json::array({{{"point", {100, 0, 0}}, {"normal", {1, 0, 0}}}});
    r = session.run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("clip_planes and crop_box remove everything 'iso-lattice'"),
              std::string::npos)
        << r.warnings[0];
    // Under 'iso' the TF only colours the surface: an empty image under a CT preset said only
    // "expects Hounsfield units", nothing of the plane that removed everything (probe).
    d["method"] = {{"name", "iso"}, {"params", {{"iso_value", 0.5}}}};
    d["transfer_function"] = "ct-bone";
    r = session.run(scene(d));
    ASSERT_EQ(r.warnings.size(), 2u);
    EXPECT_NE(r.warnings[0].find("expects Hounsfield units"), std::string::npos) << r.warnings[0];
    EXPECT_NE(r.warnings[1].find("the image is empty"), std::string::npos) << r.warnings[1];
    d["transfer_function"] = "phantom-step";
    d.erase("clip_planes");
    // An isovalue at or below every value: the whole box drawn, without a word (probe: -5000 on
    // a CT; +5000 said the isovalue lies outside the values).
    d["method"]["params"]["iso_value"] = -1.0;
    r = session.run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("is at or below every value of this volume"), std::string::npos)
        << r.warnings[0];
    d.erase("method");
    // Matter too thin for the TF to show (spacing 1e-3 mm): not the camera — the faintness, the
    // size and the spacing (the camera was blamed until 7 December).
    test::TempDir tmp;
    core::Geometry g{.dims = {12, 12, 12}};
    g.spacing = glm::dvec3(1e-3);
    core::Volume v(g, core::VoxelType::Float32);
    std::fill_n(v.dataAs<float>(), 12 * 12 * 12, 1.f);
    io::writeVolume(v, tmp / "thin.nii.gz");
    d["volume"] = (tmp / "thin.nii.gz").string();
    for (const char* method : {"gradient", "sh-local"}) {
        d["method"] = method;
        r = session.run(scene(d));
        ASSERT_EQ(r.warnings.size(), 1u) << method;
        EXPECT_NE(r.warnings[0].find("too faint"), std::string::npos) << r.warnings[0];
        EXPECT_NE(r.warnings[0].find("0.001 x 0.001 x 0.001 mm"), std::string::npos)
            << r.warnings[0];
    }
}

TEST(Pipeline, APointLightInsideTheVolumeUnderShAndDarkLightsWarn) {
    // The SH methods' visibility runs past a point light (matter behind it shadows it: 4× too
    // dark in a probe); the path tracer's shadow rays end at the light: no warning there.
    Session session;
    json d = {{"volume", {{"phantom", "sphere"}, {"size", 16}}},
              {"transfer_function", "phantom-step"},
              {"lights", json::array({{{"type", "point"}, {"position", {0, 0, 0}}}})},
              {"image", {{"width", 16}, {"height", 16}}}};
    for (const char* method : {"sh-local", "sh-global", "ritschel"}) {
        d["method"] = method;
        RunResult r = session.run(scene(d));
        ASSERT_EQ(r.warnings.size(), 1u) << method;
        EXPECT_NE(r.warnings[0].find("lights[0] is a point light inside the volume"),
                  std::string::npos)
            << r.warnings[0];
    }
    d["lights"][0]["position"] = {0, 0, 500};
    EXPECT_TRUE(session.run(scene(d)).warnings.empty());
    // Every light dark: a black picture said nothing (probe).
    d["lights"][0]["intensity"] = 0;
    for (const char* method : {"gradient", "sh-local"}) {
        d["method"] = method;
        const RunResult r = session.run(scene(d));
        ASSERT_EQ(r.warnings.size(), 1u) << method;
        EXPECT_NE(r.warnings[0].find("every light in the scene has intensity or color 0"),
                  std::string::npos)
            << r.warnings[0];
    }
}

TEST(Pipeline, ACachedVolumeRepeatsItsLoaderWarningInEveryRun) {
    // A tilted DICOM series loads with one warning (resampled). A session that serves the volume
    // from its memory cache must still say so for each render it makes from it: the warning is
    // about the data, not about this run's reading of it.
    test::TempDir tmp;
    test::writeTiltedCtSeries(tmp / "ct");
    Session session;
    json d = {{"volume", (tmp / "ct").string()},
              {"method", "gradient"},
              {"image", {{"width", 16}, {"height", 16}}}};
    const auto tiltWarnings = [](const RunResult& r) {
        std::size_t n = 0;
        for (const auto& w : r.warnings) n += w.find("gantry tilt") != std::string::npos;
        return n;
    };
    const RunResult first = session.run(scene(d));
    EXPECT_TRUE(first.stage("load_volume").ran);
    EXPECT_EQ(tiltWarnings(first), 1u);
    d["camera"] = {{"azimuth", 40}};
    const RunResult second = session.run(scene(d));
    EXPECT_FALSE(second.stage("load_volume").ran);
    EXPECT_EQ(second.stage("load_volume").reason.rfind("cached", 0), 0u)
        << second.stage("load_volume").reason;
    EXPECT_EQ(tiltWarnings(second), 1u);
    ASSERT_TRUE(second.details.contains("warnings"));
    EXPECT_NE(second.details["warnings"].dump().find("gantry tilt"), std::string::npos);
    // A volume without loader warnings does not inherit them.
    d["volume"] = {{"phantom", "sphere"}, {"size", 16}};
    EXPECT_EQ(tiltWarnings(session.run(scene(d))), 0u);
}

TEST(Pipeline, TheGradientsStageStopsWhenCancelled) {
    // The gradients stage builds its table with run.progress(): on a 512³ CT it ran 11 s on a
    // loaded machine without looking at the cancel flag. Both layouts stop (CancelledError) when
    // the flag is raised, and build the same table as before when it is not.
    core::PhantomOptions o;
    o.size = 48;
    const core::Volume v = core::makePhantom("torso", o);
    const glm::ivec3 counts = (v.dims() + (render::kSkipCellVoxels - 1)) / render::kSkipCellVoxels;
    const std::size_t cells = std::size_t(counts.x) * counts.y * counts.z;
    const grid::BrickMajorants everyCell = grid::BrickMajorants::fromCells(
        counts, render::kSkipCellVoxels, std::vector<float>(cells, 1.f),
        std::vector<std::array<float, 2>>(cells, {0.f, 1.f}));
    std::atomic<bool> flag{true};
    const core::Progress cancelled({}, &flag);
    EXPECT_THROW((void)render::VoxelGradients::build(v, cancelled), CancelledError);
    EXPECT_THROW((void)render::BrickedGradients::build(
                     v, everyCell, render::BrickedGradients::kMaxEntries, cancelled),
                 CancelledError);
    flag = false;
    EXPECT_EQ(render::VoxelGradients::build(v, cancelled).d, render::VoxelGradients::build(v).d);
    EXPECT_EQ(render::BrickedGradients::build(v, everyCell, render::BrickedGradients::kMaxEntries,
                                              cancelled)
                  .d,
              render::BrickedGradients::build(v, everyCell).d);
}

TEST(Pipeline, UpParallelToTheViewFallsBackWithAWarningNeverNaN) {
    Session session;
    json d = {{"volume", {{"phantom", "sphere"}, {"size", 16}}},
              {"transfer_function", "phantom-step"},
              {"image", {{"width", 16}, {"height", 16}}}};
    for (const json& up : {json{0, 1, 0}, json{0, -1, 0}}) {
        d["camera"] = {{"azimuth", 0}, {"elevation", 0}, {"up", up}};  // looking along ±y
        const RunResult r = session.run(scene(d));
        bool finite = true, visible = false;
        for (std::size_t i = 0; i < r.image.pixels.size(); ++i) {
            finite = finite && std::isfinite(r.image.pixels[i]);
            if (i % 4 == 3) visible = visible || r.image.pixels[i] > 0.05f;
        }
        EXPECT_TRUE(finite);
        EXPECT_TRUE(visible) << "the sphere is in view";
        ASSERT_EQ(r.warnings.size(), 1u);
        EXPECT_NE(r.warnings[0].find("camera.up is parallel"), std::string::npos) << r.warnings[0];
        for (const auto& v : r.details["camera"]["up"]) EXPECT_TRUE(std::isfinite(v.get<double>()));
    }
}

TEST(ArtifactCache, StaleTemporariesOfKilledWritersAreRemovedFreshOnesKept) {
    test::TempDir tmp;
    const fs::path stale = tmp / ".brick_grid-0123.vlcache.999.0.abc.tmp";
    const fs::path fresh = tmp / ".brick_grid-4567.vlcache.998.0.def.tmp";
    const fs::path other = tmp / "notes.tmp";  // not one of ours: left alone
    for (const auto& p : {stale, fresh, other}) std::ofstream(p) << "partial";
    fs::last_write_time(stale, fs::file_time_type::clock::now() - 2 * kStaleTemporaryAge);
    fs::last_write_time(other, fs::file_time_type::clock::now() - 2 * kStaleTemporaryAge);
    ArtifactCache cache;
    cache.setDirectory(tmp.path());
    EXPECT_FALSE(fs::exists(stale));
    EXPECT_TRUE(fs::exists(fresh)) << "a live writer may own it";
    EXPECT_TRUE(fs::exists(other));
}
