// SPDX-License-Identifier: MIT
// White furnace (issue #13): a medium of albedo 1 without emission inside a uniform environment of
// radiance 1, seen against a background of 1, is invisible under multiple scattering — every
// pixel's radiance is 1 within its noise, whatever the phase function. Energy lost or created
// anywhere in the multiple-scattering estimator (roulette, MIS weights, phase sampling, NEE to the
// environment) shows as a departure; single scattering must fall short (the test can fail).
#include <gtest/gtest.h>

#include <cmath>

#include "lights/environment_light.h"
#include "pathtrace/path_tracer.h"
#include "pathtrace_test_util.h"
#include "render/ray_caster.h"

using namespace voxlight;

namespace {

/// Pixels pass within this many of their own standard errors (fixed seed: deterministic).
constexpr double kZ = 4.0;
/// σt inside the sphere (1/mm): thick enough that most light entering scatters many times
/// (checked below), thin enough that paths escape in tens of bounces.
constexpr float kSigma = 0.5f;
constexpr int kMaxBounces = 1000;  // albedo 1 never plays roulette: paths end by escaping

struct Furnace {
    test::Medium medium;
    std::shared_ptr<const lights::Light> environment;
};

Furnace makeFurnace() {
    Furnace f;
    f.medium = test::makeMedium("sphere", test::stepTf(kSigma, glm::vec3(1.f), "white"), 24);
    core::ImageRGBA sky(16, 8);
    for (std::size_t p = 0; p < sky.pixels.size(); ++p) sky.pixels[p] = 1.f;
    f.environment = std::make_shared<lights::EnvironmentLight>(sky, lights::EnvironmentOptions{});
    return f;
}

struct Outcome {
    double worstZ = 0.0, mean = 0.0;
    int covered = 0;
};

Outcome furnace(float g, int maxBounces) {
    const Furnace f = makeFurnace();
    pathtrace::Options o;
    o.samplesPerPixel = 512;
    o.maxBounces = maxBounces;
    o.phaseG = g;
    o.pixelJitter = false;
    o.background = glm::vec3(1.f);
    o.lights = {f.environment};
    const pathtrace::PathTracer tracer = f.medium.tracer(o);
    const auto b = f.medium.volume->geometry().worldBounds();
    const render::Camera cam(render::CameraSpec{}, b[0], b[1], 8, 8);
    core::ImageRGBA se;
    const core::ImageRGBA im = tracer.render(cam, core::Progress::none(), nullptr, &se);
    Outcome out;
    double sum = 0.0;
    for (std::size_t p = 0; p < im.pixels.size() / 4; ++p) {
        if (!(im.pixels[p * 4 + 3] > 0.5f)) continue;  // mostly through the sphere
        for (int c = 0; c < 3; ++c) {
            const double v = im.pixels[p * 4 + c], e = se.pixels[p * 4 + c];
            EXPECT_TRUE(std::isfinite(v));
            out.worstZ = std::max(out.worstZ, std::abs(v - 1.0) / std::max(e, 1e-12));
        }
        sum += im.pixels[p * 4 + 1];
        ++out.covered;
    }
    out.mean = out.covered ? sum / out.covered : 0.0;
    return out;
}

}  // namespace

TEST(WhiteFurnace, TheMediumIsThickEnoughToMatter) {
    const Furnace f = makeFurnace();
    const pathtrace::PathTracer tracer = f.medium.tracer();
    const auto b = f.medium.volume->geometry().worldBounds();
    const glm::dvec3 c = 0.5 * (b[0] + b[1]);
    core::CounterRng rng(7);
    double T = 0.0;
    for (int i = 0; i < 200; ++i)
        T += tracer.transmittance({{c.x, c.y, b[0].z - 5.0}, {0, 0, 1}}, 1e3, rng);
    EXPECT_LT(T / 200, 0.01) << "the furnace would be trivially white";
}

TEST(WhiteFurnace, IsotropicMultipleScatteringReturnsTheEnvironment) {
    const Outcome o = furnace(0.f, kMaxBounces);
    ASSERT_GT(o.covered, 8);
    EXPECT_LT(o.worstZ, kZ) << "mean " << o.mean;
}

TEST(WhiteFurnace, ForwardScatteringReturnsTheEnvironment) {
    const Outcome o = furnace(0.6f, kMaxBounces);
    ASSERT_GT(o.covered, 8);
    EXPECT_LT(o.worstZ, kZ) << "mean " << o.mean;
}

TEST(WhiteFurnace, SingleScatteringLosesLight) {
    const Outcome o = furnace(0.f, 1);
    ASSERT_GT(o.covered, 8);
    EXPECT_LT(o.mean, 0.9) << "one bounce cannot return all the light of a thick medium";
}
