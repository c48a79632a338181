// SPDX-License-Identifier: MIT
#include "render/sh_shading.h"

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

ShLights::ShLights(int coefficients, std::span<const std::shared_ptr<const lights::Light>> lights)
    : coefficients_(coefficients) {
    const int band = sh::shBandForCount(coefficients_);
    VL_CHECK(coefficients_ <= 16);
    for (std::size_t n = 0; n < lights.size(); ++n) {
        const lights::Light* l = lights[n].get();
        VL_CHECK(l != nullptr);
        if (const auto* p = dynamic_cast<const lights::PointLight*>(l)) {
            points_.push_back({glm::vec3(p->position()), p->intensity(), float(p->minDistance())});
        } else if (dynamic_cast<const lights::DirectionalLight*>(l) ||
                   dynamic_cast<const lights::EnvironmentLight*>(l)) {
            // Position-independent: project once.
            const std::vector<glm::vec3> c = l->shCoefficients(glm::dvec3(0.0), band);
            for (int i = 0; i < coefficients_; ++i) constant_[i] += c[std::size_t(i)];
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
            float y[16];
            sh::evalShFixed<3>(d / dist, y);
            float dot = 0.f;
            for (int i = 0; i < C; ++i) dot += y[i] * v[i];
            sum += (directional * dot) * e;
        }
        // The uniform part inside minDistance: c_0 = E/√(4π).
        sum += ((1.f - directional) * kInvSqrt4Pi * v[0]) * e;
    }
    return glm::max(sum * kInv4Pi, glm::vec3(0.f));
}

namespace {
std::vector<std::shared_ptr<const lights::Light>> lightsOrHeadlight(const RayCaster& caster,
                                                                    const Camera& camera) {
    std::vector<std::shared_ptr<const lights::Light>> lights = caster.options().lights;
    if (lights.empty()) {
        // The same headlight as makeBuiltinModel.
        const glm::vec3 travel = glm::normalize(
            glm::vec3(camera.forward() - 0.35 * camera.up() + 0.25 * camera.right()));
        lights.push_back(std::make_shared<lights::DirectionalLight>(glm::vec3(1.f), -travel));
    }
    return lights;
}

template <class Field>
std::unique_ptr<ShadingModel> makeModel(const char* name, const RayCaster& caster,
                                        const Camera& camera, std::shared_ptr<const Field> field) {
    return std::make_unique<detail::DvrModel<ShVisibilityShader<Field>>>(
        name,
        ShVisibilityShader<Field>(std::move(field), caster.volume().geometry(),
                                  lightsOrHeadlight(caster, camera)),
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
