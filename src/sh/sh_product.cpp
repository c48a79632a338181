// SPDX-License-Identifier: MIT
#include "sh/sh_product.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "sh/sh_basis.h"
#include "sh/sphere_samples.h"

namespace voxlight::sh {

ShProduct::ShProduct(int coefficients) : coefficients_(coefficients) {
    VL_CHECK(coefficients >= 1 && coefficients <= kMaxCoeffs);
    const int band = shBandForCount(coefficients);
    VL_CHECK(shCount(band) == coefficients);
    const int n = (3 * band + 1) / 2 + 2;
    const SphereSamples rule = gaussLegendreSamples(n);
    const int C = coefficients;
    std::vector<double> y(rule.size() * std::size_t(C));
    std::vector<double> yd(static_cast<std::size_t>(kMaxCoeffs));
    for (std::size_t q = 0; q < rule.size(); ++q) {
        evalShUnitDouble(band, rule.directions[q], yd);
        std::copy_n(yd.begin(), C, y.begin() + std::ptrdiff_t(q * std::size_t(C)));
    }
    for (int k = 0; k < C; ++k)
        for (int i = 0; i < C; ++i)
            for (int j = 0; j < C; ++j) {
                double g = 0.0;
                for (std::size_t q = 0; q < rule.size(); ++q) {
                    const double* yq = y.data() + q * std::size_t(C);
                    g += rule.weights[q] * yq[i] * yq[j] * yq[k];
                }
                if (std::abs(g) > kTripleZero)
                    terms_.push_back({std::uint8_t(i), std::uint8_t(j), std::uint8_t(k), float(g)});
            }
}

void ShProduct::apply(const float* a, const float* b, float* out) const {
    if (coefficients_ == 4) {
        // Band ≤ 1 (sh-global's default, once per shaded sample) in closed form: the 10
        // non-zero entries are Γ_ii0 (i = 0..3), Γ_0kk and Γ_k0k (k = 1..3), all 1/√(4π)
        // (orthonormality; three band-1 functions have an odd band sum). terms_[0] is Γ_000.
        const float g = terms_[0].gamma;
        out[0] = g * (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
        for (int k = 1; k < 4; ++k) out[k] = g * (a[0] * b[k] + a[k] * b[0]);
        return;
    }
    std::fill(out, out + coefficients_, 0.f);
    for (const Term& t : terms_) out[t.k] += t.gamma * a[t.i] * b[t.j];
}

}  // namespace voxlight::sh
