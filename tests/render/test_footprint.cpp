// SPDX-License-Identifier: MIT
// Camera::project and the pixel footprint that lets the compositing modes skip rays which cannot
// meet a non-empty cell.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "core/phantoms.h"
#include "core/rng.h"
#include "grid/brick_grid.h"
#include "render/camera.h"
#include "render/footprint.h"
#include "render/ray_caster.h"
#include "render_test_util.h"

namespace voxlight {
namespace {

using test::stepTf;

/// project() inverts generate() to double rounding: a few 1e-9 of a pixel at these distances.
constexpr double kProjectTolPixels = 1e-6;

TEST(Camera, ProjectInvertsGenerate) {
    const glm::dvec3 lo(-40.0, -30.0, -20.0), hi(40.0, 30.0, 20.0);
    for (render::Projection p :
         {render::Projection::Perspective, render::Projection::Orthographic}) {
        render::CameraSpec s;
        s.projection = p;
        s.azimuthDeg = 37.0;
        s.elevationDeg = -24.0;
        s.rollDeg = 11.0;
        const render::Camera cam(s, lo, hi, 37, 23);  // not square: aspect enters both axes
        core::CounterRng rng(7);
        for (int n = 0; n < 500; ++n) {
            const int x = int(rng.uniform() * 37), y = int(rng.uniform() * 23);
            const render::Ray r = cam.generate(x, y);
            const double t = 1.0 + 300.0 * rng.uniform();
            double px = -1, py = -1;
            ASSERT_TRUE(cam.project(r.origin + t * r.direction, px, py));
            EXPECT_NEAR(px, x, kProjectTolPixels);
            EXPECT_NEAR(py, y, kProjectTolPixels);
        }
        double px, py;
        const bool behind = cam.project(cam.eye() - 10.0 * cam.forward(), px, py);
        EXPECT_EQ(behind, p == render::Projection::Orthographic);  // ortho: any depth projects
    }
}

/// A sparse sphere shell on an oblique, anisotropic grid (so that index and world axes differ).
core::Volume obliqueSphere() {
    core::Volume v = test::spherePhantom(64);
    const double c = std::cos(0.4), s = std::sin(0.4);
    v.geometry().direction =
        glm::dmat3(glm::dvec3(c, s, 0), glm::dvec3(-s, c, 0), glm::dvec3(0, 0, 1));
    v.geometry().spacing = glm::dvec3(0.7, 1.0, 1.6);
    return v;
}

// Every pixel the footprint leaves out must have a ray that meets no non-empty cell (checked by
// brute force along the ray at 0.05-voxel steps); and the footprint must leave out a good share
// of the image, or the check is vacuous.
TEST(PixelFootprint, UncoveredPixelsSeeOnlyEmptyCells) {
    const core::Volume v = obliqueSphere();
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    // A thin shell of the sphere is visible: σt only between 0.45 and 0.55 of the profile.
    const optics::TransferFunction tf(
        {test::tfPoint(0, 0), test::tfPoint(0.45f, 0), test::tfPoint(0.5f, 1.f),
         test::tfPoint(0.55f, 0), test::tfPoint(1, 0)},
        {0.5f, 1.f}, "shell");
    const render::RayCaster caster(v, g, tf, render::RenderOptions{});
    const grid::BrickMajorants& m = caster.majorants();
    ASSERT_GT(m.nonEmptyCount(), 0u);
    ASSERT_LT(m.nonEmptyCount(), m.size());
    const auto b = v.geometry().worldBounds();
    int cameras = 0;
    for (render::Projection p : {render::Projection::Perspective, render::Projection::Orthographic})
        for (double az : {0.0, 35.0, 130.0})
            for (double el : {-60.0, 15.0}) {
                render::CameraSpec s;
                s.projection = p;
                s.azimuthDeg = az;
                s.elevationDeg = el;
                // Zoomed in, so that the object fills much of the image and part leaves it.
                s.fovYDeg = 18.0;
                s.orthoHeight = 60.0;
                const render::Camera cam(s, b[0], b[1], 56, 48);
                const render::PixelFootprint fp(caster, cam);
                ASSERT_FALSE(fp.coversEverything());
                const double f = fp.coveredFraction();
                EXPECT_GT(f, 0.05) << "az " << az << " el " << el;
                EXPECT_LT(f, 0.9) << "az " << az << " el " << el;
                int seen = 0;
                for (int y = 0; y < cam.height(); ++y)
                    for (int x = 0; x < cam.width(); ++x) {
                        const render::RaySegment r = caster.setupRay(cam, x, y);
                        if (!r.hit()) continue;
                        const float dt = 0.05f / glm::length(r.dirIndex);
                        bool meets = false;
                        for (float t = r.tNear; t <= r.tFar && !meets; t += dt)
                            meets = test::inNonEmptyCell(m, r.originIndex + t * r.dirIndex);
                        if (!meets) continue;
                        ++seen;
                        ASSERT_TRUE(fp.covers(x, y))
                            << "pixel " << x << "," << y << " az " << az << " el " << el;
                    }
                EXPECT_GT(seen, 100);
                ++cameras;
            }
    EXPECT_EQ(cameras, 12);
}

TEST(PixelFootprint, CoversEverythingWhenSkippingIsOffOrTheCameraIsInside) {
    const core::Volume v = obliqueSphere();
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const auto tf = stepTf(1.f);
    const auto b = v.geometry().worldBounds();
    render::CameraSpec inside;
    inside.eye = 0.5 * (b[0] + b[1]);
    inside.target = inside.eye.value() + glm::dvec3(1, 0, 0);
    const render::Camera in(inside, b[0], b[1], 16, 16);
    const render::Camera out(render::CameraSpec{}, b[0], b[1], 16, 16);
    render::RenderOptions o;
    EXPECT_TRUE(render::PixelFootprint(render::RayCaster(v, g, tf, o), in).coversEverything());
    EXPECT_FALSE(render::PixelFootprint(render::RayCaster(v, g, tf, o), out).coversEverything());
    o.emptySpaceSkipping = false;
    EXPECT_TRUE(render::PixelFootprint(render::RayCaster(v, g, tf, o), out).coversEverything());
}

// The skipped pixels are exactly what marching would have given: images with the footprint (the
// default) and with every ray marched agree bit for bit on the oblique grid, for both modes it
// serves, from outside and from a camera that sees part of the object leave the image.
TEST(PixelFootprint, DoesNotChangeTheImage) {
    const core::Volume v = obliqueSphere();
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const auto tf = stepTf(0.5f);
    const auto b = v.geometry().worldBounds();
    render::CameraSpec close;
    close.fovYDeg = 12.0;
    close.azimuthDeg = 200.0;
    for (const render::Camera& cam :
         {test::orthoCamera(v, 35, 25, 70, 48), render::Camera(close, b[0], b[1], 40, 30)})
        for (render::Mode mode : {render::Mode::EmissionAbsorption, render::Mode::Gradient}) {
            render::RenderOptions o;
            o.mode = mode;
            o.background = glm::vec3(0.2f, 0.3f, 0.4f);
            render::RenderStats with, without;
            const core::ImageRGBA a = test::renderWith(v, tf, cam, o, &with);
            o.pixelFootprint = false;
            const core::ImageRGBA c = test::renderWith(v, tf, cam, o, &without);
            ASSERT_EQ(a.pixels.size(), c.pixels.size());
            EXPECT_EQ(
                0, std::memcmp(a.pixels.data(), c.pixels.data(), a.pixels.size() * sizeof(float)))
                << render::toString(mode);
            EXPECT_LT(with.rays, without.rays) << "the footprint should leave rays out";
            EXPECT_EQ(with.samples, without.samples) << "and only rays that take no sample";
        }
}

/// Bit-for-bit comparison of a render with the footprint (default) and with every ray cast.
void expectFootprintChangesNothing(const core::Volume& v, const optics::TransferFunction& tf,
                                   const render::Camera& cam, render::Mode mode,
                                   const std::string& what) {
    render::RenderOptions o;
    o.mode = mode;
    o.background = glm::vec3(0.2f, 0.3f, 0.4f);
    const core::ImageRGBA a = test::renderWith(v, tf, cam, o);
    o.pixelFootprint = false;
    const core::ImageRGBA c = test::renderWith(v, tf, cam, o);
    ASSERT_EQ(a.pixels.size(), c.pixels.size());
    EXPECT_EQ(0, std::memcmp(a.pixels.data(), c.pixels.data(), a.pixels.size() * sizeof(float)))
        << what;
}

// A single slice is the slab ±0.5 voxel around index 0 on its axis; the marcher clamps the lower
// half into the edge cell, so the footprint must reach down to −0.5 (seen edge-on and zoomed in,
// the half slab spans several pixels).
TEST(PixelFootprint, SingleSliceKeepsBothHalvesOfTheSlab) {
    const core::Volume v = test::singleSlice(5.0);
    const optics::TransferFunction tf({test::tfPoint(0, 0), test::tfPoint(255, 0.3f)}, {128, 256});
    const auto b = v.geometry().worldBounds();
    for (double elevation : {0.0, 3.0, -3.0}) {
        render::CameraSpec s;
        s.elevationDeg = elevation;
        s.fovYDeg = 8.0;
        const render::Camera cam(s, b[0], b[1], 48, 48);
        for (render::Mode m : {render::Mode::EmissionAbsorption, render::Mode::Gradient})
            expectFootprintChangesNothing(v, tf, cam, m, "elevation " + std::to_string(elevation));
    }
}

// From inside the volume box, cells wholly behind the eye are left out rather than switching the
// footprint off; looking away from the object nothing is covered, looking at it part is.
TEST(PixelFootprint, CameraInsideTheBoxLeavesOutCellsBehindIt) {
    const core::Volume v = test::spherePhantom(64);
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const auto tf = stepTf(0.5f);
    const auto b = v.geometry().worldBounds();
    const glm::dvec3 corner = b[0] + 0.04 * (b[1] - b[0]);  // inside the box, outside the sphere
    const glm::dvec3 centre = 0.5 * (b[0] + b[1]);
    const render::RayCaster caster(v, g, tf, render::RenderOptions{});
    for (bool toward : {false, true}) {
        render::CameraSpec s;
        s.eye = corner;
        s.target = toward ? centre : corner - (centre - corner);
        s.fovYDeg = 100.0;  // wide enough to see past the sphere
        const render::Camera cam(s, b[0], b[1], 40, 40);
        const render::PixelFootprint fp(caster, cam);
        EXPECT_FALSE(fp.coversEverything()) << (toward ? "toward" : "away");
        if (toward) {
            EXPECT_GT(fp.coveredFraction(), 0.05);
            EXPECT_LT(fp.coveredFraction(), 0.95);
        } else {
            EXPECT_EQ(fp.coveredFraction(), 0.0);
        }
        expectFootprintChangesNothing(v, tf, cam, render::Mode::Gradient,
                                      toward ? "toward" : "away");
    }
}

// A built-in model keeps the footprint of the camera it was made for; rendering it with another
// camera (here larger, so a stale mask would be read out of bounds) casts every ray instead.
TEST(PixelFootprint, ModelRenderedWithAnotherCameraIgnoresIt) {
    const core::Volume v = obliqueSphere();
    const grid::BrickGrid g = grid::BrickGrid::build(v);
    const auto tf = stepTf(0.5f);
    render::RenderOptions o;
    o.mode = render::Mode::EmissionAbsorption;  // the gradient mode's headlight follows the camera
    const render::RayCaster caster(v, g, tf, o);
    const render::Camera small = test::orthoCamera(v, 35, 25, 70, 24);
    const render::Camera large = test::orthoCamera(v, 120, -10, 70, 56);
    const auto model = render::makeBuiltinModel(caster, small);
    const core::ImageRGBA a = caster.render(large, *model, core::Progress::none());
    const core::ImageRGBA c = caster.render(large, core::Progress::none());
    ASSERT_EQ(a.pixels.size(), c.pixels.size());
    EXPECT_EQ(0, std::memcmp(a.pixels.data(), c.pixels.data(), a.pixels.size() * sizeof(float)));
}

}  // namespace
}  // namespace voxlight

namespace voxlight {
namespace {

// pipeline's framing stage gives a placed camera (eye and target, and a perspective or an
// orthographic height) the volume's box instead of the visible hull: that is only right if such a
// camera does not depend on the points at all — also with a roll and with `up` along the view.
TEST(Camera, APlacedCameraDoesNotDependOnThePoints) {
    const std::vector<glm::dvec3> hull = {{-20, -5, 3}, {40, 12, 9}, {7, 30, -11}};
    const std::vector<glm::dvec3> box = {{-200, -200, -200}, {200, 200, 200}};
    for (const auto projection :
         {render::Projection::Perspective, render::Projection::Orthographic})
        for (const glm::dvec3 up : {glm::dvec3(0, 0, 1), glm::dvec3(0, 1, 0)})
            for (const double roll : {0.0, 25.0}) {
                render::CameraSpec spec;
                spec.projection = projection;
                spec.eye = glm::dvec3(10, -300, 40);
                spec.target = glm::dvec3(0, 0, 10);
                spec.up = up;  // (0, 1, 0) is nearly the view direction: replaced
                spec.rollDeg = roll;
                spec.orthoHeight = 120.0;
                const render::Camera a(spec, hull, 64, 48), b(spec, box, 64, 48);
                EXPECT_EQ(a.eye(), b.eye());
                EXPECT_EQ(a.forward(), b.forward());
                EXPECT_EQ(a.up(), b.up());
                EXPECT_EQ(a.orthoHeight(), b.orthoHeight());
                EXPECT_EQ(a.pixelMap().rightStep, b.pixelMap().rightStep);
                EXPECT_EQ(a.pixelMap().upStep, b.pixelMap().upStep);
            }
}

TEST(Camera, AnEyeOnTheDefaultTargetIsAnInputErrorNamingTheEye) {
    // Without camera.target the target is the matter's centre; an eye placed there used to give
    // a NaN view direction, reported as the headlight's "light: direction".
    const std::vector<glm::dvec3> box = {{-10, -10, -10}, {10, 10, 10}};
    render::CameraSpec spec;
    spec.eye = glm::dvec3(0.0);
    try {
        const render::Camera c(spec, box, 32, 32);
        ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "camera.eye");
    }
    spec.eye = glm::dvec3(1e-6, 0.0, 0.0);  // a nanometre away: a direction
    spec.target = glm::dvec3(0.0);
    EXPECT_NO_THROW(render::Camera(spec, box, 32, 32));
}

}  // namespace
}  // namespace voxlight
