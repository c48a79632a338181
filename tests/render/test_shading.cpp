// SPDX-License-Identifier: MIT
// Blinn–Phong shader against its closed form: the tabulated specular power stays within its
// interpolation bound, and a shaded sample equals ambient + diffuse·(n·l) + specular·(n·h)^n.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "render/dvr_march.h"
#include "render/shading.h"

using namespace voxlight;

namespace {
/// Bound of linear interpolation of x^n on cells of width h: n(n − 1)·h² / 8 (plus float rounding).
double tableBound(double n) {
    const double h = 1.0 / render::kSpecularTableCells;
    return n * (n - 1.0) * h * h / 8.0 + 4e-7;
}
}  // namespace

TEST(BlinnPhong, SpecularPowerTableStaysWithinItsInterpolationBound) {
    for (const float n : {2.f, 8.f, 24.f, 100.f, 256.f}) {
        render::BlinnPhongParams p;
        p.shininess = n;
        const render::BlinnPhongShader s(p, {});
        double worst = 0.0;
        for (int i = 0; i <= 100000; ++i) {
            const float x = float(i) / 100000.f;
            worst = std::max(worst, std::abs(double(s.specularPower(x)) - std::pow(double(x), n)));
        }
        EXPECT_LE(worst, tableBound(n)) << "shininess " << n;
        EXPECT_GT(worst, 0.0) << "shininess " << n << ": the table path should be in use";
    }
}

TEST(BlinnPhong, ShininessOutsideTheTableRangeIsExact) {
    for (const float n : {0.5f, 1.f, 300.f, 1000.f}) {
        render::BlinnPhongParams p;
        p.shininess = n;
        const render::BlinnPhongShader s(p, {});
        for (const float x : {0.f, 0.001f, 0.3f, 0.9f, 0.999f, 1.f})
            EXPECT_FLOAT_EQ(s.specularPower(x), std::pow(x, n)) << n << " " << x;
    }
}

TEST(BlinnPhong, ScatterMatchesTheClosedForm) {
    render::BlinnPhongParams p;  // defaults: 0.25 / 0.75 / 0.25, n = 24
    const glm::vec3 travel = glm::normalize(glm::vec3(0.3f, -0.2f, -1.f));
    const glm::vec3 radiance(1.f, 0.5f, 2.f);
    const std::vector<std::shared_ptr<const lights::Light>> ls = {
        std::make_shared<lights::DirectionalLight>(radiance, -travel)};
    const render::BlinnPhongShader s(p, ls);
    render::ShadeInput in;
    in.position = glm::vec3(0.f);
    in.toEye = glm::normalize(glm::vec3(-0.1f, 0.2f, 1.f));
    for (const glm::vec3 n : {glm::vec3(0, 0, 1), glm::normalize(glm::vec3(0.2f, -0.1f, 1.f)),
                              glm::normalize(glm::vec3(1.f, 0.f, 0.1f))}) {
        in.normal = n;
        const render::Scatter sc = s.scatter(in);
        const glm::dvec3 ld = -glm::dvec3(travel), nd(n), ed(in.toEye);
        const double ndl = glm::dot(nd, ld);
        const double ndh = glm::dot(nd, glm::normalize(ld + ed));
        for (int c = 0; c < 3; ++c) {
            const double diffuse = p.ambient + (ndl > 0 ? p.diffuse * ndl * radiance[c] : 0.0);
            const double spec = ndl > 0 && ndh > 0
                                    ? p.specular * std::pow(ndh, double(p.shininess)) * radiance[c]
                                    : 0.0;
            EXPECT_NEAR(sc.diffuse[c], diffuse, 1e-5);
            EXPECT_NEAR(sc.specular[c], spec,
                        2.f * radiance[c] * p.specular * tableBound(24) + 1e-5);
        }
    }
}

// The marcher's opacity α = 1 − e^(−τ) (series for thin segments, Eigen's inline exp above)
// against −expm1(−τ) in double over τ ∈ [1e-8, 88] (log-spaced, 2·10⁵ values).
TEST(Opacity, MatchesOneMinusExpIncludingThinSegments) {
    // Series branch: a few float roundings (≈ 6e-8 each) plus truncation (4e-8 at τ = 0.01).
    constexpr double kSeriesRelTol = 3e-7;
    // Exp branch: ≈ 2 ulp of e^(−τ) near 1 (1.2e-7 absolute), relative to α ≥ 0.00995.
    constexpr double kExpRelTol = 1.5e-5;
    double worstSeries = 0.0, worstExp = 0.0;
    constexpr int kN = 200000;
    for (int i = 0; i <= kN; ++i) {
        const float tau = float(std::pow(10.0, -8.0 + 9.94 * i / kN));  // 1e-8 … 8.7e1
        const float alpha = render::detail::opacity(tau);
        const double want = -std::expm1(-double(tau));
        const double rel = std::abs(alpha - want) / want;
        double& worst = tau < render::detail::kOpacitySeriesTau ? worstSeries : worstExp;
        worst = std::max(worst, rel);
        ASSERT_GE(alpha, 0.f) << tau;
        ASSERT_LE(alpha, 1.f) << tau;
    }
    EXPECT_LE(worstSeries, kSeriesRelTol);
    EXPECT_LE(worstExp, kExpRelTol);
    std::printf("opacity: worst relative error %.2g (series), %.2g (exp)\n", worstSeries, worstExp);
    // The plain float form would fail the series tolerance by orders of magnitude at τ = 1e-6.
    EXPECT_GT(std::abs((1.f - std::exp(-1e-6f)) - 1e-6) / 1e-6, 100 * kSeriesRelTol);
    for (const float tau : {88.f, 100.f, 1e6f, INFINITY})
        EXPECT_EQ(render::detail::opacity(tau), 1.f) << tau;
    EXPECT_EQ(render::detail::opacity(0.f), 0.f);
    EXPECT_EQ(render::detail::expInline(0.f), 1.f);
}
