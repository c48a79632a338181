// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "sh/sh_window.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
constexpr double kPi = std::numbers::pi;
// Quadrature-exact projections in float output: float rounding of coefficients of size ≤ ~1.
constexpr double kExactProjectionTol = 1e-6;
// The bar for env projection against per-pixel brute force.
constexpr double kEnvRelTol = 1e-4;
// Gauss–Legendre is exact for the band-limited products here; what is left is double rounding of
// ~10² terms of size ≤ ~10 (measured ~1e-14).
constexpr double kExactQuadratureTol = 1e-12;
// Sample values rounded to float (relative 6e-8) summed over the set: coefficients of size ≤ ~1.
constexpr double kFloatSampleTol = 1e-5;
// Float reconstruction of a delta's projection (values ≤ (L+1)²/4π ≈ 6.4 at L = 8).
constexpr double kFloatPeakTol = 1e-5;
// Where the reconstruction peaks: the 20000-point Fibonacci search spacing is ~0.025 rad.
constexpr double kPeakAngleTol = 0.05;
// The clamped cosine's kink makes 200-node Gauss–Legendre inexact: measured ~1e-6.
constexpr double kKinkQuadratureTol = 2e-5;
// Constant map: c_0 in float (≈ 7.1) and orders m ≠ 0, which vanish by φ symmetry up to rounding.
constexpr double kFloatConstantTol = 1e-5;

std::vector<double> randomCoefficients(int band, std::uint64_t seed) {
    std::vector<double> c(shCount(band));
    core::CounterRng rng(seed);
    for (double& x : c) x = 2.0 * rng.uniformDouble() - 1.0;
    return c;
}
}  // namespace

TEST(ShProjection, BandLimitedFunctionIsRecoveredExactly) {
    constexpr int kL = 8;
    const auto truth = randomCoefficients(kL, 5);
    const SphereSamples q = gaussLegendreSamples(kL + 1);  // degree 2L ≤ 2(L+1)−1
    const auto c =
        projectFunction(kL, q, [&](const glm::dvec3& d) { return shReconstructDouble(truth, d); });
    for (int i = 0; i < shCount(kL); ++i) EXPECT_NEAR(c[i], truth[i], kExactQuadratureTol) << i;

    std::vector<float> values(q.size());
    for (std::size_t k = 0; k < q.size(); ++k)
        values[k] = float(shReconstructDouble(truth, q.directions[k]));
    const auto cf = projectSamples(kL, q, values);
    for (int i = 0; i < shCount(kL); ++i) EXPECT_NEAR(cf[i], truth[i], kFloatSampleTol) << i;
}

TEST(ShProjection, CallableMayReturnRgb) {
    // Three band-limited channels through the dvec3 (and vec3) path: each channel equals the scalar
    // projection bit for bit (same double arithmetic per component) and recovers its truth.
    constexpr int kL = 6;
    const std::vector<double> truth[3] = {randomCoefficients(kL, 11), randomCoefficients(kL, 12),
                                          randomCoefficients(kL, 13)};
    const SphereSamples q = gaussLegendreSamples(kL + 1);
    auto channelF = [&](int ch) {
        return [&, ch](const glm::dvec3& d) { return shReconstructDouble(truth[ch], d); };
    };
    const std::vector<glm::dvec3> rgb = projectFunction(kL, q, [&](const glm::dvec3& d) {
        return glm::dvec3(channelF(0)(d), channelF(1)(d), channelF(2)(d));
    });
    ASSERT_EQ(rgb.size(), std::size_t(shCount(kL)));
    for (int ch = 0; ch < 3; ++ch) {
        const std::vector<double> scalar = projectFunction(kL, q, channelF(ch));
        for (int i = 0; i < shCount(kL); ++i) {
            EXPECT_EQ(rgb[i][ch], scalar[i]) << "channel " << ch << " i=" << i;
            EXPECT_NEAR(rgb[i][ch], truth[ch][i], kExactQuadratureTol) << ch << " " << i;
        }
    }
    // A float vec3 callable is widened to double.
    const std::vector<glm::dvec3> f3 =
        projectFunction(kL, q, [&](const glm::dvec3& d) { return glm::vec3(channelF(0)(d)); });
    for (int i = 0; i < shCount(kL); ++i) EXPECT_NEAR(f3[i].y, truth[0][i], kFloatSampleTol) << i;
}

TEST(ShProjection, DeltaProjectionReconstructsThePeak) {
    // A unit delta at d projects to c_i = Y_i(d); its reconstruction peaks at d with value
    // (L+1)²/(4π) (addition theorem with P_l(1) = 1).
    for (int L : {2, 4, 8}) {
        const glm::dvec3 d = glm::normalize(glm::dvec3(0.3, -0.5, 0.8));
        ShProjector p(L);
        p.add(d, glm::dvec3(1.0));
        const auto c = p.coefficients();
        const double peak = shReconstruct(c, glm::vec3(d));
        EXPECT_NEAR(peak, shCount(L) / (4.0 * kPi), kFloatPeakTol);
        const SphereSamples f = fibonacciSamples(20000);
        double best = -1e9;
        glm::dvec3 arg(0.0);
        for (const auto& w : f.directions) {
            const double v = shReconstruct(c, glm::vec3(w));
            if (v > best) best = v, arg = w;
        }
        EXPECT_LE(best, peak + kFloatPeakTol);
        EXPECT_GT(glm::dot(arg, d), std::cos(kPeakAngleTol))
            << "maximum found away from the delta, L=" << L;
    }
}

TEST(ShProjection, CallableClampedCosineMatchesClosedForm) {
    const glm::dvec3 axis = glm::normalize(glm::dvec3(-1, 2, 0.5));
    const SphereSamples q =
        gaussLegendreSamples(200);  // the kink makes quadrature inexact: ~1e-6 at 200 nodes
    const auto c = projectFunction(
        8, q, [&](const glm::dvec3& d) { return std::max(0.0, glm::dot(d, axis)); });
    const auto ref = zonalToAxis(clampedCosineZonal(8), axis);
    for (int i = 0; i < shCount(8); ++i) EXPECT_NEAR(c[i], ref[i], kKinkQuadratureTol) << i;
}

TEST(ShProjection, EquirectMatchesPerPixelBruteForce) {
    // Brute force: every pixel centre, exact pixel solid angle, Y from the textbook slow path, in
    // double.
    constexpr int kW = 96, kH = 48, kL = 8;
    const EquirectLayout layout{kW, kH, kPi, -2.0 * kPi / kW};
    std::vector<glm::vec3> img(kW * kH);
    core::CounterRng rng(42);
    for (auto& p : img) p = {rng.uniform() * 5.0f, rng.uniform(), rng.uniform() * 0.1f};
    img[7 * kW + 30] = glm::vec3(900.0f, 20.0f, 1.0f);  // a sun
    const auto fast = projectEquirect(kL, layout, img);

    std::vector<glm::dvec3> ref(shCount(kL), glm::dvec3(0.0));
    for (int r = 0; r < kH; ++r) {
        const double t0 = kPi * r / kH, t1 = kPi * (r + 1) / kH;
        const double omega = (2.0 * kPi / kW) * (std::cos(t0) - std::cos(t1));
        for (int c = 0; c < kW; ++c) {
            const double phi = layout.phi0 + layout.phiStep * (c + 0.5);
            for (int l = 0; l <= kL; ++l)
                for (int m = -l; m <= l; ++m)
                    ref[shIndex(l, m)] += glm::dvec3(img[r * kW + c]) * omega *
                                          evalShSlow(l, m, 0.5 * (t0 + t1), phi);
        }
    }
    double scale = 0;
    for (const auto& v : ref)
        scale = std::max({scale, std::abs(v.x), std::abs(v.y), std::abs(v.z)});
    for (int i = 0; i < shCount(kL); ++i)
        for (int ch = 0; ch < 3; ++ch)
            EXPECT_NEAR(fast[i][ch], ref[i][ch], kEnvRelTol * scale)
                << "i=" << i << " channel " << ch;
    EXPECT_THROW(projectEquirect(2, EquirectLayout{0, 0, 0, 1}, {}), InputError);
}

TEST(ShProjection, ConstantEnvironmentHasOnlyDc) {
    // The midpoint rule in θ integrates Y_l0 with error ≈ l(l+1)/24 · (π/H)² relative: at H = 256,
    // L = 4 about 4e-5 of c_0 (≈ 3e-4 absolute); orders m ≠ 0 vanish exactly by the φ symmetry.
    constexpr int kW = 512, kH = 256;
    constexpr double kMidpointTol = 4e-4;
    std::vector<glm::vec3> img(kW * kH, glm::vec3(2.0f));
    const auto c = projectEquirect(4, EquirectLayout{kW, kH, 0.0, 2.0 * kPi / kW}, img);
    EXPECT_NEAR(c[0].x, 2.0 * std::sqrt(4.0 * kPi), kFloatConstantTol);  // ∫ 2 Y_0 = 2·4π/√(4π)
    for (int l = 1; l <= 4; ++l)
        for (int m = -l; m <= l; ++m)
            EXPECT_NEAR(c[shIndex(l, m)].x, 0.0, m == 0 ? kMidpointTol : kFloatConstantTol)
                << l << m;
}
