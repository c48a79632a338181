// SPDX-License-Identifier: MIT
// Hybrid scattering in the path tracer (path_tracer.h, Kroes et al. 2012 eq. 1–2): phase mode and
// gradient_factor 0 are today's images bit for bit (also with a TF carrying surface channels);
// the same image for any thread count; a zero-gradient medium never takes the BRDF (no NaN
// normal); a hybrid torso render is finite and non-negative; and a BRDF-only optically thick slab
// under a directional light matches its closed form (z-test).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/phantoms.h"
#include "grid/brick_grid.h"
#include "lights/environment_light.h"
#include "lights/light.h"
#include "optics/presets.h"
#include "pathtrace/brdf.h"
#include "pathtrace/path_tracer.h"
#include "pathtrace_test_util.h"
#include "render/ray_caster.h"

using namespace voxlight;
using pathtrace::PathTracer;
using pathtrace::Scattering;
using test::makeMedium;
using test::Medium;

namespace {

/// z-tests pass within this many standard errors (fixed seed; 3σ fails a correct estimator with
/// probability 0.27 %).
constexpr double kZ = 3.0;

/// A torso TF (soft tissue faint, bone dense) with or without the surface channels.
optics::TransferFunction torsoTf(bool surface) {
    std::vector<optics::TfPoint> p = {{-200.f, {0.9f, 0.8f, 0.7f}, 0.f, {}},
                                      {300.f, {0.9f, 0.8f, 0.7f}, 0.3f, {}},
                                      {2000.f, {0.9f, 0.9f, 0.9f}, 0.5f, {}}};
    if (surface)
        for (auto& q : p) q.specular = glm::vec3(0.3f), q.roughness = 0.4f;
    return optics::TransferFunction(p, {900.f, 2200.f}, surface ? "bone-glossy" : "bone");
}

render::Camera torsoCamera(const Medium& s, int w = 24, int h = 20) {
    const auto b = s.volume->geometry().worldBounds();
    return render::Camera(render::CameraSpec{}, b[0], b[1], w, h);
}

pathtrace::Options torsoOptions() {
    pathtrace::Options o;
    o.samplesPerPixel = 4;
    o.maxBounces = 4;
    o.phaseG = 0.3f;
    o.lights = {std::make_shared<lights::DirectionalLight>(glm::vec3(2.f), glm::vec3(1, -1, 2))};
    return o;
}

}  // namespace

TEST(HybridScattering, PhaseModeAndGradientFactorZeroAreTodaysImageBitForBit) {
    const Medium plain = makeMedium("torso", torsoTf(false), 32);
    const Medium glossy = makeMedium("torso", torsoTf(true), 32);
    const render::Camera cam = torsoCamera(plain);
    pathtrace::Options o = torsoOptions();
    const core::ImageRGBA today = plain.tracer(o).render(cam, core::Progress::none());
    // Surface channels in the TF change nothing under the phase function.
    EXPECT_EQ(glossy.tracer(o).render(cam, core::Progress::none()).pixels, today.pixels);
    // Hybrid with g_f = 0: P_brdf = 0 everywhere, no random number drawn for the choice.
    o.scattering = Scattering::Hybrid;
    o.gradientFactor = 0.f;
    pathtrace::Stats st;
    EXPECT_EQ(glossy.tracer(o).render(cam, core::Progress::none(), &st).pixels, today.pixels);
    EXPECT_EQ(st.surfaceEvents, 0u);
    // And g_f > 0 does change it (the comparison above can fail).
    o.gradientFactor = 1.f;
    EXPECT_NE(glossy.tracer(o).render(cam, core::Progress::none(), &st).pixels, today.pixels);
    EXPECT_GT(st.surfaceEvents, 0u);
}

TEST(HybridScattering, TheImageIsTheSameForAnyThreadCount) {
    const Medium s = makeMedium("torso", torsoTf(true), 32);
    const render::Camera cam = torsoCamera(s);
    pathtrace::Options o = torsoOptions();
    o.scattering = Scattering::Hybrid;
    o.gradientFactor = 1.f;
    o.threads = 1;
    const core::ImageRGBA one = s.tracer(o).render(cam, core::Progress::none());
    o.threads = 2;
    const core::ImageRGBA two = s.tracer(o).render(cam, core::Progress::none());
    EXPECT_EQ(one.pixels, two.pixels);
}

TEST(HybridScattering, AZeroGradientMediumNeverTakesTheBrdf) {
    // A constant field under a constant TF: homogeneous, ∇s = 0 everywhere. Brdf and hybrid modes
    // fall back to the phase function (no normal, no NaN): the phase image, bit for bit.
    core::Geometry g;
    g.dims = {12, 12, 12};
    g.spacing = glm::dvec3(2.0);
    auto v = std::make_shared<core::Volume>(g, core::VoxelType::Float32);
    const glm::vec3 a(0.8f);
    const optics::TransferFunction tf(
        {{-1.f, a, 0.05f, {}, glm::vec3(0.5f), 0.2f}, {1.f, a, 0.05f, {}, glm::vec3(0.5f), 0.2f}},
        {0.f, 2.f}, "constant");
    Medium s;
    s.volume = v;
    s.table = std::make_shared<optics::TfTable>(tf);
    render::RenderOptions ro;
    ro.mode = render::Mode::EmissionAbsorption;
    s.cells = std::make_shared<grid::BrickMajorants>(
        render::buildSkipCells(*v, grid::BrickGrid::build(*v), tf, *s.table, ro));
    const auto b = v->geometry().worldBounds();
    const glm::dvec3 c = 0.5 * (b[0] + b[1]);
    pathtrace::Options o;
    o.samplesPerPixel = 4;
    o.maxBounces = 8;
    o.lights = {std::make_shared<lights::DirectionalLight>(glm::vec3(1.f), glm::vec3(0, 0, 1)),
                std::make_shared<lights::PointLight>(glm::vec3(100.f), c, 1.0)};
    const render::Camera cam(render::CameraSpec{}, b[0], b[1], 12, 12);
    const core::ImageRGBA phase = s.tracer(o).render(cam, core::Progress::none());
    for (Scattering mode : {Scattering::Brdf, Scattering::Hybrid}) {
        o.scattering = mode;
        o.gradientFactor = 1.f;
        const PathTracer t = s.tracer(o);
        EXPECT_EQ(t.brdfProbabilityAt(c), 0.0);
        pathtrace::Stats st;
        const core::ImageRGBA im = t.render(cam, core::Progress::none(), &st);
        for (float x : im.pixels) ASSERT_TRUE(std::isfinite(x) && x >= 0.f);
        EXPECT_EQ(st.surfaceEvents, 0u);
        EXPECT_EQ(im.pixels, phase.pixels);
    }
}

TEST(HybridScattering, ATorsoRenderIsFiniteAndNonNegative) {
    const Medium s = makeMedium("torso", optics::makePreset("ct-bone"), 32);
    const render::Camera cam = torsoCamera(s, 32, 32);
    for (Scattering mode : {Scattering::Hybrid, Scattering::Brdf}) {
        pathtrace::Options o = torsoOptions();
        o.scattering = mode;
        o.gradientFactor = 1.f;
        o.maxBounces = 6;
        pathtrace::Stats st;
        const core::ImageRGBA im = s.tracer(o).render(cam, core::Progress::none(), &st);
        double sum = 0.0;
        for (float x : im.pixels) {
            ASSERT_TRUE(std::isfinite(x) && x >= 0.f);
            sum += x;
        }
        EXPECT_GT(sum, 0.0);
        EXPECT_GT(st.surfaceEvents, 0u);
        EXPECT_EQ(st.majorantViolations, 0u);
    }
}

TEST(HybridScattering, ABrdfOnlyOpaqueSlabMatchesTheClosedForm) {
    // An optically thick slab (σt 20/mm, 2.5 mm voxels: τ > 40 within the first voxel of matter)
    // seen straight from above, lit by a directional light at θ from the normal. The field varies
    // only in z, so every collision (all within the ±1-voxel ramp where ∇s ≠ 0) has the normal
    // ±z, flipped up. In a stratified medium a camera ray collides at optical depth τ with density
    // e^{−τ}, and the shadow ray toward the light leaves with transmittance e^{−τ/μl}, so
    //   L = f(wo, wi) · μl · E · ∫ e^{−τ} e^{−τ/μl} dτ = f · μl · E · μl / (1 + μl)
    // whatever the σt profile across the ramp.
    const float sigma = 20.f;
    optics::TransferFunction tf({{0.f, {0.7f, 0.5f, 0.3f}, 0.f, {}, glm::vec3(0.2f), 0.5f},
                                 {0.499f, {0.7f, 0.5f, 0.3f}, 0.f, {}, glm::vec3(0.2f), 0.5f},
                                 {0.501f, {0.7f, 0.5f, 0.3f}, sigma, {}, glm::vec3(0.2f), 0.5f},
                                 {1.f, {0.7f, 0.5f, 0.3f}, sigma, {}, glm::vec3(0.2f), 0.5f}},
                                {0.5f, 1.f}, "opaque-slab");
    const Medium s = makeMedium("slab", tf, 16);
    const double theta = 40.0 * std::numbers::pi / 180.0;
    const glm::dvec3 toLight(std::sin(theta), 0.0, std::cos(theta));
    const double E = 3.0;
    pathtrace::Options o;
    o.samplesPerPixel = 4096;
    o.maxBounces = 1;
    o.scattering = Scattering::Brdf;
    o.lights = {
        std::make_shared<lights::DirectionalLight>(glm::vec3(float(E)), glm::vec3(toLight))};
    render::CameraSpec spec;
    spec.projection = render::Projection::Orthographic;
    spec.elevationDeg = 90.0;
    spec.orthoHeight = 10.0;  // mm: the centre of the slab, far from its sides
    const auto b = s.volume->geometry().worldBounds();
    const render::Camera cam(spec, b[0], b[1], 4, 4);
    pathtrace::Stats st;
    core::ImageRGBA se;
    const core::ImageRGBA im = s.tracer(o).render(cam, core::Progress::none(), &st, &se);
    const glm::dvec3 wo = -cam.forward();
    const glm::dvec3 n(0.0, 0.0, wo.z > 0.0 ? 1.0 : -1.0);
    ASSERT_GT(glm::dot(n, toLight), 0.0) << "camera and light on the same side";
    const double mu = glm::dot(n, toLight);
    const pathtrace::SurfaceMaterial m{{0.7, 0.5, 0.3}, glm::dvec3(0.2), 0.5};
    const glm::dvec3 expected = pathtrace::evalBrdf(m, n, wo, toLight) * (mu * E * mu / (1.0 + mu));
    EXPECT_EQ(st.surfaceEvents, st.realCollisions) << "every collision on the ramp";
    for (int c = 0; c < 3; ++c) {
        double mean = 0.0, var = 0.0;
        for (int y = 0; y < 4; ++y)
            for (int x = 0; x < 4; ++x) {
                mean += im.at(x, y)[c] / 16.0;
                var += double(se.at(x, y)[c]) * se.at(x, y)[c] / 256.0;
            }
        EXPECT_NEAR(mean, expected[c], kZ * std::sqrt(var) + 1e-6) << "channel " << c;
        EXPECT_GT(var, 0.0);
    }
}

TEST(HybridScattering, TheBrdfProbabilityFollowsKroes) {
    // P_brdf = α · (1 − exp(−25 g_f³ |∇s|_n)) at a point on the slab's ramp, from the gradient the
    // tracer reports: α of one voxel step, |∇s|_n per voxel over the data's range [0, 1].
    optics::TransferFunction tf = test::stepTf(0.3f, glm::vec3(0.8f), "ramp");
    const Medium s = makeMedium("slab", tf, 16);
    const core::SlabFacts f = core::slabPhantomFacts(s.volume->geometry());
    const auto b = s.volume->geometry().worldBounds();
    const glm::dvec3 p(0.5 * (b[0].x + b[1].x), 0.5 * (b[0].y + b[1].y), f.zMax - 0.1);
    const double h = s.volume->geometry().spacing.z;
    for (float gf : {0.25f, 0.5f, 1.f}) {
        pathtrace::Options o;
        o.scattering = Scattering::Hybrid;
        o.gradientFactor = gf;
        const PathTracer t = s.tracer(o);
        glm::dvec3 grad;
        const double pb = t.brdfProbabilityAt(p, &grad);
        ASSERT_GT(glm::length(grad), 0.0);
        const double alpha = 1.0 - std::exp(-double(t.extinctionAt(p)) * h);
        const double expected =
            alpha * (1.0 - std::exp(-25.0 * gf * gf * gf * glm::length(grad) * h / 1.0));
        EXPECT_NEAR(pb, expected, 1e-9 * expected) << "g_f " << gf;
        EXPECT_GT(pb, 0.0);
        EXPECT_LT(pb, 1.0);
    }
}

TEST(HybridScattering, ATfPhaseGChannelReplacesTheMethodsPhaseG) {
    // g = 0.6 on every point of the TF renders exactly as phase_g 0.6 with a TF without the
    // channel, whatever the method's phase_g says; and differs from the method's g alone.
    optics::TransferFunction plain = torsoTf(false);
    std::vector<optics::TfPoint> p = plain.points();
    for (auto& q : p) q.phaseG = 0.6f;
    const optics::TransferFunction withG(p, plain.window(), "bone-g");
    const Medium a = makeMedium("torso", plain, 32), b = makeMedium("torso", withG, 32);
    const render::Camera cam = torsoCamera(a);
    pathtrace::Options o = torsoOptions();
    o.phaseG = 0.6f;
    const core::ImageRGBA expected = a.tracer(o).render(cam, core::Progress::none());
    o.phaseG = -0.5f;
    EXPECT_EQ(b.tracer(o).render(cam, core::Progress::none()).pixels, expected.pixels);
    EXPECT_NE(a.tracer(o).render(cam, core::Progress::none()).pixels, expected.pixels);
}

TEST(HybridScattering, ABrdfOnlyOpaqueSlabUnderAUniformSkyMatchesTheQuadrature) {
    // As above under a uniform environment of radiance 1 (light sampling and BRDF sampling
    // combined by MIS, single scattering): in the stratified medium the shadow ray toward ωi
    // leaves with e^{−τ/μi}, so L = ∫ f(wo, ωi) μi · μi / (1 + μi) dωi over the upper hemisphere,
    // here by midpoint quadrature (roughness 0.5: the lobe is resolved).
    const pathtrace::SurfaceMaterial m{{0.7, 0.5, 0.3}, glm::dvec3(0.3), 0.5};
    std::vector<optics::TfPoint> pts = {{0.f, {0.7f, 0.5f, 0.3f}, 0.f, {}},
                                        {0.499f, {0.7f, 0.5f, 0.3f}, 0.f, {}},
                                        {0.501f, {0.7f, 0.5f, 0.3f}, 20.f, {}},
                                        {1.f, {0.7f, 0.5f, 0.3f}, 20.f, {}}};
    for (auto& p : pts) p.specular = glm::vec3(0.3f), p.roughness = 0.5f;
    const Medium s =
        makeMedium("slab", optics::TransferFunction(pts, {0.5f, 1.f}, "opaque-slab"), 16);
    core::ImageRGBA sky(16, 8);
    for (std::size_t p = 0; p < sky.pixels.size(); ++p) sky.pixels[p] = 1.f;
    pathtrace::Options o;
    o.samplesPerPixel = 1024;
    o.maxBounces = 1;
    o.scattering = Scattering::Brdf;
    o.lights = {std::make_shared<lights::EnvironmentLight>(sky, lights::EnvironmentOptions{})};
    render::CameraSpec spec;
    spec.projection = render::Projection::Orthographic;
    spec.elevationDeg = 90.0;
    spec.orthoHeight = 10.0;
    const auto b = s.volume->geometry().worldBounds();
    const render::Camera cam(spec, b[0], b[1], 4, 4);
    core::ImageRGBA se;
    const core::ImageRGBA im = s.tracer(o).render(cam, core::Progress::none(), nullptr, &se);
    const glm::dvec3 wo = -cam.forward();
    const glm::dvec3 n(0.0, 0.0, wo.z > 0.0 ? 1.0 : -1.0);
    // The quadrature over the hemisphere of n (θ from n, 256 × 512 cells).
    glm::dvec3 t1, t2;
    t1 = glm::normalize(glm::cross(n, glm::dvec3(1.0, 0.0, 0.0)));
    t2 = glm::cross(n, t1);
    glm::dvec3 expected(0.0);
    constexpr int kTheta = 256, kPhi = 512;
    const double dt = 0.5 * std::numbers::pi / kTheta, dp = 2.0 * std::numbers::pi / kPhi;
    for (int i = 0; i < kTheta; ++i) {
        const double t = (i + 0.5) * dt, mu = std::cos(t), st = std::sin(t);
        for (int j = 0; j < kPhi; ++j) {
            const double p = (j + 0.5) * dp;
            const glm::dvec3 wi = st * std::cos(p) * t1 + st * std::sin(p) * t2 + mu * n;
            expected += pathtrace::evalBrdf(m, n, wo, wi) * (mu * mu / (1.0 + mu) * st * dt * dp);
        }
    }
    // The quadrature's own error (relative; lobe 14° wide against 0.35° cells) is far below this.
    constexpr double kQuadratureTol = 2e-3;
    for (int c = 0; c < 3; ++c) {
        double mean = 0.0, var = 0.0;
        for (int y = 0; y < 4; ++y)
            for (int x = 0; x < 4; ++x) {
                mean += im.at(x, y)[c] / 16.0;
                var += double(se.at(x, y)[c]) * se.at(x, y)[c] / 256.0;
            }
        EXPECT_NEAR(mean, expected[c], kZ * std::sqrt(var) + kQuadratureTol * expected[c])
            << "channel " << c;
        EXPECT_GT(var, 0.0);
    }
}
