// SPDX-License-Identifier: MIT
#pragma once
// Shading models: what a volume sample scatters toward the eye. The seam is small on purpose:
// a shader is a concrete struct the ray marcher is *templated* on (no virtual call or
// std::function per sample); the runtime choice happens once per tile through ShadingModel
// (ray_caster.h). Later methods (SH visibility, PVRT radiance, ...) add a shader struct with the
// same two members and reuse the traversal unchanged:
//
//   static constexpr bool kNeedsNormal;        // marcher computes the gradient normal if true
//   Scatter scatter(const ShadeInput&) const;   // in-scattered radiance factors at the sample
//   R forRay(const glm::vec3& toEye) const;     // per-ray form: R::scatter(in) == scatter(in)
//                                               // for in.toEye == toEye (ray constants hoisted)
//
// The optical model (ARCHITECTURE.md §1): a segment with opacity α, extinction-weighted albedo A
// and emission term E adds  T · α · (E + A ⊙ diffuse + specular)  to the pixel, where
// (diffuse, specular) = scatter(...). `diffuse` is the in-scattered radiance that the albedo
// filters (∫ p · L_light · V dω for the exact model); `specular` is added unfiltered.
//
// Lights are lights::Light (lights/light.h), the one light type below io: directions point from
// the shaded point *toward* the light. BlinnPhongShader flattens them once into the few numbers
// its per-sample loop reads (no virtual call per sample).
#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <memory>
#include <numbers>
#include <span>
#include <vector>

#include "lights/light.h"
#include "render/camera.h"
#include "sh/sh_basis.h"

namespace voxlight::render {

struct ShadeInput {
    glm::vec3 position;  ///< world mm
    glm::vec3 toEye;     ///< unit, from the sample toward the eye
    glm::vec3 normal;    ///< unit shading normal facing the eye (valid when kNeedsNormal)
    float value;         ///< physical value at the sample
};

struct Scatter {
    glm::vec3 diffuse{0.f};
    glm::vec3 specular{0.f};
};

/// Emission–absorption with uniform unit illumination and no visibility: every sample scatters
/// `ambient` (the classic "unshaded" DVR; colour = TF albedo).
struct EmissionAbsorptionShader {
    static constexpr bool kNeedsNormal = false;
    float ambient = 1.f;
    Scatter scatter(const ShadeInput&) const { return {glm::vec3(ambient), glm::vec3(0.f)}; }
    const EmissionAbsorptionShader& forRay(const glm::vec3&) const { return *this; }
};

struct BlinnPhongParams {
    float ambient = 0.25f;   ///< fraction of unit illumination reaching every sample
    float diffuse = 0.75f;   ///< Lambert weight
    float specular = 0.25f;  ///< Blinn–Phong weight (white, not filtered by the albedo)
    float shininess = 24.f;  ///< Blinn–Phong exponent
};

/// Specular powers x^n, x ∈ [0, 1], come from a table of kSpecularTableCells cells with linear
/// interpolation when kMinTableShininess ≤ n ≤ kMaxTableShininess (std::pow costs about a fifth of
/// a shaded sample). Interpolation error ≤ max|f''|·h²/8 = n(n − 1)/(8·cells²): 1.9e-3 at n = 256,
/// 6.6e-6 at the default n = 24 — below one 8-bit level after the specular weight. Outside that
/// range (n < 2 has an unbounded second derivative at 0) std::pow is used.
inline constexpr int kSpecularTableCells = 2048;
inline constexpr float kMinTableShininess = 2.f;
inline constexpr float kMaxTableShininess = 256.f;

/// Irradiance of the headlight for the volumetric methods (sh-local, sh-global, ritschel,
/// pathtrace): 4π, so that a fully lit scatterer of albedo a under the isotropic phase 1/(4π)
/// shows radiance a, as a lit diffuse surface of colour a does under the surface-like shading
/// (gradient, iso) with irradiance 1.
inline constexpr float kVolumetricHeadlightIrradiance = float(4.0 * std::numbers::pi);

/// The light of a scene without lights: directional, travelling along the view from just above
/// and left of the camera (shapes read as in clinical viewers), of the given irradiance (1 for the
/// surface-like shading, kVolumetricHeadlightIrradiance for the volumetric methods).
std::shared_ptr<const lights::Light> headlight(const Camera& camera, float irradiance);

/// Irradiance SH of the lights that are neither delta nor area lights (environment maps): 9 RGB
/// coefficients E_lm = Â_l L_lm (Ramamoorthi & Hanrahan 2001; Â = π, 2π/3, π/4 for bands 0..2),
/// so that E(n) = Σ E_lm Y_lm(n) is the irradiance on a surface facing n with no visibility (error
/// of the 3-band truncation ≤ ~3 % of the mean for natural maps). Position-independent (environment
/// lights are at infinity). Empty when there is no such light.
std::vector<glm::vec3> environmentIrradianceSh(
    std::span<const std::shared_ptr<const lights::Light>> lights);

/// Gradient Blinn–Phong without visibility (the clinical baseline, Kronander et al. 2012 Fig. 1a
/// "local diffuse shading"). Two-sided: the marcher hands over a normal that faces the eye.
/// Lights, per sample at x with normal n:
///   directional  E·max(n·ω, 0), Blinn–Phong highlight
///   point        I/max(d, minDistance)² · max(n·ω, 0), highlight
///   sphere area  as a point light of intensity L·π r² at its centre (exact irradiance facing the
///                sphere for d ≥ r), minDistance = r; highlight
///   rect / disk  as a point light at the centre with the one-sided far-field intensity
///                L·A·max(cos θ_emitter, 0); minDistance = √(A/π); highlight
///   environment  diffuse only: E(n) from environmentIrradianceSh (no highlight)
/// Environment lights need `irradianceSh` (InputError naming the light otherwise).
class BlinnPhongShader {
  public:
    static constexpr bool kNeedsNormal = true;

    BlinnPhongShader(const BlinnPhongParams& params,
                     std::span<const std::shared_ptr<const lights::Light>> lights,
                     std::span<const glm::vec3> irradianceSh = {});
    const BlinnPhongParams& params() const { return params_; }

    /// x^shininess for x ∈ [0, 1] (table or std::pow, see kSpecularTableCells).
    float specularPower(float x) const {
        if (powTable_.empty()) return std::pow(x, params_.shininess);
        const float u = std::min(std::max(x, 0.f), 1.f) * float(kSpecularTableCells);
        const int i = std::min(int(u), kSpecularTableCells - 1);
        const float f = u - float(i);
        const float a = powTable_[std::size_t(i)], b = powTable_[std::size_t(i) + 1];
        return a + f * (b - a);
    }

    Scatter scatter(const ShadeInput& in) const { return scatter(in, nullptr); }

    /// Halfway vectors of the first kRayLights directional lights are fixed along a ray (the eye
    /// direction is); the per-ray form computes them once. Same arithmetic as scatter(), so the
    /// same results bit for bit.
    static constexpr int kRayLights = 4;
    class RayShader {
      public:
        [[gnu::always_inline]] Scatter scatter(const ShadeInput& in) const {
            return s_->scatter(in, halfway_);
        }

      private:
        friend class BlinnPhongShader;
        const BlinnPhongShader* s_ = nullptr;
        glm::vec3 halfway_[kRayLights];
    };
    RayShader forRay(const glm::vec3& toEye) const {
        RayShader r;
        r.s_ = this;
        int k = 0;
        for (const Emitter& l : lights_)
            if (l.directional && k < kRayLights)
                r.halfway_[k++] = glm::normalize(l.toLight + toEye);
        return r;
    }

  private:
    /// `halfway`: the halfway vectors of the first kRayLights directional lights for in.toEye,
    /// or nullptr (computed here).
    [[gnu::always_inline]] Scatter scatter(const ShadeInput& in, const glm::vec3* halfway) const {
        Scatter s;
        s.diffuse = glm::vec3(params_.ambient);
        int k = 0;  // directional lights seen so far
        for (const Emitter& l : lights_) {
            glm::vec3 toLight, e = l.value;
            const glm::vec3* h = nullptr;
            if (l.directional) {
                toLight = l.toLight;
                if (halfway && k < kRayLights) h = halfway + k;
                ++k;
            } else {
                const glm::vec3 d = l.position - in.position;
                const float dist = glm::length(d);
                toLight = dist > 0.f ? d / dist : in.normal;
                const float r = dist > l.minDistance ? dist : l.minDistance;
                e /= r * r;
                if (l.oneSided) {
                    const float c = -glm::dot(toLight, l.emitterNormal);
                    if (c <= 0.f) continue;
                    e *= c;
                }
            }
            const float ndl = glm::dot(in.normal, toLight);
            if (ndl <= 0.f) continue;
            s.diffuse += (params_.diffuse * ndl) * e;
            if (params_.specular > 0.f) {
                const float ndh = glm::dot(in.normal, h ? *h : glm::normalize(toLight + in.toEye));
                if (ndh > 0.f) s.specular += (params_.specular * specularPower(ndh)) * e;
            }
        }
        if (hasEnvironment_) s.diffuse += params_.diffuse * environmentIrradiance(in.normal);
        return s;
    }

    /// E(n) of the environment lights from their 9 irradiance SH coefficients.
    glm::vec3 environmentIrradiance(const glm::vec3& n) const {
        float y[9];
        sh::evalShFixed<2>(n, y);
        glm::vec3 e(0.f);
        for (int i = 0; i < 9; ++i) e += envSh_[i] * y[i];
        return glm::max(e, glm::vec3(0.f));  // ringing of the truncation can dip below 0
    }

  public:
    /// A light as the per-sample loop reads it (a flat copy of a lights::Light); public for
    /// evaluators of the same shading outside this class (the viewer's GLSL ray caster).
    struct Emitter {
        bool directional = false;
        bool oneSided = false;         ///< rect/disk: emits toward emitterNormal only
        glm::vec3 toLight{0.f};        ///< directional: unit, toward the light
        glm::vec3 position{0.f};       ///< point-like: world mm
        glm::vec3 value{0.f};          ///< directional: irradiance; point-like: intensity
        float minDistance = 1.f;       ///< point-like: clamps 1/d², mm
        glm::vec3 emitterNormal{0.f};  ///< oneSided: unit emission direction
    };
    /// The lights but environment maps, flattened, in the order given.
    const std::vector<Emitter>& emitters() const { return lights_; }
    /// Whether an environment light adds its SH irradiance.
    bool hasEnvironment() const { return hasEnvironment_; }

  private:
    BlinnPhongParams params_;
    std::vector<Emitter> lights_;
    bool hasEnvironment_ = false;
    glm::vec3 envSh_[9] = {};
    std::vector<float> powTable_;
};

}  // namespace voxlight::render
