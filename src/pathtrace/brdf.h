// SPDX-License-Identifier: MIT
#pragma once
// The surface BRDF of the path tracer's hybrid scattering (Kroes et al. 2012, "Exposure Render",
// PLOS ONE 7(7) e38586, section "Hybrid scattering"): a diffuse lobe under a glossy microfacet
// lobe, both reciprocal, the sum never reflecting more than it receives.
//
//   f(wo, wi) = f_d + f_s  on the hemisphere of the normal n (0 when wo or wi lies below it)
//   f_s = F(wo·h) · D(h) · G(wo, wi) / (4 μo μi)          h = normalize(wo + wi), μ = n·w
//     D  GGX / Trowbridge–Reitz, α = roughness² (Walter et al. 2007, eq. 33), α ≥ kMinAlpha
//     G  separable Smith G1(wo)·G1(wi) for GGX (Walter et al. 2007, eq. 34)
//     F  Schlick: F0 + (1 − F0)(1 − c)⁵, F0 = the TF's specular colour (per channel)
//   f_d = a · (1 − F(μo)) · (1 − F(μi)) / π                a = the TF's albedo colour
// The diffuse lobe is Ashikmin & Shirley's "Fresnel blend" idea (what Kroes used, with a Blinn
// lobe): what the coat's Fresnel reflects at the macro normal does not reach the diffuse base, on
// the way in or out, which keeps f reciprocal. Its albedo is exactly
//   ∫ f_d μi dωi = a · (1 − F(μo)) · (1 − F0) · 20/21       (∫₀¹ (1 − μ)⁵ μ dμ = 1/42)
// and the glossy lobe's is at most E_vis[F(wo·h)] (G ≤ G1(wo) and the visible normals integrate
// to 1). That the sum stays ≤ 1 is not proven here, only checked: tests/pathtrace/test_brdf.cpp
// integrates it by quadrature (glossy lobes: by the sampled estimator) for wo, roughness and F0 on
// a grid with a = 1 (the largest found, F0 = 1 at roughness 0.03–0.1, is 1 within 2·10⁻⁴).
//
// Sampling: the glossy lobe by the GGX distribution of visible normals (Heitz 2018, "Sampling the
// GGX Distribution of Visible Normals", JCGT 7(4) 1–13, listing 1, isotropic α),
//   D_wo(h) = G1(wo)·max(0, wo·h)·D(h)/μo,   pdf(wi) = D_wo(h)/(4 wo·h) = G1(wo)·D(h)/(4 μo),
// reflected about h: no microfacet facing away from wo is drawn, and the glossy lobe's weight
// f·μi/pdf is F·G1(wi) ≤ 1 (drawing h by D(h)·(n·h), Walter eq. 35–36, as before, gave the weight
// F·G1(wo)·G1(wi)·(wo·h)/(μo·(n·h)), above 1 at grazing wo); the diffuse lobe by a cosine. The
// lobe is chosen with a probability from their Fresnel weights at μo (clamped to
// [kMinLobeProbability, 1 − kMinLobeProbability] so that each lobe is sampled wherever it is
// non-zero), and pdf() is the one-sample mixture of both densities.
//
// Directions are unit vectors pointing away from the surface point; n is unit and on wo's side
// (the caller flips the gradient normal toward the incoming direction).
#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <numbers>

#include "core/color.h"

namespace voxlight::pathtrace {

/// The BRDF's parameters at one point.
struct SurfaceMaterial {
    glm::dvec3 diffuse{0.0};   ///< a, 0..1 (the TF's albedo colour)
    glm::dvec3 specular{0.0};  ///< F0, 0..1 (the TF's specular channel)
    double roughness = 1.0;    ///< (0, 1]
};

/// Smallest GGX α: below it the lobe is a mirror at double precision's mercy (roughness 0.03).
inline constexpr double kMinAlpha = 1e-3;
/// Each lobe is chosen with at least this probability (so it is sampled wherever it is non-zero).
inline constexpr double kMinLobeProbability = 0.1;

struct BrdfSample {
    glm::dvec3 wi{0.0};
    glm::dvec3 f{0.0};  ///< f(wo, wi)
    double pdf = 0.0;   ///< solid-angle density of wi; 0 = no sample (below the surface)
};

namespace brdf_detail {
inline double alphaOf(double roughness) { return std::max(roughness * roughness, kMinAlpha); }
inline glm::dvec3 schlick(const glm::dvec3& f0, double c) {
    const double m = std::clamp(1.0 - c, 0.0, 1.0);
    const double m5 = (m * m) * (m * m) * m;
    return f0 + (glm::dvec3(1.0) - f0) * m5;
}
inline double ggxD(double cosH, double alpha) {
    const double a2 = alpha * alpha;
    const double d = cosH * cosH * (a2 - 1.0) + 1.0;
    return a2 / (std::numbers::pi * d * d);
}
inline double smithG1(double cosV, double alpha) {
    const double a2 = alpha * alpha;
    return 2.0 * cosV / (cosV + std::sqrt(a2 + (1.0 - a2) * cosV * cosV));
}
using core::luminance;
/// Probability of sampling the glossy lobe for this wo (a function of μo only).
inline double glossyProbability(const SurfaceMaterial& m, double cosO) {
    const glm::dvec3 fo = schlick(m.specular, cosO);
    const double ws = luminance(fo), wd = luminance(m.diffuse * (glm::dvec3(1.0) - fo));
    const double p = ws + wd > 0.0 ? ws / (ws + wd) : 0.5;
    return std::clamp(p, kMinLobeProbability, 1.0 - kMinLobeProbability);
}
/// Orthonormal basis around n (Duff et al. 2017).
inline void basis(const glm::dvec3& n, glm::dvec3& t1, glm::dvec3& t2) {
    const double sign = std::copysign(1.0, n.z);
    const double a = -1.0 / (sign + n.z), b = n.x * n.y * a;
    t1 = glm::dvec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    t2 = glm::dvec3(b, sign + n.y * n.y * a, -n.y);
}
}  // namespace brdf_detail

/// f(wo, wi) (without the cosine).
inline glm::dvec3 evalBrdf(const SurfaceMaterial& m, const glm::dvec3& n, const glm::dvec3& wo,
                           const glm::dvec3& wi) {
    using namespace brdf_detail;
    const double cosO = glm::dot(n, wo), cosI = glm::dot(n, wi);
    if (!(cosO > 0.0) || !(cosI > 0.0)) return glm::dvec3(0.0);
    const glm::dvec3 fd = m.diffuse * (glm::dvec3(1.0) - schlick(m.specular, cosO)) *
                          (glm::dvec3(1.0) - schlick(m.specular, cosI)) * (1.0 / std::numbers::pi);
    const glm::dvec3 hs = wo + wi;
    const double hl = glm::length(hs);
    if (!(hl > 0.0)) return fd;
    const glm::dvec3 h = hs / hl;
    const double alpha = alphaOf(m.roughness);
    const double cosH = glm::dot(n, h), oh = glm::dot(wo, h);
    const glm::dvec3 fs = schlick(m.specular, oh) * (ggxD(cosH, alpha) * smithG1(cosO, alpha) *
                                                     smithG1(cosI, alpha) / (4.0 * cosO * cosI));
    return fd + fs;
}

/// Density (solid angle) with which sampleBrdf draws wi for this wo.
inline double pdfBrdf(const SurfaceMaterial& m, const glm::dvec3& n, const glm::dvec3& wo,
                      const glm::dvec3& wi) {
    using namespace brdf_detail;
    const double cosO = glm::dot(n, wo), cosI = glm::dot(n, wi);
    if (!(cosO > 0.0) || !(cosI > 0.0)) return 0.0;
    const double ps = glossyProbability(m, cosO);
    double glossy = 0.0;
    const glm::dvec3 hs = wo + wi;
    const double hl = glm::length(hs);
    if (hl > 0.0) {
        const glm::dvec3 h = hs / hl;
        if (glm::dot(wo, h) > 0.0) {
            const double alpha = alphaOf(m.roughness);
            glossy = smithG1(cosO, alpha) * ggxD(glm::dot(n, h), alpha) / (4.0 * cosO);
        }
    }
    return ps * glossy + (1.0 - ps) * cosI / std::numbers::pi;
}

/// Draws wi for wo with u ∈ [0,1)³ (u0 picks the lobe). pdf 0 when wo is below the surface or
/// the glossy sample lands below it (the path ends there: f is 0).
inline BrdfSample sampleBrdf(const SurfaceMaterial& m, const glm::dvec3& n, const glm::dvec3& wo,
                             double u0, double u1, double u2) {
    using namespace brdf_detail;
    BrdfSample s;
    const double cosO = glm::dot(n, wo);
    if (!(cosO > 0.0)) return s;
    glm::dvec3 t1, t2;
    basis(n, t1, t2);
    const double phi = 2.0 * std::numbers::pi * u2;
    if (u0 < glossyProbability(m, cosO)) {
        // h from the visible normals (Heitz 2018, listing 1): stretch wo by α, sample the
        // projected half disk of the hemisphere it sees, unstretch the normal.
        const double alpha = alphaOf(m.roughness);
        const glm::dvec3 vh =
            glm::normalize(glm::dvec3(alpha * glm::dot(wo, t1), alpha * glm::dot(wo, t2), cosO));
        const double lensq = vh.x * vh.x + vh.y * vh.y;
        const glm::dvec3 b1 = lensq > 0.0 ? glm::dvec3(-vh.y, vh.x, 0.0) / std::sqrt(lensq)
                                          : glm::dvec3(1.0, 0.0, 0.0);
        const glm::dvec3 b2 = glm::cross(vh, b1);
        const double r = std::sqrt(u1);
        const double p1 = r * std::cos(phi);
        const double blend = 0.5 * (1.0 + vh.z);
        const double p2 =
            (1.0 - blend) * std::sqrt(std::max(0.0, 1.0 - p1 * p1)) + blend * r * std::sin(phi);
        const glm::dvec3 nh =
            p1 * b1 + p2 * b2 + std::sqrt(std::max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh;
        const glm::dvec3 hl =
            glm::normalize(glm::dvec3(alpha * nh.x, alpha * nh.y, std::max(0.0, nh.z)));
        const glm::dvec3 h = hl.x * t1 + hl.y * t2 + hl.z * n;
        s.wi = 2.0 * glm::dot(wo, h) * h - wo;
    } else {
        // Cosine-weighted hemisphere.
        const double r = std::sqrt(u1);
        s.wi = r * std::cos(phi) * t1 + r * std::sin(phi) * t2 +
               std::sqrt(std::max(0.0, 1.0 - u1)) * n;
    }
    const double len = glm::length(s.wi);
    if (!(len > 0.0)) return s;
    s.wi /= len;
    if (!(glm::dot(n, s.wi) > 0.0)) return s;
    s.pdf = pdfBrdf(m, n, wo, s.wi);
    s.f = evalBrdf(m, n, wo, s.wi);
    return s;
}

}  // namespace voxlight::pathtrace
