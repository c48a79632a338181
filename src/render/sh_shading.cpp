// SPDX-License-Identifier: MIT
#include "render/sh_shading.h"

#include <algorithm>
#include <numbers>

#include "core/error.h"
#include "lights/environment_light.h"
#include "render/dvr_march.h"
#include "sh/sh_basis.h"

namespace voxlight::render {

namespace {
constexpr float kInv4Pi = float(1.0 / (4.0 * std::numbers::pi));
const float kInvSqrt4Pi = float(1.0 / std::sqrt(4.0 * std::numbers::pi));
}  // namespace

double ringingBound(int coefficients, std::span<const double> window) {
    const int bands = sh::shBandForCount(coefficients);
    double sum = 0.0;
    for (int l = 0; l <= bands; ++l) {
        const double w = std::size_t(l) < window.size() ? window[std::size_t(l)] : 1.0;
        sum += w * w * double(2 * l + 1);
    }
    return std::sqrt(sum);
}

ShLights::ShLights(int coefficients, std::span<const std::shared_ptr<const lights::Light>> lights,
                   std::span<const double> window, float ambient)
    : coefficients_(coefficients) {
    const int band = sh::shBandForCount(coefficients_);
    VL_CHECK(coefficients_ <= 16);
    VL_CHECK(window.empty() || int(window.size()) > band);
    for (int l = 0, i = 0; l <= band; ++l)
        for (int m = -l; m <= l; ++m, ++i)
            window_[i] = window.empty() ? 1.f : float(window[std::size_t(l)]);
    VL_CHECK(ambient >= 0.f);
    constant_[0] += glm::vec3(ambient * float(std::sqrt(4.0 * std::numbers::pi)));  // w_0 = 1
    for (std::size_t n = 0; n < lights.size(); ++n) {
        const lights::Light* l = lights[n].get();
        VL_CHECK(l != nullptr);
        if (const auto* p = dynamic_cast<const lights::PointLight*>(l)) {
            points_.push_back({glm::vec3(p->position()), p->intensity(), float(p->minDistance())});
        } else if (dynamic_cast<const lights::DirectionalLight*>(l) ||
                   dynamic_cast<const lights::EnvironmentLight*>(l)) {
            // Position-independent: project once.
            const std::vector<glm::vec3> c = l->shCoefficients(glm::dvec3(0.0), band);
            for (int i = 0; i < coefficients_; ++i) constant_[i] += window_[i] * c[std::size_t(i)];
        } else {
            throw InputError("lights", std::string(l->kind()),
                             "is a light type SH visibility shading does not know",
                             "use directional, point or environment lights");
        }
    }
}

glm::vec3 ShLights::shade(const glm::vec3& x, const float* v) const {
    const int C = coefficients_;
    glm::vec3 sum(0.f);
    for (int i = 0; i < C; ++i) sum += constant_[i] * v[i];
    for (const Point& p : points_) {
        const glm::vec3 d = p.position - x;
        const float dist = glm::length(d);
        const float r = std::max(dist, p.minDistance);
        const glm::vec3 e = p.intensity / (r * r);
        const float directional = std::min(1.f, dist / p.minDistance);
        if (directional > 0.f) {
            float y[16];  // only the bands the field has (once per shaded sample and light)
            const glm::vec3 u = d / dist;
            if (C <= 4)
                sh::evalShFixed<1>(u, y);
            else if (C <= 9)
                sh::evalShFixed<2>(u, y);
            else
                sh::evalShFixed<3>(u, y);
            float dot = 0.f;
            for (int i = 0; i < C; ++i) dot += window_[i] * y[i] * v[i];
            sum += (directional * dot) * e;
        }
        // The uniform part inside minDistance: c_0 = E/√(4π).
        sum += ((1.f - directional) * kInvSqrt4Pi * v[0]) * e;
    }
    return glm::max(sum * kInv4Pi, glm::vec3(0.f));
}

ShCutFaceShader::ShCutFaceShader(std::shared_ptr<const visibility::GlobalVisibility> global,
                                 std::shared_ptr<const visibility::LocalVisibility> local,
                                 std::span<const core::HalfSpace> faces, float bandMm,
                                 const core::Geometry& geometry,
                                 std::span<const std::shared_ptr<const lights::Light>> lights,
                                 std::span<const double> window, float ambient)
    : global_(std::move(global)),
      local_(std::move(local)),
      invBand_(bandMm > 0.f ? 1.f / bandMm : 0.f),
      lights_(global_->coefficients(), lights, window, ambient) {
    VL_CHECK(global_ && local_);
    VL_CHECK(global_->coefficients() == local_->coefficients());
    for (const core::HalfSpace& f : faces)
        faces_.push_back({glm::vec3(f.point), glm::vec3(f.normal)});
    worldToIndex_ = glm::mat3(geometry.worldToIndexMatrix());
    origin_ = glm::vec3(geometry.origin);
}

Scatter ShCutFaceShader::scatter(const ShadeInput& in) const {
    const glm::vec3& x = in.position;
    float d = INFINITY;
    for (const Face& f : faces_) d = std::min(d, glm::dot(x - f.point, f.normal));
    const float w = std::clamp(d * invBand_, 0.f, 1.f);
    const glm::vec3 p = worldToIndex_ * (x - origin_);
    const int C = lights_.coefficients();
    float v[16];
    global_->sample(p, v);
    if (w < 1.f) {
        // Near a cut face: toward the local field.
        float vl[16];
        local_->sample(p, vl);
        for (int i = 0; i < C; ++i) v[i] = w * v[i] + (1.f - w) * vl[i];
    }
    return {lights_.shade(x, v), glm::vec3(0.f)};
}

std::vector<core::HalfSpace> lightCutFaces(const RenderOptions& options) {
    std::vector<core::HalfSpace> faces;
    for (const ClipPlane& c : options.clipPlanes)
        if (!c.shadowsFromRemoved) faces.push_back({c.point, c.normal});
    if (options.cropBox && !options.cropBox->shadowsFromRemoved)
        for (const core::HalfSpace& f :
             core::boxHalfSpaces(options.cropBox->min, options.cropBox->max))
            faces.push_back(f);
    return faces;
}

namespace {
std::vector<std::shared_ptr<const lights::Light>> lightsOrHeadlight(const RayCaster& caster,
                                                                    const Camera& camera) {
    std::vector<std::shared_ptr<const lights::Light>> lights = caster.options().lights;
    if (lights.empty()) lights.push_back(headlight(camera, kVolumetricHeadlightIrradiance));
    return lights;
}

template <class Field>
std::unique_ptr<ShadingModel> makeModel(const char* name, const RayCaster& caster,
                                        const Camera& camera, std::shared_ptr<const Field> field) {
    return std::make_unique<detail::DvrModel<ShVisibilityShader<Field>>>(
        name,
        ShVisibilityShader<Field>(std::move(field), caster.volume().geometry(),
                                  lightsOrHeadlight(caster, camera), caster.options().shWindow,
                                  caster.options().shAmbient),
        PixelFootprint(caster, camera));
}
}  // namespace

std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::LocalVisibility> field) {
    return makeModel("sh-local", caster, camera, std::move(field));
}

std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::GlobalVisibility> field) {
    return makeModel("sh-global", caster, camera, std::move(field));
}

std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::HierarchicalVisibility> field) {
    return makeModel("ritschel", caster, camera, std::move(field));
}

}  // namespace voxlight::render

namespace voxlight::render {

std::unique_ptr<ShadingModel> makeShVisibilityModel(
    const RayCaster& caster, const Camera& camera,
    std::shared_ptr<const visibility::GlobalVisibility> global,
    std::shared_ptr<const visibility::LocalVisibility> local, float bandMm) {
    const std::vector<core::HalfSpace> faces = lightCutFaces(caster.options());
    if (faces.empty() || !(bandMm > 0.f))
        return makeShVisibilityModel(caster, camera, std::move(global));
    return std::make_unique<detail::DvrModel<ShCutFaceShader>>(
        "sh-global",
        ShCutFaceShader(std::move(global), std::move(local), faces, bandMm,
                        caster.volume().geometry(), lightsOrHeadlight(caster, camera),
                        caster.options().shWindow, caster.options().shAmbient),
        PixelFootprint(caster, camera));
}

}  // namespace voxlight::render
