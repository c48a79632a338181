// SPDX-License-Identifier: MIT
#pragma once
// SH visibility shading (Kronander et al. 2012 eq. 7, 10, 12): at a sample x with visibility
// coefficients V_i(x) (local, global or hierarchical: visibility/local_visibility.h,
// global_visibility.h, hierarchical_visibility.h) and incident radiance coefficients L_i(x) of
// all lights added together (eq. 12),
//   diffuse = 1/(4π) · Σ_i L_i(x) V_i(x)   (isotropic phase; the marcher multiplies by α and the
//                                            TF albedo and adds the TF emission: ARCHITECTURE §1)
// clamped at 0 (a truncated SH product can ring below 0; radiance never does).
//
// Ringing and its bound. For a directional light of irradiance E the product is (E/4π)·Ṽ(ω_l),
// where Ṽ(ω) = Σ_l w_l Σ_m V_lm Y_lm(ω) is the (windowed) reconstruction of the visibility, whose
// true value lies in [0, 1]. Cauchy–Schwarz with Σ_m Y_lm(ω)² = (2l+1)/(4π) and Σ V_lm² ≤ ∫V² ≤ 4π
// (Bessel) give |Ṽ(ω)| ≤ B = √(Σ_l w_l² (2l+1)) (ringingBound()): without a window 2, 3 and 4 for
// 4, 9 and 16 coefficients — a sample can look up to B times brighter than unshadowed ("bright
// spots", Kronander §5) before the clamp at 0 removes the negative side. A window (method param
// `window`: hanning, lanczos or gaussian with `window_strength`) multiplies band l of the lights'
// coefficients by w_l ≤ 1 (w_0 = 1: an unshadowed sample keeps its brightness), which lowers B —
// Hanning: 1.32, 1.73, 2.14 — and the undershoot the clamp hides, at the price of softer shadows.
// Measured on Kronander's corner case (hard shadows of an opaque sphere and torus; 64 rays, full
// resolution, every grid point × 400 directions; tests/render/test_sh_ringing.cpp): without a
// window Ṽ ∈ [−0.33, 1.34] (4 coefficients) and [−0.41, 1.39] (16), with Hanning [−0.04, 1.04]
// and [−0.09, 1.09] — far inside B, which holds for any visibility in [0, 1].
// Lights (lights/light.h conventions):
//   directional  L_i = E · Y_i(ω_l)                                    (eq. 10, once per frame)
//   environment  L_i = its SH projection (EnvironmentLight: projected once in the map frame,
//                rotated by SH rotation when the light turns; once per frame here)
//   point        per sample: L_i = E(x) · Y_i(ω(x)) with E = I / max(d, minDistance)², blending to
//                a uniform radiance of the same irradiance within minDistance, exactly as
//                PointLight::shCoefficients does (so a light inside the volume or on a grid point
//                stays finite)
//   ambient      optional (method param `ambient`, default 0): a uniform sky of radiance A,
//                L_0 += A·√(4π), shadowed like any light (A·V_0/√(4π): ambient occlusion)
// Area lights are not shaded by this model (InputError naming the light): their SH differs per
// sample and would need the light's virtual projection per sample.
#include <memory>
#include <span>
#include <vector>

#include "core/half_space.h"
#include "render/ray_caster.h"
#include "visibility/global_visibility.h"
#include "visibility/hierarchical_visibility.h"
#include "visibility/local_visibility.h"

namespace voxlight::render {

/// The lights of a scene as SH radiance for the per-sample product with a visibility field.
class ShLights {
  public:
    /// Throws InputError for area lights. `window`: band factors w_0..w_L (empty = none).
    /// `ambient`: radiance of a uniform sky added to the lights (L_0 += A·√(4π)).
    ShLights(int coefficients, std::span<const std::shared_ptr<const lights::Light>> lights,
             std::span<const double> window = {}, float ambient = 0.f);
    int coefficients() const { return coefficients_; }
    /// 1/(4π) Σ L_i(x) V_i, clamped at 0, for visibility coefficients v at world point x (mm).
    glm::vec3 shade(const glm::vec3& x, const float* v) const;

    // What shade() evaluates, for other evaluators of it (the viewer's shaders/raycast.frag).
    struct Point {
        glm::vec3 position, intensity;
        float minDistance;
    };
    /// The position-independent L_i (directional + environment + ambient), windowed.
    const glm::vec3* constants() const { return constant_; }
    /// w_l of coefficient i (1 without a window).
    float window(int i) const { return window_[i]; }
    const std::vector<Point>& points() const { return points_; }

  private:
    int coefficients_ = 0;
    glm::vec3 constant_[16] = {};  ///< directional + environment L_i, windowed
    float window_[16] = {};        ///< w_l of each coefficient (1 without a window)
    std::vector<Point> points_;
};

/// B = √(Σ_l w_l² (2l+1)) over the bands of `coefficients` (see the header comment): the largest
/// |Ṽ(ω)| a visibility in [0, 1] can reconstruct to. Empty window = all factors 1.
double ringingBound(int coefficients, std::span<const double> window = {});

/// The shader of a visibility field: LocalVisibility (sh-local), GlobalVisibility (sh-global) or
/// HierarchicalVisibility (ritschel), anything with coefficients() and sample(voxel index, out).
template <class Field>
class ShVisibilityShader {
  public:
    static constexpr bool kNeedsNormal = false;
    /// Segments are shaded where their light is scattered (render/dvr_march.h meanScatterDepth).
    static constexpr bool kScatterAtMeanDepth = true;
    ShVisibilityShader(std::shared_ptr<const Field> field, const core::Geometry& geometry,
                       std::span<const std::shared_ptr<const lights::Light>> lights,
                       std::span<const double> window = {}, float ambient = 0.f)
        : field_(std::move(field)), lights_(field_->coefficients(), lights, window, ambient) {
        worldToIndex_ = glm::mat3(geometry.worldToIndexMatrix());
        origin_ = glm::vec3(geometry.origin);
    }

    Scatter scatter(const ShadeInput& in) const {
        return {inScattered(in.position), glm::vec3(0.f)};
    }
    const ShVisibilityShader& forRay(const glm::vec3&) const { return *this; }

    /// 1/(4π) Σ L_i V_i at world point x (mm), clamped at 0.
    glm::vec3 inScattered(const glm::vec3& x) const {
        float v[16];
        field_->sample(worldToIndex_ * (x - origin_), v);
        return lights_.shade(x, v);
    }
    int coefficients() const { return lights_.coefficients(); }

  private:
    std::shared_ptr<const Field> field_;
    ShLights lights_;
    glm::mat3 worldToIndex_{1.f};
    glm::vec3 origin_{0.f};
};

/// Global visibility with local visibility near cut faces (Kronander et al. 2012 §6, Fig. 15:
/// "local visibility is used for clip-plane renderings"). Within `bandMm` of a face that removes
/// matter for the light (shadows_from_removed false; on the kept side) the coefficients blend
/// linearly from the local field (at the face) to the global one (at bandMm and beyond):
/// V = w·V^G + (1 − w)·V^L, w = clamp(d / bandMm, 0, 1), d = the distance to the nearest such
/// face. Why: there the light's visibility jumps at the face, and the global grid is coarse (one
/// point per spacingVoxels()), so its trilinear interpolation mixes points in front of the face
/// (clear) with points behind it, while the (clip-aware) local field resolves the face at the
/// block grid's resolution. Section-view faces (true) are left to the global field: it is
/// continuous there, and the local field drops the removed matter's shadows beyond r_s (blending
/// there too made the section views of docs/clip-planes brighter than the path tracer's: mean grey
/// 16.3 against 13.7 without, path tracer 10.3, torso). The two fields must describe the same
/// light (both clip-aware, or both unclipped).
class ShCutFaceShader {
  public:
    static constexpr bool kNeedsNormal = false;
    static constexpr bool kScatterAtMeanDepth = true;
    ShCutFaceShader(std::shared_ptr<const visibility::GlobalVisibility> global,
                    std::shared_ptr<const visibility::LocalVisibility> local,
                    std::span<const core::HalfSpace> faces, float bandMm,
                    const core::Geometry& geometry,
                    std::span<const std::shared_ptr<const lights::Light>> lights,
                    std::span<const double> window = {}, float ambient = 0.f);
    Scatter scatter(const ShadeInput& in) const;
    const ShCutFaceShader& forRay(const glm::vec3&) const { return *this; }

  private:
    struct Face {
        glm::vec3 point, normal;
    };
    std::shared_ptr<const visibility::GlobalVisibility> global_;
    std::shared_ptr<const visibility::LocalVisibility> local_;
    std::vector<Face> faces_;
    float invBand_ = 0.f;
    ShLights lights_;
    glm::mat3 worldToIndex_{1.f};
    glm::vec3 origin_{0.f};
};

/// The kept half-spaces of the caster's clip planes and crop box that remove matter for the light
/// too (shadowsFromRemoved false).
std::vector<core::HalfSpace> lightCutFaces(const RenderOptions& options);

/// The DVR model with SH visibility shading for `caster` (its options' lights; none → one
/// headlight like makeBuiltinModel's).
std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::LocalVisibility> field);
std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::GlobalVisibility> field);
std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::HierarchicalVisibility> field);
/// sh-global with clip planes: ShCutFaceShader within `bandMm` of the caster's lightCutFaces (the
/// plain global shader when it has none).
std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::GlobalVisibility> global,
    std::shared_ptr<const visibility::LocalVisibility> local, float bandMm);

}  // namespace voxlight::render
