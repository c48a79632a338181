// SPDX-License-Identifier: MIT
#include "sh/dsf.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "core/error.h"

namespace voxlight::sh {

namespace {
constexpr double kPi = std::numbers::pi;

double angleBetween(const glm::dvec3& a, const glm::dvec3& b) {
    return std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0));
}

// Cube-map face f = 2·axis + (negative ? 1 : 0); (u, v) ∈ [−1, 1]² on the other two axes in cyclic
// order.
glm::dvec3 faceDirection(int face, double u, double v) {
    const int a = face / 2;
    glm::dvec3 d(0.0);
    d[a] = (face % 2) ? -1.0 : 1.0;
    d[(a + 1) % 3] = u;
    d[(a + 2) % 3] = v;
    return glm::normalize(d);
}
}  // namespace

Dsf::Dsf(int directionCount) {
    int frequency = 0;
    for (int f : {1, 2, 4, 8, 16, 32})
        if (10 * f * f + 2 == directionCount) frequency = f;
    if (frequency == 0)
        throw InputError(
            "dsf", "directions",
            "a DSF has 10·f²+2 icosahedral directions, not " + std::to_string(directionCount),
            "use 42, 162, 642 (Zhang 2013's choice) or 2562");
    const SphereMesh mesh = subdividedPolyhedron(Polyhedron::Icosahedron, frequency);
    dirs_ = mesh.vertices;
    tris_ = mesh.triangles;
    // h = the minimum angle between two directions; nearest pairs are mesh edges.
    h_ = kPi;
    for (const auto& t : tris_) {
        h_ = std::min({h_, angleBetween(dirs_[t.x], dirs_[t.y]),
                       angleBetween(dirs_[t.y], dirs_[t.z]), angleBetween(dirs_[t.z], dirs_[t.x])});
    }
    cosH_ = std::cos(h_);

    // Candidate lists per cube-map cell: directions within h, triangles whose bounding cap meets
    // the cell's cap.
    gridN_ = std::max(1, int(std::ceil(2.0 / h_)));
    const int cells = 6 * gridN_ * gridN_;
    std::vector<glm::dvec3> triCentre(tris_.size());
    std::vector<double> triRadius(tris_.size());
    for (std::size_t t = 0; t < tris_.size(); ++t) {
        const glm::dvec3 a = dirs_[tris_[t].x], b = dirs_[tris_[t].y], c = dirs_[tris_[t].z];
        triCentre[t] = glm::normalize(a + b + c);
        triRadius[t] = std::max({angleBetween(triCentre[t], a), angleBetween(triCentre[t], b),
                                 angleBetween(triCentre[t], c)});
    }
    dirStart_.assign(cells + 1, 0);
    triStart_.assign(cells + 1, 0);
    constexpr double kSlack = 1e-9;
    for (int cell = 0; cell < cells; ++cell) {
        const int face = cell / (gridN_ * gridN_), ij = cell % (gridN_ * gridN_);
        const int i = ij / gridN_, j = ij % gridN_;
        auto uv = [&](double x) { return -1.0 + 2.0 * x / gridN_; };
        const glm::dvec3 centre = faceDirection(face, uv(i + 0.5), uv(j + 0.5));
        double radius = 0;
        for (int ci = 0; ci <= 1; ++ci)
            for (int cj = 0; cj <= 1; ++cj)
                radius = std::max(
                    radius, angleBetween(centre, faceDirection(face, uv(i + ci), uv(j + cj))));
        // angle < a ⇔ cos(angle) > cos(a) for a ≤ π: compare dot products, no acos per pair.
        const double cosDir = std::cos(std::min(kPi, h_ + radius + kSlack));
        for (int k = 0; k < size(); ++k)
            if (glm::dot(centre, dirs_[k]) > cosDir) dirList_.push_back(k);
        for (std::size_t t = 0; t < tris_.size(); ++t)
            if (glm::dot(centre, triCentre[t]) >
                std::cos(std::min(kPi, triRadius[t] + radius + kSlack)))
                triList_.push_back(int(t));
        dirStart_[cell + 1] = int(dirList_.size());
        triStart_[cell + 1] = int(triList_.size());
    }

    // Basis solid angles A_k = ∫ w̄_k dω by a dense equal-weight quadrature (also checks the
    // covering property).
    area_.assign(dirs_.size(), 0.0);
    const SphereSamples q = fibonacciSamples(std::max(20000, 64 * size()));
    int idx[kMaxSupport];
    double w[kMaxSupport];
    for (std::size_t k = 0; k < q.size(); ++k) {
        const int n = weights(q.directions[k], idx, w);
        VL_CHECK_GT(n, 0);
        for (int j = 0; j < n; ++j) area_[idx[j]] += w[j] * q.weights[k];
    }
}

int Dsf::cellOf(const glm::dvec3& d) const {
    const glm::dvec3 ad = glm::abs(d);
    const int a = (ad.x >= ad.y && ad.x >= ad.z) ? 0 : (ad.y >= ad.z ? 1 : 2);
    const int face = 2 * a + (d[a] < 0 ? 1 : 0);
    const double u = d[(a + 1) % 3] / ad[a], v = d[(a + 2) % 3] / ad[a];
    const int i = std::clamp(int((u + 1.0) * 0.5 * gridN_), 0, gridN_ - 1);
    const int j = std::clamp(int((v + 1.0) * 0.5 * gridN_), 0, gridN_ - 1);
    return face * gridN_ * gridN_ + i * gridN_ + j;
}

int Dsf::weights(const glm::dvec3& d, int* index, double* weight) const {
    const int cell = cellOf(d);
    int n = 0;
    double sum = 0;
    const double h2 = h_ * h_;
    for (int c = dirStart_[cell]; c < dirStart_[cell + 1]; ++c) {
        const int k = dirList_[c];
        const double cosT = glm::dot(d, dirs_[k]);
        if (cosT <= cosH_) continue;
        const double theta = std::acos(std::min(cosT, 1.0));
        const double t = h2 - theta * theta;
        if (t <= 0) continue;
        VL_DCHECK(n < kMaxSupport);
        index[n] = k;
        weight[n] = t * t * t;
        sum += weight[n];
        ++n;
    }
    for (int j = 0; j < n; ++j) weight[j] /= sum;
    return n;
}

template <class T>
T Dsf::evaluateImpl(std::span<const T> s, const glm::dvec3& d) const {
    VL_CHECK_EQ(int(s.size()), size());
    int idx[kMaxSupport];
    double w[kMaxSupport];
    const int n = weights(d, idx, w);
    T r(0);
    for (int j = 0; j < n; ++j) r += s[idx[j]] * float(w[j]);
    return r;
}

float Dsf::evaluate(std::span<const float> s, const glm::dvec3& d) const {
    return evaluateImpl(s, d);
}
glm::vec3 Dsf::evaluateRgb(std::span<const glm::vec3> s, const glm::dvec3& d) const {
    return evaluateImpl(s, d);
}

void Dsf::barycentric(const glm::dvec3& d, int index[3], double b[3]) const {
    const int cell = cellOf(d);
    int best = -1;
    double bestScore = -INFINITY;
    for (int c = triStart_[cell]; c < triStart_[cell + 1]; ++c) {
        const glm::ivec3 t = tris_[triList_[c]];
        const glm::dvec3 p = dirs_[t.x], q = dirs_[t.y], r = dirs_[t.z];
        // Inside the spherical triangle ⇔ on the inner side of its three great-circle edges.
        const double score = std::min({glm::dot(d, glm::cross(p, q)), glm::dot(d, glm::cross(q, r)),
                                       glm::dot(d, glm::cross(r, p))});
        if (score > bestScore) {
            bestScore = score;
            best = triList_[c];
        }
        if (score >= 0) break;
    }
    VL_CHECK_GE(best, 0);
    const glm::ivec3 t = tris_[best];
    const glm::dvec3 p = dirs_[t.x], q = dirs_[t.y], r = dirs_[t.z];
    // Planar barycentrics of the ray's intersection with the triangle's plane.
    const glm::dvec3 n = glm::cross(q - p, r - p);
    const glm::dvec3 x = d * (glm::dot(n, p) / glm::dot(n, d));
    double w[3] = {glm::dot(n, glm::cross(r - q, x - q)), glm::dot(n, glm::cross(p - r, x - r)),
                   glm::dot(n, glm::cross(q - p, x - p))};
    double sum = 0;
    for (double& v : w) sum += (v = std::max(v, 0.0));
    index[0] = t.x, index[1] = t.y, index[2] = t.z;
    for (int i = 0; i < 3; ++i) b[i] = w[i] / sum;
}

void Dsf::addDirectional(std::span<glm::vec3> s, const glm::dvec3& towardLight,
                         const glm::vec3& irradiance) const {
    VL_CHECK_EQ(int(s.size()), size());
    int idx[3];
    double b[3];
    barycentric(towardLight, idx, b);
    for (int i = 0; i < 3; ++i) s[idx[i]] += irradiance * float(b[i] / area_[idx[i]]);
}

std::vector<glm::vec3> Dsf::sampleEquirect(const EquirectLayout& layout,
                                           std::span<const glm::vec3> rgb, double sigma,
                                           const glm::dmat3& mapFromWorld) const {
    const int w = layout.width, h = layout.height;
    if (w <= 0 || h <= 0)
        throw InputError("dsf", "equirect size", "grid is empty",
                         "give a non-empty latitude–longitude image");
    VL_CHECK_EQ(rgb.size(), std::size_t(w) * std::size_t(h));
    if (sigma <= 0) sigma = h_ / 3.0;
    const double cutoff = 3.0 * sigma, inv2s2 = 1.0 / (2.0 * sigma * sigma);
    const double dphi = std::abs(layout.phiStep);
    std::vector<double> rowZ(h), rowS(h), rowOmega(h), colC(w), colS(w);
    for (int r = 0; r < h; ++r) {
        const double t0 = kPi * r / h, t1 = kPi * (r + 1) / h, t = 0.5 * (t0 + t1);
        rowZ[r] = std::cos(t);
        rowS[r] = std::sin(t);
        rowOmega[r] = dphi * (std::cos(t0) - std::cos(t1));
    }
    for (int c = 0; c < w; ++c) {
        const double phi = layout.phi0 + layout.phiStep * (c + 0.5);
        colC[c] = std::cos(phi);
        colS[c] = std::sin(phi);
    }
    std::vector<glm::vec3> s(dirs_.size());
    for (int k = 0; k < size(); ++k) {
        const glm::dvec3 d = glm::normalize(mapFromWorld * dirs_[k]);
        const double theta = std::acos(std::clamp(d.z, -1.0, 1.0));
        const double phi = std::atan2(d.y, d.x);
        const int r0 = std::max(0, int(std::floor((theta - cutoff) / kPi * h)));
        const int r1 = std::min(h - 1, int(std::ceil((theta + cutoff) / kPi * h)));
        // Columns: all near a pole, else a φ window widened by 1/sinθ at the window's most polar
        // edge.
        int halfCols = w;
        if (theta - cutoff > 0 && theta + cutoff < kPi) {
            const double smin = std::min(std::sin(theta - cutoff), std::sin(theta + cutoff));
            halfCols = int(std::ceil(std::min(kPi, cutoff / smin) / dphi)) + 1;
        }
        const double cc = (phi - layout.phi0) / layout.phiStep - 0.5;
        const int cCentre = int(std::lround(cc));
        const bool allCols = 2 * halfCols + 1 >= w;
        glm::dvec3 acc(0.0), nearest(0.0);
        double wsum = 0, nearestCos = -2.0;
        for (int r = r0; r <= r1; ++r) {
            const int cb = allCols ? 0 : cCentre - halfCols,
                      ce = allCols ? w - 1 : cCentre + halfCols;
            for (int c = cb; c <= ce; ++c) {
                const int cw = ((c % w) + w) % w;
                const double cosT =
                    d.x * rowS[r] * colC[cw] + d.y * rowS[r] * colS[cw] + d.z * rowZ[r];
                if (cosT > nearestCos) {
                    nearestCos = cosT;
                    nearest = glm::dvec3(rgb[std::size_t(r) * w + cw]);
                }
                const double t = std::acos(std::clamp(cosT, -1.0, 1.0));
                if (t >= cutoff) continue;
                const double g = std::exp(-t * t * inv2s2) * rowOmega[r];
                acc += g * glm::dvec3(rgb[std::size_t(r) * w + cw]);
                wsum += g;
            }
        }
        // A grid coarser than the filter: fall back to the nearest pixel centre.
        s[k] = glm::vec3(wsum > 0 ? acc / wsum : nearest);
    }
    return s;
}

std::vector<glm::vec3> Dsf::projectEquirect(const EquirectLayout& layout,
                                            std::span<const glm::vec3> rgb,
                                            const glm::dmat3& mapFromWorld) const {
    const int w = layout.width, h = layout.height;
    if (w <= 0 || h <= 0)
        throw InputError("dsf", "equirect size", "grid is empty",
                         "give a non-empty latitude–longitude image");
    VL_CHECK_EQ(rgb.size(), std::size_t(w) * std::size_t(h));
    const glm::dmat3 worldFromMap = glm::transpose(mapFromWorld);
    // Split every pixel into sub × sub cells (exact sub-cell solid angles) so that the pixel
    // quadrature Σ_p Ω_p w̄_k(ω_p) reproduces A_k = ∫ w̄_k dω. Without it a map whose pixels are not
    // small against the kernel radius h gives a *constant* environment non-constant coefficients
    // (256×128 map, n = 2562: up to 15 % off). Each cell's radiance still goes entirely to the
    // basis functions (Σ_k w̄_k = 1), so energy stays conserved exactly.
    const double pixelAngle = std::max(kPi / h, std::abs(layout.phiStep));
    const int sub = std::clamp(int(std::ceil(pixelAngle * kProjectionCellsPerKernel / h_)), 1,
                               kMaxProjectionSubdivision);
    std::vector<glm::dvec3> acc(dirs_.size(), glm::dvec3(0.0));
    int idx[kMaxSupport];
    double wt[kMaxSupport];
    for (int r = 0; r < h; ++r) {
        for (int sr = 0; sr < sub; ++sr) {
            const double t0 = kPi * (r + double(sr) / sub) / h,
                         t1 = kPi * (r + double(sr + 1) / sub) / h;
            const double omega = std::abs(layout.phiStep) / sub * (std::cos(t0) - std::cos(t1));
            for (int c = 0; c < w; ++c) {
                const glm::dvec3 v = glm::dvec3(rgb[std::size_t(r) * w + c]) * omega;
                if (v == glm::dvec3(0.0)) continue;
                for (int sc = 0; sc < sub; ++sc) {
                    const glm::dvec3 d =
                        worldFromMap *
                        sphericalToDirection(0.5 * (t0 + t1),
                                             layout.phi0 + layout.phiStep * (c + (sc + 0.5) / sub));
                    const int n = weights(d, idx, wt);
                    for (int j = 0; j < n; ++j) acc[idx[j]] += v * wt[j];
                }
            }
        }
    }
    std::vector<glm::vec3> s(dirs_.size());
    for (int k = 0; k < size(); ++k) s[k] = glm::vec3(acc[k] / area_[k]);
    return s;
}

glm::dvec3 Dsf::integrate(std::span<const glm::vec3> s) const {
    VL_CHECK_EQ(int(s.size()), size());
    glm::dvec3 sum(0.0);
    for (int k = 0; k < size(); ++k) sum += area_[k] * glm::dvec3(s[k]);
    return sum;
}

}  // namespace voxlight::sh

#include "sh/sh_window.h"

namespace voxlight::sh {

std::vector<DsfShComparisonRow> compareDsfWithSh(const EquirectLayout& layout,
                                                 std::span<const glm::vec3> rgb,
                                                 std::span<const int> dsfCounts) {
    const int w = layout.width, h = layout.height;
    VL_CHECK_EQ(rgb.size(), std::size_t(w) * std::size_t(h));
    // Pixel directions and solid angles of the evaluation grid.
    std::vector<glm::dvec3> dir(rgb.size());
    std::vector<double> omega(rgb.size());
    for (int r = 0; r < h; ++r) {
        const double t0 = kPi * r / h, t1 = kPi * (r + 1) / h;
        for (int c = 0; c < w; ++c) {
            dir[std::size_t(r) * w + c] =
                sphericalToDirection(0.5 * (t0 + t1), layout.phi0 + layout.phiStep * (c + 0.5));
            omega[std::size_t(r) * w + c] =
                std::abs(layout.phiStep) * (std::cos(t0) - std::cos(t1));
        }
    }
    double norm = 0;
    for (std::size_t p = 0; p < rgb.size(); ++p)
        norm += omega[p] * glm::dot(glm::dvec3(rgb[p]), glm::dvec3(rgb[p]));
    auto relError = [&](auto&& reconstruct) {
        double e = 0;
        for (std::size_t p = 0; p < rgb.size(); ++p) {
            const glm::dvec3 diff = glm::dvec3(reconstruct(p)) - glm::dvec3(rgb[p]);
            e += omega[p] * glm::dot(diff, diff);
        }
        return std::sqrt(e / norm);
    };

    std::vector<DsfShComparisonRow> rows;
    for (int n : dsfCounts) {
        DsfShComparisonRow row;
        row.dsfCount = n;
        const Dsf dsf(n);
        const auto s = dsf.sampleEquirect(layout, rgb);
        row.dsfError = relError([&](std::size_t p) { return dsf.evaluateRgb(s, dir[p]); });
        const auto sp = dsf.projectEquirect(layout, rgb);
        row.dsfProjectedError =
            relError([&](std::size_t p) { return dsf.evaluateRgb(sp, dir[p]); });

        int band = 0;
        for (int l = 0; l <= kMaxBand; ++l)
            if (std::abs(shCount(l) - n) <= std::abs(shCount(band) - n)) band = l;
        row.shBand = band;
        row.shCount = shCount(band);
        auto c = projectEquirect(band, layout, rgb);
        std::vector<double> y(shCount(band));
        auto shEval = [&](const std::vector<glm::vec3>& coeffs) {
            return [&, coeffs](std::size_t p) {
                evalShUnitDouble(band, dir[p], y);
                glm::dvec3 v(0.0);
                for (int i = 0; i < shCount(band); ++i) v += glm::dvec3(coeffs[i]) * y[i];
                return v;
            };
        };
        row.shError = relError(shEval(c));
        applyWindowRgb(c, ShWindow::Hanning);
        row.shHanningError = relError(shEval(c));
        rows.push_back(row);
    }
    return rows;
}

}  // namespace voxlight::sh
