// SPDX-License-Identifier: MIT
#include "sh/sh_window.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::sh {

namespace {
constexpr double kPi = std::numbers::pi;

// min over the direction set of Σ_l w_l Σ_m c_lm Y_lm, with per-band partial sums precomputed.
double minWindowed(const std::vector<double>& bandSums, int bands, std::size_t ndirs,
                   const std::vector<double>& w) {
    double mn = INFINITY;
    for (std::size_t k = 0; k < ndirs; ++k) {
        double s = 0;
        for (int l = 0; l <= bands; ++l) s += w[l] * bandSums[k * (bands + 1) + l];
        mn = std::min(mn, s);
    }
    return mn;
}
}  // namespace

std::string_view toString(ShWindow w) {
    switch (w) {
        case ShWindow::None:
            return "none";
        case ShWindow::Hanning:
            return "hanning";
        case ShWindow::Lanczos:
            return "lanczos";
        case ShWindow::Gaussian:
            return "gaussian";
    }
    return "?";
}

ShWindow parseShWindow(std::string_view name, const char* source, const char* field) {
    for (ShWindow w : {ShWindow::None, ShWindow::Hanning, ShWindow::Lanczos, ShWindow::Gaussian})
        if (name == toString(w)) return w;
    throw InputError(source, field, "unknown SH window \"" + std::string(name) + "\"",
                     "use one of none, hanning, lanczos, gaussian");
}

std::vector<double> windowFactors(ShWindow window, int maxBand, double strength) {
    checkBand(maxBand);
    if (window == ShWindow::Gaussian && !(strength >= 0 && std::isfinite(strength)))
        throw InputError(
            "sh", "window strength",
            "Gaussian window strength must be finite and ≥ 0, got " + std::to_string(strength),
            "use e.g. 0.01 (mild) to 0.1 (strong)");
    std::vector<double> w(maxBand + 1, 1.0);
    for (int l = 1; l <= maxBand; ++l) {
        const double t = kPi * l / (maxBand + 1.0);
        switch (window) {
            case ShWindow::None:
                break;
            case ShWindow::Hanning:
                w[l] = 0.5 * (1.0 + std::cos(t));
                break;
            case ShWindow::Lanczos:
                w[l] = std::sin(t) / t;
                break;
            case ShWindow::Gaussian:
                w[l] = std::exp(-strength * l * (l + 1.0));
                break;
        }
    }
    return w;
}

void applyWindow(std::span<float> coeffs, ShWindow window, double strength) {
    const int bands = shBandForCount(int(coeffs.size()));
    const auto w = windowFactors(window, bands, strength);
    for (int l = 0; l <= bands; ++l)
        for (int m = -l; m <= l; ++m) coeffs[shIndex(l, m)] *= float(w[l]);
}

void applyWindowRgb(std::span<glm::vec3> coeffs, ShWindow window, double strength) {
    const int bands = shBandForCount(int(coeffs.size()));
    const auto w = windowFactors(window, bands, strength);
    for (int l = 0; l <= bands; ++l)
        for (int m = -l; m <= l; ++m) coeffs[shIndex(l, m)] *= float(w[l]);
}

double nonNegativeGaussianStrength(std::span<const float> coeffs, const SphereSamples& dirs,
                                   double tolerance) {
    const int bands = shBandForCount(int(coeffs.size()));
    // Tolerance × the mean value.
    const double floor = -tolerance * coeffs[0] * 0.5 / std::sqrt(kPi);
    if (!(coeffs[0] > 0))
        throw InputError("sh", "coefficients",
                         "a function with a non-positive mean (c_0 = " + std::to_string(coeffs[0]) +
                             ") cannot be windowed to be non-negative",
                         "only window non-negative quantities such as light or visibility");
    // Per-direction, per-band partial sums Σ_m c_lm Y_lm(ω_k).
    const std::size_t nd = dirs.size();
    std::vector<double> bandSums(nd * (bands + 1), 0.0), y(shCount(bands));
    for (std::size_t k = 0; k < nd; ++k) {
        evalShUnitDouble(bands, dirs.directions[k], y);
        for (int l = 0; l <= bands; ++l)
            for (int m = -l; m <= l; ++m)
                bandSums[k * (bands + 1) + l] += coeffs[shIndex(l, m)] * y[shIndex(l, m)];
    }
    auto ok = [&](double lambda) {
        return minWindowed(bandSums, bands, nd, windowFactors(ShWindow::Gaussian, bands, lambda)) >=
               floor;
    };
    if (ok(0.0)) return 0.0;
    double lo = 0.0, hi = 1e-3;
    while (!ok(hi)) {
        lo = hi;
        hi *= 2.0;
        VL_CHECK_LT(hi, 1e6);  // at large λ only c_0 > 0 survives, which is feasible
    }
    while (hi - lo > 1e-4 * hi) {
        const double mid = 0.5 * (lo + hi);
        (ok(mid) ? hi : lo) = mid;
    }
    return hi;
}

std::vector<double> projectZonal(int maxBand, const std::function<double(double)>& g,
                                 int quadratureNodes) {
    checkBand(maxBand);
    std::vector<double> x, w;
    gaussLegendre(quadratureNodes, x, w);
    std::vector<double> z(maxBand + 1, 0.0), y(shCount(maxBand));
    for (std::size_t k = 0; k < x.size(); ++k) {
        const double s = std::sqrt(std::max(0.0, 1.0 - x[k] * x[k]));
        evalShUnitDouble(maxBand, {s, 0.0, x[k]}, y);
        const double gv = g(x[k]) * w[k] * 2.0 * kPi;  // ∫ dφ = 2π
        for (int l = 0; l <= maxBand; ++l) z[l] += gv * y[shIndex(l, 0)];
    }
    return z;
}

std::vector<double> clampedCosineConvolution(int maxBand) {
    checkBand(maxBand);
    std::vector<double> a(maxBand + 1, 0.0);
    a[0] = kPi;
    if (maxBand >= 1) a[1] = 2.0 * kPi / 3.0;
    for (int l = 2; l <= maxBand; l += 2) {
        // Â_l = 2π (−1)^{l/2−1} / ((l+2)(l−1)) · C(l, l/2) / 2^l, the binomial ratio formed without
        // factorials.
        double ratio = 1.0;
        for (int k = 1; k <= l / 2; ++k) ratio *= double(l / 2 + k) / (4.0 * k);
        const double sign = ((l / 2 - 1) % 2 == 0) ? 1.0 : -1.0;
        a[l] = 2.0 * kPi * sign / ((l + 2.0) * (l - 1.0)) * ratio;
    }
    return a;
}

std::vector<double> clampedCosineZonal(int maxBand) {
    auto z = clampedCosineConvolution(maxBand);
    for (int l = 0; l <= maxBand; ++l) z[l] *= std::sqrt((2.0 * l + 1.0) / (4.0 * kPi));
    return z;
}

std::vector<float> zonalToAxis(std::span<const double> zonal, const glm::dvec3& axis) {
    const int bands = int(zonal.size()) - 1;
    checkBand(bands);
    std::vector<float> c(shCount(bands));
    zonalToAxis(zonal, axis, c);
    return c;
}

void zonalToAxis(std::span<const double> zonal, const glm::dvec3& axis, std::span<float> out) {
    const int bands = int(zonal.size()) - 1;
    checkBand(bands);
    VL_CHECK_GE(out.size(), std::size_t(shCount(bands)));
    const glm::dvec3 a = normalizeDirection(axis, "sh", "zonal axis");
    std::array<double, kMaxCoeffs> y;
    evalShUnitDouble(bands, a, y);
    for (int l = 0; l <= bands; ++l) {
        const double k = zonal[l] * std::sqrt(4.0 * kPi / (2.0 * l + 1.0));
        for (int m = -l; m <= l; ++m) out[shIndex(l, m)] = float(k * y[shIndex(l, m)]);
    }
}

void convolveZonal(std::span<float> coeffs, std::span<const double> zonal) {
    const int bands = shBandForCount(int(coeffs.size()));
    VL_CHECK_GE(int(zonal.size()), bands + 1);
    for (int l = 0; l <= bands; ++l) {
        const double k = zonal[l] * std::sqrt(4.0 * kPi / (2.0 * l + 1.0));
        for (int m = -l; m <= l; ++m) coeffs[shIndex(l, m)] = float(coeffs[shIndex(l, m)] * k);
    }
}

void convolveZonalRgb(std::span<glm::vec3> coeffs, std::span<const double> zonal) {
    const int bands = shBandForCount(int(coeffs.size()));
    VL_CHECK_GE(int(zonal.size()), bands + 1);
    for (int l = 0; l <= bands; ++l) {
        const float k = float(zonal[l] * std::sqrt(4.0 * kPi / (2.0 * l + 1.0)));
        for (int m = -l; m <= l; ++m) coeffs[shIndex(l, m)] *= k;
    }
}

}  // namespace voxlight::sh
