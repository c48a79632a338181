// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <fstream>

#include "io/scene.h"
#include "support/test_support.h"

using namespace voxlight;
using nlohmann::json;

namespace {
io::Scene parse(const json& j) { return io::parseScene(j, "scene.json", "/data"); }

/// Expects parse to fail with a message naming `key` and containing `words`.
void expectBad(const json& j, const std::string& key, const std::vector<std::string>& words = {}) {
    try {
        (void)parse(j);
        ADD_FAILURE() << "accepted: " << j.dump();
    } catch (const InputError& e) {
        EXPECT_EQ(e.source(), "scene.json");
        EXPECT_EQ(e.field(), key) << e.what();
        for (const auto& w : words)
            EXPECT_NE(std::string(e.what()).find(w), std::string::npos) << e.what();
    }
}
}  // namespace

TEST(Scene, FullDocumentParses) {
    const json j = json::parse(R"({
      "volume": {"phantom": "torso", "size": 64},
      "transfer_function": {"points": [{"value": -1000, "extinction": 0},
                                       {"value": 300, "color": [1, 0.5, 0.4], "extinction": 0.2}]},
      "camera": {"projection": "orthographic", "azimuth": 45, "elevation": 10, "fov_y": 25},
      "lights": [{"type": "directional", "direction": [0, 0, -2], "intensity": 3},
                 {"type": "point", "position": [0, 0, 100], "min_distance": 2},
                 {"type": "environment", "path": "env/sky.hdr", "rotation": [0, 0, 90]}],
      "clip_planes": [{"point": [0, 0, 0], "normal": [0, 0, 5]}],
      "crop_box": {"min": [-10, -10, -10], "max": [10, 10, 10]},
      "method": {"name": "sh-local", "params": {"rays": 64}},
      "image": {"width": 320, "height": 200},
      "render": {"step": 0.25, "seed": 7},
      "effects": ["local_shadows"]
    })");
    const io::Scene s = parse(j);
    EXPECT_EQ(s.volume.phantom, "torso");
    EXPECT_EQ(s.volume.phantomSize, 64);
    ASSERT_EQ(s.transferFunction.points.size(), 2u);
    EXPECT_DOUBLE_EQ(s.transferFunction.points[1].extinction, 0.2);
    EXPECT_EQ(s.camera.projection, "orthographic");
    ASSERT_EQ(s.lights.size(), 3u);
    EXPECT_DOUBLE_EQ(s.lights[0].direction.z, -1.0);  // normalised
    EXPECT_EQ(s.lights[2].path, std::filesystem::path("/data/env/sky.hdr"));
    EXPECT_DOUBLE_EQ(s.clipPlanes[0].normal.z, 1.0);
    EXPECT_EQ(s.method.name, "sh-local");
    EXPECT_EQ(s.method.params["rays"], 64);
    EXPECT_EQ(s.image.width, 320);
    EXPECT_EQ(s.render.seed, 7u);
}

TEST(Scene, AWindowWithoutAPresetWindowsTheModalitysPreset) {
    // `--set transfer_function.window.level=… --set …width=…` on a scene without a TF: refused as
    // "needs exactly one of 'preset' or 'points'" (probe). The automatic preset, windowed.
    const io::Scene s = parse(json::parse(
        R"({"volume": "a.nii", "transfer_function": {"window": {"level": 100, "width": 200}}})"));
    EXPECT_TRUE(s.transferFunction.preset.empty());
    EXPECT_TRUE(s.transferFunction.points.empty());
    ASSERT_TRUE(s.transferFunction.window);
    EXPECT_EQ(*s.transferFunction.window, glm::dvec2(100, 200));
    expectBad(json::parse(R"({"volume": "a.nii", "transfer_function": {"preset": "generic",
                 "points": [{"value": 0}]}})"),
              "transfer_function", {"not both"});
}

TEST(Scene, RelativeVolumePathResolvesAgainstSceneDirectory) {
    const io::Scene s = parse(json::parse(R"({"volume": "ct/head.nii.gz"})"));
    EXPECT_EQ(s.volume.path, std::filesystem::path("/data/ct/head.nii.gz"));
}

TEST(Scene, ErrorsNameTheKeyPath) {
    expectBad(json::object(), "volume", {"required"});
    expectBad(json::parse(R"({"volume": "a.nii", "camera": {"fov_y": "wide"}})"), "camera.fov_y",
              {"must be a number", "string"});
    expectBad(json::parse(R"({"volume": "a.nii", "camera": {"fovy": 30}})"), "camera.fovy",
              {"did you mean 'fov_y'"});
    expectBad(json::parse(R"({"volume": "a.nii", "image": {"width": 0}})"), "image.width",
              {"[1, 16384]"});
    expectBad(json::parse(R"({"volume": "a.nii", "image": {"width": 1e9}})"), "image.width");
    expectBad(json::parse(R"({"volume": "a.nii", "lights": [{"type": "laser"}]})"),
              "lights[0].type", {"directional"});
    expectBad(
        json::parse(
            R"({"volume": "a.nii", "lights": [{"type": "directional", "direction": [0, 0, 0]}]})"),
        "lights[0].direction", {"non-zero"});
    expectBad(json::parse(
                  R"({"volume": "a.nii", "lights": [{"type": "point", "direction": [0, 0, 1]}]})"),
              "lights[0].direction", {"applies to directional lights, not to a point light"});
    expectBad(
        json::parse(
            R"({"volume": "a.nii", "transfer_function": {"points": [{"value": 300}, {"value": 100}]}})"),
        "transfer_function.points[1].value", {"strictly increasing", "100 after 300"});
    expectBad(
        json::parse(
            R"({"volume": "a.nii", "transfer_function": {"points": [{"value": 0, "color": [2, 0, 0]}]}})"),
        "transfer_function.points[0].color[0]", {"[0, 1]"});
    // Method and effect *names* are the pipeline registry's to check (tests/pipeline); io checks
    // their shape.
    expectBad(json::parse(R"({"volume": "a.nii", "method": 3})"), "method", {"object"});
    expectBad(json::parse(R"({"volume": "a.nii", "method": {"params": {}}})"), "method", {"name"});
    expectBad(json::parse(R"({"volume": "a.nii", "clip_planes": {"normal": [0, 0, 1]}})"),
              "clip_planes", {"array"});
    expectBad(
        json::parse(R"({"volume": "a.nii", "crop_box": {"min": [0, 0, 0], "max": [1, -1, 1]}})"),
        "crop_box.min", {"below"});
    expectBad(json::parse(R"({"volume": {"path": "a.nii", "phantom": "torso"}})"), "volume",
              {"exactly one"});
    expectBad(json::parse(R"({"volume": {"path": "a.nii", "series": ""}})"), "volume.series",
              {"empty"});
    // Another shape's keys (they were ignored without a word).
    expectBad(
        json::parse(
            R"({"volume": "a.nii", "lights": [{"type": "area", "shape": "sphere", "size": [5, 5]}]})"),
        "lights[0].size", {"applies to rect area lights, not to a sphere area light"});
    expectBad(
        json::parse(
            R"({"volume": "a.nii", "lights": [{"type": "area", "shape": "rect", "radius": 5}]})"),
        "lights[0].radius", {"applies to sphere and disk area lights, not to a rect area light"});
    expectBad(json::parse(R"({"volume": "a.nii", "effects": [7]})"), "effects[0]", {"string"});
    expectBad(json::parse(R"({"volume": "a.nii", "effects": "specular"})"), "effects", {"array"});
}

TEST(Scene, ShadowsFromRemovedParsesDefaultsToFalseAndRoundTrips) {
    const io::Scene s = parse(json::parse(R"({"volume": "a.nii",
      "clip_planes": [{"normal": [0, 0, 1]}, {"normal": [1, 0, 0], "shadows_from_removed": true}],
      "crop_box": {"min": [-1, -1, -1], "max": [1, 1, 1], "shadows_from_removed": true}})"));
    ASSERT_EQ(s.clipPlanes.size(), 2u);
    EXPECT_FALSE(s.clipPlanes[0].shadowsFromRemoved);  // default: gone for the light too
    EXPECT_TRUE(s.clipPlanes[1].shadowsFromRemoved);
    ASSERT_TRUE(s.cropBox.has_value());
    EXPECT_TRUE(s.cropBox->shadowsFromRemoved);
    EXPECT_FALSE(parse(json::parse(R"({"volume": "a.nii",
      "crop_box": {"min": [-1, -1, -1], "max": [1, 1, 1]}})"))
                     .cropBox->shadowsFromRemoved);
    // The complete document writes every plane's choice, and reads back the same.
    json d = io::sceneDocument(s);
    EXPECT_EQ(d["clip_planes"][0]["shadows_from_removed"], false);
    EXPECT_EQ(d["clip_planes"][1]["shadows_from_removed"], true);
    EXPECT_EQ(d["crop_box"]["shadows_from_removed"], true);
    d["transfer_function"]["preset"] = "ct-bone";  // as `scene --init` fills it from the data
    const io::Scene back = parse(d);
    EXPECT_EQ(back.clipPlanes[1].shadowsFromRemoved, true);
    EXPECT_EQ(io::sceneDocument(back)["clip_planes"], d["clip_planes"]);
    EXPECT_EQ(io::sceneDocument(back)["crop_box"], d["crop_box"]);
    // A wrong type names the key and says what to write.
    expectBad(json::parse(R"({"volume": "a.nii",
      "clip_planes": [{"normal": [0, 0, 1], "shadows_from_removed": "true"}]})"),
              "clip_planes[0].shadows_from_removed", {"true or false", "section view"});
    expectBad(json::parse(R"({"volume": "a.nii",
      "crop_box": {"min": [0, 0, 0], "max": [1, 1, 1], "shadows_from_removed": 1}})"),
              "crop_box.shadows_from_removed", {"true or false", "a number"});
    expectBad(json::parse(R"({"volume": "a.nii",
      "clip_planes": [{"normal": [0, 0, 1], "shadow_from_removed": true}]})"),
              "clip_planes[0].shadow_from_removed", {"did you mean 'shadows_from_removed'"});
}

TEST(Scene, OverridesApplyBeforeValidation) {
    json j = json::parse(R"({"volume": "a.nii", "lights": [{"type": "directional"}]})");
    io::applyOverride(j, "camera.azimuth=45");
    io::applyOverride(j, "method.name=mip");
    io::applyOverride(j, "method.params.rays=64");
    io::applyOverride(j, "lights.0.intensity=2.5");
    io::applyOverride(j, "lights.0.color=[1,0.5,0]");
    const io::Scene s = parse(j);
    EXPECT_DOUBLE_EQ(s.camera.azimuthDeg, 45.0);
    EXPECT_EQ(s.method.name, "mip");
    EXPECT_EQ(s.method.params["rays"], 64);
    EXPECT_DOUBLE_EQ(s.lights[0].intensity, 2.5);
    EXPECT_DOUBLE_EQ(s.lights[0].color.y, 0.5);
    // The form errors print the key in ("lights[0].intensity") sets it too: it was read as a key
    // "lights[0]" of the scene, "unknown key".
    io::applyOverride(j, "lights[0].intensity=3.5");
    io::applyOverride(j, "transfer_function={\"points\": [{\"value\": 0}]}");
    io::applyOverride(j, "transfer_function.points[0].value=7");
    EXPECT_DOUBLE_EQ(parse(j).lights[0].intensity, 3.5);
    EXPECT_EQ(j["transfer_function"]["points"][0]["value"], 7);
    // Any other bracket is the override's error, not an unknown key of the scene's.
    for (const char* bad :
         {"lights[x].intensity=2", "lights[-1].intensity=2", "lights[0]intensity=2",
          "lights.[0].intensity=2", "[0]=1", "a[0=1", "a]=1", "lights[\u00e9].intensity=2"}) {
        try {
            io::applyOverride(j, bad);
            ADD_FAILURE() << bad;
        } catch (const InputError& e) {
            EXPECT_EQ(e.source(), std::string("--set ") + bad);
            EXPECT_NE(std::string(e.what()).find("not a list index"), std::string::npos)
                << e.what();
        }
    }
    // A bad override is caught by the same validation, naming the key.
    io::applyOverride(j, "camera.azimuth=left");
    expectBad(j, "camera.azimuth", {"must be a number"});
    EXPECT_THROW(io::applyOverride(j, "noequals"), InputError);
    EXPECT_THROW(io::applyOverride(j, "lights.7.intensity=1"), InputError);
    // An index past any std::size_t (std::stoul threw std::out_of_range here: an internal error
    // with exit code 1), also on a path key, whose value applyOverrides makes absolute.
    for (const char* big :
         {"lights.99999999999999999999.intensity=1", "lights.99999999999999999999.path=x"}) {
        try {
            io::applyOverrides(j, {big});
            ADD_FAILURE() << big;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("is past the end (size 1)"), std::string::npos)
                << e.what();
        }
    }
    EXPECT_THROW(io::applyOverride(j, "a..b=1"), InputError);
    // A direction whose length overflows is still a direction (it read as the zero vector).
    json big = json::parse(R"({"volume": "a.nii",
        "lights": [{"type": "directional", "direction": [-1e200, 0, 0]}],
        "camera": {"up": [0, 1e300, 1e300]}})");
    const io::Scene b = parse(big);
    EXPECT_EQ(b.lights[0].direction, glm::dvec3(-1, 0, 0));
    EXPECT_NEAR(b.camera.up.y, std::sqrt(0.5), 1e-15);
    EXPECT_THROW(io::applyOverride(j, "camera.azimuth.x=1"), InputError);
}

TEST(Scene, AnErrorAnOverrideCausesNamesTheOverrideNotTheSceneFile) {
    test::TempDir tmp;
    std::ofstream(tmp / "s.json") << R"({"volume": "a.nii", "camera": {"fov_y": 30},
        "lights": [{"type": "directional"}]})";
    auto sourceOf = [&](const std::vector<std::string>& overrides) {
        try {
            (void)io::loadScene(tmp / "s.json", overrides);
        } catch (const InputError& e) {
            return e.source() + " | " + e.field();
        }
        return std::string("no error");
    };
    // The override's own value, and a value inside an object it set.
    EXPECT_EQ(sourceOf({"image.width=-3"}), "--set image.width=-3 | image.width");
    EXPECT_EQ(sourceOf({"camera={\"fov_y\": 500}"}),
              "--set camera={\"fov_y\": 500} | camera.fov_y");
    EXPECT_EQ(sourceOf({"lights.0.intensity=-1"}),
              "--set lights.0.intensity=-1 | lights[0].intensity");
    // An object the override created: a method with parameters but no name.
    EXPECT_EQ(sourceOf({"method.params.rays=64"}), "--set method.params.rays=64 | method");
    // The scene's own fault stays the scene's, whatever else was overridden.
    std::ofstream(tmp / "s.json") << R"({"volume": "a.nii", "camera": {"fov_y": 500},
        "method": {"params": {"rays": 8}}})";
    EXPECT_EQ(sourceOf({"image.width=64"}), (tmp / "s.json").string() + " | camera.fov_y");
    std::ofstream(tmp / "s.json") << R"({"volume": "a.nii", "method": {"params": {"rays": 8}}})";
    EXPECT_EQ(sourceOf({"method.params.rays=64"}), (tmp / "s.json").string() + " | method");
    // Of two overrides of one key the last is named.
    EXPECT_EQ(sourceOf({"camera.fov_y=40", "camera.fov_y=0"}),
              "--set camera.fov_y=0 | camera.fov_y");
    // A removal names the override when the parent then lacks what it needs; array indices
    // match however they were spelled.
    std::ofstream(tmp / "s.json") << R"({"volume": "a.nii", "method": {"name": "mip"},
        "lights": [{"type": "directional"}]})";
    EXPECT_EQ(sourceOf({"method.name=null"}), "--set method.name=null | method");
    EXPECT_EQ(sourceOf({"lights.00.intensity=-5"}),
              "--set lights.00.intensity=-5 | lights[0].intensity");
    // Removing a key under something that is not an object changes nothing: the scene's own
    // error, not the override's.
    std::ofstream(tmp / "s.json") << R"({"volume": "a.nii", "camera": "front"})";
    EXPECT_EQ(sourceOf({"camera.azimuth=null"}), (tmp / "s.json").string() + " | camera");
    // Nor does removing a key that is not there.
    std::ofstream(tmp / "s.json") << R"({"volume": "a.nii", "method": {"params": {}}})";
    EXPECT_EQ(sourceOf({"method.name=null"}), (tmp / "s.json").string() + " | method");

    // A key the override added under an object whose error names the object; a key spelled
    // with brackets as errors spell it is the dotted index (nothing there to index here).
    std::ofstream(tmp / "s.json") << R"({"volume": {"phantom": "torso"}})";
    EXPECT_EQ(sourceOf({"volume.path=b.nii"}), "--set volume.path=b.nii | volume");
    EXPECT_EQ(sourceOf({"image.width[0]=5"}), "--set image.width[0]=5 | image.width.0");

    // Removing a path key leaves it removed (the absolute-path pass once put it back as null).
    std::ofstream(tmp / "s.json") << R"({"volume": {"phantom": "torso", "path": "a.nii"}})";
    EXPECT_EQ(sourceOf({"volume.path=null"}), "no error");

    // Errors raised later (a method's parameters, checked by the pipeline) name it too.
    std::ofstream(tmp / "s.json") << R"({"volume": "a.nii"})";
    const io::Scene s =
        io::loadScene(tmp / "s.json", {"method.name=sh-local", "method.params.rays=abc"});
    ASSERT_EQ(s.overrides.size(), 2u);
    const InputError later(s.source, "method.params.rays", "must be an integer");
    EXPECT_EQ(io::blameOverride(later, s.source, s.overrides).source(),
              "--set method.params.rays=abc");
    const InputError elsewhere(s.source, "image.width", "too large");
    EXPECT_EQ(io::blameOverride(elsewhere, s.source, s.overrides).source(), s.source);
    const InputError otherFile("t.nii", "method.params.rays", "unreadable");
    EXPECT_EQ(io::blameOverride(otherFile, s.source, s.overrides).source(), "t.nii");
    // "methods" is not under "method".
    EXPECT_EQ(io::blamedOverride(s.overrides, "methods"), nullptr);
}

TEST(Scene, MalformedJsonFileNamesTheFile) {
    test::TempDir tmp;
    {
        std::ofstream f(tmp / "s.json");
        f << "{\"volume\": \"a.nii\",, }";
    }
    try {
        (void)io::loadScene(tmp / "s.json");
        ADD_FAILURE();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("s.json"), std::string::npos);
        EXPECT_NE(std::string(e.what()).find("not valid JSON"), std::string::npos) << e.what();
    }
    EXPECT_THROW(io::loadScene(tmp / "missing.json"), InputError);
}

TEST(Scene, AKeyGivenTwiceInOneObjectIsRefusedByItsPath) {
    test::TempDir tmp;
    const auto refusal = [&](const std::string& text) {
        std::ofstream(tmp / "s.json") << text;
        try {
            (void)io::readJsonFile(tmp / "s.json");
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    // nlohmann keeps the last of two equal keys, other readers the first: the edited value could
    // be the one dropped, so the file is refused naming the key where it repeats.
    EXPECT_NE(refusal(R"({"camera": {"azimuth": 10}, "camera": {"azimuth": 20}})")
                  .find("s.json: camera: is given twice"),
              std::string::npos);
    const std::string nested = refusal(R"({"lights": [{"type": "directional"},
        {"type": "point", "position": [0, [1], 0], "intensity": 1, "intensity": 2}]})");
    EXPECT_NE(nested.find("lights[1].intensity: is given twice"), std::string::npos) << nested;
    const std::string deep =
        refusal(R"({"a": [[{"x": 1}], [{"y": 1}, {"x": 1, "y": {}, "y": 2}]]})");
    EXPECT_NE(deep.find("a[1][1].y: is given twice"), std::string::npos) << deep;
    // The same key in different objects, or in sibling array elements, is not a repeat.
    EXPECT_EQ(refusal(R"({"lights": [{"type": "point"}, {"type": "point"}],
        "camera": {"type": "x", "eye": {"type": 1}}})"),
              "accepted");
    json doc = json::object();
    try {
        io::applyOverride(doc, R"(lights=[{"type": "point"}, {"type": "point", "type": "spot"}])");
        ADD_FAILURE();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(": lights[1].type: is given twice"), std::string::npos)
            << e.what();
    }
    try {
        io::applyOverride(doc, R"(camera={"azimuth": 1, "azimuth": 2})");
        ADD_FAILURE();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("camera.azimuth: is given twice"), std::string::npos)
            << e.what();
    }
}

TEST(Scene, OverridesReachIntoShorthandForms) {
    json j =
        json::parse(R"({"volume": "a.nii", "method": "gradient", "transfer_function": "ct-bone"})");
    io::applyOverride(j, "method.name=mip");
    io::applyOverride(j, "transfer_function.extinction_scale=2");
    io::applyOverride(j, "volume.nonfinite=min");
    const io::Scene s = parse(j);
    EXPECT_EQ(s.method.name, "mip");
    EXPECT_EQ(s.transferFunction.preset, "ct-bone");
    EXPECT_DOUBLE_EQ(s.transferFunction.extinctionScale, 2.0);
    EXPECT_EQ(s.volume.path, std::filesystem::path("/data/a.nii"));
    EXPECT_EQ(s.volume.readOptions.nonFinite, io::NonFinitePolicy::ReplaceWithMin);
    // Other strings are not objects: descending into them stays an error.
    json k = json::parse(R"({"volume": "a.nii", "camera": {"projection": "perspective"}})");
    EXPECT_THROW(io::applyOverride(k, "camera.projection.x=1"), InputError);
}

TEST(Scene, StrictGeometryIsABooleanThatRoundTrips) {
    // The scene twin of --strict-geometry: false by default, strictly a boolean, and kept by the
    // resolved document (and by the --set path the CLI uses).
    EXPECT_FALSE(parse(json::parse(R"({"volume": "dicom/"})")).volume.readOptions.strictGeometry);
    const io::Scene s =
        parse(json::parse(R"({"volume": {"path": "dicom/", "strict_geometry": true}})"));
    EXPECT_TRUE(s.volume.readOptions.strictGeometry);
    EXPECT_EQ(io::sceneDocument(s)["volume"]["strict_geometry"], true);
    EXPECT_TRUE(
        parse(json{{"volume", io::sceneDocument(s)["volume"]}}).volume.readOptions.strictGeometry);
    expectBad(json::parse(R"({"volume": {"path": "dicom/", "strict_geometry": "yes"}})"),
              "volume.strict_geometry", {"must be true or false", "string", "resample"});
    expectBad(json::parse(R"({"volume": {"path": "dicom/", "strict_geometry": 1}})"),
              "volume.strict_geometry", {"must be true or false"});
    json j = json::parse(R"({"volume": {"path": "dicom/"}})");
    io::applyOverride(j, "volume.strict_geometry=true");
    EXPECT_TRUE(parse(j).volume.readOptions.strictGeometry);
}

namespace {
/// loadScene's InputError message for a scene file holding `text`; fails the test if it loads.
std::string loadError(const test::TempDir& tmp, const std::string& text) {
    std::ofstream(tmp / "s.json", std::ios::binary) << text;
    try {
        (void)io::loadScene(tmp / "s.json");
    } catch (const InputError& e) {
        EXPECT_EQ(e.source(), (tmp / "s.json").string());
        return e.what();
    }
    ADD_FAILURE() << "loaded: " << text.substr(0, 80);
    return {};
}
}  // namespace

TEST(Scene, HostileFilesAreInputErrorsNamingTheFile) {
    test::TempDir tmp;
    // 200 000 levels would overflow the stack in nlohmann's recursive copy and dump; refused by
    // the byte scan, with the offset of the first level too deep.
    const std::string deep =
        loadError(tmp, "{\"a\": " + std::string(200000, '[') + std::string(200000, ']') + "}");
    EXPECT_NE(deep.find("deeper than 64"), std::string::npos) << deep;
    EXPECT_NE(deep.find("byte 69"), std::string::npos) << deep;  // {"a": + 63 more levels
    const std::string open = loadError(tmp, std::string(200000, '['));
    EXPECT_NE(open.find("byte 64"), std::string::npos) << open;
    // Brackets inside strings do not count.
    const std::string inString =
        loadError(tmp, R"({"volume": {"phantom": "torso"}, "description": ")" +
                           std::string(1000, '[') + R"(", "camera": {"fov_y": "wide"}})");
    EXPECT_NE(inString.find("camera.fov_y"), std::string::npos) << inString;
    // A number beyond double range is nlohmann's out_of_range, not a parse_error.
    const std::string huge =
        loadError(tmp, R"({"volume": {"phantom": "torso"}, "image": {"exposure": 1e999}})");
    EXPECT_NE(huge.find("not valid JSON"), std::string::npos) << huge;
    EXPECT_NE(huge.find("1e999"), std::string::npos) << huge;
    // Invalid UTF-8 is quoted escaped, so the message itself is clean text.
    const std::string bytes = loadError(tmp, "{\"description\": \"caf\xe9\"}");
    EXPECT_NE(bytes.find("\\xe9"), std::string::npos) << bytes;
    EXPECT_EQ(bytes.find('\xe9'), std::string::npos) << bytes;
    EXPECT_THROW(io::loadScene(tmp.path()), InputError);  // a directory
}

TEST(Scene, AWholeNumberWrittenAsAFloatIsAnIntegerAndNullIsSaidOnce) {
    // JSON has one number type: 256.0 and 2.56e2 are the integer 256 (refused as "an integer"
    // until 7 December); 1e9 is out of range as written, 256.5 is not an integer.
    const io::Scene s =
        io::parseScene(json{{"volume", "a.nii"}, {"image", {{"width", 256.0}, {"height", 2.56e2}}}},
                       "t.json", ".");
    EXPECT_EQ(s.image.width, 256);
    EXPECT_EQ(s.image.height, 256);
    expectBad(json{{"volume", "a.nii"}, {"image", {{"width", 1e9}}}}, "image.width",
              {"[1, 16384]", "got 1000000000"});
    expectBad(json{{"volume", "a.nii"}, {"image", {{"width", 256.5}}}}, "image.width",
              {"must be an integer, got a number 256.5"});
    // "got null", not "got null null".
    try {
        io::parseScene(json{{"volume", "a.nii"}, {"image", {{"width", nullptr}}}}, "t.json", ".");
        ADD_FAILURE() << "accepted width null";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "image.width");
        EXPECT_NE(std::string(e.what()).find("got null"), std::string::npos) << e.what();
        EXPECT_EQ(std::string(e.what()).find("null null"), std::string::npos) << e.what();
    }
}

TEST(Scene, HugeUnsignedIntegerIsReportedAsGiven) {
    expectBad(json{{"volume", "a.nii"}, {"image", {{"width", 18446744073709551615ull}}}},
              "image.width", {"18446744073709551615"});
}

TEST(Scene, HostileOverridesAreInputErrors) {
    json doc = json::parse(R"({"volume": {"phantom": "torso"}})");
    EXPECT_THROW(io::applyOverride(doc, "description=caf\xe9"), InputError);
    // An index into a list that is not there (a preset TF's points) is said at once; it had made
    // "points" an object, refused later as "must be a non-empty array".
    {
        json preset = json::parse(R"({"volume": "a.nii", "transfer_function": "ct-bone"})");
        try {
            io::applyOverride(preset, "transfer_function.points.0.value=0");
            ADD_FAILURE() << preset.dump();
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("'transfer_function.points' is not there"),
                      std::string::npos)
                << e.what();
        }
        EXPECT_FALSE(io::applyOverride(preset, "transfer_function.points.0=null").removed);
    }
    EXPECT_THROW(io::applyOverride(doc, "description=" + std::string(100000, '[')), InputError);
    // A key path of 100 components nests 100 objects: refused before anything recurses into it.
    std::string key = "a";
    for (int i = 0; i < 99; ++i) key += ".a";
    io::applyOverride(doc, key + "=1");
    try {
        (void)parse(doc);
        ADD_FAILURE() << "accepted a 100-level document";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("deeper than 64"), std::string::npos) << e.what();
    }
    // A deep document built in code is refused the same way (built in place: copying it would
    // recurse once per level).
    json built = {{"volume", "a.nii"}};
    json* leaf = &built["description"];
    for (int i = 0; i < 100000; ++i) leaf = &(*leaf)[0];
    EXPECT_THROW((void)parse(built), InputError);
}

TEST(Scene, EmptyPathsAndUnknownPhantomsAreNamedByTheirKey) {
    // "" resolved to the scene's folder ("./: is a directory"), and through --set made
    // std::filesystem throw (an internal error); an unknown phantom named no file.
    expectBad(json::parse(R"({"volume": ""})"), "volume", {"empty path"});
    expectBad(json::parse(R"({"volume": {"path": ""}})"), "volume.path", {"empty path"});
    expectBad(json::parse(R"({"volume": {"phantom": "torsoo"}})"), "volume.phantom",
              {"torsoo", "torso, sphere"});
    expectBad(
        json::parse(R"({"volume": "a.nii", "lights": [{"type": "environment", "path": ""}]})"),
        "lights[0].path", {"empty path"});
    json doc = json::parse(R"({"volume": "a.nii"})");
    (void)io::applyOverrides(doc, {"volume.path="});
    expectBad(doc, "volume.path", {"empty path"});
}

TEST(Scene, TextAfterANulByteIsNotIgnored) {
    // nlohmann's lexer ends the input at a NUL: the bytes after it were never read.
    test::TempDir tmp;
    std::ofstream(tmp / "nul.json", std::ios::binary)
        << std::string("{\"volume\": \"a.nii\"}\0{{{{", 24);
    try {
        (void)io::loadScene(tmp / "nul.json");
        ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("NUL byte at byte 19"), std::string::npos) << e.what();
    }
}

TEST(Scene, EndlessFileIsRefusedAtTheSizeLimit) {
    // A file past the limit (sparse: no disk used) is refused at 16 MiB read instead of exhausting
    // memory; /dev/zero, which never ends, is a device and refused before it is opened.
    test::TempDir tmp;
    std::ofstream(tmp / "huge.json") << "{";
    std::filesystem::resize_file(tmp / "huge.json", std::uintmax_t(17) << 20);
    for (const auto& [path, words] :
         {std::pair<std::filesystem::path, std::string>{tmp / "huge.json", "16 MiB"},
          {"/dev/zero", "device"}}) {
        try {
            (void)io::loadScene(path);
            ADD_FAILURE() << "read " << path;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
        }
    }
}

TEST(Scene, TransferFunctionSurfaceChannelsAreReadStrictlyAndRoundTrip) {
    const io::Scene s = parse(json::parse(R"({"volume": "a.nii", "transfer_function": {"points": [
      {"value": 0, "specular": [0.04, 0.04, 0.04], "roughness": 0.5, "phase_g": 0.2},
      {"value": 1, "extinction": 1, "phase_g": -0.3}]}})"));
    ASSERT_EQ(s.transferFunction.points.size(), 2u);
    EXPECT_EQ(s.transferFunction.points[0].specular, glm::dvec3(0.04));
    EXPECT_EQ(s.transferFunction.points[0].roughness, 0.5);
    EXPECT_EQ(s.transferFunction.points[1].roughness, 1.0);  // default
    EXPECT_EQ(*s.transferFunction.points[1].phaseG, -0.3);
    const json d = io::sceneDocument(s);
    EXPECT_EQ(d["transfer_function"]["points"][0]["roughness"], 0.5);
    EXPECT_EQ(d["transfer_function"]["points"][1]["phase_g"], -0.3);
    EXPECT_FALSE(d["transfer_function"]["points"][1].contains("specular"));  // default not written
    EXPECT_EQ(io::sceneDocument(parse(d))["transfer_function"], d["transfer_function"]);
    // Wrong types and values out of range: the field, what was found, and what to write.
    const auto tf = [](const std::string& point) {
        return json::parse(R"({"volume": "a.nii", "transfer_function": {"points": [)" + point +
                           "]}}");
    };
    expectBad(tf(R"({"value": 0, "roughness": "rough"})"), "transfer_function.points[0].roughness",
              {"(0, 1]", "string", "e.g."});
    expectBad(tf(R"({"value": 0, "roughness": 0})"), "transfer_function.points[0].roughness",
              {"(0, 1]"});
    expectBad(tf(R"({"value": 0, "roughness": 1.5})"), "transfer_function.points[0].roughness");
    expectBad(tf(R"({"value": 0, "phase_g": 1})"), "transfer_function.points[0].phase_g",
              {"between -1 and 1"});
    expectBad(tf(R"({"value": 0, "phase_g": [0.1]})"), "transfer_function.points[0].phase_g",
              {"array"});
    expectBad(tf(R"({"value": 0, "specular": 0.04})"), "transfer_function.points[0].specular",
              {"array of 3", "e.g."});
    expectBad(tf(R"({"value": 0, "specular": [0, 2, 0]})"),
              "transfer_function.points[0].specular[1]", {"[0, 1]"});
    expectBad(tf(R"({"value": 0, "phase_g": 0.1}, {"value": 1})"),
              "transfer_function.points[1].phase_g", {"every point or on none"});
    expectBad(tf(R"({"value": 0, "roughnes": 0.1})"), "transfer_function.points[0].roughnes",
              {"did you mean 'roughness'"});
}

TEST(Scene, TransferFunctionPointsAreCheckedInTheRenderersSinglePrecision) {
    // The scene is read in double, the TF built in float: what only a double tells apart was
    // refused later by the TF itself, naming neither the file nor the field (and 1e308 as "not
    // finite").
    const auto tf = [](const std::string& points) {
        return json::parse(R"({"volume": "a.nii", "transfer_function": {"points": [)" + points +
                           "]}}");
    };
    expectBad(tf(R"({"value": 0}, {"value": 1000.0}, {"value": 1000.00001})"),
              "transfer_function.points[2].value", {"same as points[1]", "single precision"});
    expectBad(tf(R"({"value": 0}, {"value": 5e-324})"), "transfer_function.points[1].value",
              {"single precision"});
    expectBad(tf(R"({"value": -1e308}, {"value": 0})"), "transfer_function.points[0].value",
              {"1e+37"});
    // An empty preset name was the modality's default, silently.
    expectBad(json::parse(R"({"volume": "a.nii", "transfer_function": ""})"), "transfer_function",
              {"empty preset name"});
    expectBad(json::parse(R"({"volume": "a.nii", "transfer_function": {"preset": ""}})"),
              "transfer_function.preset", {"empty preset name"});
    expectBad(tf(R"({"value": 0, "phase_g": 0.999999999})"), "transfer_function.points[0].phase_g",
              {"rounds to ±1"});
    // Distinct floats and a g float tells from 1 are fine; a roughness below the smallest GGX
    // lobe's is that lobe (not float 0).
    const io::Scene s = parse(tf(R"({"value": 1000, "phase_g": 0.9999999, "roughness": 1e-300},
        {"value": 1000.0001, "phase_g": -0.9999999})"));
    ASSERT_EQ(s.transferFunction.points.size(), 2u);
    EXPECT_GT(s.transferFunction.points[0].roughness, 0.0);
    EXPECT_LT(std::abs(float(*s.transferFunction.points[1].phaseG)), 1.0f);
}
