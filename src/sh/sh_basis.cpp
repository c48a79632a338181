// SPDX-License-Identifier: MIT
#include "sh/sh_basis.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "core/error.h"

namespace voxlight::sh {

namespace {

// Coefficients of the normalised associated-Legendre recurrence (P̄ includes K_l^m, excludes
// sin^m θ):
//   P̄_m^m     = P̄_{m−1}^{m−1} · √((2m+1)/(2m)),     P̄_0^0 = 1/√(4π)
//   P̄_{m+1}^m = √(2m+3) · z · P̄_m^m
//   P̄_l^m     = a_l^m z P̄_{l−1}^m − b_l^m P̄_{l−2}^m,  a = √((4l²−1)/(l²−m²)),
//                                                      b = √(((l−1)²−m²)(2l+1)/((2l−3)(l²−m²)))
struct RecurrenceTables {
    std::array<double, kMaxBand + 1> diag{};  // P̄_m^m / P̄_{m−1}^{m−1}
    std::array<double, kMaxCoeffs> a{}, b{};  // indexed by shIndex(l, m), m ≥ 0
    RecurrenceTables() {
        diag[0] = 0.5 / std::sqrt(std::numbers::pi);
        for (int m = 1; m <= kMaxBand; ++m) diag[m] = std::sqrt((2.0 * m + 1.0) / (2.0 * m));
        for (int m = 0; m <= kMaxBand; ++m) {
            for (int l = m + 2; l <= kMaxBand; ++l) {
                const double l2 = double(l) * l, m2 = double(m) * m;
                a[shIndex(l, m)] = std::sqrt((4.0 * l2 - 1.0) / (l2 - m2));
                b[shIndex(l, m)] = std::sqrt(((l - 1.0) * (l - 1.0) - m2) * (2.0 * l + 1.0) /
                                             ((2.0 * l - 3.0) * (l2 - m2)));
            }
        }
    }
};

const RecurrenceTables& tables() {
    static const RecurrenceTables t;
    return t;
}

template <class T>
void evalRecurrence(int maxBand, T x, T y, T z, T* out) {
    const RecurrenceTables& tb = tables();
    const T sqrt2 = T(std::numbers::sqrt2);
    T pmm = T(tb.diag[0]);
    T cm = 1, sm = 0;  // Re, Im of (x + iy)^m = sin^m θ · (cos mφ, sin mφ)
    for (int m = 0; m <= maxBand; ++m) {
        if (m > 0) {
            pmm *= T(tb.diag[m]);
            const T c = cm * x - sm * y;
            sm = cm * y + sm * x;
            cm = c;
        }
        const T wc = m == 0 ? T(1) : sqrt2 * cm;
        const T ws = sqrt2 * sm;
        auto store = [&](int l, T p) {
            out[shIndex(l, m)] = p * wc;
            if (m > 0) out[shIndex(l, -m)] = p * ws;
        };
        store(m, pmm);
        if (m + 1 > maxBand) continue;
        T p2 = pmm;
        T p1 = T(std::sqrt(2.0 * m + 3.0)) * z * pmm;
        store(m + 1, p1);
        for (int l = m + 2; l <= maxBand; ++l) {
            const T p = T(tb.a[shIndex(l, m)]) * z * p1 - T(tb.b[shIndex(l, m)]) * p2;
            store(l, p);
            p2 = p1;
            p1 = p;
        }
    }
}

template <class V>
V normalizeDirectionImpl(const V& dir, const char* source, const char* field) {
    const bool finite = std::isfinite(dir.x) && std::isfinite(dir.y) && std::isfinite(dir.z);
    if (!finite)
        throw InputError(source, field,
                         "direction has a NaN or infinite component (" + std::to_string(dir.x) +
                             ", " + std::to_string(dir.y) + ", " + std::to_string(dir.z) + ")",
                         "give a finite, non-zero direction vector");
    // A direction already of unit length to rounding is kept as given: normalising it again would
    // only move its last bits (and a renderer handed a unit vector should shade with exactly it).
    using S = typename V::value_type;
    const S len2 = dir.x * dir.x + dir.y * dir.y + dir.z * dir.z;
    if (std::abs(len2 - S(1)) <= S(4) * std::numeric_limits<S>::epsilon()) return dir;
    // Scale by the largest component first so that tiny (but non-zero) vectors normalise without
    // underflow.
    const auto big = std::max(std::abs(dir.x), std::max(std::abs(dir.y), std::abs(dir.z)));
    if (!(big > 0))
        throw InputError(source, field, "direction is the zero vector, which has no direction",
                         "give a non-zero direction vector, e.g. [0, 0, 1]");
    const V s = dir / big;
    return s / std::sqrt(s.x * s.x + s.y * s.y + s.z * s.z);
}

}  // namespace

int shBandOf(int i) {
    VL_CHECK_GE(i, 0);
    int l = int(std::sqrt(double(i)));
    while ((l + 1) * (l + 1) <= i) ++l;
    while (l * l > i) --l;
    return l;
}

int shBandForCount(int count) {
    const int l = count > 0 ? shBandOf(count - 1) : -1;
    if (count <= 0 || shCount(l) != count || l > kMaxBand)
        throw InputError(
            "sh", "coefficient count",
            std::to_string(count) + " is not (L+1)² for a band L in 0.." + std::to_string(kMaxBand),
            "use 1, 4, 9, 16, 25, 36, 49, 64 or 81 coefficients (bands 0..8)");
    return l;
}

void checkBand(int maxBand, const char* source, const char* field) {
    if (maxBand < 0 || maxBand > kMaxBand)
        throw InputError(
            source, field,
            "SH band " + std::to_string(maxBand) + " is outside 0.." + std::to_string(kMaxBand),
            "use a band between 0 and 8 for rendering (4 is the usual choice)");
}

glm::vec3 normalizeDirection(const glm::vec3& dir, const char* source, const char* field) {
    return normalizeDirectionImpl(dir, source, field);
}

glm::dvec3 normalizeDirection(const glm::dvec3& dir, const char* source, const char* field) {
    return normalizeDirectionImpl(dir, source, field);
}

glm::dvec3 sphericalToDirection(double theta, double phi) {
    const double st = std::sin(theta);
    return {st * std::cos(phi), st * std::sin(phi), std::cos(theta)};
}

void evalShUnit(int maxBand, const glm::vec3& d, std::span<float> out) {
    VL_CHECK(maxBand >= 0 && maxBand <= kMaxBand);
    VL_CHECK_GE(int(out.size()), shCount(maxBand));
    VL_DCHECK(std::abs(glm::dot(d, d) - 1.0f) < 1e-3f);
    evalRecurrence<float>(maxBand, d.x, d.y, d.z, out.data());
}

void evalShUnitDouble(int maxBand, const glm::dvec3& d, std::span<double> out) {
    VL_CHECK(maxBand >= 0 && maxBand <= kMaxBand);
    VL_CHECK_GE(int(out.size()), shCount(maxBand));
    VL_DCHECK(std::abs(glm::dot(d, d) - 1.0) < 1e-6);
    evalRecurrence<double>(maxBand, d.x, d.y, d.z, out.data());
}

void evalSh(int maxBand, const glm::vec3& dir, std::span<float> out) {
    checkBand(maxBand);
    VL_CHECK_GE(int(out.size()), shCount(maxBand));
    const glm::vec3 d = normalizeDirection(dir);
    switch (maxBand) {
        case 0:
            evalShFixed<0>(d, out.data());
            return;
        case 1:
            evalShFixed<1>(d, out.data());
            return;
        case 2:
            evalShFixed<2>(d, out.data());
            return;
        case 3:
            evalShFixed<3>(d, out.data());
            return;
        case 4:
            evalShFixed<4>(d, out.data());
            return;
        default:
            evalRecurrence<float>(maxBand, d.x, d.y, d.z, out.data());
    }
}

double evalShSlow(int l, int m, double theta, double phi) {
    VL_CHECK(l >= 0 && l <= kMaxBand && std::abs(m) <= l);
    const int am = std::abs(m);
    const double x = std::cos(theta);
    // Associated Legendre P_l^|m|(x) without the Condon–Shortley phase (Numerical Recipes plgndr,
    // sign dropped).
    const double somx2 = std::sqrt(std::max(0.0, (1.0 - x) * (1.0 + x)));
    double pmm = 1.0, fact = 1.0;
    for (int i = 1; i <= am; ++i) {
        pmm *= fact * somx2;
        fact += 2.0;
    }
    double plm = pmm;
    if (l > am) {
        double pmmp1 = x * (2.0 * am + 1.0) * pmm;
        plm = pmmp1;
        for (int ll = am + 2; ll <= l; ++ll) {
            plm = (x * (2.0 * ll - 1.0) * pmmp1 - (ll + am - 1.0) * pmm) / double(ll - am);
            pmm = pmmp1;
            pmmp1 = plm;
        }
    }
    // K_l^m² = (2l+1)/(4π) · (l−|m|)!/(l+|m|)!, as a product of ratios (no factorial is ever
    // formed).
    double k2 = (2.0 * l + 1.0) / (4.0 * std::numbers::pi);
    for (int j = l - am + 1; j <= l + am; ++j) k2 /= double(j);
    const double k = std::sqrt(k2);
    if (m == 0) return k * plm;
    if (m > 0) return std::numbers::sqrt2 * k * plm * std::cos(m * phi);
    return std::numbers::sqrt2 * k * plm * std::sin(am * phi);
}

double evalShSlow(int l, int m, const glm::dvec3& dir) {
    const glm::dvec3 d = normalizeDirection(dir);
    const double theta = std::acos(std::clamp(d.z, -1.0, 1.0));
    const double phi = std::atan2(d.y, d.x);
    return evalShSlow(l, m, theta, phi);
}

double shDot(std::span<const float> a, std::span<const float> b) {
    const std::size_t n = std::min(a.size(), b.size());
    double s = 0;
    for (std::size_t i = 0; i < n; ++i) s += double(a[i]) * b[i];
    return s;
}

float shReconstruct(std::span<const float> coeffs, const glm::vec3& unitDir) {
    const int band = shBandForCount(int(coeffs.size()));
    std::array<float, kMaxCoeffs> y;
    if (band <= kMaxFixedBand) {
        switch (band) {
            case 0:
                evalShFixed<0>(unitDir, y.data());
                break;
            case 1:
                evalShFixed<1>(unitDir, y.data());
                break;
            case 2:
                evalShFixed<2>(unitDir, y.data());
                break;
            case 3:
                evalShFixed<3>(unitDir, y.data());
                break;
            default:
                evalShFixed<4>(unitDir, y.data());
                break;
        }
    } else {
        evalRecurrence<float>(band, unitDir.x, unitDir.y, unitDir.z, y.data());
    }
    float s = 0;
    for (std::size_t i = 0; i < coeffs.size(); ++i) s += coeffs[i] * y[i];
    return s;
}

double shReconstructDouble(std::span<const double> coeffs, const glm::dvec3& unitDir) {
    const int band = shBandForCount(int(coeffs.size()));
    std::array<double, kMaxCoeffs> y;
    evalRecurrence<double>(band, unitDir.x, unitDir.y, unitDir.z, y.data());
    double s = 0;
    for (std::size_t i = 0; i < coeffs.size(); ++i) s += coeffs[i] * y[i];
    return s;
}

}  // namespace voxlight::sh
