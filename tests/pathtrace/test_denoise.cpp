// SPDX-License-Identifier: MIT
// The path tracer's denoiser (pathtrace/denoise.h): no bias in flat regions, no blur across an edge
// of the guides, nothing done where the error is already small (bit for bit), closer to the
// converged image than the raw estimate at low spp on the torso phantom, the same for any thread
// count — and the guides themselves.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>

#include "core/rng.h"
#include "optics/presets.h"
#include "pathtrace/denoise.h"
#include "pathtrace/path_tracer.h"
#include "pathtrace_test_util.h"

using namespace voxlight;
using pathtrace::denoise;
using pathtrace::DenoiseOptions;
using pathtrace::Guides;

namespace {

constexpr int kW = 64, kH = 64;

/// Constant guides: albedo 0.5, normal +z, depth 100 mm.
Guides flatGuides(int w = kW, int h = kH) {
    Guides g;
    g.width = w;
    g.height = h;
    g.albedo.assign(std::size_t(w) * h, glm::vec3(0.5f));
    g.normal.assign(std::size_t(w) * h, glm::vec3(0.f, 0.f, 1.f));
    g.depth.assign(std::size_t(w) * h, 100.f);
    return g;
}

/// A grey image truth(x) + Gaussian noise of standard deviation `sigma` (fixed seed), and its
/// standard-error image (sigma everywhere, as the path tracer would estimate it).
struct Noisy {
    core::ImageRGBA mean, stdError;
};
template <class Truth>
Noisy noisyImage(Truth truth, float sigma, int w = kW, int h = kH, std::uint64_t seed = 7) {
    Noisy n{core::ImageRGBA(w, h), core::ImageRGBA(w, h)};
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            core::CounterRng rng(core::hashCounters(std::uint64_t(y) * w + x, seed));
            // Box–Muller.
            const double u1 = 1.0 - rng.uniformDouble(), u2 = rng.uniformDouble();
            const float g =
                float(std::sqrt(-2.0 * std::log(u1)) * std::cos(2 * std::numbers::pi * u2));
            const float v = truth(x, y) + sigma * g;
            float* p = n.mean.at(x, y);
            p[0] = p[1] = p[2] = v;
            p[3] = 1.f;
            float* s = n.stdError.at(x, y);
            s[0] = s[1] = s[2] = sigma;
            s[3] = 1.f;
        }
    return n;
}

double meanRed(const core::ImageRGBA& im, int x0 = 0, int x1 = kW) {
    double s = 0.0;
    for (int y = 0; y < im.height; ++y)
        for (int x = x0; x < x1; ++x) s += im.at(x, y)[0];
    return s / (double(x1 - x0) * im.height);
}

double rmsRedAround(const core::ImageRGBA& im, float truth) {
    double s = 0.0;
    for (int y = 0; y < im.height; ++y)
        for (int x = 0; x < im.width; ++x) s += std::pow(im.at(x, y)[0] - truth, 2);
    return std::sqrt(s / (double(im.width) * im.height));
}

}  // namespace

TEST(Denoise, AFlatNoisyRegionKeepsItsMeanAndLosesItsNoise) {
    // Truth 1, noise 20 %: full strength (20 % ≥ 8 × 1 %).
    const Noisy n = noisyImage([](int, int) { return 1.f; }, 0.2f);
    pathtrace::DenoiseStats st;
    const core::ImageRGBA out = denoise(n.mean, n.stdError, flatGuides(), {}, &st);
    // The filter is a normalised average: the image mean moves by far less than its own standard
    // error over 4096 pixels (0.2 / 64 = 0.003).
    constexpr double kFlatMeanTol = 0.005;
    EXPECT_NEAR(meanRed(out), meanRed(n.mean), kFlatMeanTol);
    EXPECT_NEAR(meanRed(out), 1.0, kFlatMeanTol + 3 * 0.2 / 64);
    // And the noise is mostly gone: at least this factor less RMS error.
    constexpr double kNoiseReduction = 4.0;
    EXPECT_LT(rmsRedAround(out, 1.f) * kNoiseReduction, rmsRedAround(n.mean, 1.f))
        << rmsRedAround(out, 1.f) << " vs " << rmsRedAround(n.mean, 1.f);
    EXPECT_DOUBLE_EQ(st.fullFraction, 1.0);
}

TEST(Denoise, AnEdgeInTheGuidesIsNotBlurredAcross) {
    // A radiance step (0.5 | 0.6) well inside the noise (σ 0.15): only the guides can keep it.
    const auto step = [](int x, int) { return x < kW / 2 ? 0.5f : 0.6f; };
    const Noisy n = noisyImage(step, 0.15f);
    // Contrast kept across the two columns at the edge, averaged over the rows (the truth is 0.1;
    // blurred by the filter's footprint it would be about half of that).
    constexpr double kMinContrast = 0.08;
    auto edgeContrast = [](const core::ImageRGBA& im) {
        return meanRed(im, kW / 2, kW / 2 + 2) - meanRed(im, kW / 2 - 2, kW / 2);
    };
    // An albedo step in the guides.
    Guides albedoStep = flatGuides();
    for (int y = 0; y < kH; ++y)
        for (int x = kW / 2; x < kW; ++x)
            albedoStep.albedo[std::size_t(y) * kW + x] = glm::vec3(0.6f);
    const core::ImageRGBA a = denoise(n.mean, n.stdError, albedoStep, {});
    EXPECT_GT(edgeContrast(a), kMinContrast);
    // A depth step (100 → 160 mm) in the guides.
    Guides depthStep = flatGuides();
    for (int y = 0; y < kH; ++y)
        for (int x = kW / 2; x < kW; ++x) depthStep.depth[std::size_t(y) * kW + x] = 160.f;
    const core::ImageRGBA d = denoise(n.mean, n.stdError, depthStep, {});
    EXPECT_GT(edgeContrast(d), kMinContrast);
    // Both sides still denoised (each side's RMS error well below the input's).
    for (const core::ImageRGBA* im : {&a, &d}) {
        double s = 0.0;
        for (int y = 0; y < kH; ++y)
            for (int x = 0; x < kW; ++x) s += std::pow(im->at(x, y)[0] - step(x, y), 2);
        EXPECT_LT(std::sqrt(s / (kW * kH)), 0.5 * 0.15);
    }
    // Without the guides' edge the step blurs: the test can tell.
    const core::ImageRGBA blurred = denoise(n.mean, n.stdError, flatGuides(), {});
    EXPECT_LT(edgeContrast(blurred), kMinContrast);
}

TEST(Denoise, ZeroVarianceOrAnErrorBelowTheTargetLeavesTheImageBitForBit) {
    const Noisy n =
        noisyImage([](int x, int y) { return 0.2f + 0.01f * float((x * 7 + y) % 13); }, 0.f);
    pathtrace::DenoiseStats st;
    EXPECT_EQ(denoise(n.mean, n.stdError, flatGuides(), {}, &st).pixels, n.mean.pixels);
    EXPECT_EQ(st.filteredFraction, 0.0);
    // A relative error of 0.9 % under a 1 % target: untouched too; above it: filtered.
    Noisy small = noisyImage([](int, int) { return 1.f; }, 0.009f);
    EXPECT_EQ(denoise(small.mean, small.stdError, flatGuides(), {}).pixels, small.mean.pixels);
    DenoiseOptions tight;
    tight.targetError = 0.005;
    EXPECT_NE(denoise(small.mean, small.stdError, flatGuides(), tight).pixels, small.mean.pixels);
}

TEST(Denoise, TheStrengthFadesAsTheErrorFalls) {
    // The same pattern at falling noise: the strength goes 1 → partial → 0.
    double last = 2.0;
    for (float sigma : {0.2f, 0.05f, 0.02f, 0.005f}) {
        const Noisy n = noisyImage([](int, int) { return 1.f; }, sigma);
        pathtrace::DenoiseStats st;
        denoise(n.mean, n.stdError, flatGuides(), {}, &st);
        EXPECT_LT(st.meanStrength, last) << sigma;
        last = st.meanStrength;
    }
    EXPECT_EQ(last, 0.0);
}

TEST(Denoise, TheSameForAnyThreadCount) {
    // Large enough that both threads take rows.
    constexpr int kSide = 512;
    const Noisy n = noisyImage([](int x, int) { return x < 20 ? 0.3f : 1.f; }, 0.2f, kSide, kSide);
    Guides g = flatGuides(kSide, kSide);
    for (std::size_t p = 0; p < g.depth.size(); ++p) g.depth[p] = 100.f + float(p % 17);
    DenoiseOptions o;
    o.threads = 1;
    const core::ImageRGBA one = denoise(n.mean, n.stdError, g, o);
    o.threads = 2;
    EXPECT_EQ(denoise(n.mean, n.stdError, g, o).pixels, one.pixels);
}

using test::nrmse;

TEST(Denoise, GuidesAreTheSameForAnyThreadCountAndSeeTheVolume) {
    const test::Medium s = test::torsoMedium();
    const auto b = s.volume->geometry().worldBounds();
    // Large enough that both threads take rows.
    const render::Camera cam(render::CameraSpec{}, b[0], b[1], 128, 96);
    pathtrace::Options o;
    o.threads = 1;
    const Guides one = s.tracer(o).guides(cam);
    o.threads = 2;
    const Guides two = s.tracer(o).guides(cam);
    EXPECT_EQ(one.albedo, two.albedo);
    EXPECT_EQ(one.normal, two.normal);
    EXPECT_EQ(one.depth, two.depth);
    // The centre sees matter (albedo ≈ 0.8–0.9, a normal), a corner the background (0).
    const std::size_t centre = std::size_t(48) * 128 + 64;
    EXPECT_GT(one.albedo[centre].x, 0.5f);
    EXPECT_GT(glm::length(one.normal[centre]), 0.1f);
    EXPECT_EQ(one.albedo[0], glm::vec3(0.f));
    EXPECT_GT(one.depth[0], one.depth[centre]);
}

TEST(Denoise, AtLowSppItIsCloserToTheConvergedTorsoThanTheRawEstimate) {
    const test::Medium s = test::torsoMedium();
    const auto b = s.volume->geometry().worldBounds();
    const render::Camera cam(render::CameraSpec{}, b[0], b[1], 48, 40);
    pathtrace::Options o;
    o.samplesPerPixel = 1024;
    o.seed = 99;  // independent of the low-spp renders
    const core::ImageRGBA converged = s.tracer(o).render(cam, core::Progress::none());
    o.seed = 1;
    const pathtrace::PathTracer tracer = s.tracer(o);
    const Guides g = tracer.guides(cam);
    // Denoised NRMSE at most this fraction of the raw one (measured 0.36 at 4 spp and 0.42 at 16 with σℓ = 3; 0.34 and 0.41 with 4 — this small
    // headlit scene is the one where 3 did slightly worse).
    constexpr double kImprovement = 0.5;
    for (int spp : {4, 16}) {
        o.samplesPerPixel = spp;
        core::ImageRGBA se;
        const core::ImageRGBA raw = s.tracer(o).render(cam, core::Progress::none(), nullptr, &se);
        const core::ImageRGBA den = denoise(raw, se, g, {});
        const double eRaw = nrmse(raw, converged), eDen = nrmse(den, converged);
        EXPECT_LT(eDen, kImprovement * eRaw)
            << spp << " spp: raw " << eRaw << ", denoised " << eDen;
        std::printf("%d spp: NRMSE raw %.4f, denoised %.4f\n", spp, eRaw, eDen);
    }
    // 1 spp: no variance of its own (the tracer reports 0, and the filter returned the raw
    // image); with the neighbourhood's spread standing in, it denoises like the others.
    o.samplesPerPixel = 1;
    core::ImageRGBA se;
    const core::ImageRGBA raw = s.tracer(o).render(cam, core::Progress::none(), nullptr, &se);
    EXPECT_EQ(denoise(raw, se, g, {}).pixels, raw.pixels);  // why the stand-in is needed
    const core::ImageRGBA den = denoise(raw, pathtrace::neighbourhoodStdError(raw), g, {});
    const double eRaw = nrmse(raw, converged), eDen = nrmse(den, converged);
    EXPECT_LT(eDen, kImprovement * eRaw) << "1 spp: raw " << eRaw << ", denoised " << eDen;
    std::printf("1 spp (neighbourhood variance): NRMSE raw %.4f, denoised %.4f\n", eRaw, eDen);
}
