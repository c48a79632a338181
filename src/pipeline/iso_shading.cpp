// SPDX-License-Identifier: MIT
#include "pipeline/iso_shading.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <numbers>
#include <thread>

#include "core/error.h"
#include "core/timing.h"
#include "render/dvr_march.h"

namespace voxlight::pipeline {

namespace {

/// Pass 1: per pixel the world point of the first crossing (RGB) and whether there is one (A),
/// and the ray caster's normal there (facing the eye) into `normals` (phong reads it).
class IsoHitModel final : public render::ShadingModel {
  public:
    explicit IsoHitModel(core::ImageRGBA& normals) : normals_(normals) {}
    std::string name() const override { return "iso-hits"; }
    void renderTile(const render::RayCaster& c, const render::Camera& cam, int x0, int y0, int x1,
                    int y1, core::ImageRGBA& film, render::RenderStats& stats) const override {
        c.volume().visit([&](const auto& view) {
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    float* px = film.at(x, y);
                    const render::RaySegment r = c.setupRay(cam, x, y);
                    render::detail::IsoHit hit;
                    if (!r.hit() || !render::detail::marchIso(c, view, r, hit, stats.samples)) {
                        px[0] = px[1] = px[2] = px[3] = 0.f;
                        continue;
                    }
                    ++stats.rays;
                    const glm::vec3 p = r.originWorld + hit.t * r.dirWorld;
                    px[0] = p.x, px[1] = p.y, px[2] = p.z, px[3] = 1.f;
                    float* n = normals_.at(x, y);
                    n[0] = hit.normal.x, n[1] = hit.normal.y, n[2] = hit.normal.z, n[3] = 1.f;
                }
        });
    }

  private:
    core::ImageRGBA& normals_;  ///< tiles are disjoint: concurrent writes never meet
};

}  // namespace

const std::vector<std::string>& isoShadingNames() {
    static const std::vector<std::string> names = {"lattice", "paths",    "lambert",
                                                   "shadows", "vicinity", "phong"};
    return names;
}

IsoShading isoShadingFromName(const std::string& name) {
    const auto& n = isoShadingNames();
    for (std::size_t i = 0; i < n.size(); ++i)
        if (n[i] == name) return IsoShading(i);
    throw InternalError("unknown iso shading '" + name + "'");
}

core::ImageRGBA renderLitIsosurface(const render::RayCaster& caster, const render::Camera& camera,
                                    iso::IlluminationLattice* lattice, const IsoShadingOptions& o,
                                    const core::Progress& progress, IsoFrameStats& stats) {
    VL_CHECK(lattice != nullptr || !isoShadingTraces(o.shading));
    const int W = camera.width(), H = camera.height();
    core::Stopwatch clock;
    core::ImageRGBA normals(W, H);
    const IsoHitModel hitModel(normals);
    render::RenderStats hitStats;
    const core::ImageRGBA hits = caster.render(camera, hitModel, progress, &hitStats);
    stats.samples = hitStats.samples;
    stats.hitSeconds = clock.seconds();
    clock.restart();

    const double iso = caster.isoValue();
    // The hit points: the texels they read (lattice shading only), and how many there are.
    std::vector<glm::dvec3> points;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const float* h = hits.at(x, y);
            if (!(h[3] > 0.f)) continue;
            ++stats.hits;
            if (o.shading == IsoShading::Lattice) points.emplace_back(h[0], h[1], h[2]);
        }
    if (o.shading == IsoShading::Lattice) stats.lattice = lattice->require(points, iso, progress);

    const glm::vec3 bg = caster.options().background;
    const glm::vec3 albedo = caster.transferFunction().eval(float(iso)).albedo;
    std::vector<std::shared_ptr<const lights::Light>> phongLights = caster.options().lights;
    if (phongLights.empty()) phongLights.push_back(render::headlight(camera, 1.f));
    const render::BlinnPhongShader phong(o.phong, phongLights, caster.options().irradianceSh);
    const float invPi = float(1.0 / std::numbers::pi);

    core::ImageRGBA film(W, H);
    std::atomic<int> rowsDone{0};
    const std::thread::id caller = std::this_thread::get_id();
    const char* stage = "shading the isosurface";
    progress.report(stage, 0.0);
    const int threads = caster.options().threads;
    tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
    arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<int>(0, H, 1), [&](const tbb::blocked_range<int>& r) {
            if (progress.cancelled()) return;
            for (int y = r.begin(); y < r.end(); ++y)
                for (int x = 0; x < W; ++x) {
                    const float* h = hits.at(x, y);
                    float* px = film.at(x, y);
                    if (!(h[3] > 0.f)) {
                        render::detail::writeMiss(px, bg);
                        continue;
                    }
                    const glm::dvec3 p(h[0], h[1], h[2]);
                    const std::uint64_t key =
                        std::uint64_t(y) * std::uint64_t(W) + std::uint64_t(x);
                    glm::vec3 c(0.f);
                    switch (o.shading) {
                        case IsoShading::Lattice:
                            c = albedo * lattice->irradiance(p, iso) * invPi;
                            break;
                        case IsoShading::Paths:
                            c = albedo * lattice->pointIrradiance(p, iso, o.samples, key) * invPi;
                            break;
                        case IsoShading::Lambert:
                        case IsoShading::Shadows:
                            c = albedo *
                                lattice->directIrradiance(p, iso,
                                                          o.shading == IsoShading::Shadows) *
                                invPi;
                            break;
                        case IsoShading::Vicinity:
                            c = albedo *
                                lattice->vicinityIrradiance(p, iso, o.vicinityRadiusMm, o.samples,
                                                            key) *
                                invPi;
                            break;
                        case IsoShading::Phong: {
                            const float* n = normals.at(x, y);
                            render::ShadeInput in;
                            in.position = glm::vec3(p);
                            in.toEye = camera.projection() == render::Projection::Orthographic
                                           ? -glm::vec3(camera.forward())
                                           : glm::vec3(glm::normalize(camera.eye() - p));
                            in.normal = glm::vec3(n[0], n[1], n[2]);
                            in.value = float(iso);
                            const render::Scatter s = phong.scatter(in);
                            c = albedo * s.diffuse + s.specular;
                            break;
                        }
                    }
                    for (int k = 0; k < 3; ++k) px[k] = render::detail::finiteOr0(c[k]);
                    px[3] = 1.f;
                }
            const int now = rowsDone.fetch_add(int(r.size())) + int(r.size());
            if (std::this_thread::get_id() == caller) progress.report(stage, double(now) / H);
        });
    });
    progress.checkCancel();
    progress.report(stage, 1.0);
    stats.shadeSeconds = clock.seconds();
    return film;
}

}  // namespace voxlight::pipeline
