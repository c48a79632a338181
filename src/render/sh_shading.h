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
//                rotated by SH rotation when the light turns; once per frame here). Its dominant
//                direction is split off as a directional light (Sloan's dominant-light
//                extraction): along the luminance's band-1 vector, of irradiance E per channel
//                such that its band 1 is the map's band 1 projected onto that direction (clamped
//                to [0, L_0·√(4π)]: the rest keeps band 0 ≥ 0); the rest (the map minus that
//                light's SH) stays spread over the field at x. The two add up to the map's
//                coefficients, so the plain product (ShVisibilityShader, ritschel, near_shadow
//                false) is unchanged, while the near shadow traces the split-off light like any
//                directional one. Accuracy study, torso under the courtyard map (128², 1:8, linear
//                NRMSE against the path tracer, 5 December): sh-local 1.244 → 0.995, sh-global
//                0.754 → 0.567; with 16 coefficients 1.427 → 1.180 and 0.846 → 0.665.
//   point        per sample: L_i = E(x) · Y_i(ω(x)) with E = I / max(d, minDistance)², blending to
//                a uniform radiance of the same irradiance within minDistance, exactly as
//                PointLight::shCoefficients does (so a light inside the volume or on a grid point
//                stays finite)
//   ambient      optional (method param `ambient`, default 0): a uniform sky of radiance A,
//                L_0 += A·√(4π), shadowed like any light (A·V_0/√(4π): ambient occlusion)
// Area lights are not shaded by this model (InputError naming the light): their SH differs per
// sample and would need the light's virtual projection per sample.
#include <cmath>
#include <memory>
#include <numbers>
#include <span>
#include <vector>

#include "core/half_space.h"
#include "render/ray_caster.h"
#include "sh/sh_basis.h"
#include "visibility/global_visibility.h"
#include "visibility/hierarchical_visibility.h"
#include "visibility/local_visibility.h"

namespace voxlight::render {

/// An environment map's band-1 vector shorter than this fraction of its band 0 (luminance) has
/// no dominant direction to split off (a uniform map has none).
inline constexpr float kDominantMinFraction = 1e-3f;

/// A delta light's visibility traced to where nothing beyond can shadow it (NearShadowTrace),
/// and the weight it takes in the light's term (ShLights::shadeToward).
struct WholeReading {
    float weight = 0.f;
    float T = 1.f;
};

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
    /// The same sum with a second reading of the delta lights' visibility: for each directional
    /// light and the directional part of each point light, `toward(ω, maxMm, scratch, T, whole)`
    /// returns coefficients and a factor T (ω: world unit vector toward the light, maxMm: its
    /// distance, ∞ for a directional one), and the light's term is T times its reading of those,
    /// the reading at most an open field's (ShLocalShader says why); returning v itself keeps the
    /// plain term (from v). `whole` (WholeReading) may add a traced visibility that is the
    /// light's whole one: the term becomes weight·(that) + (1 − weight)·(the above), and with
    /// weight 1 the return value is not read. Environment, ambient and a point light's uniform
    /// part read v.
    template <class Toward>
    glm::vec3 shadeToward(const glm::vec3& x, const float* v, Toward&& toward) const;
    /// Whether shadeToward at x reads v when every `toward` returns its own reading (not v):
    /// environment or ambient light, or a point light's uniform part (x within its
    /// minDistance). Where not, v's values do not change the result: a shader whose readings all
    /// come from the ends of traced stretches may pass zeros instead of reading the field at x.
    bool readsPlain(const glm::vec3& x) const {
        if (spreads_) return true;
        for (const Point& p : points_)
            if (!(glm::length(p.position - x) >= p.minDistance)) return true;
        return false;
    }

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
    struct Directional {
        glm::vec3 toward;  ///< world unit vector toward the light
        glm::vec3 c[16];   ///< its windowed L_i (its share of constants())
    };
    /// The directional lights one by one, and constants() without them (environment + ambient):
    /// what shadeToward reads (the viewer's shader repeats it).
    const std::vector<Directional>& directionals() const { return directional_; }
    const glm::vec3* spread() const { return spread_; }

  private:
    template <class Toward>
    glm::vec3 addPoints(glm::vec3 sum, const glm::vec3& x, const float* v, Toward&& toward) const;
    int coefficients_ = 0;
    glm::vec3 constant_[16] = {};  ///< directional + environment + ambient L_i, windowed
    glm::vec3 spread_[16] = {};    ///< constant_ without the directional lights
    bool spreads_ = false;         ///< spread_ has a nonzero coefficient
    float window_[16] = {};        ///< w_l of each coefficient (1 without a window)
    std::vector<Directional> directional_;
    std::vector<Point> points_;
};

template <class Toward>
glm::vec3 ShLights::addPoints(glm::vec3 sum, const glm::vec3& x, const float* v,
                              Toward&& toward) const {
    const int C = coefficients_;
    for (const Point& p : points_) {
        const glm::vec3 d = p.position - x;
        const float dist = glm::length(d);
        const float r = std::max(dist, p.minDistance);
        const glm::vec3 e = p.intensity / (r * r);
        const float directional = std::min(1.f, dist / p.minDistance);
        if (directional > 0.f) {
            float y[16];  // only the bands the field has (once per shaded sample and light)
            const glm::vec3 u = d / dist;
            sh::evalShForCount(C, u, y);
            float scratch[16], T = 1.f;
            WholeReading whole;
            const float* vt = toward(u, dist, scratch, T, whole);
            float term = 0.f;
            if (whole.weight < 1.f) {
                // One sum: over v itself (the plain term) or over the end's reading, that one at
                // most an open field's (Ṽ = w_0): V ≤ T beyond the stretch.
                float dot = 0.f;
                for (int i = 0; i < C; ++i) dot += window_[i] * y[i] * vt[i];
                term = (1.f - whole.weight) * (vt == v ? dot : T * std::min(dot, window_[0]));
            }
            term += whole.weight * whole.T * window_[0];  // an open field: Ṽ = w_0
            sum += (directional * term) * e;
        }
        // The uniform part inside minDistance: c_0 = E/√(4π).
        sum += ((1.f - directional) * float(1.0 / std::sqrt(4.0 * std::numbers::pi)) * v[0]) * e;
    }
    return sum;
}

template <class Toward>
glm::vec3 ShLights::shadeToward(const glm::vec3& x, const float* v, Toward&& toward) const {
    const int C = coefficients_;
    glm::vec3 sum(0.f);
    for (int i = 0; i < C; ++i) sum += spread_[i] * v[i];
    for (const Directional& d : directional_) {
        float scratch[16], T = 1.f;
        WholeReading whole;
        const float* vt = toward(d.toward, INFINITY, scratch, T, whole);
        if (whole.weight < 1.f) {
            // One sum: over v itself (the plain term) or over the end's reading, that one at most
            // an open field's, (√(4π), 0, …): V ≤ T beyond the stretch.
            glm::vec3 s(0.f);
            for (int i = 0; i < C; ++i) s += d.c[i] * vt[i];
            const glm::vec3 open = float(std::sqrt(4.0 * std::numbers::pi)) * d.c[0];
            sum += (1.f - whole.weight) * (vt == v ? s : T * glm::min(s, open));
        }
        // An open field, (√(4π), 0, …), times the traced visibility.
        sum += whole.weight * whole.T * float(std::sqrt(4.0 * std::numbers::pi)) * d.c[0];
    }
    sum = addPoints(sum, x, v, toward);
    return glm::max(sum * float(1.0 / (4.0 * std::numbers::pi)), glm::vec3(0.f));
}

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

/// Where the local field is stored coarser than the voxels, how far (in sample spacings s beyond
/// the first voxel: ℓ = kNearShadowSpacings·(s − 1) voxels) ShLocalShader traces each delta
/// light's shadow exactly before reading the field. ½ puts the field's read as far out as a
/// coarse block's outermost samples lie inside it. Measured on sh-local at 1:16 against 1:1
/// (PSNR over the covered pixels, 5 December; a first version: LOD-step march, no minimum):
/// torso 256³ (ct-bone, thin ribs at 8³/4³) 24.9 dB without, 30.9 / 32.2 / 31.7 / 31.0 dB at
/// ¼ / ½ / ¾ / 1; bonsai 40.7 dB without, 41.7 / 40.1 / 38.6 / 37.3 dB.
/// On top of that, method param `near_trace` traces a fixed number of voxels at every level,
/// full resolution included (default 0). Against the path tracer's single scattering the exact
/// trace beats the band-limited field wherever it runs (5 December, late; 128², 1:8, linear
/// NRMSE sh-local / sh-global, near_trace 0 → 2 → 4): corner case 0.325 → 0.185 → 0.157 /
/// 0.465 → 0.281 → 0.221, torso `ct-bone` 0.854 → 0.758 → 0.750 / 0.709 → 0.618 → 0.606,
/// `ct-soft-tissue` 0.228 → 0.164 → 0.142 / 0.216 → 0.186 → 0.173, abdominal CT 0.517 → 0.366
/// → 0.328 / 0.519 → 0.313 → 0.268 — at +50–75 % (2) and +77–115 % (4) frame time
/// (BM_ShFrame512, 512², torso and abdominal CT), so not the default.
inline constexpr float kNearShadowSpacings = 0.5f;

/// How far (voxels) from a sample toward a delta light the near shadow looks for an exit (the
/// light, the volume's box, a face of the kept region: NearShadowTrace): within this (at most r_s;
/// ℓ where that is longer) the light's visibility is traced whole, weighted 1 up to half of it.
/// 4: the samples a viewer sees on a face lit from outside lie within 1–2 voxels of it; the first
/// version looked as far as r_s (16) and cost the bonsai's frame at 1:8 2–4.5× that without the
/// near shadow (its pot fills the volume's faces), against 1.31× at 4.
inline constexpr float kWholeReachVoxels = 4.f;

/// The near shadow's traced stretches (ShLocalShader, ShGlobalShader), from a sample toward a delta
/// light (world unit vector ω). Its exit: where the ray reaches the light, the volume's box or a
/// face of the region that clip planes and a crop box removing matter for the light keep (the
/// field read there is then the clip-aware one). The kept region is convex, so a ray that leaves
/// it never comes back: past the exit nothing can shadow the light.
class NearShadowTrace {
  public:
    /// `radiusVoxels`: the local field's r_s; `traceVoxels`: traced at every level (near_trace).
    NearShadowTrace(const visibility::MultiresGrid& grid,
                    std::shared_ptr<const optics::TfTable> table, const core::Geometry& geometry,
                    std::span<const core::HalfSpace> cutFaces, double radiusVoxels,
                    float traceVoxels = 0.f);
    /// ℓ (mm) where the field is read at blended sample spacing s (0 at level 0 unless
    /// traceVoxels > 0).
    float ellMm(float spacing) const {
        return (traceVoxels_ + kNearShadowSpacings * (spacing - 1.f)) * h_;
    }
    /// The continuous voxel index of world point x (mm).
    glm::vec3 index(const glm::vec3& x) const { return worldToIndex_ * (x - origin_); }
    /// How far (mm) the exit lies from x (voxel index p) toward ω, at most maxMm.
    float exitMm(const glm::vec3& x, const glm::vec3& p, const glm::vec3& toward,
                 float maxMm) const;
    /// Exits closer than this are traced whole: kWholeReachVoxels (at most r_s), or ℓ where
    /// that is longer.
    float wholeMm(float ellMm) const { return std::max(reachMm_, ellMm); }
    /// Transmittance of the first `mm` toward ω from voxel index p (visibility::nearTransmittance).
    float transmittance(const glm::vec3& p, const glm::vec3& toward, float mm) const;
    /// The voxel index `mm` from p toward ω.
    glm::vec3 along(const glm::vec3& p, const glm::vec3& toward, float mm) const {
        return p + worldToIndex_ * (toward * mm);
    }

  private:
    const visibility::MultiresGrid* grid_;
    std::shared_ptr<const optics::TfTable> table_;
    std::vector<core::HalfSpace> cutFaces_;
    glm::mat3 worldToIndex_{1.f};
    glm::vec3 origin_{0.f};
    float h_ = 1.f;  ///< smallest spacing (mm): the field's voxel unit
    float reachMm_ = 0.f;
    float traceVoxels_ = 0.f;
};

/// One delta light's reading under the near shadow (ShLights::shadeToward's `toward`). Its exit
/// within reach = wholeMm(ℓ): T traced to there is the light's whole visibility, weighted 1 up to
/// reach/2 and fading to 0 at reach (a hard switch would leave a seam where the field's
/// band-limited value and the exact one differ). The rest of the term: where ℓ > 0, T over ℓ
/// (or to the exit if closer) and `field(end, scratch)` at the stretch's end; else v (plain).
template <class Field>
const float* nearShadowReading(const NearShadowTrace& trace, const glm::vec3& x, const glm::vec3& p,
                               const float* v, float ellMm, const glm::vec3& toward, float maxMm,
                               float* scratch, float& T, WholeReading& whole, Field&& field) {
    const float exit = trace.exitMm(x, p, toward, maxMm);
    const float reach = trace.wholeMm(ellMm);
    if (exit < reach) {
        whole.T = trace.transmittance(p, toward, exit);
        whole.weight = std::min(1.f, 2.f * (reach - exit) / reach);
        if (whole.weight >= 1.f) return v;
    }
    if (!(ellMm > 0.f)) return v;
    const float len = std::min(ellMm, exit);
    T = trace.transmittance(p, toward, len);
    field(trace.along(p, toward, len), scratch);
    return scratch;
}

/// sh-local's shader: ShVisibilityShader<LocalVisibility>'s product, except that a delta light
/// (directional, or a point light's directional part) may be read through the exact
/// transmittance of the first ℓ mm toward it and the field at the end of that stretch:
///   V(x, ω) = T(x → x + ℓω) · V(x + ℓω, ω)
/// (exact for the continuous model up to the radius, which it extends by ℓ), with
/// ℓ = near_trace + kNearShadowSpacings·(s − 1) voxels where the field is read at sample spacing s
/// (LocalVisibility::sample's blended spacing, continuous across blocks) — with near_trace 0 (the
/// default) ℓ = 0 at full resolution (level 0: the unchanged product away from an exit, below). Why: a coarse block
/// stores V every s voxels, so at a thin structure (a rib 2–4 voxels thick) the interpolation
/// mixes points in the open air on either side with points inside it, and the side facing away
/// from the light read the air's V and lit up in block-shaped spots; the self-shadow of the first
/// voxels is what varies fastest, and it is now traced at voxel resolution, T by a
/// pre-integrated march in sub-steps of at most half a voxel (visibility::nearTransmittance:
/// no LOD steps, so a shader can trace it alike). The field's reading at the stretch's end is
/// capped at an open field's: V(x + ℓω, ω) ≤ 1 for the true visibility, so V ≤ T(x → x + ℓω),
/// while a 4-coefficient reconstruction of the open hemisphere above a lit face overshoots (to
/// 1.25 toward its pole). Until 5 December, late, the term was instead the smaller of this and
/// the plain product ("the near shadow only darkens"), which kept the plain field's own
/// too-dark readings on lit faces; against the path tracer's single scattering the cap is better
/// in all 8 scene × method cases of tools/bench_sh_accuracy.py (linear NRMSE, 128², 1:8: the
/// corner case 0.351 → 0.325, torso `ct-bone` 0.860 → 0.854, `ct-soft-tissue` 0.230 → 0.228,
/// abdominal CT 0.518 → 0.517; sh-global 0.489 → 0.465, 0.720 → 0.709, 0.231 → 0.216,
/// 0.524 → 0.519). Near an exit, at any level: where the ray toward the light reaches the light,
/// the volume's box or a face of the kept region (NearShadowTrace) within kWholeReachVoxels (or
/// ℓ if longer), nothing beyond could shadow the light, so T traced to there is the light's whole
/// visibility and replaces the term (blended out over the reach's second half, so no seam) —
/// exact, where the field would give a band-limited hemisphere. A fixed reach, not ℓ: a rule
/// depending on ℓ mixed exact and field terms block by block, and on the bonsai's pot (the
/// volume's face, lit from outside) sh-global showed the levels as patches. On a cut face lit through the removed side it replaces the interpolation of the
/// clip-aware field across the face (block-shaped patches at 1:8). On unless the method param `near_shadow` is
/// false; the viewer's shader traces it alike (shaders/raycast.frag shShadeNear). Environment
/// light and ambient read the field at x (a per-sample projection of a traced hemisphere would
/// cost a field's rays per sample).
class ShLocalShader {
  public:
    static constexpr bool kNeedsNormal = false;
    static constexpr bool kScatterAtMeanDepth = true;
    ShLocalShader(std::shared_ptr<const visibility::LocalVisibility> field,
                  std::shared_ptr<const optics::TfTable> table, const core::Geometry& geometry,
                  std::span<const std::shared_ptr<const lights::Light>> lights,
                  std::span<const double> window = {}, float ambient = 0.f, bool nearShadow = true,
                  std::span<const core::HalfSpace> cutFaces = {}, float nearTraceVoxels = 0.f);
    Scatter scatter(const ShadeInput& in) const {
        return {inScattered(in.position), glm::vec3(0.f)};
    }
    const ShLocalShader& forRay(const glm::vec3&) const { return *this; }
    glm::vec3 inScattered(const glm::vec3& x) const;

  private:
    std::shared_ptr<const visibility::LocalVisibility> field_;
    bool near_ = true;  ///< false: ShVisibilityShader's product exactly (method param off)
    NearShadowTrace trace_;
    ShLights lights_;
};

/// sh-global's shader: V^G = V^L ⊗ V^F at the sample (GlobalVisibility::sample), plus two
/// corrections where the field alone is coarse.
///
/// Near cut faces (Kronander et al. 2012 §6, Fig. 15: "local visibility is used for clip-plane
/// renderings"). Within `bandMm` of a face that removes matter for the light (shadows_from_removed
/// false; on the kept side) the coefficients blend linearly from the local field (at the face) to
/// the global one (at bandMm and beyond): V = w·V^G + (1 − w)·V^L, w = clamp(d / bandMm, 0, 1),
/// d = the distance to the nearest such face. Why: there the light's visibility jumps at the face,
/// and the global grid is coarse (one point per spacingVoxels()), so its trilinear interpolation
/// mixes points in front of the face (clear) with points behind it, while the (clip-aware) local
/// field resolves the face at the block grid's resolution. Section-view faces (true) are left to
/// the global field: it is continuous there, and the local field drops the removed matter's
/// shadows beyond r_s (blending there too made the section views of docs/clip-planes brighter
/// than the path tracer's: mean grey 16.3 against 13.7 without, path tracer 10.3, torso). The two
/// fields must describe the same light (both clip-aware, or both unclipped).
///
/// Near shadow (method param `near_shadow`, on by default; only with the near/far split,
/// GlobalVisibility::nearFromLocal): the near factor V^L is stored on the same multiresolution
/// grid as sh-local's, with the same fault at thin structures, so each delta light is read as
/// ShLocalShader reads it — the first ℓ mm toward it traced, the field at the stretch's end:
///   V(x, ω) = T(x → x + ℓω) · V^G(x + ℓω, ω),   V^G = V^L ⊗ V^F
/// (the end's near factor covers the next r_s, its far factor the rest, so the three pieces
/// meet without overlap), the end's reading capped at an open field's as there; near a cut
/// face the end's coefficients blend as the sample's do. ℓ from the local field's blended
/// spacing at the sample (0 at level 0 with near_trace 0: the plain shader bit for bit; near_trace
/// adds its voxels at every level as there). Measured at 1:8 / 1:16
/// against 1:1 (PSNR over the covered pixels, 512², one directional light, 5 December): 256³
/// torso `ct-bone` 39.3 → 46.2 / 26.1 → 33.4 dB; bonsai 50.5 → 54.6 / 42.9 → 41.3 dB.
class ShGlobalShader {
  public:
    static constexpr bool kNeedsNormal = false;
    static constexpr bool kScatterAtMeanDepth = true;
    /// `local`: the field blended in near `faces` (the global field's own in the pipeline);
    /// `faces`: lightCutFaces, for the blend (bandMm > 0) and to end the near shadow's trace;
    /// `table`: the TF the trace integrates (may be null when !nearShadow).
    ShGlobalShader(std::shared_ptr<const visibility::GlobalVisibility> global,
                   std::shared_ptr<const visibility::LocalVisibility> local,
                   std::span<const core::HalfSpace> faces, float bandMm,
                   const core::Geometry& geometry,
                   std::span<const std::shared_ptr<const lights::Light>> lights,
                   std::span<const double> window = {}, float ambient = 0.f,
                   bool nearShadow = false, std::shared_ptr<const optics::TfTable> table = {},
                   float nearTraceVoxels = 0.f);
    Scatter scatter(const ShadeInput& in) const;
    const ShGlobalShader& forRay(const glm::vec3&) const { return *this; }

  private:
    struct Face {
        glm::vec3 point, normal;
    };
    std::shared_ptr<const visibility::GlobalVisibility> global_;
    std::shared_ptr<const visibility::LocalVisibility> local_;
    std::vector<Face> faces_;
    float invBand_ = 0.f;  ///< 0: no blend
    bool near_ = false;    ///< nearShadow and the global field has its near/far split
    NearShadowTrace trace_;
    ShLights lights_;
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
/// sh-global: ShGlobalShader, blending toward `local` within `bandMm` of the caster's
/// lightCutFaces, with the near shadow when the options ask for it.
std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::GlobalVisibility> global,
    std::shared_ptr<const visibility::LocalVisibility> local, float bandMm);

}  // namespace voxlight::render
