// SPDX-License-Identifier: MIT
#include "sh/sh_projection.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>

#include "core/error.h"
#include "sh/sphere_samples.h"

namespace voxlight::sh {

namespace {
// Evaluates Y at a unit direction into `y` (float), the unrolled path where possible.
void evalFast(int band, const glm::vec3& d, float* y) {
    switch (band) {
        case 0:
            evalShFixed<0>(d, y);
            return;
        case 1:
            evalShFixed<1>(d, y);
            return;
        case 2:
            evalShFixed<2>(d, y);
            return;
        case 3:
            evalShFixed<3>(d, y);
            return;
        case 4:
            evalShFixed<4>(d, y);
            return;
        default:
            evalShUnit(band, d, std::span<float>(y, shCount(band)));
    }
}
}  // namespace

ShProjector::ShProjector(int maxBand) : band_(maxBand) {
    checkBand(maxBand);
    sum_.assign(shCount(maxBand), glm::dvec3(0.0));
}

void addShSample(int maxBand, const glm::dvec3& unitDir, const glm::dvec3& weightedValue,
                 std::span<glm::dvec3> sum) {
    VL_CHECK(maxBand >= 0 && maxBand <= kMaxBand);
    const int n = shCount(maxBand);
    VL_CHECK_GE(sum.size(), std::size_t(n));
    std::array<float, kMaxCoeffs> y;
    evalFast(maxBand, glm::vec3(unitDir), y.data());
    for (int i = 0; i < n; ++i) sum[i] += weightedValue * double(y[i]);
}

void ShProjector::add(const glm::dvec3& unitDir, const glm::dvec3& weightedValue) {
    addShSample(band_, unitDir, weightedValue, sum_);
}

void ShProjector::merge(const ShProjector& other) {
    VL_CHECK_EQ(band_, other.band_);
    for (std::size_t i = 0; i < sum_.size(); ++i) sum_[i] += other.sum_[i];
}

std::vector<glm::vec3> ShProjector::coefficientsRgb() const {
    return std::vector<glm::vec3>(sum_.begin(), sum_.end());
}

std::vector<float> ShProjector::coefficients() const {
    std::vector<float> c(sum_.size());
    for (std::size_t i = 0; i < c.size(); ++i) c[i] = float(sum_[i].x);
    return c;
}

std::vector<float> projectSamples(int maxBand, const SphereSamples& samples,
                                  std::span<const float> values) {
    checkBand(maxBand);
    VL_CHECK_EQ(values.size(), samples.size());
    const int n = shCount(maxBand);
    std::vector<double> c(n, 0.0);
    std::array<double, kMaxCoeffs> y;
    for (std::size_t k = 0; k < samples.size(); ++k) {
        evalShUnitDouble(maxBand, samples.directions[k], y);
        const double v = samples.weights[k] * values[k];
        for (int i = 0; i < n; ++i) c[i] += v * y[i];
    }
    return std::vector<float>(c.begin(), c.end());
}

std::vector<glm::vec3> projectSamplesRgb(int maxBand, const SphereSamples& samples,
                                         std::span<const glm::vec3> values) {
    VL_CHECK_EQ(values.size(), samples.size());
    ShProjector p(maxBand);
    for (std::size_t k = 0; k < samples.size(); ++k)
        p.add(samples.directions[k], glm::dvec3(values[k]) * samples.weights[k]);
    return p.coefficientsRgb();
}

std::vector<glm::vec3> projectEquirect(int maxBand, const EquirectLayout& layout,
                                       std::span<const glm::vec3> rgb) {
    checkBand(maxBand);
    const int w = layout.width, h = layout.height;
    if (w <= 0 || h <= 0)
        throw InputError(
            "sh", "equirect size",
            "grid is " + std::to_string(w) + "×" + std::to_string(h) + ", which is empty",
            "give a non-empty latitude–longitude image");
    VL_CHECK_EQ(rgb.size(), std::size_t(w) * std::size_t(h));
    VL_CHECK(std::abs(std::abs(layout.phiStep) * w - 2.0 * std::numbers::pi) < 1e-9);
    const int n = shCount(maxBand);
    const int nm = maxBand + 1;

    // Each pixel is a constant over its patch θ ∈ [θ_r, θ_r+1], φ between its column's edges: the
    // integral of f·Y over the patch splits into an exact φ integral of cos(mφ), sin(mφ) per column
    // and a θ integral of Y_l^|m|(θ, 0)·sin θ per row by Gauss–Legendre in θ (a trigonometric
    // polynomial of degree ≤ L + 1: nodes enough that a 2×1 map integrates as exactly as a 512×256
    // one — the midpoint rule gave a uniform 2×1 map band-2 light, +41 % under gradient shading).
    std::vector<double> cosT(std::size_t(w) * nm), sinT(std::size_t(w) * nm);
    const double sign = layout.phiStep < 0 ? -1.0 : 1.0;
    const double dphi = std::abs(layout.phiStep);
    for (int c = 0; c < w; ++c) {
        const double pa = layout.phi0 + layout.phiStep * c;
        const double pb = layout.phi0 + layout.phiStep * (c + 1);
        cosT[std::size_t(c) * nm] = dphi;
        sinT[std::size_t(c) * nm] = 0.0;
        for (int m = 1; m < nm; ++m) {
            cosT[std::size_t(c) * nm + m] = sign * (std::sin(m * pb) - std::sin(m * pa)) / m;
            sinT[std::size_t(c) * nm + m] = sign * (std::cos(m * pa) - std::cos(m * pb)) / m;
        }
    }
    // Nodes per row: about 2(L + 2) over the whole [0, π] and at least 3 in a row.
    const int nodes = std::clamp(int(std::ceil(2.0 * (maxBand + 2) / h)) + 2, 3, 64);
    std::vector<double> gx, gw;
    gaussLegendre(nodes, gx, gw);
    std::vector<glm::dvec3> coeff(n, glm::dvec3(0.0));
    std::vector<glm::dvec3> a(nm), b(nm);
    std::array<double, kMaxCoeffs> y;
    std::vector<double> rowY(n);
    for (int r = 0; r < h; ++r) {
        // Row sums A_m = Σ_c f ∫cos(mφ), B_m = Σ_c f ∫sin(mφ) over each column.
        std::fill(a.begin(), a.end(), glm::dvec3(0.0));
        std::fill(b.begin(), b.end(), glm::dvec3(0.0));
        const glm::vec3* row = rgb.data() + std::size_t(r) * w;
        for (int c = 0; c < w; ++c) {
            const glm::dvec3 f(row[c]);
            const double* ct = &cosT[std::size_t(c) * nm];
            const double* st = &sinT[std::size_t(c) * nm];
            for (int m = 0; m < nm; ++m) {
                a[m] += f * ct[m];
                b[m] += f * st[m];
            }
        }
        // Row factor ∫ Y_l^|m|(θ, φ = 0) sin θ dθ (Y at φ = 0 carries K, √2 and sin^m θ).
        const double t0 = std::numbers::pi * r / h, t1 = std::numbers::pi * (r + 1) / h;
        const double half = 0.5 * (t1 - t0), mid = 0.5 * (t0 + t1);
        std::fill(rowY.begin(), rowY.end(), 0.0);
        for (int q = 0; q < nodes; ++q) {
            const double theta = mid + half * gx[q];
            evalShUnitDouble(maxBand, {std::sin(theta), 0.0, std::cos(theta)}, y);
            const double wq = half * gw[q] * std::sin(theta);
            for (int i = 0; i < n; ++i) rowY[i] += wq * y[i];
        }
        for (int l = 0; l <= maxBand; ++l) {
            coeff[shIndex(l, 0)] += a[0] * rowY[shIndex(l, 0)];
            for (int m = 1; m <= l; ++m) {
                const double p = rowY[shIndex(l, m)];
                coeff[shIndex(l, m)] += a[m] * p;
                coeff[shIndex(l, -m)] += b[m] * p;
            }
        }
    }
    return std::vector<glm::vec3>(coeff.begin(), coeff.end());
}

std::vector<float> channel(std::span<const glm::vec3> rgb, int c) {
    VL_CHECK(c >= 0 && c < 3);
    std::vector<float> out(rgb.size());
    for (std::size_t i = 0; i < rgb.size(); ++i) out[i] = rgb[i][c];
    return out;
}

}  // namespace voxlight::sh
