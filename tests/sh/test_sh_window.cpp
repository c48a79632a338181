// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/error.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "sh/sh_window.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
constexpr double kPi = std::numbers::pi;
// Closed-form band weights and window factors in double: a few ulps of values ≤ π.
constexpr double kClosedFormTol = 1e-14;
constexpr double kWindowFactorTol = 1e-15;  // values ≤ 1, one cos or sin
// Gauss–Legendre with 2000 nodes across the clamped cosine's kink: measured ~1e-7.
constexpr double kKinkZonalTol = 1e-6;
// Band-8 irradiance of a delta light vs max(n·d, 0): the truncation residual is ≈ 1 %.
constexpr double kBand8IrradianceTol = 0.02;
// "Non-negative" after the Gaussian window, relative to c_0: float reconstruction noise only.
constexpr double kNonNegativeRelTol = 1e-5;
// Zonal rotation vs 200-node projection of a smooth (t⁸) lobe with a kink of order 8 at t = 0.
constexpr double kZonalToAxisTol = 1e-6;
// The raw delta's negative lobe is at least 5 % of c_0 (so the windows have something to remove),
// and Hanning/Lanczos must at least halve it.
constexpr double kRawLobeAtLeast = 0.05;
constexpr double kWindowLobeShrink = 0.5;

double minOver(std::span<const float> c, const SphereSamples& s) {
    double mn = INFINITY;
    for (const auto& d : s.directions) mn = std::min(mn, double(shReconstruct(c, glm::vec3(d))));
    return mn;
}
}  // namespace

TEST(ShWindow, ClampedCosineBandWeightsClosedForm) {
    // Ramamoorthi & Hanrahan 2001: Â_l = π, 2π/3, π/4, 0, −π/24, 0, π/64.
    const auto a = clampedCosineConvolution(8);
    EXPECT_NEAR(a[0], kPi, kClosedFormTol);
    EXPECT_NEAR(a[1], 2 * kPi / 3, kClosedFormTol);
    EXPECT_NEAR(a[2], kPi / 4, kClosedFormTol);
    EXPECT_NEAR(a[3], 0.0, kClosedFormTol);
    EXPECT_NEAR(a[4], -kPi / 24, kClosedFormTol);
    EXPECT_NEAR(a[5], 0.0, kClosedFormTol);
    EXPECT_NEAR(a[6], kPi / 64, kClosedFormTol);
    // Against Gauss–Legendre projection of max(t, 0) (kink at 0: the rule with an even node count
    // is still ~1e-7).
    const auto z = projectZonal(
        8, [](double t) { return std::max(t, 0.0); }, 2000);
    const auto zc = clampedCosineZonal(8);
    for (int l = 0; l <= 8; ++l) EXPECT_NEAR(z[l], zc[l], kKinkZonalTol) << l;
}

TEST(ShWindow, ConvolutionWithClampedCosineIsIrradiance) {
    // Irradiance from a unit directional light at d onto normal n is max(n·d, 0). With L = δ_d,
    // E_lm = Â_l Y_lm(d); up to the band-limit this must approach max(n·d, 0): check at band 8,
    // where the residual is ≈ 1 %.
    const glm::dvec3 d = glm::normalize(glm::dvec3(1, 1, 1));
    ShProjector p(8);
    p.add(d, glm::dvec3(1.0));
    auto e = p.coefficients();
    convolveZonal(e, clampedCosineZonal(8));
    for (const glm::dvec3 n : {d, glm::dvec3(0, 0, 1), glm::dvec3(1, 0, 0), -d}) {
        EXPECT_NEAR(shReconstruct(e, glm::vec3(n)), std::max(0.0, glm::dot(n, d)),
                    kBand8IrradianceTol)
            << n.x << n.y << n.z;
    }
}

TEST(ShWindow, WindowFactorsAreMonotoneAndKeepDc) {
    for (auto w : {ShWindow::Hanning, ShWindow::Lanczos, ShWindow::Gaussian}) {
        const auto f = windowFactors(w, 8, 0.05);
        EXPECT_EQ(f[0], 1.0);
        for (int l = 1; l <= 8; ++l) {
            EXPECT_LE(f[l], f[l - 1]) << toString(w);
            EXPECT_GE(f[l], 0.0);
        }
    }
    EXPECT_NEAR(windowFactors(ShWindow::Hanning, 3, 0)[2], 0.5 * (1 + std::cos(kPi * 2 / 4)),
                kWindowFactorTol);
    EXPECT_NEAR(windowFactors(ShWindow::Lanczos, 3, 0)[1], std::sin(kPi / 4) / (kPi / 4),
                kWindowFactorTol);
    EXPECT_EQ(parseShWindow("lanczos"), ShWindow::Lanczos);
    EXPECT_THROW(parseShWindow("hamming"), InputError);
    EXPECT_THROW(windowFactors(ShWindow::Gaussian, 4, -1.0), InputError);
}

TEST(ShWindow, WindowingReducesRingingOfADelta) {
    // A delta light ≥ 0 reconstructs with negative lobes; Hanning and Lanczos shrink them, the
    // Gaussian search removes them on the test set.
    const glm::dvec3 d(0, 0, 1);
    ShProjector p(6);
    p.add(d, glm::dvec3(1.0));
    const auto raw = p.coefficients();
    const SphereSamples test = fibonacciSamples(4000);
    const double rawMin = minOver(raw, test);
    ASSERT_LT(rawMin, -kRawLobeAtLeast * raw[0]);
    for (auto w : {ShWindow::Hanning, ShWindow::Lanczos}) {
        auto c = raw;
        applyWindow(c, w);
        EXPECT_GT(minOver(c, test), kWindowLobeShrink * rawMin) << toString(w);
        EXPECT_EQ(c[0], raw[0]);
    }
    const double lambda = nonNegativeGaussianStrength(raw, test);
    EXPECT_GT(lambda, 0.0);
    auto c = raw;
    applyWindow(c, ShWindow::Gaussian, lambda);
    EXPECT_GE(minOver(c, test), -kNonNegativeRelTol * raw[0]);
    // A slightly weaker window is not enough (λ is the smallest to 1e-4).
    auto weaker = raw;
    applyWindow(weaker, ShWindow::Gaussian, 0.97 * lambda);
    EXPECT_LT(minOver(weaker, test), 0.0);
}

TEST(ShWindow, ZonalToAxisMatchesDirectProjection) {
    // A narrow cosine lobe max(ω·a, 0)^8 about a tilted axis.
    const glm::dvec3 axis = glm::normalize(glm::dvec3(0.2, -0.9, 0.3));
    const auto zonal = projectZonal(8, [](double t) { return t > 0 ? std::pow(t, 8) : 0.0; });
    const auto c = zonalToAxis(zonal, axis);
    const auto direct = projectFunction(8, gaussLegendreSamples(200), [&](const glm::dvec3& w) {
        const double t = glm::dot(w, axis);
        return t > 0 ? std::pow(t, 8) : 0.0;
    });
    for (int i = 0; i < shCount(8); ++i) EXPECT_NEAR(c[i], direct[i], kZonalToAxisTol) << i;
    EXPECT_THROW(zonalToAxis(zonal, glm::dvec3(0.0)), InputError);
}
