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
#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <vector>

namespace voxlight::render {

struct Light {
    enum class Type { Directional, Point };
    Type type = Type::Directional;
    glm::vec3 direction{0.f, 0.f, -1.f};  ///< directional: unit direction the light *travels*
    glm::vec3 position{0.f};              ///< point: world mm
    glm::vec3 radiance{1.f};              ///< colour × intensity (directional: irradiance; point:
                                          ///< intensity, falls off as 1/d² with d in mm)
    float minDistance = 1.f;              ///< point: clamps 1/d² near the light, mm
};

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

/// Gradient Blinn–Phong with directional and point lights, no visibility (the clinical baseline,
/// Kronander et al. 2012 Fig. 1a "local diffuse shading"). Two-sided: the marcher hands over a
/// normal that faces the eye.
class BlinnPhongShader {
  public:
    static constexpr bool kNeedsNormal = true;

    BlinnPhongShader(const BlinnPhongParams& params, std::vector<Light> lights)
        : params_(params), lights_(std::move(lights)) {
        const float n = params_.shininess;
        if (n >= kMinTableShininess && n <= kMaxTableShininess) {
            powTable_.resize(kSpecularTableCells + 1);
            for (int i = 0; i <= kSpecularTableCells; ++i)
                powTable_[std::size_t(i)] =
                    float(std::pow(double(i) / kSpecularTableCells, double(n)));
        }
    }
    const BlinnPhongParams& params() const { return params_; }
    const std::vector<Light>& lights() const { return lights_; }

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
        for (const Light& l : lights_)
            if (l.type == Light::Type::Directional && k < kRayLights)
                r.halfway_[k++] = glm::normalize(-l.direction + toEye);
        return r;
    }

  private:
    /// `halfway`: the halfway vectors of the first kRayLights directional lights for in.toEye,
    /// or nullptr (computed here).
    [[gnu::always_inline]] Scatter scatter(const ShadeInput& in, const glm::vec3* halfway) const {
        Scatter s;
        s.diffuse = glm::vec3(params_.ambient);
        int k = 0;  // directional lights seen so far
        for (const Light& l : lights_) {
            glm::vec3 toLight, e = l.radiance;
            const glm::vec3* h = nullptr;
            if (l.type == Light::Type::Directional) {
                toLight = -l.direction;
                if (halfway && k < kRayLights) h = halfway + k;
                ++k;
            } else {
                const glm::vec3 d = l.position - in.position;
                const float dist = glm::length(d);
                toLight = dist > 0.f ? d / dist : in.normal;
                const float r = dist > l.minDistance ? dist : l.minDistance;
                e /= r * r;
            }
            const float ndl = glm::dot(in.normal, toLight);
            if (ndl <= 0.f) continue;
            s.diffuse += (params_.diffuse * ndl) * e;
            if (params_.specular > 0.f) {
                const float ndh = glm::dot(in.normal, h ? *h : glm::normalize(toLight + in.toEye));
                if (ndh > 0.f) s.specular += (params_.specular * specularPower(ndh)) * e;
            }
        }
        return s;
    }

    BlinnPhongParams params_;
    std::vector<Light> lights_;
    std::vector<float> powTable_;
};

}  // namespace voxlight::render
