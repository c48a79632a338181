// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>
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
// Constant map: c_0 in float (≈ 7.1) and bands l ≥ 1, which vanish under exact per-patch
// integration up to rounding.
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

// Brute force for projectEquirect: every pixel a constant over its patch, ∫ Y over the patch by a
// tensor Gauss–Legendre rule of patchNodes² points in (θ, φ) with sin θ, Y from the textbook slow
// path, in double — independent of the separable fast path. Gauss–Legendre is not exact for
// cos(mφ) over a wide patch: 12 nodes leave 1.6e-5 on Y_44 over a whole circle, 32 nodes < 1e-12.
std::vector<glm::dvec3> equirectBruteForce(int maxBand, const EquirectLayout& layout,
                                           const std::vector<glm::vec3>& img, int patchNodes) {
    const int kPatchNodes = patchNodes;
    std::vector<double> x, wx;
    gaussLegendre(kPatchNodes, x, wx);
    std::vector<glm::dvec3> ref(shCount(maxBand), glm::dvec3(0.0));
    const int w = layout.width, h = layout.height;
    std::vector<double> patch(shCount(maxBand));
    for (int r = 0; r < h; ++r) {
        const double t0 = kPi * r / h, t1 = kPi * (r + 1) / h;
        for (int c = 0; c < w; ++c) {
            const double p0 = layout.phi0 + layout.phiStep * c;
            const double p1 = p0 + layout.phiStep;
            std::fill(patch.begin(), patch.end(), 0.0);
            for (int i = 0; i < kPatchNodes; ++i)
                for (int j = 0; j < kPatchNodes; ++j) {
                    const double theta = 0.5 * (t0 + t1) + 0.5 * (t1 - t0) * x[i];
                    const double phi = 0.5 * (p0 + p1) + 0.5 * (p1 - p0) * x[j];
                    const double wt =
                        0.25 * (t1 - t0) * std::abs(p1 - p0) * wx[i] * wx[j] * std::sin(theta);
                    for (int l = 0; l <= maxBand; ++l)
                        for (int m = -l; m <= l; ++m)
                            patch[shIndex(l, m)] += wt * evalShSlow(l, m, theta, phi);
                }
            for (int k = 0; k < shCount(maxBand); ++k)
                ref[k] += glm::dvec3(img[std::size_t(r) * w + c]) * patch[k];
        }
    }
    return ref;
}

TEST(ShProjection, EquirectMatchesPerPatchBruteForce) {
    constexpr int kW = 24, kH = 12, kL = 6;
    const EquirectLayout layout{kW, kH, kPi, -2.0 * kPi / kW};
    std::vector<glm::vec3> img(kW * kH);
    core::CounterRng rng(42);
    for (auto& p : img) p = {rng.uniform() * 5.0f, rng.uniform(), rng.uniform() * 0.1f};
    img[3 * kW + 10] = glm::vec3(900.0f, 20.0f, 1.0f);  // a sun
    const auto fast = projectEquirect(kL, layout, img);
    const auto ref = equirectBruteForce(kL, layout, img, 12);  // patches 30° wide
    double scale = 0;
    for (const auto& v : ref)
        scale = std::max({scale, std::abs(v.x), std::abs(v.y), std::abs(v.z)});
    for (int i = 0; i < shCount(kL); ++i)
        for (int ch = 0; ch < 3; ++ch)
            EXPECT_NEAR(fast[i][ch], ref[i][ch], kEnvRelTol * scale)
                << "i=" << i << " channel " << ch;
    EXPECT_THROW(projectEquirect(2, EquirectLayout{0, 0, 0, 1}, {}), InputError);
}

TEST(ShProjection, ConstantEnvironmentHasOnlyDcAtAnySize) {
    // Exact per-patch integration: a uniform map has no band above 0 at any size — the midpoint
    // rule in θ gave a 2×1 map c_20 ≈ −0.63·c_0 (gradient shading +41 %) and a 512×256 one ≈ 1e-4.
    for (const auto& [w, h] :
         {std::pair{2, 1}, std::pair{4, 2}, std::pair{3, 5}, std::pair{512, 256}}) {
        std::vector<glm::vec3> img(std::size_t(w) * h, glm::vec3(2.0f));
        const auto c = projectEquirect(4, EquirectLayout{w, h, 0.0, 2.0 * kPi / w}, img);
        EXPECT_NEAR(c[0].x, 2.0 * std::sqrt(4.0 * kPi), kFloatConstantTol) << w << "x" << h;
        for (int l = 1; l <= 4; ++l)
            for (int m = -l; m <= l; ++m)
                EXPECT_NEAR(c[shIndex(l, m)].x, 0.0, kFloatConstantTol)
                    << w << "x" << h << " l=" << l << " m=" << m;
    }
}

TEST(ShProjection, TwoPixelMapsProjectTheirHemispheresExactly) {
    // A 1×2 map (upper hemisphere 1, lower 0) and a 2×1 map (φ ∈ [0, π) 1, the rest 0): their
    // projections against the brute force (independent) and the closed form c_0 = 2π/√(4π).
    const std::vector<glm::vec3> upper{glm::vec3(1.0f), glm::vec3(0.0f)};
    for (const auto& layout :
         {EquirectLayout{1, 2, 0.0, 2.0 * kPi}, EquirectLayout{2, 1, 0.0, kPi}}) {
        const auto c = projectEquirect(4, layout, upper);
        const auto ref = equirectBruteForce(4, layout, upper, 32);
        EXPECT_NEAR(c[0].x, 2.0 * kPi / std::sqrt(4.0 * kPi), kFloatConstantTol);
        for (int i = 0; i < shCount(4); ++i)
            EXPECT_NEAR(c[i].x, ref[i].x, kFloatConstantTol)
                << layout.width << "x" << layout.height << " i=" << i;
    }
}
