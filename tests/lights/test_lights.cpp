// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <numbers>

#include "core/error.h"
#include "core/rng.h"
#include "lights/area_light.h"
#include "lights/light.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"

using namespace voxlight;
using namespace voxlight::lights;

// Counts every heap allocation of this test program, so the span overloads can be shown not to
// allocate.
namespace {
std::atomic<long> gAllocations{0};
}
void* operator new(std::size_t n) {
    ++gAllocations;
    if (void* p = std::malloc(n ? n : 1)) return p;
    throw std::bad_alloc();
}
// GCC pairs the inlined replacement operator new with this free and calls them mismatched
// (-Wmismatched-new-delete); they are the matched pair here, by design.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace {
constexpr double kPi = std::numbers::pi;
const double kSqrt4Pi = std::sqrt(4.0 * kPi);
// Float rounding of values ≈ 1 (ulp 1.2e-7) and ≈ 10–30 (ulp ≤ 1.9e-6): exact formulas in float.
constexpr double kUnitValueTol = 1e-6;
constexpr double kTensValueTol = 1e-5;
// Double closed forms (solid angle of a cone): a few ulps.
constexpr double kDoubleTol = 1e-12;
// Float SH/DSF coefficients (E·Y_i, size ≤ ~3) computed two ways.
constexpr double kFloatCoeffTol = 1e-6;
// Σ A_k s_k = E holds exactly for the barycentric blend; float coefficients summed over 162.
constexpr double kFloatIntegralTol = 1e-5;
// Point light near its clamp (E = 25): c_0·√(4π) in float, and the coefficient change across a
// 2e-6 mm step at d = minDistance or from d = 1e-7 to 0 (continuous blend, slope ~E/minDistance).
constexpr double kPointDcTol = 1e-4;
constexpr double kPointContinuityTol = 1e-4;
// ∫ L dω = E at every distance is exact in both bases; float coefficients of E ≤ 25.
constexpr double kPointPowerTol = 1e-3;
// Sampler checks: pdf() recomputes the density from the float wi (cone / plane hit of a rounded
// direction); radiance() returns Le itself.
constexpr double kPdfRelTol = 2e-3;
constexpr double kRadianceTol = 1e-6;
// Monte-Carlo mean within 5σ of the estimator, plus 0.1 % for the float pdfs.
constexpr double kSamplerSigmas = 5.0;
constexpr double kSamplerRelBias = 1e-3;
// Sphere light: the 600-node reference's cone-edge error is ~1e-3 of c_0; the DSF's 16×32 cone
// cells each keep their power, so only float sums remain.
constexpr double kConeEdgeRelTol = 2e-3;
constexpr double kSphereDsfPowerRelTol = 1e-3;
// Planar lights: 32² midpoint cells of the emitter (c_0 of the rectangle), plus the 400-node
// reference's error at the emitter's edges (higher rectangle coefficients); the disk's polar cells
// are coarsest at the rim.
constexpr double kRectMidpointRelTol = 2e-3;
constexpr double kRectShRelTol = 5e-3;
constexpr double kDiskQuadratureRelTol = 3e-3;

const sh::Dsf& dsf162() {
    static const sh::Dsf d(162);
    return d;
}

// Solid angle of triangle (a, b, c) seen from x (Van Oosterom & Strackee).
double triangleSolidAngle(const glm::dvec3& x, glm::dvec3 a, glm::dvec3 b, glm::dvec3 c) {
    a = glm::normalize(a - x), b = glm::normalize(b - x), c = glm::normalize(c - x);
    return 2.0 * std::atan2(std::abs(glm::dot(a, glm::cross(b, c))),
                            1.0 + glm::dot(a, b) + glm::dot(b, c) + glm::dot(c, a));
}

// Monte-Carlo check of a light's sampler: E[value/pdf] = ∫ L dω = Le·Ω, and pdf() agrees with
// sample().
void checkSampler(const Light& light, const glm::dvec3& x, double expectedIntegral, double le) {
    constexpr int kN = 40000;
    double sum = 0, sum2 = 0;
    for (int i = 0; i < kN; ++i) {
        core::CounterRng rng(i, 99);
        const LightSample s = light.sample(x, {rng.uniform(), rng.uniform()});
        double v = 0;
        if (s.pdf > 0) {
            v = s.value.x / s.pdf;
            ASSERT_NEAR(light.pdf(x, s.wi), s.pdf, kPdfRelTol * s.pdf) << light.toString();
            ASSERT_NEAR(light.radiance(x, s.wi).x, le, kRadianceTol) << light.toString();
        }
        sum += v, sum2 += v * v;
    }
    const double mean = sum / kN, sigma = std::sqrt(std::max(0.0, sum2 / kN - mean * mean) / kN);
    // 5σ of the estimator plus 0.1 % for float pdfs.
    EXPECT_NEAR(mean, expectedIntegral, kSamplerSigmas * sigma + kSamplerRelBias * expectedIntegral)
        << light.toString();
}
}  // namespace

TEST(DirectionalLight, ShAndDsfCoefficients) {
    const glm::vec3 dir = glm::normalize(glm::vec3(1, -2, 0.5f));
    const DirectionalLight l({2.0f, 1.0f, 0.5f}, dir * 7.0f);  // not normalised on input
    const auto c = l.shCoefficients({0, 0, 0}, 4);
    std::vector<double> y(25);
    sh::evalShUnitDouble(4, glm::dvec3(dir), y);
    for (int i = 0; i < 25; ++i) EXPECT_NEAR(c[i].x, 2.0 * y[i], kFloatCoeffTol);
    const auto s = l.dsfCoefficients({0, 0, 0}, dsf162());
    const glm::dvec3 e = dsf162().integrate(s);
    EXPECT_NEAR(e.x, 2.0, kFloatIntegralTol);
    EXPECT_NEAR(e.z, 0.5, kFloatIntegralTol);
    const LightSample ls = l.sample({1, 2, 3}, {0.5f, 0.5f});
    EXPECT_TRUE(ls.delta);
    EXPECT_NEAR(glm::dot(ls.wi, dir), 1.0f, float(kUnitValueTol));
}

TEST(DirectionalLight, BadInput) {
    EXPECT_THROW(DirectionalLight({1, 1, 1}, {0, 0, 0}), InputError);
    EXPECT_THROW(DirectionalLight({1, -1, 1}, {0, 0, 1}), InputError);
    EXPECT_THROW(DirectionalLight({1, NAN, 1}, {0, 0, 1}), InputError);
    try {
        DirectionalLight({1, 1, 1}, {0, 0, 0});
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "direction");
    }
}

TEST(PointLight, InverseSquareWithMinimumDistanceClamp) {
    const PointLight l({100.0f, 100.0f, 100.0f}, {10, 0, 0}, 2.0);
    EXPECT_NEAR(l.irradianceAt({0, 0, 0}).x, 1.0, kUnitValueTol);
    EXPECT_NEAR(l.irradianceAt({9, 0, 0}).x, 25.0, kTensValueTol);   // d = 1 < 2: clamped to 100/4
    EXPECT_NEAR(l.irradianceAt({10, 0, 0}).x, 25.0, kTensValueTol);  // at the light: finite
    const LightSample s = l.sample({10, 0, 0}, {0.1f, 0.2f});
    EXPECT_EQ(s.pdf, 0.0f);  // no direction at the light
    const LightSample far = l.sample({0, 0, 0}, {0.1f, 0.2f});
    EXPECT_NEAR(far.distance, 10.0f, float(kTensValueTol));
    EXPECT_NEAR(far.wi.x, 1.0f, float(kUnitValueTol));
    EXPECT_THROW(PointLight({1, 1, 1}, {0, 0, 0}, 0.0), InputError);
    EXPECT_THROW(PointLight({1, 1, 1}, {NAN, 0, 0}), InputError);
    // A bad band is an InputError also at the light itself (where no delta direction exists).
    EXPECT_THROW(l.shCoefficients({10, 0, 0}, -1), InputError);
    EXPECT_THROW(l.shCoefficients({0, 0, 0}, sh::kMaxBand + 1), InputError);
}

TEST(PointLight, ShIsFiniteAndContinuousThroughTheLight) {
    const PointLight l({100.0f, 100.0f, 100.0f}, {0, 0, 0}, 2.0);
    // At the light: isotropic, only DC, ∫ L dω = E.
    const auto at = l.shCoefficients({0, 0, 0}, 4);
    EXPECT_NEAR(at[0].x * kSqrt4Pi, 25.0, kPointDcTol);
    for (int i = 1; i < 25; ++i) EXPECT_EQ(at[i].x, 0.0f);
    // Continuity at d = minDistance and at d → 0.
    const auto inside = l.shCoefficients({0, 0, 1.999999}, 4),
               outside = l.shCoefficients({0, 0, 2.000001}, 4);
    for (int i = 0; i < 25; ++i) EXPECT_NEAR(inside[i].x, outside[i].x, kPointContinuityTol) << i;
    const auto near0 = l.shCoefficients({0, 1e-7, 0}, 4);
    for (int i = 0; i < 25; ++i) EXPECT_NEAR(near0[i].x, at[i].x, kPointContinuityTol) << i;
    // ∫ L dω = E everywhere, in SH and in DSF.
    for (double d : {0.0, 0.5, 1.5, 3.0}) {
        const glm::dvec3 x(d, 0, 0);
        EXPECT_NEAR(l.shCoefficients(x, 2)[0].x * kSqrt4Pi, l.irradianceAt(x).x, kPointPowerTol);
        EXPECT_NEAR(dsf162().integrate(l.dsfCoefficients(x, dsf162())).x, l.irradianceAt(x).x,
                    kPointPowerTol);
    }
    // Far away it is a directional light.
    const glm::dvec3 x(0, 0, -30);
    const DirectionalLight dl(l.irradianceAt(x), {0, 0, 1});
    const auto a = l.shCoefficients(x, 4), b = dl.shCoefficients(x, 4);
    for (int i = 0; i < 25; ++i) EXPECT_NEAR(a[i].x, b[i].x, kFloatCoeffTol);
}

TEST(SphereLight, ShClosedFormMatchesQuadratureAndSolidAngle) {
    const SphereLight l({3.0f, 3.0f, 3.0f}, {0, 0, 10}, 4.0);
    const glm::dvec3 x(1, 2, -3);
    const double omega = l.solidAngle(x);
    const double d = glm::length(glm::dvec3(-1, -2, 13));
    EXPECT_NEAR(omega, 2 * kPi * (1 - std::sqrt(1 - 16.0 / (d * d))), kDoubleTol);
    const auto c = l.shCoefficients(x, 8);
    EXPECT_NEAR(c[0].x, 3.0 * omega / kSqrt4Pi, kFloatCoeffTol);
    // Brute force: project the radiance seen along each direction (indicator of the cone; its edge
    // limits the quadrature to ~1e-3 of c_0 with 600 Gauss–Legendre nodes).
    const auto q = sh::gaussLegendreSamples(600);
    const auto ref = sh::projectFunction(
        8, q, [&](const glm::dvec3& w) { return l.radiance(x, glm::vec3(w)).x; });
    for (int i = 0; i < 81; ++i) EXPECT_NEAR(c[i].x, ref[i], kConeEdgeRelTol * c[0].x) << i;
    // DSF keeps the power.
    EXPECT_NEAR(dsf162().integrate(l.dsfCoefficients(x, dsf162())).x, 3.0 * omega,
                kSphereDsfPowerRelTol * 3.0 * omega);
    checkSampler(l, x, 3.0 * omega, 3.0);
    // Inside: radiance from everywhere.
    EXPECT_NEAR(l.shCoefficients({0, 0, 9}, 2)[0].x, 3.0 * kSqrt4Pi, kTensValueTol);
    checkSampler(l, {0, 0, 9}, 3.0 * 4 * kPi, 3.0);
    EXPECT_THROW(SphereLight({1, 1, 1}, {0, 0, 0}, -1.0), InputError);
}

TEST(RectLight, SolidAngleSamplingAndSh) {
    const glm::dvec3 p0(-5, -5, 20), eu(10, 0, 0), ev(0, 10, 0);
    // cross(eu, ev) = +z: emits upward; flip so it faces the origin below.
    const RectLight l({2.0f, 2.0f, 2.0f}, p0 + ev, eu, -ev);
    const glm::dvec3 x(1, -2, 0);
    const double omega = triangleSolidAngle(x, p0, p0 + eu, p0 + eu + ev) +
                         triangleSolidAngle(x, p0, p0 + eu + ev, p0 + ev);
    const auto c = l.shCoefficients(x, 4);
    EXPECT_NEAR(c[0].x * kSqrt4Pi, 2.0 * omega, kRectMidpointRelTol * 2.0 * omega);
    const auto q = sh::gaussLegendreSamples(400);
    const auto ref = sh::projectFunction(
        4, q, [&](const glm::dvec3& w) { return l.radiance(x, glm::vec3(w)).x; });
    for (int i = 0; i < 25; ++i) EXPECT_NEAR(c[i].x, ref[i], kRectShRelTol * c[0].x) << i;
    checkSampler(l, x, 2.0 * omega, 2.0);
    // Behind the emitter: nothing.
    EXPECT_EQ(l.sample({0, 0, 30}, {0.5f, 0.5f}).pdf, 0.0f);
    EXPECT_EQ(l.shCoefficients({0, 0, 30}, 2)[0].x, 0.0f);
    EXPECT_THROW(RectLight({1, 1, 1}, p0, eu, eu), InputError);
    EXPECT_THROW(RectLight({1, 1, 1}, p0, eu, glm::dvec3(1, 1, 0)), InputError);
}

TEST(DiskLight, OnAxisSolidAngleSamplingAndDsf) {
    const DiskLight l({1.5f, 1.5f, 1.5f}, {0, 0, 8}, {0, 0, -1}, 6.0);
    const glm::dvec3 x(0, 0, 0);
    const double omega = 2 * kPi * (1 - 8.0 / std::sqrt(64.0 + 36.0));
    EXPECT_NEAR(l.shCoefficients(x, 2)[0].x * kSqrt4Pi, 1.5 * omega,
                kDiskQuadratureRelTol * 1.5 * omega);
    EXPECT_NEAR(dsf162().integrate(l.dsfCoefficients(x, dsf162())).x, 1.5 * omega,
                kDiskQuadratureRelTol * 1.5 * omega);
    checkSampler(l, x, 1.5 * omega, 1.5);
    // Off axis: against the emitter quadrature's own ∫ L dω (independent of the sampler).
    const glm::dvec3 y(3, 1, 2);
    checkSampler(l, y, l.shCoefficients(y, 0)[0].x * kSqrt4Pi, 1.5);
}

TEST(Light, SpanOverloadsMatchVectorsAndDoNotAllocate) {
    const DirectionalLight dir({2.0f, 1.0f, 0.5f}, {1, -2, 0.5f});
    const PointLight point({100.0f, 50.0f, 10.0f}, {3, 0, 1}, 2.0);
    const SphereLight sphere({3.0f, 3.0f, 3.0f}, {0, 0, 10}, 4.0);
    RectLight rect({2.0f, 2.0f, 2.0f}, {-5, 5, 20}, {10, 0, 0}, {0, -10, 0});
    rect.setQuadratureResolution(8);
    const DiskLight disk({1.5f, 1.5f, 1.5f}, {0, 0, 8}, {0, 0, -1}, 6.0);
    const Light* lights[] = {&dir, &point, &sphere, &rect, &disk};
    const sh::Dsf& dsf = dsf162();
    std::array<glm::vec3, sh::shCount(6)> sh;
    std::vector<glm::vec3> s(dsf.size());
    // Points off the light, inside the point light's clamp and at its position.
    for (const glm::dvec3 x : {glm::dvec3(1, 2, -3), glm::dvec3(3, 0.5, 1), glm::dvec3(3, 0, 1)})
        for (const Light* l : lights) {
            const long before = gAllocations.load();
            l->shCoefficients(x, 6, sh);
            l->dsfCoefficients(x, dsf, s);
            EXPECT_EQ(gAllocations.load(), before) << l->toString();
            // Bit-identical to the allocating wrappers.
            EXPECT_EQ(l->shCoefficients(x, 6), std::vector<glm::vec3>(sh.begin(), sh.end()))
                << l->toString();
            EXPECT_EQ(l->dsfCoefficients(x, dsf), s) << l->toString();
        }
    // The counter sees allocations: the vector wrapper is one.
    const long before = gAllocations.load();
    EXPECT_EQ(dir.shCoefficients({}, 2).size(), 9u);
    EXPECT_GT(gAllocations.load(), before);
    // A span of the wrong size is a programming error (always checked); a bad band is user input.
    EXPECT_THROW(dir.shCoefficients({}, 5, sh), InternalError);
    EXPECT_THROW(dir.dsfCoefficients({}, dsf, std::span(s).first(10)), InternalError);
    EXPECT_THROW(dir.shCoefficients({}, -1, std::span(sh).first(0)), InputError);
}
