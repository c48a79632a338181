// SPDX-License-Identifier: MIT
// The SH triple product against an independent projection of the pointwise product.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "core/rng.h"
#include "sh/sh_basis.h"
#include "sh/sh_product.h"
#include "sh/sh_projection.h"
#include "sh/sphere_samples.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
// Float Γ (relative 6e-8) times coefficients ≤ 1 summed over ≤ ~100 terms per output, against
// a double quadrature: ~1e-6.
constexpr double kProductTol = 1e-5;
}  // namespace

TEST(ShProduct, MultiplyingByAConstantScalesAndTheMeanIsExact) {
    const float inv = float(1.0 / std::sqrt(4.0 * std::numbers::pi));
    for (const int C : {1, 4, 9, 16}) {
        const ShProduct p(C);
        const std::size_t n = static_cast<std::size_t>(C);
        std::vector<float> a(n), one(n, 0.f), out(n);
        core::CounterRng rng(std::uint64_t(C), 7);
        for (float& x : a) x = float(rng.uniformDouble() * 2.0 - 1.0);
        // The constant function 1 is (√(4π), 0, …): f ⊗ 1 = f.
        one[0] = float(std::sqrt(4.0 * std::numbers::pi));
        p.apply(a.data(), one.data(), out.data());
        for (int i = 0; i < C; ++i)
            EXPECT_NEAR(out[std::size_t(i)], a[std::size_t(i)], kProductTol);
        // Band 0 of a product is ∫ f g / √(4π) = Σ a_i b_i / √(4π) (orthonormality).
        std::vector<float> b(n);
        for (float& x : b) x = float(rng.uniformDouble() * 2.0 - 1.0);
        p.apply(a.data(), b.data(), out.data());
        double dot = 0.0;
        for (int i = 0; i < C; ++i) dot += double(a[std::size_t(i)]) * b[std::size_t(i)];
        EXPECT_NEAR(out[0], dot * inv, kProductTol) << C;
    }
    // The real Gaunt coefficients' sparsity: band-1 × band-1 has no band-1 part (odd sum).
    EXPECT_EQ(ShProduct(4).entries(), 10u);
}

TEST(ShProduct, EqualsTheProjectionOfThePointwiseProduct) {
    // Independent truth: reconstruct both expansions, multiply pointwise, project with a
    // product rule of another size (exact for the degree-3L integrand).
    const SphereSamples rule = gaussLegendreSamples(12);
    for (const int C : {4, 9, 16}) {
        const int band = shBandForCount(C);
        const ShProduct p(C);
        core::CounterRng rng(std::uint64_t(C), 3);
        const std::size_t n = static_cast<std::size_t>(C);
        std::vector<float> a(n), b(n), out(n);
        for (float& x : a) x = float(rng.uniformDouble() * 2.0 - 1.0);
        for (float& x : b) x = float(rng.uniformDouble() * 2.0 - 1.0);
        std::vector<double> y(static_cast<std::size_t>(kMaxCoeffs));
        auto eval = [&](const std::vector<float>& c, const glm::dvec3& w) {
            evalShUnitDouble(band, w, y);
            double s = 0.0;
            for (int i = 0; i < C; ++i) s += c[std::size_t(i)] * y[std::size_t(i)];
            return s;
        };
        const auto expected = projectFunction(
            band, rule, [&](const glm::dvec3& w) { return eval(a, w) * eval(b, w); });
        p.apply(a.data(), b.data(), out.data());
        for (int i = 0; i < C; ++i)
            EXPECT_NEAR(out[std::size_t(i)], expected[std::size_t(i)], kProductTol)
                << C << " " << i;
    }
}
