// SPDX-License-Identifier: MIT
#include "pathtrace/march_reference.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <memory>

#include "core/error.h"
#include "render/shading.h"

namespace voxlight::pathtrace {

namespace {

constexpr const char* kSource = "pathtrace reference";

/// exp(−∫σt) from x along wi over [0, distance], clipped to the tracer's light interval, by the
/// midpoint rule at steps of at most `step` mm.
double shadowTransmittance(const PathTracer& tracer, const glm::dvec3& x, const glm::dvec3& wi,
                           double distance, double step) {
    const Ray ray{x, wi};
    double t0 = 0.0, t1 = distance;
    if (!tracer.lightInterval(ray, t0, t1) || !(t1 > t0)) return 1.0;
    const int n = std::max(1, int(std::ceil((t1 - t0) / step)));
    const double dt = (t1 - t0) / n;
    double tau = 0.0;
    for (int i = 0; i < n && tau < kMarchMaxOpticalDepth; ++i)
        tau += double(tracer.extinctionAt(x + (t0 + (i + 0.5) * dt) * wi)) * dt;
    return tau < kMarchMaxOpticalDepth ? std::exp(-tau) : 0.0;
}

}  // namespace

core::ImageRGBA marchSingleScattering(const PathTracer& tracer, const render::Camera& camera,
                                      const MarchOptions& options, const core::Progress& progress) {
    if (!(options.stepMm > 0.0) || !(options.shadowStepMm > 0.0))
        throw InputError(kSource, "step", "must be positive",
                         "give steps of a fraction of a voxel");
    const Options& o = tracer.options();
    if (o.scattering != Scattering::Phase || tracer.table().hasPhaseG())
        throw InputError(kSource, "scattering",
                         "only the phase function (options phaseG, no TF phase channel) is marched",
                         "use scattering phase and a TF without phase_g");
    if (o.apertureMm > 0.0)
        throw InputError(kSource, "aperture", "only a pinhole camera is marched",
                         "set the aperture to 0");
    std::vector<std::shared_ptr<const lights::Light>> lightList = o.lights;
    if (lightList.empty())
        lightList.push_back(render::headlight(camera, render::kVolumetricHeadlightIrradiance));
    for (const auto& l : lightList)
        if (!l->isDelta())
            throw InputError(kSource, "lights",
                             "a " + std::string(l->kind()) + " light is not marched",
                             "use directional and point lights only");

    std::unique_ptr<tbb::global_control> limit;
    if (o.threads > 0 || options.threads > 0)
        limit = std::make_unique<tbb::global_control>(
            tbb::global_control::max_allowed_parallelism,
            std::size_t(options.threads > 0 ? options.threads : o.threads));
    const int w = camera.width(), h = camera.height();
    core::ImageRGBA im(w, h);
    const glm::dvec3 bg(o.background);
    tbb::parallel_for(0, h, [&](int y) {
        progress.checkCancel();
        for (int x = 0; x < w; ++x) {
            const render::Ray cr = camera.generateAt(x + 0.5, y + 0.5);
            const Ray ray{cr.origin, cr.direction};
            glm::dvec3 L(0.0);
            double T = 1.0;
            double t0 = 0.0, t1 = INFINITY;
            if (tracer.keptInterval(ray, t0, t1)) {
                const int n = std::max(1, int(std::ceil((t1 - t0) / options.stepMm)));
                const double dt = (t1 - t0) / n;
                for (int i = 0; i < n && T >= kMarchTermination; ++i) {
                    const glm::dvec3 p = ray.origin + (t0 + (i + 0.5) * dt) * ray.direction;
                    const optics::TfSample m = tracer.mediumAt(p);
                    if (!(m.extinction > 0.f)) continue;
                    const double absorbed = -std::expm1(-double(m.extinction) * dt);
                    const glm::dvec3 a(m.albedo);
                    // Emission, then in-scattering from every light (shadowed at the midpoint).
                    glm::dvec3 S = (1.0 - a) * glm::dvec3(m.emission);
                    if (a != glm::dvec3(0.0))
                        for (const auto& light : lightList) {
                            const lights::LightSample ls = light->sample(p, glm::vec2(0.5f));
                            if (!(ls.pdf > 0.f) || ls.value == glm::vec3(0.f)) continue;
                            const glm::dvec3 wi(ls.wi);
                            const double V =
                                options.shadows
                                    ? shadowTransmittance(tracer, p, wi, double(ls.distance),
                                                          options.shadowStepMm)
                                    : 1.0;
                            const double phase =
                                henyeyGreenstein(float(glm::dot(ray.direction, wi)), o.phaseG);
                            S += a * (phase * V) * glm::dvec3(ls.value);
                        }
                    L += (T * absorbed) * S;
                    T *= 1.0 - absorbed;
                }
            }
            L += T * bg;
            float* px = im.at(x, y);
            px[0] = float(L.x), px[1] = float(L.y), px[2] = float(L.z);
            px[3] = float(1.0 - T);
        }
    });
    return im;
}

}  // namespace voxlight::pathtrace
