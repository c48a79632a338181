// SPDX-License-Identifier: MIT
#include "sh/sh_rotation.h"

#include <array>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::sh {

namespace {
// Row/column of the 3×3 rotation holding real-SH band-1 order m = −1, 0, 1 ↔ y, z, x.
constexpr int kAxisOfM[3] = {1, 2, 0};
}  // namespace

void checkRotation(const glm::dmat3& r, const char* source, const char* field) {
    double err = 0;
    bool finite = true;
    const glm::dmat3 rtr = glm::transpose(r) * r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            finite = finite && std::isfinite(r[i][j]);
            err = std::max(err, std::abs(rtr[i][j] - (i == j ? 1.0 : 0.0)));
        }
    const double det = glm::determinant(r);
    if (!finite || !(err < 1e-4) || !(det > 0)) {
        std::ostringstream os;
        os << "matrix is not a rotation (max |RᵀR − I| = " << err << ", det = " << det << ")";
        throw InputError(
            source, field, os.str(),
            "give an orthonormal 3×3 matrix with determinant +1 (no scaling or mirroring)");
    }
}

namespace {
double orthonormalityError(const glm::dmat3& r) {
    const glm::dmat3 rtr = glm::transpose(r) * r;
    double err = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) err = std::max(err, std::abs(rtr[i][j] - (i == j ? 1.0 : 0.0)));
    return err;
}
}  // namespace

glm::dmat3 orthonormalizeRotation(const glm::dmat3& r) {
    VL_CHECK(glm::determinant(r) > 0);
    // Already a rotation to rounding: keep the caller's matrix bit for bit.
    if (orthonormalityError(r) <= kRotationRoundingTol) return r;
    glm::dmat3 q = r;
    for (int step = 0; step < 8; ++step) {
        const glm::dmat3 next = 0.5 * (q + glm::transpose(glm::inverse(q)));
        double change = 0;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) change = std::max(change, std::abs(next[i][j] - q[i][j]));
        if (change == 0) break;  // already orthonormal to the last bit (exact rotations stay put)
        q = next;
        if (change < 1e-15) break;
    }
    return q;
}

ShRotation::ShRotation(const glm::dmat3& r, int maxBand) : band_(maxBand) {
    checkBand(maxBand, "sh", "rotation band");
    checkRotation(r);
    r_ = orthonormalizeRotation(r);
    blocks_.assign(offset(maxBand + 1), 0.0);
    at(0, 0, 0) = 1.0;
    if (maxBand == 0) return;
    // Band 1: R with rows/columns in (y, z, x) order. glm is column-major: r[col][row].
    for (int m = -1; m <= 1; ++m)
        for (int n = -1; n <= 1; ++n) at(1, m, n) = r_[kAxisOfM[n + 1]][kAxisOfM[m + 1]];

    // Ivanic–Ruedenberg recursion for bands 2..L (Table 2 of the 1998 erratum; Wyman 2006 Table 3).
    for (int l = 2; l <= maxBand; ++l) {
        auto r1 = [&](int i, int j) { return element(1, i, j); };
        auto rp = [&](int a, int b) { return element(l - 1, a, b); };
        auto P = [&](int i, int a, int b) {
            if (b == l) return r1(i, 1) * rp(a, l - 1) - r1(i, -1) * rp(a, -l + 1);
            if (b == -l) return r1(i, 1) * rp(a, -l + 1) + r1(i, -1) * rp(a, l - 1);
            return r1(i, 0) * rp(a, b);
        };
        for (int m = -l; m <= l; ++m) {
            for (int n = -l; n <= l; ++n) {
                const double d = m == 0 ? 1.0 : 0.0;
                const int am = std::abs(m);
                const double denom =
                    std::abs(n) == l ? double(2 * l) * (2 * l - 1) : double(l + n) * (l - n);
                const double u = std::sqrt(double(l + m) * (l - m) / denom);
                const double v = 0.5 * std::sqrt((1.0 + d) * (l + am - 1.0) * (l + am) / denom) *
                                 (1.0 - 2.0 * d);
                const double w =
                    -0.5 * std::sqrt(double(l - am - 1) * (l - am) / denom) * (1.0 - d);
                double value = 0;
                if (u != 0) value += u * P(0, m, n);
                if (v != 0) {
                    double V;
                    if (m == 0)
                        V = P(1, 1, n) + P(-1, -1, n);
                    else if (m > 0)
                        V = P(1, m - 1, n) * std::sqrt(1.0 + (m == 1)) -
                            P(-1, -m + 1, n) * (m != 1);
                    else
                        V = P(1, m + 1, n) * (m != -1) +
                            P(-1, -m - 1, n) * std::sqrt(1.0 + (m == -1));
                    value += v * V;
                }
                if (w != 0) {
                    double W;
                    if (m > 0)
                        W = P(1, m + 1, n) + P(-1, -m - 1, n);
                    else
                        W = P(1, m - 1, n) - P(-1, -m + 1, n);
                    value += w * W;
                }
                at(l, m, n) = value;
            }
        }
    }
}

template <class T>
void ShRotation::applyImpl(std::span<const T> in, std::span<T> out) const {
    const int bands = shBandForCount(int(in.size()));
    VL_CHECK_LE(bands, band_);
    VL_CHECK_GE(out.size(), in.size());
    std::array<double, 2 * kMaxBand + 1> tmp;
    for (int l = 0; l <= bands; ++l) {
        const int w = 2 * l + 1, base = l * l;
        const double* blk = &blocks_[offset(l)];
        for (int m = 0; m < w; ++m) {
            double s = 0;
            for (int n = 0; n < w; ++n) s += blk[m * w + n] * double(in[base + n]);
            tmp[m] = s;
        }
        for (int m = 0; m < w; ++m) out[base + m] = T(tmp[m]);
    }
}

void ShRotation::apply(std::span<const float> in, std::span<float> out) const {
    applyImpl(in, out);
}
void ShRotation::apply(std::span<const double> in, std::span<double> out) const {
    applyImpl(in, out);
}

void ShRotation::applyRgb(std::span<const glm::vec3> in, std::span<glm::vec3> out) const {
    const int bands = shBandForCount(int(in.size()));
    VL_CHECK_LE(bands, band_);
    VL_CHECK_GE(out.size(), in.size());
    std::array<glm::dvec3, 2 * kMaxBand + 1> tmp;
    for (int l = 0; l <= bands; ++l) {
        const int w = 2 * l + 1, base = l * l;
        const double* blk = &blocks_[offset(l)];
        for (int m = 0; m < w; ++m) {
            glm::dvec3 s(0.0);
            for (int n = 0; n < w; ++n) s += blk[m * w + n] * glm::dvec3(in[base + n]);
            tmp[m] = s;
        }
        for (int m = 0; m < w; ++m) out[base + m] = glm::vec3(tmp[m]);
    }
}

const ShRotation& CachedShRotation::get(const glm::dmat3& r, int maxBand) {
    if (cached_.empty() || cached_.front().maxBand() != maxBand || key_ != r) {
        cached_.clear();
        cached_.emplace_back(r, maxBand);
        key_ = r;
        ++builds_;
    }
    return cached_.front();
}

void rotateZ(double angle, std::span<const float> in, std::span<float> out) {
    const int bands = shBandForCount(int(in.size()));
    VL_CHECK_GE(out.size(), in.size());
    const double c1 = std::cos(angle), s1 = std::sin(angle);
    out[0] = in[0];
    double cm = 1.0, sm = 0.0;  // cos(mα), sin(mα) by the angle-addition recurrence
    for (int m = 1; m <= bands; ++m) {
        const double c = cm * c1 - sm * s1;
        sm = sm * c1 + cm * s1;
        cm = c;
        for (int l = m; l <= bands; ++l) {
            const double a = in[shIndex(l, m)], b = in[shIndex(l, -m)];
            out[shIndex(l, m)] = float(a * cm - b * sm);
            out[shIndex(l, -m)] = float(a * sm + b * cm);
        }
    }
    for (int l = 1; l <= bands; ++l) out[shIndex(l, 0)] = in[shIndex(l, 0)];
}

}  // namespace voxlight::sh
