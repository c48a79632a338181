// SPDX-License-Identifier: MIT
#include "render/shading.h"

#include <numbers>

#include "core/error.h"
#include "lights/area_light.h"
#include "lights/environment_light.h"
#include "sh/sh_window.h"

namespace voxlight::render {

namespace {
constexpr int kIrradianceBand = 2;  // 9 coefficients: E is smooth (Ramamoorthi & Hanrahan 2001)
}

std::vector<glm::vec3> environmentIrradianceSh(
    std::span<const std::shared_ptr<const lights::Light>> lights) {
    std::vector<glm::vec3> e;
    const std::vector<double> a = sh::clampedCosineConvolution(kIrradianceBand);
    for (const auto& l : lights) {
        if (!dynamic_cast<const lights::EnvironmentLight*>(l.get())) continue;
        // Environment radiance is the same at every point (the light is at infinity).
        const std::vector<glm::vec3> c = l->shCoefficients(glm::dvec3(0.0), kIrradianceBand);
        if (e.empty()) e.assign(c.size(), glm::vec3(0.f));
        for (std::size_t i = 0; i < c.size(); ++i)
            e[i] += float(a[std::size_t(sh::shBandOf(int(i)))]) * c[i];
    }
    return e;
}

BlinnPhongShader::BlinnPhongShader(const BlinnPhongParams& params,
                                   std::span<const std::shared_ptr<const lights::Light>> lights,
                                   std::span<const glm::vec3> irradianceSh)
    : params_(params) {
    const float n = params_.shininess;
    if (n >= kMinTableShininess && n <= kMaxTableShininess) {
        powTable_.resize(kSpecularTableCells + 1);
        for (int i = 0; i <= kSpecularTableCells; ++i)
            powTable_[std::size_t(i)] = float(std::pow(double(i) / kSpecularTableCells, double(n)));
    }
    // Flatten each light into what the per-sample loop reads (see the class comment).
    bool environment = false;
    for (const auto& light : lights) {
        VL_CHECK(light != nullptr);
        Emitter e;
        if (const auto* d = dynamic_cast<const lights::DirectionalLight*>(light.get())) {
            e.directional = true;
            e.toLight = d->direction();
            e.value = d->irradiance();
        } else if (const auto* p = dynamic_cast<const lights::PointLight*>(light.get())) {
            e.position = glm::vec3(p->position());
            e.value = p->intensity();
            e.minDistance = float(p->minDistance());
        } else if (const auto* s = dynamic_cast<const lights::SphereLight*>(light.get())) {
            const double r = s->radius();
            e.position = glm::vec3(s->centre());
            e.value = s->emittedRadiance() * float(std::numbers::pi * r * r);
            e.minDistance = float(r);
        } else if (const auto* q = dynamic_cast<const lights::PlanarLight*>(light.get())) {
            e.position = glm::vec3(q->centre());
            e.value = q->emittedRadiance() * float(q->area());
            e.minDistance = float(std::sqrt(q->area() / std::numbers::pi));
            e.oneSided = true;
            e.emitterNormal = glm::vec3(q->normal());
        } else if (dynamic_cast<const lights::EnvironmentLight*>(light.get())) {
            environment = true;
            continue;
        } else {
            throw InputError("lights", std::string(light->kind()),
                             "is a light type Blinn–Phong shading does not know",
                             "use directional, point, area or environment lights");
        }
        lights_.push_back(e);
    }
    if (environment) {
        if (irradianceSh.size() != 9)
            throw InputError("lights", "environment",
                             "needs its irradiance SH (9 coefficients) for Blinn–Phong shading",
                             "pass environmentIrradianceSh(lights) to the shader");
        hasEnvironment_ = true;
        std::copy(irradianceSh.begin(), irradianceSh.end(), envSh_);
    }
}

std::shared_ptr<const lights::Light> headlight(const Camera& camera, float irradiance) {
    const glm::vec3 travel =
        glm::normalize(glm::vec3(camera.forward() - 0.35 * camera.up() + 0.25 * camera.right()));
    return std::make_shared<lights::DirectionalLight>(glm::vec3(irradiance), -travel);
}

}  // namespace voxlight::render
