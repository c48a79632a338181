// SPDX-License-Identifier: MIT
// Sessions (src/session/session.h): the format's refusals, the state at keyframes and between
// them (the camera against the orbit's closed form), the Recorder's round trip, atomic writing,
// and replaying a camera-only timeline through one pipeline session (visibility not recomputed).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>

#include "core/error.h"
#include "pipeline/pipeline.h"
#include "pipeline/scene_inputs.h"
#include "render/camera.h"
#include "session/session.h"
#include "support/test_support.h"

using namespace voxlight;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

/// Positions and angles computed by two different routes (quaternions vs sin/cos): a few ulps of
/// a 400 mm radius.
constexpr double kPositionTolMm = 1e-9 * 400.0;
constexpr double kAngleTolDeg = 1e-9;

json torsoScene() {
    return {{"volume", {{"phantom", "torso"}, {"size", 24}}},
            {"transfer_function", "ct-bone"},
            {"image", {{"width", 24}, {"height", 24}}}};
}

json orbitSession() {
    return {{"format", "voxlight-session"},
            {"version", 1},
            {"scene", torsoScene()},
            {"keyframes",
             {{{"time", 0.0},
               {"camera",
                {{"azimuth", 0}, {"elevation", 0}, {"distance", 400}, {"target", {0, 0, 0}}}}},
              {{"time", 2.0},
               {"camera",
                {{"azimuth", 90}, {"elevation", 0}, {"distance", 400}, {"target", {0, 0, 0}}}}}}}};
}

/// The InputError a document raises, or a test failure naming why there was none.
InputError errorOf(const json& doc) {
    try {
        session::parseSession(doc, "s.json", fs::current_path());
    } catch (const InputError& e) {
        return e;
    }
    ADD_FAILURE() << "no error for " << doc.dump();
    return InputError("", "", "");
}

/// The eye render::Camera places for a scene's camera (bounds ±100 mm; explicit target and
/// distance make it independent of them).
glm::dvec3 eyeOf(const io::Scene& s) {
    const render::Camera cam(pipeline::buildCameraSpec(s.camera), glm::dvec3(-100.0),
                             glm::dvec3(100.0), 32, 32);
    return cam.eye();
}

}  // namespace

TEST(Session, ExampleSessionsParseAndEveryKeyframeIsAScene) {
    int n = 0;
    for (const auto& e : fs::directory_iterator(test::sourceDir() / "datasets" / "sessions")) {
        if (e.path().extension() != ".json") continue;
        const session::Session s = session::loadSession(e.path());
        EXPECT_GE(s.keyframes.size(), 2u) << e.path();
        for (std::size_t k = 0; k < s.keyframes.size(); ++k)
            EXPECT_NO_THROW((void)s.sceneAt(k)) << e.path() << " keyframe " << k;
        ++n;
    }
    EXPECT_GE(n, 2);
}

TEST(Session, BadInputNamesTheFieldAndTheFix) {
    struct Case {
        const char* what;
        std::function<void(json&)> change;
        std::string field;
    };
    const std::vector<Case> cases = {
        {"not an object", [](json& d) { d = json::array(); }, ""},
        {"no format", [](json& d) { d.erase("format"); }, "format"},
        {"wrong format", [](json& d) { d["format"] = "voxlight-scene"; }, "format"},
        {"version as text", [](json& d) { d["version"] = "1"; }, "version"},
        {"newer version", [](json& d) { d["version"] = 3; }, "version"},
        {"unknown key", [](json& d) { d["keyframe"] = json::array(); }, "keyframe"},
        {"no scene", [](json& d) { d.erase("scene"); }, "scene"},
        {"scene a number", [](json& d) { d["scene"] = 3; }, "scene"},
        {"scene without volume", [](json& d) { d["scene"].erase("volume"); }, "scene.volume"},
        {"scene file missing", [](json& d) { d["scene"] = "no-such-scene.json"; }, "scene"},
        {"no keyframes", [](json& d) { d.erase("keyframes"); }, "keyframes"},
        {"empty keyframes", [](json& d) { d["keyframes"] = json::array(); }, "keyframes"},
        {"keyframe not an object", [](json& d) { d["keyframes"][1] = 2.0; }, "keyframes[1]"},
        {"time missing", [](json& d) { d["keyframes"][1].erase("time"); }, "keyframes[1].time"},
        {"time as text", [](json& d) { d["keyframes"][1]["time"] = "2s"; }, "keyframes[1].time"},
        {"negative time", [](json& d) { d["keyframes"][0]["time"] = -1.0; }, "keyframes[0].time"},
        {"time going back", [](json& d) { d["keyframes"][1]["time"] = 0.0; }, "keyframes[1].time"},
        {"unknown part", [](json& d) { d["keyframes"][1]["volume"] = "x.nii"; },
         "keyframes[1].volume"},
        {"camera of wrong type", [](json& d) { d["keyframes"][1]["camera"]["azimuth"] = "ninety"; },
         "keyframes[1].camera.azimuth"},
        {"camera out of range", [](json& d) { d["keyframes"][1]["camera"]["elevation"] = 100; },
         "keyframes[1].camera.elevation"},
        {"clip planes not a list",
         [](json& d) {
             d["keyframes"][1]["clip_planes"] = {{"x", 1}};
         },
         "keyframes[1].clip_planes"},
        {"light without type",
         [](json& d) {
             d["keyframes"][1]["lights"] = {{{"intensity", 2}}};
         },
         "keyframes[1].lights[0]"},
        {"note a number", [](json& d) { d["keyframes"][1]["note"] = 5; }, "keyframes[1].note"},
    };
    for (const Case& c : cases) {
        json doc = orbitSession();
        c.change(doc);
        const InputError e = errorOf(doc);
        EXPECT_EQ(e.source(), "s.json") << c.what;
        EXPECT_EQ(e.field(), c.field) << c.what << ": " << e.what();
        EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << c.what;
    }
}

TEST(Session, TruncatedOrCorruptFilesAreInputErrorsNamingTheFile) {
    test::TempDir tmp;
    const std::string text = orbitSession().dump(2);
    for (const auto& [name, content] : std::vector<std::pair<std::string, std::string>>{
             {"truncated.json", text.substr(0, text.size() / 2)},
             {"empty.json", ""},
             {"binary.json", std::string("\x89PNG\r\n\x1a\n", 8)},
             {"nan.json",
              R"({"format": "voxlight-session", "version": 1, "keyframes": [{"time": NaN}]})"}}) {
        std::ofstream(tmp / name, std::ios::binary) << content;
        try {
            session::loadSession(tmp / name);
            ADD_FAILURE() << name << " was read";
        } catch (const InputError& e) {
            EXPECT_EQ(e.source(), (tmp / name).string()) << e.what();
            EXPECT_NE(std::string(e.what()).find("not valid JSON"), std::string::npos) << e.what();
        }
    }
}

TEST(Session, StateAtAKeyframeIsTheSceneWithThePartsSoFar) {
    json doc = orbitSession();
    doc["keyframes"][1]["transfer_function"] = "ct-angio";
    doc["keyframes"].push_back({{"time", 3.0}, {"transfer_function", nullptr}});
    const session::Session s = session::parseSession(doc, "s.json", fs::current_path());
    EXPECT_EQ(s.documentAt(0)["transfer_function"], "ct-bone");
    EXPECT_EQ(s.documentAt(1)["transfer_function"], "ct-angio");
    EXPECT_EQ(s.documentAt(2)["camera"], s.documentAt(1)["camera"]) << "carried over";
    EXPECT_FALSE(s.documentAt(2).contains("transfer_function")) << "null: back to the default";
    for (std::size_t k = 0; k < s.keyframes.size(); ++k)
        EXPECT_EQ(s.documentAtTime(s.keyframes[k].time), s.documentAt(k)) << k;
    // Clamped outside the timeline; the TF is held between keyframes.
    EXPECT_EQ(s.documentAtTime(-5.0), s.documentAt(0));
    EXPECT_EQ(s.documentAtTime(99.0), s.documentAt(2));
    EXPECT_EQ(s.documentAtTime(1.9)["transfer_function"], "ct-bone");
}

TEST(Session, DocumentsFormedInAnyOrderEqualTheKeyframesAppliedFromTheStart) {
    // documentAt(k) grows from the last document it formed (8,000 keyframes took 5 s to load
    // when each was rebuilt from keyframe 0): in any order, after a copy, and after the last
    // keyframe is replaced in place (as the recorder does), it must equal the plain fold.
    json doc = orbitSession();
    for (int i = 2; i < 12; ++i)
        doc["keyframes"].push_back(
            {{"time", 2.0 * i}, {"transfer_function", i % 3 ? "ct-angio" : "ct-bone"}});
    session::Session s = session::parseSession(doc, "s.json", fs::current_path());
    auto fold = [&](const session::Session& x, std::size_t k) {
        json d = x.scene;
        for (std::size_t i = 0; i <= k; ++i)
            for (auto it = x.keyframes[i].parts.begin(); it != x.keyframes[i].parts.end(); ++it)
                if (it.value().is_null())
                    d.erase(it.key());
                else
                    d[it.key()] = it.value();
        return d;
    };
    for (const std::size_t k : {5u, 2u, 11u, 11u, 0u, 7u, 8u})
        EXPECT_EQ(s.documentAt(k), fold(s, k)) << k;
    // Frames between keyframes ask for k, then k again (the next frame in the same interval).
    for (double t = 0.0; t <= 22.0; t += 0.5)
        EXPECT_EQ(s.documentAtTime(t)["transfer_function"],
                  fold(s, std::size_t(std::min(t, 22.0) / 2.0))["transfer_function"])
            << t;
    session::Session copy = s;
    copy.keyframes.back().parts["transfer_function"] = "ct-lung";  // replaced in place
    EXPECT_EQ(copy.documentAt(11)["transfer_function"], "ct-lung");
    EXPECT_EQ(s.documentAt(11), fold(s, 11)) << "the original keeps its own";
    s.keyframes.pop_back();
    s.keyframes.push_back({22.0, {{"transfer_function", "ct-lung"}}, ""});
    EXPECT_EQ(s.documentAt(11)["transfer_function"], "ct-lung");
    // A version written as 2.0 is version 2.
    doc["version"] = 2.0;
    EXPECT_EQ(session::parseSession(doc, "s.json", fs::current_path()).keyframes.size(), 12u);
}

TEST(Session, CameraHalfwayIsTheOrbitAboutTheTarget) {
    // Azimuth 0 → 90 at elevation 0, distance 400 about the origin: at t = 1 s of 2 the eye is
    // on the circle at 45°, 400 · (sin 45°, −cos 45°, 0) — not on the chord (which is 283 mm
    // from the target).
    const session::Session s = session::parseSession(orbitSession(), "s.json", fs::current_path());
    const io::Scene mid = s.sceneAtTime(1.0);
    EXPECT_NEAR(mid.camera.azimuthDeg, 45.0, kAngleTolDeg);
    EXPECT_NEAR(mid.camera.elevationDeg, 0.0, kAngleTolDeg);
    EXPECT_DOUBLE_EQ(mid.camera.distance, 400.0);
    const double h = 400.0 * std::sqrt(0.5);
    const glm::dvec3 eye = eyeOf(mid);
    EXPECT_NEAR(eye.x, h, kPositionTolMm);
    EXPECT_NEAR(eye.y, -h, kPositionTolMm);
    EXPECT_NEAR(eye.z, 0.0, kPositionTolMm);
    // At a quarter: 22.5°.
    EXPECT_NEAR(s.sceneAtTime(0.5).camera.azimuthDeg, 22.5, kAngleTolDeg);
    // Across ±180° the orbit takes the short way (20° through the back, not 340° round the
    // front).
    json wrap = orbitSession();
    wrap["keyframes"][0]["camera"]["azimuth"] = 170;
    wrap["keyframes"][1]["camera"]["azimuth"] = -170;
    const session::Session w = session::parseSession(wrap, "s.json", fs::current_path());
    EXPECT_NEAR(std::abs(w.sceneAtTime(1.0).camera.azimuthDeg), 180.0, kAngleTolDeg);
    EXPECT_NEAR(w.sceneAtTime(0.5).camera.azimuthDeg, 175.0, kAngleTolDeg);
}

TEST(Session, LookAtCamerasSlerpAboutTheTargetWithLinearDistance) {
    // eye 300 mm in front of target (10, 20, 30) → 500 mm to its left (patient's left = +x),
    // up superior. Halfway: direction at 45° between, distance 400, target unchanged.
    json doc = orbitSession();
    const json target = {10, 20, 30};
    doc["keyframes"][0]["camera"] = {
        {"eye", {10, -280, 30}}, {"target", target}, {"up", {0, 0, 1}}};
    doc["keyframes"][1]["camera"] = {{"eye", {510, 20, 30}}, {"target", target}, {"up", {0, 0, 1}}};
    const session::Session s = session::parseSession(doc, "s.json", fs::current_path());
    const glm::dvec3 eye = eyeOf(s.sceneAtTime(1.0));
    const double h = 400.0 * std::sqrt(0.5);
    EXPECT_NEAR(eye.x, 10.0 + h, kPositionTolMm);
    EXPECT_NEAR(eye.y, 20.0 - h, kPositionTolMm);
    EXPECT_NEAR(eye.z, 30.0, kPositionTolMm);
}

TEST(Session, ElevationAndRollInterpolateWithoutFlipping) {
    // Elevation 0 → 60 at azimuth 30: the orbit rises in its vertical plane (azimuth stays 30).
    json doc = orbitSession();
    doc["keyframes"][0]["camera"] = {{"azimuth", 30}, {"elevation", 0}, {"distance", 400}};
    doc["keyframes"][1]["camera"] = {{"azimuth", 30}, {"elevation", 60}, {"distance", 400}};
    const session::Session s = session::parseSession(doc, "s.json", fs::current_path());
    const io::Scene mid = s.sceneAtTime(1.0);
    EXPECT_NEAR(mid.camera.azimuthDeg, 30.0, kAngleTolDeg);
    EXPECT_NEAR(mid.camera.elevationDeg, 30.0, kAngleTolDeg);
    EXPECT_FALSE(mid.camera.target.has_value()) << "no target given: still the fitted centre";
}

TEST(Session, ClipPlanesAndLightsInterpolateTheTfIsHeld) {
    json doc = orbitSession();
    doc["keyframes"][0]["clip_planes"] = {{{"point", {0, -100, 0}}, {"normal", {0, 1, 0}}}};
    doc["keyframes"][1]["clip_planes"] = {{{"point", {0, 60, 0}}, {"normal", {1, 0, 0}}}};
    doc["keyframes"][0]["lights"] = {
        {{"type", "directional"}, {"direction", {0, 1, 0}}, {"intensity", 1}}};
    doc["keyframes"][1]["lights"] = {
        {{"type", "directional"}, {"direction", {0, 0, -1}}, {"intensity", 3}}};
    doc["keyframes"][1]["transfer_function"] = "ct-angio";
    const session::Session s = session::parseSession(doc, "s.json", fs::current_path());
    const io::Scene mid = s.sceneAtTime(1.0);
    ASSERT_EQ(mid.clipPlanes.size(), 1u);
    EXPECT_NEAR(mid.clipPlanes[0].point.y, -20.0, 1e-12);
    EXPECT_NEAR(mid.clipPlanes[0].normal.x, std::sqrt(0.5), 1e-12);
    EXPECT_NEAR(mid.clipPlanes[0].normal.y, std::sqrt(0.5), 1e-12);
    ASSERT_EQ(mid.lights.size(), 1u);
    EXPECT_NEAR(mid.lights[0].intensity, 2.0, 1e-12);
    EXPECT_NEAR(mid.lights[0].direction.y, std::sqrt(0.5), 1e-12);
    EXPECT_NEAR(mid.lights[0].direction.z, -std::sqrt(0.5), 1e-12);
    EXPECT_EQ(mid.transferFunction.preset, "ct-bone");
    // A different number of planes is held, not interpolated.
    doc["keyframes"][1]["clip_planes"].push_back({{"normal", {0, 0, 1}}});
    const session::Session held = session::parseSession(doc, "s.json", fs::current_path());
    EXPECT_EQ(held.documentAtTime(1.9)["clip_planes"], held.documentAt(0)["clip_planes"]);
}

TEST(Session, TheMethodIsAPartHeldBetweenKeyframesFromVersion2) {
    // The viewer's method and local/global shading switches (issue #15): a keyframe may name the
    // method; between keyframes it is held (a cut, like the TF); version 1 files may not.
    json doc = orbitSession();
    doc["keyframes"][1]["method"] = {{"name", "sh-global"}, {"params", {{"rays", 8}}}};
    EXPECT_EQ(errorOf(doc).field(), "keyframes[1].method");
    doc["version"] = 2;
    const session::Session s = session::parseSession(doc, "s.json", fs::current_path());
    EXPECT_EQ(s.sceneAt(0).method.name, "gradient");  // the scene's
    EXPECT_EQ(s.sceneAtTime(1.9).method.name, "gradient");
    const io::Scene last = s.sceneAt(1);
    EXPECT_EQ(last.method.name, "sh-global");
    EXPECT_EQ(last.method.params["rays"], 8);
    // A method of the wrong shape is reported at its keyframe when the session is read (its
    // params are the pipeline's to check, at render time, as in a scene file).
    doc["keyframes"][1]["method"] = 5;
    EXPECT_EQ(errorOf(doc).field().rfind("keyframes[1]", 0), 0u) << errorOf(doc).field();
    // The recorder writes a switch as a method part alone, and reads it back.
    test::TempDir tmp;
    const io::Scene scene = io::parseScene(torsoScene(), "scene", fs::current_path());
    session::Recorder rec(scene, "switch");
    session::State st = session::stateOf(scene);
    st.method = {"sh-local", {{"rays", 8}}};
    rec.record(0.0, st);
    st.method.name = "sh-global";
    rec.record(1.0, st, "global shading");
    ASSERT_EQ(rec.session().keyframes.size(), 2u);
    EXPECT_EQ(rec.session().keyframes[1].parts.size(), 1u)
        << rec.session().keyframes[1].parts.dump();
    rec.save(tmp / "switch.json");
    const session::Session back = session::loadSession(tmp / "switch.json");
    EXPECT_EQ(back.sceneAt(0).method.name, "sh-local");
    EXPECT_EQ(back.sceneAt(1).method.name, "sh-global");
    EXPECT_EQ(back.sceneAt(1).method.params["rays"], 8);
}

TEST(Session, FrameTimesCoverTheTimelineAtTheRate) {
    const session::Session s = session::parseSession(orbitSession(), "s.json", fs::current_path());
    const std::vector<double> t = session::frameTimes(s, 2.0);
    ASSERT_EQ(t.size(), 5u);
    EXPECT_EQ(t.front(), 0.0);
    EXPECT_EQ(t.back(), 2.0);
    EXPECT_EQ(session::frameTimes(s, 0.4).size(), 1u) << "2.5 s per frame: only the start";
    EXPECT_THROW(session::frameTimes(s, 0.0), InputError);
    EXPECT_THROW(session::frameTimes(s, std::nan("")), InputError);
    EXPECT_THROW(session::frameTimes(s, -3.0), InputError);
    // Keyframes at 0.1, 0.4 and 0.8 s at 10 fps: 0.1 + 7/10 rounds to 0.7999…; the frames on
    // keyframes carry their exact times (bit for bit the keyframe's state).
    json d = orbitSession();
    d["keyframes"] = json::array();
    for (double kt : {0.1, 0.4, 0.8})
        d["keyframes"].push_back({{"time", kt}, {"camera", {{"azimuth", 100.0 * kt}}}});
    const session::Session late = session::parseSession(d, "s.json", fs::current_path());
    const std::vector<double> lt = session::frameTimes(late, 10.0);
    ASSERT_EQ(lt.size(), 8u);
    EXPECT_EQ(lt[0], 0.1);
    EXPECT_EQ(lt[3], 0.4);
    EXPECT_EQ(lt[7], 0.8);
}

TEST(Session, RecorderWritesChangedPartsAndReadsBackTheSameStates) {
    test::TempDir tmp;
    const io::Scene scene = io::parseScene(torsoScene(), "scene", fs::current_path());
    session::Recorder rec(scene, "test");
    session::State st = session::stateOf(scene);
    rec.record(0.0, st);
    st.camera.azimuthDeg = 50.0;
    rec.record(0.8, st, "orbit");
    st.clipPlanes.push_back({glm::dvec3(0.0, 10.0, 0.0), glm::dvec3(0.0, 1.0, 0.0), true});
    rec.record(1.6, st);
    st.transferFunction.preset = "ct-angio";
    rec.record(1.6, st);  // the same time: replaces the keyframe before
    const session::Session& s = rec.session();
    ASSERT_EQ(s.keyframes.size(), 3u);
    EXPECT_EQ(s.keyframes[0].parts.size(), 5u) << "the first keyframe holds every part";
    EXPECT_EQ(s.keyframes[1].parts.size(), 1u) << s.keyframes[1].parts.dump();
    EXPECT_TRUE(s.keyframes[1].parts.contains("camera"));
    EXPECT_EQ(s.keyframes[2].parts.size(), 2u) << s.keyframes[2].parts.dump();
    // Errors: time going back, NaN, a bad state.
    EXPECT_THROW(rec.record(1.0, st), InputError);
    EXPECT_THROW(rec.record(std::nan(""), st), InputError);
    EXPECT_THROW(rec.record(-1.0, st), InputError);
    session::State bad = st;
    bad.camera.fovYDeg = 500.0;
    EXPECT_THROW(rec.record(5.0, bad), InputError);
    EXPECT_EQ(rec.session().keyframes.size(), 3u)
        << "a refused record leaves the session as it was";

    rec.save(tmp / "rec.json");
    const session::Session back = session::loadSession(tmp / "rec.json");
    ASSERT_EQ(back.keyframes.size(), 3u);
    EXPECT_EQ(back.keyframes[1].note, "orbit");
    EXPECT_EQ(back.description, "test");
    for (std::size_t k = 0; k < 3; ++k) {
        const io::Scene a = s.sceneAt(k), b = back.sceneAt(k);
        EXPECT_EQ(a.document, b.document) << k;
    }
    const io::Scene last = back.sceneAt(2);
    EXPECT_EQ(last.transferFunction.preset, "ct-angio");
    EXPECT_DOUBLE_EQ(last.camera.azimuthDeg, 50.0);
    ASSERT_EQ(last.clipPlanes.size(), 1u);
    EXPECT_TRUE(last.clipPlanes[0].shadowsFromRemoved);
}

TEST(Session, WritingIsAtomic) {
    test::TempDir tmp;
    const session::Session s = session::parseSession(orbitSession(), "s.json", fs::current_path());
    session::writeSession(s, tmp / "a.json");
    std::ifstream in(tmp / "a.json");
    const std::string before((std::istreambuf_iterator<char>(in)), {});
    // Into a folder that does not exist: an InputError naming the target, and nothing written.
    EXPECT_THROW(session::writeSession(s, tmp / "missing" / "b.json"), InputError);
    EXPECT_FALSE(fs::exists(tmp / "missing"));
    // Overwriting leaves exactly the file, no temporary beside it.
    session::writeSession(s, tmp / "a.json");
    int files = 0;
    for (const auto& e : fs::directory_iterator(tmp.path())) files += e.is_regular_file();
    EXPECT_EQ(files, 1);
    EXPECT_EQ(session::loadSession(tmp / "a.json").keyframes.size(), 2u);
    EXPECT_FALSE(before.empty());
    session::Recorder empty(io::parseScene(torsoScene(), "scene", fs::current_path()));
    EXPECT_THROW(empty.save(tmp / "c.json"), InputError);
    EXPECT_FALSE(fs::exists(tmp / "c.json"));
}

TEST(SessionReplay, ACameraOnlyTimelineComputesVisibilityOnce) {
    // sh-local on a 24³ torso: five frames of an orbit through one pipeline session. Frame 0
    // computes everything; afterwards only the frame stages (camera, render) run and the
    // volume, TF, gradient and visibility stages come from the memory cache.
    json doc = orbitSession();
    doc["scene"]["method"] = "sh-local";
    const session::Session s = session::parseSession(doc, "s.json", fs::current_path());
    pipeline::Session pipe;
    const std::vector<double> times = session::frameTimes(s, 2.0);
    for (std::size_t i = 0; i < times.size(); ++i) {
        const pipeline::RunResult r = pipe.run(s.sceneAtTime(times[i]));
        const pipeline::StageRecord& vis = r.stage("local_visibility");
        if (i == 0) {
            EXPECT_TRUE(vis.ran);
            continue;
        }
        EXPECT_FALSE(vis.ran) << "frame " << i << ": " << vis.reason;
        EXPECT_EQ(vis.reason.rfind("cached", 0), 0u) << vis.reason;
        for (const auto& st : r.stages) {
            if (st.name == "camera" || st.name == "render") {
                EXPECT_TRUE(st.ran) << st.name << " frame " << i;
            } else {
                EXPECT_FALSE(st.ran) << st.name << " frame " << i << ": " << st.reason;
            }
        }
    }
}
