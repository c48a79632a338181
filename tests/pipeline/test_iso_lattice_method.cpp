// SPDX-License-Identifier: MIT
// Method iso-lattice (pipeline/iso_shading.h): the lit isosurface by direct ray casting against
// closed forms (a convex sphere under a uniform sky shows its albedo; Lambert on a sphere is
// albedo·E·cos θ/π), the lattice's laziness across frames (a new view computes only the texels it
// has not seen; an SH lattice re-dots when a light turns), the same image for any thread count,
// and bad parameters named.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/error.h"
#include "core/phantoms.h"
#include "pipeline/pipeline.h"
#include "pipeline/scene_inputs.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::pipeline;
using nlohmann::json;

namespace {

constexpr double kPi = std::numbers::pi;
const glm::vec3 kAlbedo(0.6f, 0.5f, 0.4f);

io::Scene scene(const json& doc) { return io::parseScene(doc, "test.json", "."); }

/// The sphere phantom (value 1 inside, a one-voxel ramp at the radius) at isovalue 0.5, albedo
/// kAlbedo everywhere.
json sphereScene(const json& params, int size = 32) {
    const json color = {kAlbedo.r, kAlbedo.g, kAlbedo.b};
    json p = params;
    p["iso_value"] = 0.5;
    return {{"volume", {{"phantom", "sphere"}, {"size", size}}},
            {"transfer_function",
             {{"points", json::array({{{"value", 0.0}, {"color", color}, {"extinction", 0.0}},
                                      {{"value", 1.0}, {"color", color}, {"extinction", 1.0}}})}}},
            {"method", {{"name", "iso-lattice"}, {"params", p}}},
            {"image", {{"width", 40}, {"height", 40}, {"background", {0, 0, 0}}}}};
}

int hitPixels(const core::ImageRGBA& img) {
    int n = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) n += img.at(x, y)[3] > 0.f;
    return n;
}

// A convex surface under a uniform sky sees the whole sky: E = π·L, every pixel the albedo (the
// lattice test's kConvexTolerance: grazing directions can meet the trilinear surface's bumps).
constexpr double kConvexTolerance = 0.005;

}  // namespace

TEST(IsoLatticeMethod, AConvexSphereUnderTheWhiteSkyShowsItsAlbedo) {
    Session session;
    for (const char* shading : {"lattice", "paths", "vicinity"}) {
        json params = {{"shading", shading}, {"samples", 16}};
        if (std::string(shading) != "vicinity") params["bounces"] = 1;
        const RunResult r = session.run(scene(sphereScene(params)));
        ASSERT_GT(hitPixels(r.image), 400) << shading;
        for (int y = 0; y < r.image.height; ++y)
            for (int x = 0; x < r.image.width; ++x) {
                const float* px = r.image.at(x, y);
                if (px[3] == 0.f) continue;
                for (int c = 0; c < 3; ++c)
                    ASSERT_NEAR(px[c], kAlbedo[c], kConvexTolerance * kAlbedo[c])
                        << shading << " pixel " << x << "," << y;
            }
    }
}

// Lambert on a sphere under a directional light of irradiance E: albedo·E·max(0, n·l)/π with n
// the sphere's normal at the hit point. The shading normal is the tricubic B-spline smoothed
// gradient of a field sampled at 32³: within a few degrees of the sphere's (bound: 0.03 of
// albedo·E/π, i.e. cos θ off by 0.03). A convex body casts no shadow on itself: the shadowed
// image equals it.
TEST(IsoLatticeMethod, LambertOnASphereIsTheCosineLawAndAConvexBodyCastsNoShadow) {
    constexpr double kNormalTolerance = 0.03;
    Session session;
    json d = sphereScene({{"shading", "lambert"}});
    const float E = 2.f;
    const glm::dvec3 travel = glm::normalize(glm::dvec3(1, -1, -2));
    d["lights"] = json::array({{{"type", "directional"},
                                {"direction", {travel.x, travel.y, travel.z}},
                                {"intensity", E}}});
    const RunResult lambert = session.run(scene(d));
    const RunResult ex = session.run(scene(d));
    EXPECT_EQ(lambert.image.pixels, ex.image.pixels);
    core::PhantomOptions po;
    po.size = 32;
    const core::Volume sphere = core::makePhantom("sphere", po);
    const core::SphereFacts f = core::spherePhantomFacts(sphere.geometry());
    const auto& cam = lambert.details["camera"];
    const glm::dvec3 eye(cam["eye"][0], cam["eye"][1], cam["eye"][2]);
    ASSERT_GT(hitPixels(lambert.image), 400);
    // The hit point: where the pixel's ray meets the sphere (perspective camera, checked below).
    ASSERT_EQ(cam["projection"], "perspective");
    const glm::dvec3 fwd(cam["forward"][0], cam["forward"][1], cam["forward"][2]);
    const glm::dvec3 up(cam["up"][0], cam["up"][1], cam["up"][2]);
    const glm::dvec3 right(cam["right"][0], cam["right"][1], cam["right"][2]);
    const double tanHalf = std::tan(0.5 * double(cam["fov_y_deg"]) * kPi / 180.0);
    const int W = lambert.image.width, H = lambert.image.height;
    int checked = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const float* px = lambert.image.at(x, y);
            if (px[3] == 0.f) continue;
            const double u = (2.0 * (x + 0.5) / W - 1.0) * tanHalf * W / H;
            const double v = (1.0 - 2.0 * (y + 0.5) / H) * tanHalf;
            const glm::dvec3 dir = glm::normalize(fwd + u * right + v * up);
            const glm::dvec3 oc = eye - f.centre;
            const double b = glm::dot(oc, dir), c = glm::dot(oc, oc) - f.radius * f.radius;
            const double disc = b * b - c;
            // Grazing rays near the silhouette: the hit moves far along the ray for a small error
            // of the trilinear surface; checked where the half chord is over 0.3 radius.
            if (disc < 0.09 * f.radius * f.radius) continue;
            const glm::dvec3 n = glm::normalize(eye + (-b - std::sqrt(disc)) * dir - f.centre);
            const double expected = kAlbedo.r * E * std::max(0.0, glm::dot(n, -travel)) / kPi;
            EXPECT_NEAR(px[0], expected, kNormalTolerance * kAlbedo.r * E / kPi)
                << "pixel " << x << "," << y;
            ++checked;
        }
    EXPECT_GT(checked, 300);
    d["method"]["params"]["shading"] = "shadows";
    const RunResult shadows = session.run(scene(d));
    for (std::size_t i = 0; i < shadows.image.pixels.size(); ++i)
        ASSERT_NEAR(shadows.image.pixels[i], lambert.image.pixels[i], 1e-6) << i;
}

// The lattice is kept across frames: the same view again traces nothing; a turned view computes
// only the texels it has not seen, and reuses the rest.
TEST(IsoLatticeMethod, TexelsAreComputedLazilyAndKeptAcrossFrames) {
    Session session;
    json d = sphereScene({{"shading", "lattice"}, {"samples", 8}, {"bounces", 0}});
    const RunResult first = session.run(scene(d));
    const json& l1 = first.details["iso_lattice"]["lattice"];
    EXPECT_GT(l1["texels_computed"].get<int>(), 100);
    EXPECT_LT(l1["texels_needed"].get<double>(), 0.5 * l1["texels_full"].get<double>());
    const RunResult again = session.run(scene(d));
    EXPECT_EQ(again.stage("illumination_lattice").ran, false);
    EXPECT_EQ(again.details["iso_lattice"]["lattice"]["texels_computed"], 0);
    EXPECT_EQ(again.image.pixels, first.image.pixels);
    d["camera"] = {{"azimuth", 60}};
    const RunResult turned = session.run(scene(d));
    const json& l3 = turned.details["iso_lattice"]["lattice"];
    EXPECT_FALSE(turned.stage("illumination_lattice").ran);
    EXPECT_GT(l3["texels_reused"].get<int>(), 0);
    EXPECT_GT(l3["texels_computed"].get<int>(), 0);
    EXPECT_EQ(l3["texels_stored"].get<int>(),
              l1["texels_stored"].get<int>() + l3["texels_computed"].get<int>());
}

// SH transfer: turning the light re-dots the kept texels (nothing traced) and gives the image of
// a lattice computed for the turned light from the start.
TEST(IsoLatticeMethod, AnShLatticeRedotsWhenTheLightTurns) {
    Session session;
    json d = sphereScene({{"shading", "lattice"},
                          {"samples", 8},
                          {"bounces", 0},
                          {"lattice_mode", "sh"},
                          {"sh_order", 3}});
    d["lights"] = json::array({{{"type", "directional"}, {"direction", {0, 0, -1}}}});
    session.run(scene(d));
    d["lights"][0]["direction"] = {1, 0, 0};
    const RunResult turned = session.run(scene(d));
    EXPECT_FALSE(turned.stage("illumination_lattice").ran);
    EXPECT_EQ(turned.details["iso_lattice"]["lattice"]["texels_computed"], 0);
    Session fresh;
    const RunResult direct = fresh.run(scene(d));
    ASSERT_EQ(direct.image.pixels.size(), turned.image.pixels.size());
    for (std::size_t i = 0; i < direct.image.pixels.size(); ++i)
        ASSERT_NEAR(direct.image.pixels[i], turned.image.pixels[i], 1e-5f) << i;
}

TEST(IsoLatticeMethod, SameImageForAnyThreadCount) {
    std::vector<float> images[2];
    for (int threads : {1, 2}) {
        json d = sphereScene({{"shading", "lattice"}, {"samples", 8}});
        d["volume"] = {{"phantom", "torso"}, {"size", 48}};
        d["transfer_function"] = "ct-bone";
        d["method"]["params"].erase("iso_value");
        d["render"] = {{"threads", threads}};
        Session session;
        images[threads - 1] = session.run(scene(d)).image.pixels;
    }
    EXPECT_EQ(images[0], images[1]);
}

TEST(IsoLatticeMethod, BadParametersNameTheirField) {
    Session session;
    auto expectError = [&](const json& d, const std::string& field, const std::string& words) {
        try {
            session.run(scene(d));
            ADD_FAILURE() << "no error for " << field;
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), field) << e.what();
            EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
        }
    };
    expectError(sphereScene({{"shading", "lambert"}}), "method.params.shading",
                "directional and point lights");
    expectError(sphereScene({{"shading", "phong"}, {"samples", 4}}), "method.params.samples",
                "not read by shading 'phong'");
    expectError(sphereScene({{"shading", "glossy"}}), "method.params.shading", "lattice");
    expectError(
        sphereScene({{"shading", "lattice"}, {"lattice_memory_mb", 1}, {"lattice_resolution", 8}},
                    64),
        "method.params.lattice_memory_mb", "budget");
    json point = sphereScene({{"lattice_mode", "sh"}});
    point["lights"] = json::array({{{"type", "point"}, {"position", {0, 0, 100}}}});
    expectError(point, "method.params.lattice_mode", "point");
}
