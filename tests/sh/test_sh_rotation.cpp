// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "sh/sh_rotation.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
constexpr double kPi = std::numbers::pi;
// The bars: per-band orthogonality and pointwise agreement (coefficients of size ≤ 1, L ≤
// 8).
constexpr double kOrthogonalityTol = 1e-5;
constexpr double kPointwiseTol = 1e-4;
// Float coefficients of size ≤ 1 through one or two rotations of L = 8 (≤ 17-term sums).
constexpr double kFloatRotationTol = 1e-5;
// Band 1 is R itself: float rounding of entries of size ≤ ~2.
constexpr double kBandOneTol = 1e-6;
// Double rotation vs double projection of a band-limited function (exact Gauss–Legendre).
constexpr double kDoubleRotationTol = 1e-10;
// Orthogonality at kMaxBand = 32: the recursion's double rounding grows with l (measured ~1e-12).
constexpr double kHighBandOrthoTol = 1e-9;

glm::dmat3 axisAngle(glm::dvec3 axis, double angle) {
    axis = glm::normalize(axis);
    const double c = std::cos(angle), s = std::sin(angle), t = 1.0 - c;
    const double x = axis.x, y = axis.y, z = axis.z;
    // Rodrigues; glm is column-major, so build rows and transpose.
    const glm::dmat3 rows(t * x * x + c, t * x * y - s * z, t * x * z + s * y,  //
                          t * x * y + s * z, t * y * y + c, t * y * z - s * x,  //
                          t * x * z - s * y, t * y * z + s * x, t * z * z + c);
    return glm::transpose(rows);
}

glm::dmat3 eulerZyz(double a, double b, double g) {
    return axisAngle({0, 0, 1}, a) * axisAngle({0, 1, 0}, b) * axisAngle({0, 0, 1}, g);
}

// The test's rotation set: exact quarter/half turns about each axis, near-gimbal-lock ZYZ angles,
// random.
std::vector<glm::dmat3> testRotations(int count) {
    std::vector<glm::dmat3> rs;
    for (int axis = 0; axis < 3; ++axis) {
        for (int q = -2; q <= 2; ++q) {
            if (q == 0) continue;
            glm::dmat3 r(0.0);
            // Exact integer matrices (no cos(π/2) rounding) for ±90° and 180°.
            const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
            r[axis][axis] = 1;
            const int c = q == 2 || q == -2 ? -1 : 0, s = q == 1 ? 1 : (q == -1 ? -1 : 0);
            r[a1][a1] = c, r[a2][a2] = c, r[a1][a2] = s, r[a2][a1] = -s;
            rs.push_back(r);
        }
    }
    for (double b : {0.0, 1e-9, 1e-6, kPi - 1e-9, kPi, kPi - 1e-6})
        for (double a : {0.3, -2.0}) rs.push_back(eulerZyz(a, b, 1.1 - a));
    core::CounterRng rng(2024);
    while (int(rs.size()) < count) {
        // Uniform random rotation from a random unit quaternion (Shoemake).
        const double u1 = rng.uniformDouble(), u2 = 2 * kPi * rng.uniformDouble(),
                     u3 = 2 * kPi * rng.uniformDouble();
        const double w = std::sqrt(1 - u1) * std::sin(u2), x = std::sqrt(1 - u1) * std::cos(u2);
        const double y = std::sqrt(u1) * std::sin(u3), z = std::sqrt(u1) * std::cos(u3);
        const glm::dmat3 rows(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),  //
                              2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),  //
                              2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y));
        rs.push_back(glm::transpose(rows));
    }
    return rs;
}

std::vector<float> randomCoefficients(int band, std::uint64_t seed) {
    std::vector<float> c(shCount(band));
    core::CounterRng rng(seed);
    for (float& x : c) x = 2.0f * rng.uniform() - 1.0f;
    return c;
}

glm::dvec3 randomDirection(core::CounterRng& rng) {
    const double z = 1 - 2 * rng.uniformDouble(), phi = 2 * kPi * rng.uniformDouble();
    const double r = std::sqrt(1 - z * z);
    return {r * std::cos(phi), r * std::sin(phi), z};
}
}  // namespace

TEST(ShRotation, TenThousandRotationsOrthogonalAndPointwiseCorrect) {
    constexpr int kL = 8;
    const auto rotations = testRotations(10000);
    ASSERT_GE(rotations.size(), 10000u);
    core::CounterRng rng(77);
    std::vector<float> rotated(shCount(kL));
    std::vector<double> maxErr(2, 0.0);
    for (std::size_t k = 0; k < rotations.size(); ++k) {
        const glm::dmat3& r = rotations[k];
        const ShRotation rot(r, kL);
        // Per band: R Rᵀ = I.
        for (int l = 0; l <= kL; ++l)
            for (int m = -l; m <= l; ++m)
                for (int n = -l; n <= l; ++n) {
                    double s = 0;
                    for (int j = -l; j <= l; ++j) s += rot.element(l, m, j) * rot.element(l, n, j);
                    const double err = std::abs(s - (m == n ? 1.0 : 0.0));
                    maxErr[0] = std::max(maxErr[0], err);
                    ASSERT_LT(err, kOrthogonalityTol) << "rotation " << k << " band " << l;
                }
        // Pointwise: g(ω) = f(R⁻¹ ω) at two random directions.
        const auto f = randomCoefficients(kL, k);
        rot.apply(f, rotated);
        for (int t = 0; t < 2; ++t) {
            const glm::dvec3 w = randomDirection(rng);
            const double g = shReconstruct(rotated, glm::vec3(w));
            const double ref = shReconstruct(f, glm::vec3(glm::transpose(r) * w));
            // Scale: Σ|c| |Y| can reach ~20 here; compare to the function's own magnitude.
            const double err = std::abs(g - ref) / std::max(1.0, std::abs(ref));
            maxErr[1] = std::max(maxErr[1], err);
            ASSERT_LT(err, kPointwiseTol) << "rotation " << k;
        }
    }
    RecordProperty("max_orthogonality_error", std::to_string(maxErr[0]));
    RecordProperty("max_pointwise_error", std::to_string(maxErr[1]));
}

TEST(ShRotation, ComposesAndInverts) {
    const glm::dmat3 a = eulerZyz(0.4, 1.2, -0.7), b = eulerZyz(-2.0, 0.3, 2.5);
    const ShRotation ra(a, 8), rb(b, 8), rab(a * b, 8), rinv(glm::transpose(a), 8);
    const auto f = randomCoefficients(8, 3);
    std::vector<float> x(f.size()), y(f.size());
    rb.apply(f, x);
    ra.apply(x, x);  // in place
    rab.apply(f, y);
    for (std::size_t i = 0; i < f.size(); ++i) EXPECT_NEAR(x[i], y[i], kFloatRotationTol) << i;
    ra.apply(f, x);
    rinv.apply(x, y);
    for (std::size_t i = 0; i < f.size(); ++i) EXPECT_NEAR(y[i], f[i], kFloatRotationTol) << i;
}

TEST(ShRotation, BandOneIsThePermutedMatrix) {
    // Rotating the linear function f(ω) = a·ω gives g(ω) = (R a)·ω.
    const glm::dmat3 r = eulerZyz(0.9, -0.4, 2.2);
    const glm::dvec3 a(0.2, -0.7, 0.5);
    const double k = std::sqrt(4 * kPi / 3);  // a·ω = k (a_y Y_1,-1 + a_z Y_10 + a_x Y_11)
    std::vector<float> f = {0, float(k * a.y), float(k * a.z), float(k * a.x)}, g(4);
    ShRotation(r, 1).apply(f, g);
    const glm::dvec3 ra = r * a;
    EXPECT_NEAR(g[1], k * ra.y, kBandOneTol);
    EXPECT_NEAR(g[2], k * ra.z, kBandOneTol);
    EXPECT_NEAR(g[3], k * ra.x, kBandOneTol);
}

TEST(ShRotation, ZFastPathMatchesGeneral) {
    const auto f = randomCoefficients(8, 9);
    for (double angle : {0.0, 0.5 * kPi, kPi, -1.234, 5.0}) {
        std::vector<float> a(f.size()), b = f;
        ShRotation(axisAngle({0, 0, 1}, angle), 8).apply(f, a);
        rotateZ(angle, b, b);  // in place
        for (std::size_t i = 0; i < f.size(); ++i)
            EXPECT_NEAR(a[i], b[i], kFloatRotationTol) << i << " angle " << angle;
    }
}

TEST(ShRotation, RotateThenProjectEqualsProjectRotated) {
    // Project f∘R⁻¹ directly vs. rotate the projection of f (both exact for band-limited f).
    const glm::dmat3 r = eulerZyz(1.0, 2.0, 3.0);
    const auto f = randomCoefficients(6, 21);
    std::vector<double> fd(f.begin(), f.end());
    const SphereSamples q = gaussLegendreSamples(8);
    const auto direct = projectFunction(
        6, q, [&](const glm::dvec3& w) { return shReconstructDouble(fd, glm::transpose(r) * w); });
    std::vector<double> rotated(fd.size());
    ShRotation(r, 6).apply(std::span<const double>(fd), std::span<double>(rotated));
    for (std::size_t i = 0; i < fd.size(); ++i)
        EXPECT_NEAR(direct[i], rotated[i], kDoubleRotationTol) << i;
}

TEST(ShRotation, HighBandsStayOrthogonal) {
    const ShRotation rot(eulerZyz(0.3, 1.9, -1.4), kMaxBand);
    double worst = 0;
    for (int l = kMaxBand - 1; l <= kMaxBand; ++l)
        for (int m = -l; m <= l; ++m)
            for (int n = -l; n <= l; ++n) {
                double s = 0;
                for (int j = -l; j <= l; ++j) s += rot.element(l, m, j) * rot.element(l, n, j);
                worst = std::max(worst, std::abs(s - (m == n)));
            }
    EXPECT_LT(worst, kHighBandOrthoTol);
}

TEST(ShRotation, CacheRebuildsOnlyOnChange) {
    // Addresses cannot show a rebuild (clear() + emplace_back reuses the slot): count builds, and
    // check the blocks belong to the rotation asked for.
    CachedShRotation cache;
    const glm::dmat3 a = eulerZyz(0.1, 0.2, 0.3), b = eulerZyz(0.1, 0.2, 0.4);
    auto expectBuiltFrom = [](const ShRotation& rot, const glm::dmat3& r, int band) {
        const ShRotation fresh(r, band);
        EXPECT_EQ(rot.maxBand(), band);
        EXPECT_EQ(rot.matrix(), r);
        for (int l = 0; l <= band; ++l)
            for (int m = -l; m <= l; ++m)
                for (int n = -l; n <= l; ++n)
                    ASSERT_EQ(rot.element(l, m, n), fresh.element(l, m, n)) << l << m << n;
    };
    EXPECT_EQ(cache.builds(), 0u);
    expectBuiltFrom(cache.get(a, 4), a, 4);
    EXPECT_EQ(cache.builds(), 1u);
    const glm::dmat3 aCopy = a;  // equal matrix, another object: no rebuild
    expectBuiltFrom(cache.get(aCopy, 4), a, 4);
    EXPECT_EQ(cache.builds(), 1u);
    expectBuiltFrom(cache.get(b, 4), b, 4);  // another rotation: rebuilt, different blocks
    EXPECT_EQ(cache.builds(), 2u);
    EXPECT_NE(cache.get(b, 4).element(2, 1, -2), ShRotation(a, 4).element(2, 1, -2));
    EXPECT_EQ(cache.builds(), 2u);
    expectBuiltFrom(cache.get(b, 6), b, 6);  // another band: rebuilt
    EXPECT_EQ(cache.builds(), 3u);
    expectBuiltFrom(cache.get(a, 6), a, 6);
    EXPECT_EQ(cache.builds(), 4u);
    // A near-rotation is keyed as given (its matrix() is orthonormalised): asked twice, built once.
    glm::dmat3 skewed = a;
    skewed[1][2] += 2e-5;
    cache.get(skewed, 6);
    cache.get(skewed, 6);
    EXPECT_EQ(cache.builds(), 5u);
}

TEST(ShRotation, NearRotationIsOrthonormalised) {
    // Newton's polar iteration converges to rounding: entries of QᵀQ − I are sums of three
    // products of entries ≤ 1, ~1e-16 each.
    constexpr double kOrthonormalTol = 1e-14;
    // Per-band orthogonality of blocks built from an exact rotation at L = 8 (measured ~1e-15);
    // from the unrepaired near-rotation below it would be ~1e-4.
    constexpr double kBlockOrthoTol = 1e-12;
    auto orthoError = [](const glm::dmat3& m) {
        const glm::dmat3 mtm = glm::transpose(m) * m;
        double e = 0;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) e = std::max(e, std::abs(mtm[i][j] - (i == j)));
        return e;
    };
    auto maxAbs = [](const glm::dmat3& m) {
        double e = 0;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) e = std::max(e, std::abs(m[i][j]));
        return e;
    };
    const glm::dmat3 exact = eulerZyz(0.4, 1.2, -0.7);
    glm::dmat3 skewed = exact;  // e.g. a matrix typed with five digits
    skewed[0][1] += 3e-5, skewed[2][0] -= 2e-5, skewed[1][1] *= 1 + 2e-5;
    ASSERT_NO_THROW(checkRotation(skewed));
    constexpr double kSkewAtLeast = 1e-5;  // the input is off far beyond kBlockOrthoTol
    ASSERT_GT(orthoError(skewed), kSkewAtLeast);
    const glm::dmat3 q = orthonormalizeRotation(skewed);
    EXPECT_LT(orthoError(q), kOrthonormalTol);
    EXPECT_NEAR(glm::determinant(q), 1.0, kOrthonormalTol);
    // The polar factor: S = Qᵀ·skewed is symmetric, and Q is no farther from the input than the
    // exact rotation it was perturbed from.
    const glm::dmat3 sym = glm::transpose(q) * skewed;
    EXPECT_LT(maxAbs(sym - glm::transpose(sym)), kOrthonormalTol);
    EXPECT_LE(maxAbs(q - skewed), maxAbs(exact - skewed));
    // A rotation orthonormal to rounding is kept bit for bit.
    EXPECT_EQ(orthonormalizeRotation(exact), exact);
    // ShRotation builds from the orthonormalised matrix: blocks orthogonal to rounding.
    const ShRotation rot(skewed, 8);
    EXPECT_EQ(rot.matrix(), q);
    double worst = 0;
    for (int l = 1; l <= 8; ++l)
        for (int m = -l; m <= l; ++m)
            for (int n = -l; n <= l; ++n) {
                double s = 0;
                for (int j = -l; j <= l; ++j) s += rot.element(l, m, j) * rot.element(l, n, j);
                worst = std::max(worst, std::abs(s - (m == n)));
            }
    EXPECT_LT(worst, kBlockOrthoTol);
}

TEST(ShRotation, RejectsNonRotations) {
    EXPECT_THROW(ShRotation(glm::dmat3(2.0), 2), InputError);
    glm::dmat3 mirror(1.0);
    mirror[0][0] = -1;
    EXPECT_THROW(ShRotation(mirror, 2), InputError);
    glm::dmat3 nan(1.0);
    nan[1][2] = NAN;
    EXPECT_THROW(ShRotation(nan, 2), InputError);
}
