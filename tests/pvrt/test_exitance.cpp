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
