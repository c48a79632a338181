// SPDX-License-Identifier: MIT
// Thin-lens camera (issue #13 item 5): every lens ray of a pixel meets the pinhole ray in the plane
// in focus, leaves from within the aperture, and the lens points fill the disk uniformly; aperture
// 0 is the pinhole exactly. Autofocus lands where the centre ray has lost half its light, and a
// plane in focus stays sharp while a plane out of focus blurs.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/rng.h"
#include "pathtrace/path_tracer.h"
#include "pathtrace_test_util.h"
#include "render/camera.h"
#include "render/ray_caster.h"

using namespace voxlight;

namespace {
/// Rays are built in double: a focus point is met to this (mm) at distances of ~10³ mm.
constexpr double kFocusTolMm = 1e-9 * 1e3 * 100;

render::Camera camera(render::Projection p = render::Projection::Perspective) {
    render::CameraSpec s;
    s.projection = p;
    s.azimuthDeg = 20, s.elevationDeg = 10;
    return render::Camera(s, glm::dvec3(-50), glm::dvec3(50), 40, 30);
}
}  // namespace

TEST(ThinLens, ApertureZeroIsThePinhole) {
    render::Camera c = camera();
    c.setLens(0.0, 100.0);
    const render::Ray a = c.generateAt(3.3, 7.7), b = c.generateThroughLens(3.3, 7.7, 0.9, 0.1);
    EXPECT_EQ(a.origin, b.origin);
    EXPECT_EQ(a.direction, b.direction);
}

TEST(ThinLens, LensRaysMeetThePinholeRayInThePlaneInFocus) {
    for (const auto proj : {render::Projection::Perspective, render::Projection::Orthographic}) {
        render::Camera c = camera(proj);
        const double aperture = 12.0, focus = 180.0;
        c.setLens(aperture, focus);
        core::CounterRng rng(3);
        glm::dvec2 mean(0.0);
        constexpr int kSamples = 4000;
        for (int i = 0; i < kSamples; ++i) {
            const double px = 40 * rng.uniformDouble(), py = 30 * rng.uniformDouble();
            const render::Ray pin = c.generateAt(px, py);
            const render::Ray r =
                c.generateThroughLens(px, py, rng.uniformDouble(), rng.uniformDouble());
            // Leaves from the lens disk around the pinhole ray's origin, in the image plane.
            const glm::dvec3 off = r.origin - pin.origin;
            EXPECT_NEAR(glm::dot(off, c.forward()), 0.0, 1e-9);
            EXPECT_LE(glm::length(off), 0.5 * aperture + 1e-9);
            mean += glm::dvec2(glm::dot(off, c.right()), glm::dot(off, c.up()));
            // Meets the pinhole ray where that one crosses the plane in focus.
            const double tp = focus / glm::dot(pin.direction, c.forward());
            const glm::dvec3 p = pin.origin + tp * pin.direction;
            const double tr =
                glm::dot(p - r.origin, c.forward()) / glm::dot(r.direction, c.forward());
            EXPECT_LT(glm::length(r.origin + tr * r.direction - p), kFocusTolMm);
            EXPECT_NEAR(glm::length(r.direction), 1.0, 1e-12);
        }
        // Uniform on the disk: the mean offset is 0 within its standard error (radius/2 per axis).
        const double se = 0.5 * (0.5 * aperture) / std::sqrt(double(kSamples));
        EXPECT_LT(std::abs(mean.x / kSamples), 4 * se);
        EXPECT_LT(std::abs(mean.y / kSamples), 4 * se);
    }
}

TEST(ThinLens, BadLensSettingsAreInputErrors) {
    render::Camera c = camera();
    EXPECT_THROW(c.setLens(-1.0, 100.0), InputError);
    EXPECT_THROW(c.setLens(5.0, 0.0), InputError);
    EXPECT_THROW(c.setLens(NAN, 100.0), InputError);
}

namespace {
constexpr float kSigma = 0.2f;  // 1/mm inside the slab
test::Medium makeSlab() {
    return test::makeMedium("slab", test::stepTf(kSigma, glm::vec3(0.8f), "slab"), 32);
}
}  // namespace

TEST(ThinLens, AutofocusFindsWhereTheCentreRayHasLostHalfItsLight) {
    const test::Medium s = makeSlab();
    const pathtrace::PathTracer t = s.tracer();
    // Looking straight down (superior view) onto the slab's top face.
    render::CameraSpec spec;
    spec.elevationDeg = 90.0;
    spec.up = {0, 1, 0};
    const auto b = s.volume->geometry().worldBounds();
    const render::Camera cam(spec, b[0], b[1], 9, 9);
    // Truth by a fine quadrature along the same centre ray (σt is linear within voxels).
    const render::Ray c = cam.generateAt(4.5, 4.5);
    double tau = 0.0, tHalf = -1.0;
    constexpr double dt = 1e-3;
    for (double tt = 0.0; tt < 2e3 && tHalf < 0; tt += dt) {
        const double sg = t.extinctionAt(c.origin + (tt + 0.5 * dt) * c.direction);
        if (tau + sg * dt >= std::numbers::ln2) tHalf = tt + (std::numbers::ln2 - tau) / sg;
        tau += sg * dt;
    }
    ASSERT_GT(tHalf, 0.0);
    // The march takes quarter-voxel midpoint steps through a field linear within voxels: its
    // error is below a hundredth of a voxel (1 mm here).
    EXPECT_NEAR(t.autofocus(cam), tHalf * glm::dot(c.direction, cam.forward()), 0.01);
}

TEST(ThinLens, ThePlaneInFocusStaysSharpAndAPlaneOutOfFocusBlurs) {
    // Seen from above, the slab's top face is an edge against the background at the image's
    // sides. Focused on it, a wide aperture keeps the edge pixels' coverage as the pinhole's; focused
    // far behind it, the edge spreads over more pixels.
    const test::Medium s = makeSlab();
    render::CameraSpec spec;
    spec.azimuthDeg = 0.0, spec.elevationDeg = 0.0;  // side view: the slab is a horizontal band
    const auto b = s.volume->geometry().worldBounds();
    const render::Camera cam(spec, b[0], b[1], 16, 32);
    auto coverage = [&](double aperture, double focus) {
        pathtrace::Options o;
        o.samplesPerPixel = 256;
        o.apertureMm = aperture;
        o.focusMm = focus;
        o.maxBounces = 1;
        const pathtrace::PathTracer t = s.tracer(o);
        const core::ImageRGBA im = t.render(cam, core::Progress::none());
        std::vector<double> column;
        for (int y = 0; y < 32; ++y) column.push_back(im.pixels[(std::size_t(y) * 16 + 8) * 4 + 3]);
        return column;
    };
    // Pixels with partial coverage (neither background nor the band's full opacity).
    auto blurred = [](const std::vector<double>& col) {
        const double top = *std::max_element(col.begin(), col.end());
        int n = 0;
        for (double a : col) n += a > 0.05 * top && a < 0.95 * top;
        return n;
    };
    const double depth = glm::dot(0.5 * (b[0] + b[1]) - cam.eye(), cam.forward());
    const int pin = blurred(coverage(0.0, 0.0));
    const int sharp = blurred(coverage(0.3 * depth, depth));
    const int soft = blurred(coverage(0.3 * depth, 3.0 * depth));
    EXPECT_LE(sharp, pin + 2) << "in focus the band's edges stay where the pinhole puts them";
    EXPECT_GT(soft, pin + 2) << "out of focus the edges spread";
}
