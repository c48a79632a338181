// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "sh/sh_basis.h"
#include "sh/sphere_samples.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
constexpr double kPi = std::numbers::pi;
// Float evaluation of degree-≤4 polynomials with |Y| < 2.6: a few ulps of the largest term.
constexpr float kFloatEvalTol = 2e-6f;
// Double recurrences vs. the textbook path: both accumulate ~L rounding steps; values up to ~4 at L
// = 32.
constexpr double kDoubleEvalTol = 1e-11;
// The bar for orthonormality by quadrature (the Gauss–Legendre rule used is exact up to
// rounding).
constexpr double kOrthoTol = 1e-6;
// Float recurrence at L = 8 against double: values ≤ 3, ~10 float operations each.
constexpr double kFloatVsDoubleTol = 1e-5;
// Double recurrence against std::sph_legendre (both double, L ≤ 8): a few ulps of values ≤ 3.
constexpr double kStdLegendreTol = 1e-12;
// Poles: relative error per band of the zonal recurrence, growing ~linearly with l.
constexpr double kPoleRelTolPerBand = 1e-13;
// Addition theorem up to kMaxBand = 32: sums of 65 products, std::legendre's own rounding at l
// = 32.
constexpr double kAdditionTheoremTol = 1e-11;
// Y_1 of an unnormalised float direction after normalisation in float.
constexpr double kFloatY1Tol = 1e-6;
// Float reconstruction Σ c_i Y_i over 49 terms of size ≤ ~1.
constexpr double kFloatReconstructTol = 1e-5;

glm::dvec3 randomDirection(std::uint64_t i, std::uint64_t seed = 1) {
    core::CounterRng rng(i, seed);
    const double z = 1.0 - 2.0 * rng.uniformDouble();
    const double phi = 2.0 * kPi * rng.uniformDouble();
    const double r = std::sqrt(1.0 - z * z);
    return {r * std::cos(phi), r * std::sin(phi), z};
}

template <int L>
void expectFixedMatchesRecurrence() {
    std::array<float, shCount(L)> fixed;
    std::array<double, shCount(L)> ref;
    for (int k = 0; k < 2000; ++k) {
        const glm::dvec3 d = randomDirection(k);
        evalShFixed<L>(glm::vec3(d), fixed.data());
        evalShUnitDouble(L, d, ref);
        for (int i = 0; i < shCount(L); ++i)
            ASSERT_NEAR(fixed[i], ref[i], kFloatEvalTol) << "L=" << L << " i=" << i;
    }
}
}  // namespace

TEST(ShBasis, IndexAndCounts) {
    EXPECT_EQ(shIndex(0, 0), 0);
    EXPECT_EQ(shIndex(1, -1), 1);
    EXPECT_EQ(shIndex(2, 2), 8);
    EXPECT_EQ(shIndex(8, 8), 80);
    EXPECT_EQ(shCount(4), 25);
    EXPECT_EQ(shCount(8), 81);
    for (int i = 0; i < shCount(12); ++i) {
        const int l = shBandOf(i);
        EXPECT_LE(l * l, i);
        EXPECT_LT(i, (l + 1) * (l + 1));
    }
    EXPECT_EQ(shBandForCount(25), 4);
    EXPECT_THROW(shBandForCount(10), InputError);
    EXPECT_THROW(shBandForCount(0), InputError);
    EXPECT_THROW(checkBand(kMaxBand + 1), InputError);
    EXPECT_THROW(checkBand(-1), InputError);
}

TEST(ShBasis, UnrolledMatchesRecurrence) {
    expectFixedMatchesRecurrence<0>();
    expectFixedMatchesRecurrence<1>();
    expectFixedMatchesRecurrence<2>();
    expectFixedMatchesRecurrence<3>();
    expectFixedMatchesRecurrence<4>();
}

TEST(ShBasis, RecurrenceMatchesTextbookSlowPath) {
    std::vector<double> y(shCount(kMaxBand));
    for (int k = 0; k < 300; ++k) {
        const glm::dvec3 d = randomDirection(k, 7);
        evalShUnitDouble(kMaxBand, d, y);
        const double theta = std::acos(d.z), phi = std::atan2(d.y, d.x);
        for (int l = 0; l <= kMaxBand; ++l)
            for (int m = -l; m <= l; ++m)
                ASSERT_NEAR(y[shIndex(l, m)], evalShSlow(l, m, theta, phi), kDoubleEvalTol)
                    << "l=" << l << " m=" << m << " dir " << d.x << "," << d.y << "," << d.z;
    }
}

TEST(ShBasis, FloatRecurrenceMatchesDouble) {
    std::vector<float> yf(shCount(8));
    std::vector<double> yd(shCount(8));
    for (int k = 0; k < 500; ++k) {
        const glm::dvec3 d = randomDirection(k, 3);
        evalShUnit(8, glm::vec3(d), yf);
        evalShUnitDouble(8, d, yd);
        for (int i = 0; i < shCount(8); ++i)
            ASSERT_NEAR(yf[i], yd[i], kFloatVsDoubleTol) << i;  // float, L = 8 values ≤ 3
    }
}

// Independent truth: libstdc++'s std::sph_legendre(l, m, θ) = Y_l^m(θ, 0) of the *complex* SH,
// which includes the Condon–Shortley phase (−1)^m. Ours has none: Y_l^m(θ, 0) = √2 (−1)^m
// sph_legendre(l, m, θ) for m > 0.
TEST(ShBasis, CondonShortleyPhaseIsExcluded) {
    for (int l = 0; l <= 8; ++l) {
        for (double theta : {0.1, 0.7, 1.3, 2.0, 2.9}) {
            const glm::dvec3 d = sphericalToDirection(theta, 0.0);
            std::vector<double> y(shCount(8));
            evalShUnitDouble(8, d, y);
            EXPECT_NEAR(y[shIndex(l, 0)], std::sph_legendre(l, 0, theta), kStdLegendreTol);
            for (int m = 1; m <= l; ++m) {
                const double ref =
                    std::numbers::sqrt2 * ((m % 2) ? -1.0 : 1.0) * std::sph_legendre(l, m, theta);
                EXPECT_NEAR(y[shIndex(l, m)], ref, kStdLegendreTol) << "l=" << l << " m=" << m;
            }
        }
    }
    // Band 1 is +√(3/4π)·(y, z, x): positive along +y, +z, +x.
    std::array<float, 4> b;
    const float c = float(std::sqrt(3.0 / (4.0 * kPi)));
    evalShFixed<1>({1, 0, 0}, b.data());
    EXPECT_FLOAT_EQ(b[3], c);
    evalShFixed<1>({0, 1, 0}, b.data());
    EXPECT_FLOAT_EQ(b[1], c);
    // Sectoral functions ∝ +Re/Im (x+iy)^l: Y_l^l > 0 at φ = 0 and Y_l^{−l} > 0 at φ = π/(2l).
    std::vector<double> y(shCount(8));
    for (int l = 1; l <= 8; ++l) {
        evalShUnitDouble(8, sphericalToDirection(kPi / 2, 0.0), y);
        EXPECT_GT(y[shIndex(l, l)], 0.0) << l;
        evalShUnitDouble(8, sphericalToDirection(kPi / 2, kPi / (2 * l)), y);
        EXPECT_GT(y[shIndex(l, -l)], 0.0) << l;
    }
}

TEST(ShBasis, ExactAtThePoles) {
    std::vector<double> y(shCount(kMaxBand));
    for (double s : {1.0, -1.0}) {
        evalShUnitDouble(kMaxBand, {0.0, 0.0, s}, y);
        for (int l = 0; l <= kMaxBand; ++l) {
            const double expected =
                std::sqrt((2.0 * l + 1.0) / (4.0 * kPi)) * ((s < 0 && l % 2) ? -1.0 : 1.0);
            EXPECT_NEAR(y[shIndex(l, 0)], expected,
                        kPoleRelTolPerBand * std::abs(expected) * (l + 1));
            for (int m = 1; m <= l; ++m) {
                EXPECT_EQ(y[shIndex(l, m)], 0.0);
                EXPECT_EQ(y[shIndex(l, -m)], 0.0);
            }
        }
    }
}

TEST(ShBasis, AdditionTheorem) {
    // Σ_m Y_lm(a) Y_lm(b) = (2l+1)/(4π) P_l(a·b): a closed form through std::legendre.
    std::vector<double> ya(shCount(kMaxBand)), yb(shCount(kMaxBand));
    for (int k = 0; k < 50; ++k) {
        const glm::dvec3 a = randomDirection(k, 11), b = randomDirection(k, 12);
        evalShUnitDouble(kMaxBand, a, ya);
        evalShUnitDouble(kMaxBand, b, yb);
        for (int l = 0; l <= kMaxBand; ++l) {
            double s = 0;
            for (int m = -l; m <= l; ++m) s += ya[shIndex(l, m)] * yb[shIndex(l, m)];
            EXPECT_NEAR(s, (2.0 * l + 1.0) / (4.0 * kPi) * std::legendre(l, glm::dot(a, b)),
                        kAdditionTheoremTol)
                << l;
        }
    }
}

TEST(ShBasis, OrthonormalToBand8ByQuadrature) {
    // 20 Gauss–Legendre nodes × 40 φ: exact for products of band ≤ 8 functions (degree 16 ≤ 39).
    const SphereSamples q = gaussLegendreSamples(20);
    constexpr int kL = 8, kN = shCount(kL);
    std::vector<double> gram(kN * kN, 0.0), y(kN);
    std::vector<float> yf(kN);
    std::vector<double> gramFloat(kN * kN, 0.0);
    for (std::size_t k = 0; k < q.size(); ++k) {
        evalShUnitDouble(kL, q.directions[k], y);
        evalSh(kL, glm::vec3(q.directions[k]), yf);
        for (int i = 0; i < kN; ++i)
            for (int j = 0; j < kN; ++j) {
                gram[i * kN + j] += q.weights[k] * y[i] * y[j];
                gramFloat[i * kN + j] += q.weights[k] * double(yf[i]) * yf[j];
            }
    }
    for (int i = 0; i < kN; ++i)
        for (int j = 0; j < kN; ++j) {
            EXPECT_NEAR(gram[i * kN + j], i == j ? 1.0 : 0.0, kOrthoTol) << i << "," << j;
            EXPECT_NEAR(gramFloat[i * kN + j], i == j ? 1.0 : 0.0, kOrthoTol) << i << "," << j;
        }
}

TEST(ShBasis, OrthonormalHighBandsByQuadrature) {
    // Bands up to kMaxBand (used by the Fig. 7 comparison): diagonal and a strided subset of
    // off-diagonal pairs.
    const SphereSamples q = gaussLegendreSamples(kMaxBand + 2);
    constexpr int kN = shCount(kMaxBand);
    std::vector<double> y(kN), diag(kN, 0.0), off(kN, 0.0);
    for (std::size_t k = 0; k < q.size(); ++k) {
        evalShUnitDouble(kMaxBand, q.directions[k], y);
        for (int i = 0; i < kN; ++i) {
            diag[i] += q.weights[k] * y[i] * y[i];
            off[i] += q.weights[k] * y[i] * y[(i * 37 + 11) % kN];
        }
    }
    for (int i = 0; i < kN; ++i) {
        EXPECT_NEAR(diag[i], 1.0, kOrthoTol) << i;
        if ((i * 37 + 11) % kN != i) {
            EXPECT_NEAR(off[i], 0.0, kOrthoTol) << i;
        }
    }
}

TEST(ShBasis, BadDirectionsAreInputErrors) {
    std::vector<float> y(25);
    EXPECT_THROW(evalSh(4, {0, 0, 0}, y), InputError);
    EXPECT_THROW(evalSh(4, {NAN, 0, 1}, y), InputError);
    EXPECT_THROW(evalSh(4, {INFINITY, 0, 0}, y), InputError);
    try {
        evalSh(4, {0, 0, 0}, y);
    } catch (const InputError& e) {
        EXPECT_EQ(e.field(), "direction");
        EXPECT_NE(std::string(e.what()).find("zero"), std::string::npos) << e.what();
    }
    // Not normalised, even tiny: fine.
    evalSh(4, {0, 0, 1e-30f}, y);
    EXPECT_NEAR(y[2], std::sqrt(3.0 / (4.0 * kPi)), kFloatY1Tol);
    evalSh(4, {0, 5, 0}, y);
    EXPECT_NEAR(y[1], std::sqrt(3.0 / (4.0 * kPi)), kFloatY1Tol);
}

TEST(ShBasis, ReconstructIsDotWithBasis) {
    std::vector<float> c(shCount(6));
    for (std::size_t i = 0; i < c.size(); ++i) c[i] = float(std::sin(1.0 + i));
    const glm::dvec3 d = randomDirection(5);
    double ref = 0;
    for (int l = 0; l <= 6; ++l)
        for (int m = -l; m <= l; ++m) ref += c[shIndex(l, m)] * evalShSlow(l, m, d);
    EXPECT_NEAR(shReconstruct(c, glm::vec3(d)), ref, kFloatReconstructTol);
}
