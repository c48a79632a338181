// SPDX-License-Identifier: MIT
// The first five minutes with a scan: a volume is a scene (io::volumeScene), the fitted camera
// frames the visible matter tightly, named and automatic views, MIP/MinIP windows that fit the
// data, and a warning when a CT preset meets values that are not Hounsfield units.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/phantoms.h"
#include "io/volume_io.h"
#include "optics/presets.h"
#include "pipeline/pipeline.h"
#include "pipeline/scene_inputs.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::pipeline;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

io::Scene scene(const json& doc) { return io::parseScene(doc, "test.json", "."); }

/// The default framing leaves kDefaultMargin of the limiting image dimension empty on each side,
/// so the visible matter spans 90 % of it. The hull the camera fits is conservative by up to one
/// skip cell (4 voxels) and the TF table's interpolation, and the rendered coverage is cut at one
/// 8-bit level: the accepted band is 85–95 %.
constexpr double kCoverageLo = 0.85, kCoverageHi = 0.95;
/// Alpha above which a pixel shows something (one 8-bit display level).
constexpr float kShown = 1.f / 255.f;

/// Box of the shown pixels {x0, x1, y0, y1} (inclusive); x1 < 0 when nothing shows.
std::array<int, 4> shownBox(const core::ImageRGBA& im) {
    std::array<int, 4> b{im.width, -1, im.height, -1};
    for (int y = 0; y < im.height; ++y)
        for (int x = 0; x < im.width; ++x)
            if (im.at(x, y)[3] > kShown)
                b = {std::min(b[0], x), std::max(b[1], x), std::min(b[2], y), std::max(b[3], y)};
    return b;
}

/// Fraction of the limiting image dimension the shown pixels span: max(span x / width,
/// span y / height).
double coverage(const core::ImageRGBA& im) {
    const auto [x0, x1, y0, y1] = shownBox(im);
    if (x1 < 0) return 0.0;
    return std::max(double(x1 - x0 + 1) / im.width, double(y1 - y0 + 1) / im.height);
}

/// Centre of the shown pixels' box, in pixels from the image centre (x, y).
std::array<double, 2> offCentre(const core::ImageRGBA& im) {
    const auto [x0, x1, y0, y1] = shownBox(im);
    return {0.5 * (x0 + x1 + 1) - 0.5 * im.width, 0.5 * (y0 + y1 + 1) - 0.5 * im.height};
}

void expectFramed(const std::string& what, const json& doc) {
    Session session;
    const RunResult r = session.run(scene(doc));
    const double c = coverage(r.image);
    EXPECT_GE(c, kCoverageLo) << what;
    EXPECT_LE(c, kCoverageHi) << what;
    // Centred: the shown box's centre within 3 % of the image size (the hull is conservative by
    // up to a cell on one side only).
    const auto off = offCentre(r.image);
    EXPECT_LE(std::abs(off[0]), 0.03 * r.image.width) << what;
    EXPECT_LE(std::abs(off[1]), 0.03 * r.image.height) << what;
}

json phantomDoc(const std::string& name, const std::string& tf) {
    return {{"volume", {{"phantom", name}, {"size", 64}}},
            {"transfer_function", tf},
            {"image", {{"width", 96}, {"height", 96}}}};
}

}  // namespace

TEST(Framing, VisibleMatterSpansNinetyPercentOfTheLimitingDimension) {
    for (const char* view : {"anterior", "left", "superior", "oblique"}) {
        json d = phantomDoc("torso", "ct-bone");
        d["camera"] = {{"view", view}};
        expectFramed(std::string("torso ct-bone ") + view, d);
    }
    // The lung preset shows a different part; a wide and a tall image; orthographic.
    json d = phantomDoc("torso", "ct-lung");
    expectFramed("torso ct-lung", d);
    d["image"] = {{"width", 128}, {"height", 64}};
    expectFramed("torso ct-lung 128x64", d);
    d["image"] = {{"width", 64}, {"height", 128}};
    expectFramed("torso ct-lung 64x128", d);
    d["camera"] = {{"projection", "orthographic"}, {"view", "left"}};
    expectFramed("torso ct-lung orthographic", d);
    // A clip plane removes half: the camera frames the half that is left.
    d = phantomDoc("torso", "ct-bone");
    d["clip_planes"] = json::array({{{"point", {0, 0, 0}}, {"normal", {1, 0, 0}}}});
    expectFramed("torso clipped", d);
    expectFramed("sphere", phantomDoc("sphere", "phantom-step"));
}

TEST(Framing, RealVolumesAreFramedTightly) {
    VL_REQUIRE_SHARED(ct, "ct/abdomen-totalseg/example_ct.nii.gz");
    VL_REQUIRE_FILE(mr, "/usr/share/mricron/templates/ch2.nii.gz");
    for (const fs::path& p : {ct, mr}) {
        io::Scene s = io::volumeScene(p, {"image.width=96", "image.height=96"});
        Session session;
        const RunResult r = session.run(s);
        EXPECT_GE(coverage(r.image), kCoverageLo) << p;
        EXPECT_LE(coverage(r.image), kCoverageHi) << p;
    }
}

TEST(Framing, AnExplicitTargetStaysInTheCentreAndAGivenDistanceIsKept) {
    json d = phantomDoc("sphere", "phantom-step");
    d["camera"] = {{"target", {0, 0, 0}}, {"view", "anterior"}};
    const RunResult r = Session().run(scene(d));
    const auto off = offCentre(r.image);
    EXPECT_LE(std::abs(off[0]), 1.5);
    EXPECT_LE(std::abs(off[1]), 1.5);
    d["camera"] = {{"azimuth", 0}, {"elevation", 0}, {"distance", 1234}};
    const RunResult far = Session().run(scene(d));
    const auto& eye = far.details["camera"]["eye"];
    const double dist =
        std::hypot(eye[0].get<double>(), eye[1].get<double>(), eye[2].get<double>());
    EXPECT_NEAR(dist, 1234.0, 1.0) << "the sphere phantom is centred at the origin";
}

TEST(Views, NamedViewsLookFromThatSideAndConflictWithExplicitAngles) {
    struct Case {
        const char* view;
        glm::dvec3 forward, up;
    };
    // LPS: +x left, +y posterior, +z superior.
    const Case cases[] = {
        {"anterior", {0, 1, 0}, {0, 0, 1}},   {"posterior", {0, -1, 0}, {0, 0, 1}},
        {"left", {-1, 0, 0}, {0, 0, 1}},      {"right", {1, 0, 0}, {0, 0, 1}},
        {"superior", {0, 0, -1}, {0, -1, 0}}, {"inferior", {0, 0, 1}, {0, -1, 0}}};
    for (const Case& c : cases) {
        json d = phantomDoc("sphere", "phantom-step");
        d["camera"] = {{"view", c.view}};
        const RunResult r = Session().run(scene(d));
        EXPECT_TRUE(r.warnings.empty()) << c.view;
        const auto& cam = r.details["camera"];
        for (int a = 0; a < 3; ++a) {
            EXPECT_NEAR(cam["forward"][a].get<double>(), c.forward[a], 1e-9) << c.view;
            EXPECT_NEAR(cam["up"][a].get<double>(), c.up[a], 1e-9) << c.view;
        }
    }
    json d = phantomDoc("sphere", "phantom-step");
    d["camera"] = {{"view", "left"}, {"azimuth", 10}};
    try {
        scene(d);
        FAIL() << "view and azimuth together must be refused";
    } catch (const InputError& e) {
        // Named on the placement key (a --set of it is then the one blamed), saying the view.
        EXPECT_EQ(e.field(), "camera.azimuth");
        EXPECT_NE(std::string(e.what()).find("camera.view 'left'"), std::string::npos) << e.what();
    }
}

TEST(Views, AutoShowsAThinSlabFaceOn) {
    // A torso cut to an axial slab 12 mm thick (a few CT slices): seen from above.
    json d = phantomDoc("torso", "ct-soft-tissue");
    d["crop_box"] = {{"min", {-500, -500, -6}}, {"max", {500, 500, 6}}};
    d["camera"] = {{"view", "auto"}};
    RunResult r = Session().run(scene(d));
    EXPECT_EQ(r.details["camera_view"], "auto: superior");
    // A sagittal slab: from the left. The whole torso: anterior.
    d["crop_box"] = {{"min", {-6, -500, -500}}, {"max", {6, 500, 500}}};
    r = Session().run(scene(d));
    EXPECT_EQ(r.details["camera_view"], "auto: left");
    d.erase("crop_box");
    r = Session().run(scene(d));
    EXPECT_EQ(r.details["camera_view"], "auto: anterior");
}

namespace {
/// The torso phantom with every value shifted up by `shift` (a CT exported without its HU
/// offset), written as NIfTI into `dir`.
fs::path shiftedTorso(const test::TempDir& dir, double shift) {
    core::Volume v = core::makePhantom("torso", {.size = 48});
    v.mapping.intercept += shift;
    v.mapping.unit = "";
    v.modality = core::Modality::Unknown;
    const fs::path p = dir / "torso-shifted.nii.gz";
    io::writeVolume(v, p);
    return p;
}
}  // namespace

TEST(ExtremumWindow, MipUsesTheDataRangeWhenThePresetWindowWouldGreyTheBackground) {
    test::TempDir tmp;
    const fs::path p = shiftedTorso(tmp, 1100.0);  // air at +100: no value below zero
    json d = {{"volume", p.string()},
              {"transfer_function", "ct-angio"},
              {"method", "mip"},
              {"image", {{"width", 32}, {"height", 32}}}};
    RunResult r = Session().run(scene(d));
    const core::Volume v = io::readVolume(p);
    const auto [lo, hi] = optics::robustRange(v);
    const auto& w = r.details["transfer_function"]["window"];
    EXPECT_NEAR(w["level"].get<double>(), 0.5 * (lo + hi), 1e-3);
    EXPECT_NEAR(w["width"].get<double>(), hi - lo, 1e-3);
    // The background (air, the data's low end) maps to black: the corner pixels.
    EXPECT_LT(r.image.at(0, 0)[0], 0.02f);
    // An explicit window is the scene's word.
    d["transfer_function"] = {{"preset", "ct-angio"}, {"window", {{"level", 500}, {"width", 800}}}};
    r = Session().run(scene(d));
    EXPECT_EQ(r.details["transfer_function"]["window"]["level"], 500.0);
    // On data in HU the preset's window meets the data and keeps air black: kept.
    d = {{"volume", {{"phantom", "torso"}, {"size", 48}}},
         {"transfer_function", "ct-angio"},
         {"method", "mip"},
         {"image", {{"width", 32}, {"height", 32}}}};
    r = Session().run(scene(d));
    EXPECT_EQ(r.details["transfer_function"]["window"]["level"], 400.0);
    EXPECT_EQ(r.details["transfer_function"]["window"]["width"], 1400.0);
    // MinIP: the bright end must not lie above the data.
    d["method"] = "minip";
    d["transfer_function"] = {{"preset", "ct-lung"}};
    d["volume"] = p.string();
    r = Session().run(scene(d));
    const auto& mw = r.details["transfer_function"]["window"];
    EXPECT_NEAR(mw["level"].get<double>(), 0.5 * (lo + hi), 1e-3) << "ct-lung's window is below "
                                                                     "this data";
}

TEST(ExtremumWindow, AFlatVolumesMipShowsItsOneValueInMidGrey) {
    // Every voxel 100: the generic TF's window lies just above it, which put the MIP's one value
    // at black — an opaque black box.
    test::TempDir tmp;
    core::Volume v(core::Geometry{.dims = {12, 12, 12}}, core::VoxelType::Float32);
    std::fill_n(v.dataAs<float>(), 12 * 12 * 12, 100.f);
    const fs::path p = tmp / "flat.nii.gz";
    io::writeVolume(v, p);
    constexpr float kMidGreyTolerance = 0.002f;  // half an 8-bit level
    for (const char* method : {"mip", "minip"}) {
        json d = {
            {"volume", p.string()}, {"method", method}, {"image", {{"width", 24}, {"height", 24}}}};
        const RunResult r = Session().run(scene(d));
        EXPECT_EQ(r.details["transfer_function"]["window"]["level"], 100.0) << method;
        EXPECT_NEAR(r.image.at(12, 12)[0], 0.5f, kMidGreyTolerance) << method;
    }
}

TEST(Hounsfield, ACtPresetOnValuesWithoutAirWarnsWithTheFix) {
    test::TempDir tmp;
    const fs::path p = shiftedTorso(tmp, 1100.0);
    json d = {{"volume", p.string()},
              {"transfer_function", "ct-lung"},
              {"image", {{"width", 24}, {"height", 24}}}};
    const RunResult r = Session().run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u) << "one line, not one per symptom";
    EXPECT_NE(r.warnings[0].find("'ct-lung' expects Hounsfield units"), std::string::npos)
        << r.warnings[0];
    EXPECT_NE(r.warnings[0].find("generic"), std::string::npos) << r.warnings[0];
    // The same preset on HU data, and a non-CT preset on the shifted data: no such warning.
    d["volume"] = {{"phantom", "torso"}, {"size", 32}};
    for (const auto& w : Session().run(scene(d)).warnings)
        EXPECT_EQ(w.find("Hounsfield"), std::string::npos) << w;
    d["volume"] = p.string();
    d["transfer_function"] = "generic";
    EXPECT_TRUE(Session().run(scene(d)).warnings.empty());
}

TEST(Hounsfield, UnknownModalityInHuIsRecognisedAndGetsTheCtPreset) {
    core::Volume hu = core::makePhantom("torso", {.size = 32});
    hu.modality = core::Modality::Unknown;  // as NIfTI says nothing
    hu.mapping.unit = "";
    EXPECT_TRUE(optics::looksLikeHounsfield(hu));
    EXPECT_EQ(optics::defaultPresetName(hu), "ct-bone");
    hu.mapping.intercept += 1100.0;
    EXPECT_FALSE(optics::looksLikeHounsfield(hu));
    EXPECT_EQ(optics::defaultPresetName(hu), "generic");
}

TEST(VolumeScene, AVolumeIsASceneAndCommandLinePathsResolveAgainstTheCurrentDirectory) {
    test::TempDir tmp;
    const fs::path p = shiftedTorso(tmp, 0.0);
    const fs::path cwd = fs::current_path();
    fs::current_path(tmp.path());
    io::Scene s = io::volumeScene("torso-shifted.nii.gz");
    EXPECT_EQ(s.volume.path, p);
    EXPECT_EQ(s.camera.view, "auto");
    // Overrides that place the camera replace the automatic view rather than conflict with it.
    s = io::volumeScene("torso-shifted.nii.gz", {"camera.azimuth=45"});
    EXPECT_EQ(s.camera.view, "");
    EXPECT_EQ(s.camera.azimuthDeg, 45.0);
    fs::current_path(cwd);
    EXPECT_TRUE(io::isPathKey("volume"));
    EXPECT_TRUE(io::isPathKey("lights.3.path"));
    EXPECT_FALSE(io::isPathKey("lights.x.path"));
    EXPECT_FALSE(io::isPathKey("camera.view"));
}

TEST(VolumeScene, NullRemovesAKeySoItsDefaultApplies) {
    json d = phantomDoc("sphere", "phantom-step");
    d["camera"] = {{"azimuth", 45}, {"elevation", 10}};
    io::applyOverride(d, "camera.azimuth=null");
    EXPECT_FALSE(d["camera"].contains("azimuth"));
    EXPECT_EQ(scene(d).camera.azimuthDeg, io::CameraDesc{}.azimuthDeg);
}

TEST(VolumeScene, TheCompleteDocumentDescribesTheSameRender) {
    json d = phantomDoc("torso", "ct-angio");
    d["lights"] = json::array({{{"type", "point"}, {"position", {0, -300, 100}}}});
    d["clip_planes"] = json::array({{{"point", {0, 0, 0}}, {"normal", {0, 1, 0}}}});
    d["camera"] = {{"view", "left"}, {"margin", 0.1}};
    const io::Scene s = scene(d);
    const io::Scene full = scene(io::sceneDocument(s));
    const RunResult a = Session().run(s), b = Session().run(full);
    EXPECT_EQ(a.image.pixels, b.image.pixels);
    // And writing it again gives the same document (every key already there).
    EXPECT_EQ(io::sceneDocument(full), io::sceneDocument(s));
}

TEST(WashedOut, AnImageMostlyWhiteOnTheDisplaySaysSoWithAnExposureThatFits) {
    // A sphere under a directional light 16 times the default: the lit side all white.
    json d = phantomDoc("sphere", "generic");
    d["lights"] = {{{"type", "directional"}, {"direction", {0, 0, -1}}, {"intensity", 16.0}}};
    const RunResult r = Session().run(scene(d));
    ASSERT_EQ(r.warnings.size(), 1u);
    const std::string& w = r.warnings[0];
    EXPECT_NE(w.find("the image is washed out"), std::string::npos) << w;
    EXPECT_NE(w.find("'clinical' display"), std::string::npos) << w;
    EXPECT_NE(w.find("\"filmic\""), std::string::npos) << w;
    const std::size_t at = w.find("image.exposure to ");
    ASSERT_NE(at, std::string::npos) << w;
    const double stops = std::stod(w.substr(at + 18));
    EXPECT_LT(stops, -2.0) << w;  // 16 times the light: about four stops down
    // The exposure it names brings the image back; at the default intensity nothing is said.
    json fitted = d;
    fitted["image"]["exposure"] = stops;
    EXPECT_TRUE(Session().run(scene(fitted)).warnings.empty());
    d["lights"][0]["intensity"] = 1.0;
    EXPECT_TRUE(Session().run(scene(d)).warnings.empty());
    // Under filmic the line does not offer filmic.
    d["lights"][0]["intensity"] = 1000.0;
    d["image"]["display"] = "filmic";
    const RunResult f = Session().run(scene(d));
    ASSERT_EQ(f.warnings.size(), 1u);
    EXPECT_EQ(f.warnings[0].find("\"filmic\""), std::string::npos) << f.warnings[0];
}

TEST(WashedOut, AMipWhiteWhereTheDataPassTheWindowSaysNothing) {
    json d = phantomDoc("sphere", "generic");
    d["method"] = "mip";
    d["transfer_function"] = {{"window", {{"level", 0.0}, {"width", 1.0}}}};
    const RunResult r = Session().run(scene(d));
    EXPECT_GT(r.image.at(48, 48)[0], 0.99f) << "the window leaves the sphere white";
    EXPECT_TRUE(r.warnings.empty()) << r.warnings.at(0);
}
