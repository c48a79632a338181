// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "sh/dsf.h"
#include "sh/sh_basis.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
constexpr double kPi = std::numbers::pi;
// Exact geometric identities (kernel radius = minimum separation, normalised weights, barycentric
// sums, a point on its own triangle) computed in double: a few ulps.
constexpr double kDoubleExactTol = 1e-12;
// Σ A_k = 4π: the basis solid angles come from a quadrature whose weights sum exactly, so only the
// accumulated rounding of ~10⁵ terms remains.
constexpr double kSolidAngleSumTol = 1e-9;
// Barycentric weight of a vertex at the vertex itself: double, but through the triangle search.
constexpr double kVertexWeightTol = 1e-9;
// Integrals of float coefficients (relative 6e-8 each) over ≤ 2562 directions, values ≤ ~10.
constexpr double kFloatIntegralTol = 1e-5;
// Gaussian-weighted mean of a constant 0.7 map: normalised weights, float output.
constexpr double kConstantMeanTol = 1e-5;
// S(ω_k) = s_k for float coefficients in [0, 1): float rounding of the weighted sum.
constexpr float kFloatInterpolationTol = 1e-6f;
// Gaussian prefilter (σ = h/3 ≈ 0.03 rad) of a linear function: the window shrink 1 − σ²/… and its
// truncation at 3σ leave ≲ 2e-3 at |a| ≈ 0.6; a wrong sample position is off by ~h·|a| ≈ 0.04.
constexpr double kPrefilterLinearTol = 5e-3;
// Relative slack for "least squares cannot lose to sampling": rounding of both error sums only.
constexpr double kLeastSquaresSlack = 1e-9;
// The checkerboard's dark value 0.05 as seen through float coefficients.
constexpr double kFloatValueTol = 1e-6;

glm::dvec3 randomDirection(core::CounterRng& rng) {
    const double z = 1 - 2 * rng.uniformDouble(), phi = 2 * kPi * rng.uniformDouble();
    const double r = std::sqrt(1 - z * z);
    return {r * std::cos(phi), r * std::sin(phi), z};
}

const Dsf& dsf642() {
    static const Dsf d(642);
    return d;
}

// Zhang's synthetic high-frequency "checkerboard" environment: 22.5° checks in (θ, φ), values 1 and
// 0.05.
std::vector<glm::vec3> checkerboard(const EquirectLayout& layout) {
    std::vector<glm::vec3> img(std::size_t(layout.width) * layout.height);
    for (int r = 0; r < layout.height; ++r)
        for (int c = 0; c < layout.width; ++c) {
            const int i = int(8.0 * (r + 0.5) / layout.height),
                      j = int(16.0 * (c + 0.5) / layout.width);
            img[std::size_t(r) * layout.width + c] = glm::vec3((i + j) % 2 ? 1.0f : 0.05f);
        }
    return img;
}
}  // namespace

TEST(Dsf, CountsAndKernelRadius) {
    for (int n : {42, 162, 642}) {
        const Dsf d(n);
        EXPECT_EQ(d.size(), n);
        EXPECT_NEAR(d.kernelRadius(), minimumSeparation(d.directions()), kDoubleExactTol);
        double sum = 0;
        for (double a : d.basisSolidAngles()) {
            EXPECT_GT(a, 0.0);
            sum += a;
        }
        EXPECT_NEAR(sum, 4 * kPi, kSolidAngleSumTol);
    }
    EXPECT_THROW(Dsf(100), InputError);
}

TEST(Dsf, BasisSolidAnglesAgreeWithIndependentQuadrature) {
    // A_k come from an equal-weight Fibonacci sum in the constructor (which makes Σ A_k = 4π exact
    // by construction, so CountsAndKernelRadius cannot see a wrong A_k). Check each against a
    // Gauss–Legendre product rule. Measured: 1e-5 (n = 162), 2e-4 (n = 642) relative.
    constexpr double kAreaRelTol = 1e-3;
    const SphereSamples q = gaussLegendreSamples(400);
    for (int n : {162, 642}) {
        const Dsf d(n);
        std::vector<double> ref(n, 0.0);
        int idx[Dsf::kMaxSupport];
        double w[Dsf::kMaxSupport];
        for (std::size_t k = 0; k < q.size(); ++k) {
            const int m = d.weights(q.directions[k], idx, w);
            for (int j = 0; j < m; ++j) ref[idx[j]] += w[j] * q.weights[k];
        }
        for (int k = 0; k < n; ++k)
            ASSERT_NEAR(d.basisSolidAngles()[k], ref[k], kAreaRelTol * ref[k]) << "n=" << n;
    }
}

TEST(Dsf, EnergyConservingProjectionOfAConstantMapIsConstant) {
    // 256×128 pixels (1.4°) against kernel radii 14.5°, 6.8°, 3.3°: before pixels were split into
    // sub-cells, n = 2562 gave a constant map coefficients up to 15 % off. Measured now: ≤ 7e-4
    // (pixel quadrature of A_k plus the 4e-4 error of A_k itself).
    constexpr double kConstantTol = 2e-3;
    constexpr int kW = 256, kH = 128;
    const EquirectLayout layout{kW, kH, kPi, -2 * kPi / kW};
    const std::vector<glm::vec3> img(kW * kH, glm::vec3(0.7f));
    for (int n : {162, 642, 2562}) {
        const Dsf d(n);
        const auto s = d.projectEquirect(layout, img, glm::dmat3(1.0));
        for (int k = 0; k < n; ++k) ASSERT_NEAR(s[k].x, 0.7, 0.7 * kConstantTol) << "n=" << n;
        // Energy conservation is kept exactly: Σ A_k s_k = Σ_p L_p Ω_p = 0.7 · 4π.
        EXPECT_NEAR(d.integrate(s).x, 0.7 * 4 * kPi, kFloatIntegralTol) << "n=" << n;
    }
}

TEST(Dsf, InterpolatesAtItsDirections) {
    const Dsf& d = dsf642();
    std::vector<float> s(d.size());
    core::CounterRng rng(1);
    for (float& v : s) v = rng.uniform();
    for (int k = 0; k < d.size(); ++k)
        ASSERT_NEAR(d.evaluate(s, d.directions()[k]), s[k], kFloatInterpolationTol) << k;
}

TEST(Dsf, LocalLookupEqualsBruteForceKernel) {
    const Dsf& d = dsf642();
    const double h = d.kernelRadius();
    core::CounterRng rng(2);
    int idx[Dsf::kMaxSupport];
    double w[Dsf::kMaxSupport];
    for (int t = 0; t < 3000; ++t) {
        const glm::dvec3 x = randomDirection(rng);
        std::vector<double> ref(d.size(), 0.0);
        double sum = 0;
        for (int k = 0; k < d.size(); ++k) {
            const double th = std::acos(std::clamp(glm::dot(x, d.directions()[k]), -1.0, 1.0));
            if (th < h) sum += ref[k] = std::pow(h * h - th * th, 3);
        }
        ASSERT_GT(sum, 0.0) << "a direction with no DSF direction within h";
        const int n = d.weights(x, idx, w);
        double got = 0;
        int nonzero = 0;
        for (double r : ref) nonzero += r > 0;
        ASSERT_EQ(n, nonzero);
        for (int j = 0; j < n; ++j) {
            ASSERT_NEAR(w[j], ref[idx[j]] / sum, kDoubleExactTol);
            got += w[j];
        }
        ASSERT_NEAR(got, 1.0, kDoubleExactTol);
    }
}

TEST(Dsf, DirectionalLightIsABarycentricBlend) {
    const Dsf& d = dsf642();
    core::CounterRng rng(3);
    for (int t = 0; t < 500; ++t) {
        const glm::dvec3 x = randomDirection(rng);
        int idx[3];
        double b[3];
        d.barycentric(x, idx, b);
        // Σ b_k ω_k is the ray's hit on the triangle's plane: parallel to x.
        glm::dvec3 p(0.0);
        for (int i = 0; i < 3; ++i) {
            ASSERT_GE(b[i], 0.0);
            p += b[i] * d.directions()[idx[i]];
        }
        ASSERT_NEAR(b[0] + b[1] + b[2], 1.0, kDoubleExactTol);
        ASSERT_GT(glm::dot(glm::normalize(p), x), 1.0 - kDoubleExactTol);
        // Irradiance is conserved: Σ A_k s_k = E.
        std::vector<glm::vec3> s(d.size(), glm::vec3(0.0f));
        d.addDirectional(s, x, glm::vec3(3.0f, 2.0f, 1.0f));
        const glm::dvec3 e = d.integrate(s);
        ASSERT_NEAR(e.x, 3.0, kFloatIntegralTol);
        ASSERT_NEAR(e.z, 1.0, kFloatIntegralTol);
    }
    // At a DSF direction the light lands on that direction alone.
    int idx[3];
    double b[3];
    d.barycentric(d.directions()[17], idx, b);
    for (int i = 0; i < 3; ++i)
        if (idx[i] == 17) {
            EXPECT_NEAR(b[i], 1.0, kVertexWeightTol);
        }
}

TEST(Dsf, PrefilteredSamplingOfSmoothAndConstantMaps) {
    const Dsf& d = dsf642();
    constexpr int kW = 256, kH = 128;
    const EquirectLayout layout{kW, kH, 0.0, 2 * kPi / kW};
    std::vector<glm::vec3> img(kW * kH, glm::vec3(0.7f));
    for (const auto& v : d.sampleEquirect(layout, img)) ASSERT_NEAR(v.x, 0.7f, kConstantMeanTol);
    // A linear function f = 1 + ω·a: the Gaussian mean of a linear function over a symmetric window
    // is (1 + cos-shrink · ω_k·a); with σ = h/3 ≈ 0.03 rad the shrink 1 − σ² ≈ 0.999.
    const glm::dvec3 a(0.3, 0.2, -0.5);
    for (int r = 0; r < kH; ++r)
        for (int c = 0; c < kW; ++c) {
            const glm::dvec3 w =
                sphericalToDirection(kPi * (r + 0.5) / kH, 2 * kPi * (c + 0.5) / kW);
            img[r * kW + c] = glm::vec3(float(1.0 + glm::dot(w, a)));
        }
    const auto s = d.sampleEquirect(layout, img);
    for (int k = 0; k < d.size(); ++k)
        ASSERT_NEAR(s[k].x, 1.0 + glm::dot(d.directions()[k], a), kPrefilterLinearTol) << k;
}

// Zhang et al. 2013 Fig. 7 on their synthetic checkerboard: DSF vs SH with a similar coefficient
// count. Prints the table (run the test binary, or ctest -V). What reproduces, and is asserted: DSF
// beats SH once SH is windowed (Hanning) so that it does not ring negative — the form SH lighting
// must take — and DSF error falls with n. What does not reproduce: plain SH truncation has the
// *lower* L2 error here. Note that "SH truncation is L2-optimal" alone does not decide this — it is
// optimal only within the SH span, and DSF spans a different space of similar dimension. The test
// therefore also computes the L2-optimal DSF coefficients (least squares on the same pixels, by
// conjugate gradients): even those lose to plain SH (measured 59.0 % vs 55.0 % at n = 162, 44.9 %
// vs 41.6 % at n = 642), so no choice of DSF coefficients reproduces the paper's plain-SH claim on
// this map; the paper's numbers cannot be matched without changing the metric.
namespace {
// Least-squares fit of DSF coefficients to one channel of the grid: min Σ_p Ω_p (S(ω_p) − f_p)².
// Returns the relative L2 error of the fit (same metric as compareDsfWithSh).
double l2OptimalDsfError(const Dsf& d, const EquirectLayout& layout,
                         const std::vector<glm::vec3>& img) {
    struct Pixel {
        int n;
        int idx[Dsf::kMaxSupport];
        double w[Dsf::kMaxSupport];
        double omega, f;
    };
    std::vector<Pixel> px;
    double norm = 0;
    for (int r = 0; r < layout.height; ++r) {
        const double t0 = kPi * r / layout.height, t1 = kPi * (r + 1) / layout.height;
        for (int c = 0; c < layout.width; ++c) {
            Pixel p;
            p.omega = std::abs(layout.phiStep) * (std::cos(t0) - std::cos(t1));
            p.f = img[std::size_t(r) * layout.width + c].x;
            p.n = d.weights(
                sphericalToDirection(0.5 * (t0 + t1), layout.phi0 + layout.phiStep * (c + 0.5)),
                p.idx, p.w);
            norm += p.omega * p.f * p.f;
            px.push_back(p);
        }
    }
    const int n = d.size();
    auto applyGram = [&](const std::vector<double>& x, std::vector<double>& y) {
        std::fill(y.begin(), y.end(), 0.0);
        for (const Pixel& p : px) {
            double v = 0;
            for (int j = 0; j < p.n; ++j) v += p.w[j] * x[p.idx[j]];
            for (int j = 0; j < p.n; ++j) y[p.idx[j]] += p.omega * p.w[j] * v;
        }
    };
    std::vector<double> x(n, 0.0), r(n, 0.0), q(n), ap(n);
    for (const Pixel& p : px)
        for (int j = 0; j < p.n; ++j) r[p.idx[j]] += p.omega * p.f * p.w[j];
    std::vector<double> dir = r;
    double rr = 0;
    for (double v : r) rr += v * v;
    const double rr0 = rr;
    for (int it = 0; it < 2000 && rr > 1e-24 * rr0; ++it) {
        applyGram(dir, ap);
        double pap = 0;
        for (int k = 0; k < n; ++k) pap += dir[k] * ap[k];
        const double alpha = rr / pap;
        double rrNew = 0;
        for (int k = 0; k < n; ++k) {
            x[k] += alpha * dir[k];
            r[k] -= alpha * ap[k];
            rrNew += r[k] * r[k];
        }
        for (int k = 0; k < n; ++k) dir[k] = r[k] + rrNew / rr * dir[k];
        rr = rrNew;
    }
    double e = 0;
    for (const Pixel& p : px) {
        double v = 0;
        for (int j = 0; j < p.n; ++j) v += p.w[j] * x[p.idx[j]];
        e += p.omega * (v - p.f) * (v - p.f);
    }
    return std::sqrt(e / norm);
}
}  // namespace

TEST(Dsf, Fig7DsfBeatsShOnHighFrequencyEnvironment) {
    constexpr int kW = 512, kH = 256;
    const EquirectLayout layout{kW, kH, 0.0, 2 * kPi / kW};
    const auto img = checkerboard(layout);
    const int counts[] = {42, 162, 642};
    const auto rows = compareDsfWithSh(layout, img, counts);
    std::printf(
        "\nZhang 2013 Fig. 7 (synthetic checkerboard, 22.5° checks, %dx%d): relative L2 error\n",
        kW, kH);
    std::printf(
        "  DSF n | DSF error | DSF energy-cons. | SH L | SH coeffs | SH error | SH+Hanning\n");
    for (const auto& r : rows)
        std::printf("  %5d | %8.2f%% | %15.2f%% | %4d | %9d | %7.2f%% | %9.2f%%\n", r.dsfCount,
                    100 * r.dsfError, 100 * r.dsfProjectedError, r.shBand, r.shCount,
                    100 * r.shError, 100 * r.shHanningError);
    // At n = 42 the 22.5° checks are beyond both bases (both keep little more than the mean, errors
    // equal to 0.01 %), so the comparison is asserted for 162 and 642 only.
    for (const auto& r : rows) {
        if (r.dsfCount < 162) continue;
        EXPECT_LT(r.dsfError, r.shHanningError)
            << "DSF " << r.dsfCount << " vs windowed SH band " << r.shBand;
        EXPECT_GT(r.dsfError, r.shError)
            << "plain SH beat DSF so far; if DSF wins now, update the comment above and the report";
        // The best any DSF coefficients can do on this map (grey: the red channel is the error).
        const double optimal = l2OptimalDsfError(Dsf(r.dsfCount), layout, img);
        std::printf("  DSF n = %d, L2-optimal coefficients: %.2f%%\n", r.dsfCount, 100 * optimal);
        EXPECT_LE(optimal, r.dsfError * (1 + kLeastSquaresSlack))
            << "least squares must not lose to sampling";
        EXPECT_GT(optimal, r.shError) << "DSF (even L2-optimal) now beats plain SH: update the "
                                         "comment above and the report";
        RecordProperty("dsf" + std::to_string(r.dsfCount) + "_error", std::to_string(r.dsfError));
        RecordProperty("sh" + std::to_string(r.shCount) + "_error", std::to_string(r.shError));
    }
    // More directions → smaller error (Zhang Fig. 6).
    EXPECT_LT(rows[2].dsfError, rows[1].dsfError);
    EXPECT_LT(rows[1].dsfError, rows[0].dsfError);
}

TEST(Dsf, ReconstructionOfNonNegativeLightStaysNonNegative) {
    // Weights are ≥ 0 and prefiltering averages, so a non-negative environment never reconstructs
    // negative — unlike truncated SH (checked on the same checkerboard at band 24).
    constexpr int kW = 256, kH = 128;
    const EquirectLayout layout{kW, kH, 0.0, 2 * kPi / kW};
    const auto img = checkerboard(layout);
    const auto s = dsf642().sampleEquirect(layout, img);
    const auto c = projectEquirect(24, layout, img);
    const auto red = channel(c, 0);
    const SphereSamples test = fibonacciSamples(5000);
    double dsfMin = INFINITY, shMin = INFINITY;
    for (const auto& d : test.directions) {
        dsfMin = std::min(dsfMin, double(dsf642().evaluateRgb(s, d).x));
        shMin = std::min(shMin, double(shReconstruct(red, glm::vec3(d))));
    }
    EXPECT_GE(dsfMin, 0.05 - kFloatValueTol);  // the checkerboard's dark value
    EXPECT_LT(shMin, 0.0);
}
