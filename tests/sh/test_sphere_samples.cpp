// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/error.h"
#include "sh/sh_basis.h"
#include "sh/sphere_samples.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
constexpr double kFourPi = 4.0 * std::numbers::pi;
// Weights are sums of ~N doubles of size 4π/N.
constexpr double kWeightSumTol = 1e-9;
// Unit directions and closed-form Gauss–Legendre nodes/weights in double: a few ulps.
constexpr double kUnitLengthTol = 1e-12;
constexpr double kNodeTol = 1e-14;
constexpr double kZeroNodeTol = 1e-15;
// Moment errors (relative error of ∫ z⁴): the area-weighted tetrahedron with 290 points on
// strongly non-uniform triangles, Fibonacci with 2000 points, and Gauss–Legendre, exact for
// degree ≤ 7 up to rounding.
constexpr double kTetrahedronMomentTol = 0.02;
constexpr double kFibonacciMomentTol = 1e-3;
constexpr double kExactMomentTol = 1e-13;
// Monte-Carlo error of z⁴ at N = 4096 has σ ≈ 0.8/√N ≈ 1.3 % relative; 8 seeds, 5σ.
constexpr double kMonteCarloMomentBound = 0.065;
// Jittered stratification must at least halve the uniform Monte-Carlo moment error (the test's bar;
// for a smooth integrand like z⁴ the real gain is much larger).
constexpr double kStratificationGain = 0.5;

double sumWeights(const SphereSamples& s) {
    double w = 0;
    for (double x : s.weights) w += x;
    return w;
}

// ∫ z⁴ dω = 4π/5; ∫ x²y² dω = 4π/15: low-order moments for quadrature-accuracy checks.
double momentError(const SphereSamples& s) {
    double z4 = 0, x2y2 = 0;
    for (std::size_t k = 0; k < s.size(); ++k) {
        const auto& d = s.directions[k];
        z4 += s.weights[k] * std::pow(d.z, 4);
        x2y2 += s.weights[k] * d.x * d.x * d.y * d.y;
    }
    return std::max(std::abs(z4 - kFourPi / 5) / (kFourPi / 5),
                    std::abs(x2y2 - kFourPi / 15) / (kFourPi / 15));
}

void expectUnitAndSummed(const SphereSamples& s) {
    ASSERT_EQ(s.directions.size(), s.weights.size());
    for (const auto& d : s.directions) ASSERT_NEAR(glm::length(d), 1.0, kUnitLengthTol);
    EXPECT_NEAR(sumWeights(s), kFourPi, kWeightSumTol) << s;
}
}  // namespace

TEST(SphereSamples, PolyhedronVertexCounts) {
    for (int f : {1, 2, 4, 8, 16}) {
        EXPECT_EQ(polyhedronSamples(Polyhedron::Icosahedron, f).size(),
                  std::size_t(10 * f * f + 2));
        EXPECT_EQ(polyhedronSamples(Polyhedron::Octahedron, f).size(), std::size_t(4 * f * f + 2));
        EXPECT_EQ(polyhedronSamples(Polyhedron::Tetrahedron, f).size(), std::size_t(2 * f * f + 2));
        // Euler: a closed triangulated sphere has F = 2V − 4.
        const SphereMesh m = subdividedPolyhedron(Polyhedron::Icosahedron, f);
        EXPECT_EQ(m.triangles.size(), 2 * m.vertices.size() - 4);
    }
    EXPECT_THROW(subdividedPolyhedron(Polyhedron::Octahedron, 0), InputError);
}

TEST(SphereSamples, WeightsSumTo4PiAndDirectionsAreUnit) {
    for (auto p : {Polyhedron::Tetrahedron, Polyhedron::Octahedron, Polyhedron::Icosahedron}) {
        expectUnitAndSummed(polyhedronSamples(p, 5, SampleWeighting::Area));
        expectUnitAndSummed(polyhedronSamples(p, 5, SampleWeighting::Equal));
    }
    expectUnitAndSummed(fibonacciSamples(777));
    expectUnitAndSummed(jitteredSamples(500, 3, 9));
    expectUnitAndSummed(jitteredSamples(7));
    expectUnitAndSummed(uniformRandomSamples(300, 4));
    expectUnitAndSummed(gaussLegendreSamples(12));
    EXPECT_THROW(fibonacciSamples(0), InputError);
    EXPECT_THROW(jitteredSamples(-3), InputError);
}

TEST(SphereSamples, QuadratureAccuracyOrdering) {
    // Deterministic sets integrate low-order moments far better than Monte-Carlo; area weights beat
    // equal weights on the (non-uniform) subdivided tetrahedron.
    const double areaTet =
        momentError(polyhedronSamples(Polyhedron::Tetrahedron, 12, SampleWeighting::Area));
    const double equalTet =
        momentError(polyhedronSamples(Polyhedron::Tetrahedron, 12, SampleWeighting::Equal));
    EXPECT_LT(areaTet, equalTet);
    EXPECT_LT(areaTet, kTetrahedronMomentTol);
    EXPECT_LT(momentError(fibonacciSamples(2000)), kFibonacciMomentTol);
    EXPECT_LT(momentError(gaussLegendreSamples(4)), kExactMomentTol);
    // Stratification reduces the error of uniform Monte-Carlo at N = 4096 (averaged over 8 seeds).
    double jit = 0, mc = 0;
    for (int s = 0; s < 8; ++s) {
        jit += momentError(jitteredSamples(4096, s));
        mc += momentError(uniformRandomSamples(4096, s));
    }
    EXPECT_LT(jit, kStratificationGain * mc);
    EXPECT_LT(mc / 8, kMonteCarloMomentBound);
}

TEST(SphereSamples, JitteredPatternsAreDeterministicAndDistinct) {
    const auto a = jitteredSamples(256, 1, 0), b = jitteredSamples(256, 1, 0),
               c = jitteredSamples(256, 1, 1);
    ASSERT_EQ(a.size(), 256u);
    EXPECT_EQ(a.directions, b.directions);
    EXPECT_NE(a.directions, c.directions);
}

TEST(SphereSamples, GaussLegendreNodes) {
    std::vector<double> x, w;
    gaussLegendre(5, x, w);
    // Closed form for n = 5: nodes 0, ±(1/3)√(5 − 2√(10/7)), ±(1/3)√(5 + 2√(10/7)); weight of 0 is
    // 128/225.
    EXPECT_NEAR(x[2], 0.0, kZeroNodeTol);
    EXPECT_NEAR(w[2], 128.0 / 225.0, kNodeTol);
    EXPECT_NEAR(std::abs(x[1]), std::sqrt(5.0 - 2.0 * std::sqrt(10.0 / 7.0)) / 3.0, kNodeTol);
    EXPECT_NEAR(std::abs(x[0]), std::sqrt(5.0 + 2.0 * std::sqrt(10.0 / 7.0)) / 3.0, kNodeTol);
}

TEST(SphereSamples, MinimumSeparationOfIcosahedron) {
    // The 12 icosahedron vertices are atan(2) ≈ 63.43° apart.
    EXPECT_NEAR(minimumSeparation(polyhedronSamples(Polyhedron::Icosahedron, 1).directions),
                std::atan(2.0), 1e-12);
}
