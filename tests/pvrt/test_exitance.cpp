// SPDX-License-Identifier: MIT
// Exitance coefficients of PVRT's transfer (pvrt/transfer.h): the Funk–Hecke evaluation of the
// Henyey–Greenstein in-scattered radiance from the SH coefficients of the incident radiance,
// against brute-force quadrature of the path tracer's own HG phase function (its cos θ between
// propagation directions), and CPCA's per-coefficient light combination.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "pathtrace/path_tracer.h"
#include "pvrt/cpca.h"
#include "pvrt/radiance.h"
#include "pvrt/transfer.h"
#include "sh/sh_basis.h"

using namespace voxlight;

namespace {

constexpr double kPi = std::numbers::pi;

/// A band-3 incident radiance L(ω) = Σ_j c_j Y_j(ω) (ω toward where the light comes from) with
/// every band present — odd bands too, so a flipped direction convention changes the result.
struct BandLimited {
    std::array<double, 16> c{};
    double operator()(const glm::dvec3& w) const {
        double y[16];
        sh::evalShUnitDouble(3, w, std::span<double>(y, 16));
        double s = 0;
        for (int j = 0; j < 16; ++j) s += c[std::size_t(j)] * y[j];
        return s;
    }
};

BandLimited testRadiance() {
    BandLimited L;
    // Deterministic, no symmetry: a strong mean, a strong band-1 lobe, smaller higher bands.
    const double c[16] = {3.0,  0.8,  1.1,   -0.9, 0.35,  -0.4, 0.5,  0.25,
                          -0.3, 0.15, -0.22, 0.18, -0.12, 0.2,  0.09, -0.16};
    for (int j = 0; j < 16; ++j) L.c[std::size_t(j)] = c[j];
    return L;
}

/// An orthonormal frame (u, v) about unit a.
void frame(const glm::dvec3& a, glm::dvec3& u, glm::dvec3& v) {
    u = glm::normalize(
        glm::cross(std::abs(a.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0), a));
    v = glm::cross(a, u);
}

/// Brute force ∫ p_HG(cos θ) L(ω) dω toward the eye: the light arriving from ω propagates along
/// −ω, leaves toward the eye along toEye, cos θ = (−ω)·toEye (pathtrace::henyeyGreenstein's
/// convention). Integrated in (μ, φ) about −toEye, where HG depends on μ alone: midpoint rule in μ
/// (kMu cells resolve HG's peak of width ~(1 − g)²/(2g) in μ even at g = 0.95), and kPhi points in
/// φ (exact for the band ≤ 3 dependence on φ).
double bruteForce(const BandLimited& L, float g, const glm::dvec3& toEye) {
    constexpr int kMu = 40000, kPhi = 16;
    const glm::dvec3 a = -toEye;
    glm::dvec3 u, v;
    frame(a, u, v);
    double sum = 0;
    for (int i = 0; i < kMu; ++i) {
        const double mu = -1.0 + (i + 0.5) * 2.0 / kMu;
        const double s = std::sqrt(std::max(0.0, 1.0 - mu * mu));
        const double p = pathtrace::henyeyGreenstein(float(mu), g);
        double ring = 0;
        for (int k = 0; k < kPhi; ++k) {
            const double phi = 2.0 * kPi * (k + 0.5) / kPhi;
            ring += L(mu * a + s * (std::cos(phi) * u + std::sin(phi) * v));
        }
        sum += p * ring;
    }
    return sum * (2.0 / kMu) * (2.0 * kPi / kPhi);
}

/// The stored exitance coefficients t_j = (1/4π) ∫ L Ŷ_j dω, by a Gauss-free fine quadrature
/// (midpoint in cos θ and φ; exact enough for band 6 products).
std::array<double, 16> exitance(const BandLimited& L) {
    constexpr int kT = 256, kP = 512;
    std::array<double, 16> t{};
    double y[16];
    for (int i = 0; i < kT; ++i) {
        const double z = -1.0 + (i + 0.5) * 2.0 / kT, s = std::sqrt(1.0 - z * z);
        for (int k = 0; k < kP; ++k) {
            const double phi = 2.0 * kPi * (k + 0.5) / kP;
            const glm::dvec3 w(s * std::cos(phi), s * std::sin(phi), z);
            pvrt::scaledSh(16, w, y);
            const double l = L(w);
            for (int j = 0; j < 16; ++j) t[std::size_t(j)] += l * y[j];
        }
    }
    for (double& x : t) x *= (2.0 / kT) * (2.0 * kPi / kP) / (4.0 * kPi);
    return t;
}

double evaluate(const std::array<double, 16>& t, int n, float g, const glm::vec3& toEye) {
    float w[pvrt::kMaxExitance];
    pvrt::exitanceWeights(n, g, toEye, w);
    double s = 0;
    for (int j = 0; j < n; ++j) s += double(w[j]) * t[std::size_t(j)];
    return s;
}

}  // namespace

TEST(PvrtExitance, ScaledShIsOneForBandZeroAndOrthogonal) {
    double y[16];
    pvrt::scaledSh(16, glm::normalize(glm::dvec3(0.3, -0.5, 0.8)), y);
    EXPECT_EQ(y[0], 1.0);  // exactly: n = 1 keeps the isotropic arithmetic bit for bit
    // (1/4π)∫ Ŷ_i Ŷ_j = δ_ij: the projection of L = Ŷ_5 alone.
    BandLimited L;
    L.c[5] = std::sqrt(4.0 * kPi);
    const auto t = exitance(L);
    // The midpoint rule in cos θ (256 cells) integrates the band-6 product to ~4e-5 (measured
    // 3.8e-5 on the diagonal); the off-diagonal entries vanish by symmetry to ~1e-15.
    constexpr double kMidpointTol = 1e-4;
    for (int j = 0; j < 16; ++j)
        EXPECT_NEAR(t[std::size_t(j)], j == 5 ? 1.0 : 0.0, kMidpointTol) << j;
}

TEST(PvrtExitance, FunkHeckeMatchesBruteForceHgQuadrature) {
    // For a band-3 L the 16-coefficient evaluation is exact: any difference is the quadratures'
    // (~1e-6 relative) or a wrong convention (sign of toEye, g^l, normalisation: O(1) errors).
    constexpr double kQuadratureTol = 2e-4;  // relative to the mean radiance L_00·Y_00 = 3/√(4π)
    const BandLimited L = testRadiance();
    const auto t = exitance(L);
    const double scale = t[0];
    const glm::vec3 eyes[] = {glm::normalize(glm::vec3(0.2f, -1.f, 0.3f)), glm::vec3(0, 0, 1),
                              glm::normalize(glm::vec3(-0.7f, 0.4f, -0.6f))};
    for (float g : {-0.95f, -0.6f, 0.f, 0.3f, 0.6f, 0.9f, 0.95f})
        for (const glm::vec3& e : eyes) {
            const double ref = bruteForce(L, g, glm::dvec3(e));
            const double sh = evaluate(t, 16, g, e);
            EXPECT_NEAR(sh, ref, kQuadratureTol * scale) << "g " << g << " eye " << e.x;
            if (g != 0.f) {
                // The opposite convention (Ŷ_j(+toEye), i.e. evaluating at −e: the odd bands
                // change sign) is far off, so this test can fail.
                const double flipped = evaluate(t, 16, g, -e);
                EXPECT_GT(std::abs(flipped - sh), 100 * kQuadratureTol * scale) << "g " << g;
            }
        }
}

TEST(PvrtExitance, IsotropicIsTheMeanAndFewerBandsTruncateHg) {
    const BandLimited L = testRadiance();
    const auto t = exitance(L);
    const glm::vec3 e = glm::normalize(glm::vec3(0.2f, -1.f, 0.3f));
    // n = 1 or g = 0: the isotropic S = (1/4π)∫L, whatever the direction.
    EXPECT_DOUBLE_EQ(evaluate(t, 1, 0.6f, e), t[0]);
    EXPECT_NEAR(evaluate(t, 16, 0.f, e), t[0], 1e-12);
    // Truncation: the error of n = 4 and 9 against the brute force is the dropped bands' share,
    // Σ_{l>L} g^l (band l of L)·Y — non-zero here, and shrinking with n.
    const double ref = bruteForce(L, 0.6f, glm::dvec3(e));
    const double e1 = std::abs(evaluate(t, 1, 0.6f, e) - ref);
    const double e4 = std::abs(evaluate(t, 4, 0.6f, e) - ref);
    const double e16 = std::abs(evaluate(t, 16, 0.6f, e) - ref);
    EXPECT_GT(e1, e16 * 100);
    EXPECT_GT(e4, e16 * 10);
}

TEST(PvrtExitance, ExtremeAsymmetryStaysFinite) {
    float w[16];
    for (float g : {-0.999f, 0.999f}) {
        pvrt::exitanceWeights(16, g, glm::vec3(0, 0, 1), w);
        for (float x : w) EXPECT_TRUE(std::isfinite(x));
    }
}

TEST(PvrtExitance, CpcaCombinesEveryCoefficient) {
    // Rows of n = 4 coefficients × m = 3 basis lights × RGB, as many clusters as rows: CPCA
    // reconstructs them exactly, so its radiance must equal the direct combination per j.
    const int n = 4, m = 3, dim = n * m * 3, rows = 6;
    std::vector<float> data(std::size_t(rows) * dim);
    for (std::size_t i = 0; i < data.size(); ++i) data[i] = float(std::sin(0.37 * double(i) + 1.0));
    pvrt::CpcaOptions o;
    o.clusters = rows;
    o.components = 0;
    const pvrt::Cpca c = pvrt::compressCpca(data, dim, o, core::Progress::none());
    const std::vector<glm::vec3> light = {
        {1.f, 0.5f, 0.2f}, {-0.3f, 0.7f, 1.1f}, {0.4f, -0.2f, 0.9f}};
    std::vector<glm::vec3> out(std::size_t(rows) * n);
    c.radiance(light, n, out);
    constexpr float kFloatTol = 1e-5f;
    for (int r = 0; r < rows; ++r)
        for (int j = 0; j < n; ++j)
            for (int ch = 0; ch < 3; ++ch) {
                double s = 0;
                for (int k = 0; k < m; ++k)
                    s += double(data[std::size_t(r) * dim + std::size_t((j * m + k) * 3 + ch)]) *
                         light[std::size_t(k)][ch];
                EXPECT_NEAR(out[std::size_t(r * n + j)][ch], s, kFloatTol) << r << " " << j;
            }
}

namespace {

/// A 7 × 5 × 6 grid where every third point is empty, stored points numbered in grid order.
pvrt::TransferLayout sparseLayout() {
    pvrt::TransferLayout l;
    l.res = {7, 5, 6};
    l.scale = glm::vec3(2.f);
    l.slot.assign(7 * 5 * 6, -1);
    for (std::size_t i = 0; i < l.slot.size(); ++i)
        if (i % 3 != 1) l.slot[i] = l.points++;
    return l;
}

/// The radiance volume the pipeline built before combineCpca: Cpca::radiance per stored point,
/// then scattered into the grid.
pvrt::RadianceVolume twoStep(const pvrt::TransferLayout& layout, const pvrt::Cpca& c,
                             const std::vector<glm::vec3>& light, int n) {
    std::vector<glm::vec3> perPoint(std::size_t(layout.points) * std::size_t(n));
    c.radiance(light, n, perPoint);
    return pvrt::scatterRadiance(layout, perPoint, n);
}

/// The frame's trilinear Σ_j w_j t_j as it was evaluated before (the corners' sums, blended); with
/// `magnitude`, the same of |w_j|·|t_j| (the size of the terms, for a rounding tolerance).
glm::vec3 mixOfSums(const pvrt::RadianceVolume& r, const glm::vec3& p, const float* w,
                    bool magnitude = false) {
    const glm::vec3 g =
        glm::clamp((p + 0.5f) / r.scale - 0.5f, glm::vec3(0.f), glm::vec3(r.res - 1));
    const glm::ivec3 i0 = glm::min(glm::ivec3(g), r.res - 1);
    const glm::ivec3 i1 = glm::min(i0 + 1, r.res - 1);
    const glm::vec3 f = g - glm::vec3(i0);
    auto at = [&](int x, int y, int z) {
        const glm::vec3* t =
            r.values.data() +
            (std::size_t(x) + std::size_t(r.res.x) * (std::size_t(y) + std::size_t(r.res.y) * z)) *
                std::size_t(r.exitance);
        glm::vec3 s(0.f);
        for (int j = 0; j < r.exitance; ++j)
            s += magnitude ? std::abs(w[j]) * glm::abs(t[j]) : w[j] * t[j];
        return s;
    };
    const glm::vec3 c00 = glm::mix(at(i0.x, i0.y, i0.z), at(i1.x, i0.y, i0.z), f.x);
    const glm::vec3 c10 = glm::mix(at(i0.x, i1.y, i0.z), at(i1.x, i1.y, i0.z), f.x);
    const glm::vec3 c01 = glm::mix(at(i0.x, i0.y, i1.z), at(i1.x, i0.y, i1.z), f.x);
    const glm::vec3 c11 = glm::mix(at(i0.x, i1.y, i1.z), at(i1.x, i1.y, i1.z), f.x);
    return glm::mix(glm::mix(c00, c10, f.y), glm::mix(c01, c11, f.y), f.z);
}

}  // namespace

TEST(PvrtExitance, CpcaDomainCombinationEqualsTheTwoStepOne) {
    // The light change's fused pass (combineCpca: projected clusters → grid) against the previous
    // Cpca::radiance + scatterRadiance, and the frame's corner-blended sampleWeighted against the
    // previous blend of the corners' sums. Rows and lights mix signs (SH basis lights carry
    // negative flux), so the n > 1 coefficients and some n = 1 sums are negative.
    // Both are float sums of the same terms: the light change in the same order (only whether a
    // multiply-add is fused may differ), the frame in another order (blend, then weight). Each of
    // the ≤ ~200 roundings is ≤ 6e-8 of the running sum, itself ≤ Σ|term|: so the tolerance is
    // relative to the sum of the terms' magnitudes, not to the (possibly cancelling) result.
    constexpr float kFusedTol = 2e-5f;
    const pvrt::TransferLayout layout = sparseLayout();
    const int m = 4;
    const std::vector<glm::vec3> light = {
        {1.2f, 0.9f, 0.7f}, {-0.6f, 0.4f, -1.1f}, {0.3f, -0.8f, 0.5f}, {-0.2f, -0.3f, 0.9f}};
    for (int n : {1, 4, 9, 16})
        for (int clusters : {5, int(layout.points)}) {  // the latter: every cluster one member
            SCOPED_TRACE(testing::Message() << "n " << n << ", clusters " << clusters);
            const int dim = n * m * 3;
            std::vector<float> rows(std::size_t(layout.points) * std::size_t(dim));
            for (std::size_t i = 0; i < rows.size(); ++i)
                rows[i] =
                    float(std::sin(0.61 * double(i) + 0.3) + 0.4 * std::cos(0.013 * double(i)));
            pvrt::CpcaOptions o;
            o.clusters = clusters;
            o.components = 3;
            const pvrt::Cpca c = pvrt::compressCpca(rows, dim, o, core::Progress::none());
            const pvrt::RadianceVolume want = twoStep(layout, c, light, n);
            const pvrt::RadianceVolume got = pvrt::combineCpca(layout, c, light, n, 2);
            ASSERT_EQ(got.values.size(), want.values.size());
            // Σ|term| per entry: |mean| + Σ_i |w_i|·|component_i|, projected.
            const std::vector<float> proj = c.projectLight(light, n);
            auto magnitude = [&](std::size_t i, int ch) {
                const std::int32_t s = layout.slot[i / std::size_t(n)];
                if (s < 0) return 0.f;
                const std::size_t e = (i % std::size_t(n)) * 3 + std::size_t(ch);
                const float* p = proj.data() + std::size_t(c.cluster[std::size_t(s)]) *
                                                   std::size_t(c.components + 1) * std::size_t(n) *
                                                   3;
                float sum = std::abs(p[e]);
                for (int k = 0; k < c.components; ++k)
                    sum += std::abs(c.weights[std::size_t(s) * std::size_t(c.components) + k]) *
                           std::abs(p[std::size_t(1 + k) * std::size_t(n) * 3 + e]);
                return sum;
            };
            EXPECT_EQ(got.clamped, want.clamped);
            EXPECT_GT(want.clamped, 0u) << "no negative sums: the test would miss the clamp";
            for (std::size_t i = 0; i < want.values.size(); ++i)
                for (int ch = 0; ch < 3; ++ch) {
                    const float a = got.values[i][ch], b = want.values[i][ch];
                    ASSERT_TRUE(std::isfinite(a)) << i;
                    if (layout.slot[i / std::size_t(n)] < 0) {
                        ASSERT_EQ(a, 0.f) << i;
                    }
                    ASSERT_NEAR(a, b, kFusedTol * magnitude(i, ch)) << i << " " << ch;
                }
            // Toward an eye per grid point (EyeFold), perspective and orthographic: Σ_j w_j t_j
            // with the double exitanceWeights of the direction from each point to the eye.
            core::Geometry geometry;
            geometry.dims = {14, 10, 12};
            geometry.spacing = {0.8, 1.1, 1.3};
            geometry.origin = {-5.0, 3.0, 2.0};
            geometry.direction =
                glm::dmat3(glm::dvec3(0, 1, 0), glm::dvec3(-1, 0, 0), glm::dvec3(0, 0, 1));
            for (bool orthographic : {false, true}) {
                if (n == 1) break;
                const pvrt::EyeFold fold{.g = 0.6f,
                                         .geometry = geometry,
                                         .orthographic = orthographic,
                                         .eye = {40.0, -25.0, 60.0},
                                         .forward = glm::normalize(glm::dvec3(-1, 0.5, -1.5))};
                const pvrt::RadianceVolume toward =
                    pvrt::combineCpca(layout, c, light, n, 2, &fold);
                ASSERT_TRUE(toward.towardEye);
                ASSERT_EQ(toward.exitance, 1);
                ASSERT_EQ(toward.values.size(), layout.slot.size());
                for (int z = 0; z < layout.res.z; ++z)
                    for (int y = 0; y < layout.res.y; ++y)
                        for (int x = 0; x < layout.res.x; ++x) {
                            const std::size_t i = layout.linear({x, y, z});
                            const glm::dvec3 world =
                                geometry.indexToWorld(glm::dvec3(layout.position({x, y, z})));
                            const glm::vec3 toEye(orthographic ? -fold.forward
                                                               : glm::normalize(fold.eye - world));
                            float we[pvrt::kMaxExitance];
                            pvrt::exitanceWeights(n, fold.g, toEye, we);
                            for (int ch = 0; ch < 3; ++ch) {
                                double sum = 0, size = 0;
                                for (int j = 0; j < n; ++j) {
                                    const std::size_t e = i * std::size_t(n) + std::size_t(j);
                                    sum += double(we[j]) * want.values[e][ch];
                                    size += std::abs(we[j]) * magnitude(e, ch);
                                }
                                ASSERT_TRUE(std::isfinite(toward.values[i][ch]));
                                ASSERT_NEAR(toward.values[i][ch], sum, kFusedTol * size)
                                    << x << " " << y << " " << z << " " << ch;
                            }
                        }
            }
            float w[pvrt::kMaxExitance];
            pvrt::exitanceWeights(n, 0.6f, glm::normalize(glm::vec3(0.3f, -0.5f, 0.8f)), w);
            for (int k = 0; k < 200; ++k) {
                // Points across the grid and past its ends (clamped corners).
                const glm::vec3 p(-1.f + 0.083f * float(k), 11.f - 0.061f * float(k),
                                  float(k % 13) - 0.5f);
                const glm::vec3 a = got.sampleWeighted(p, w), b = mixOfSums(got, p, w);
                const glm::vec3 size = mixOfSums(got, p, w, true);
                for (int ch = 0; ch < 3; ++ch) {
                    ASSERT_TRUE(std::isfinite(a[ch])) << k;
                    ASSERT_NEAR(a[ch], b[ch], kFusedTol * size[ch]) << k;
                }
            }
        }
}
