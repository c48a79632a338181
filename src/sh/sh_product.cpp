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
    std::fill(out, out + coefficients_, 0.f);
    for (const Term& t : terms_) out[t.k] += t.gamma * a[t.i] * b[t.j];
}

}  // namespace voxlight::sh
