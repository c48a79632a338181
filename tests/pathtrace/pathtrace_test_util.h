// SPDX-License-Identifier: MIT
#pragma once
// A phantom under a TF, ready for the path tracer: the volume, its TF table and the majorant
// cells the pipeline's skip_cells stage would build (emission-absorption skip rule).
#include <cmath>
#include <cstddef>
#include <memory>
#include <string>

#include "core/phantoms.h"
#include "grid/brick_grid.h"
#include "pathtrace/path_tracer.h"
#include "render/ray_caster.h"

namespace voxlight::test {

struct Medium {
    std::shared_ptr<const core::Volume> volume;
    std::shared_ptr<const optics::TfTable> table;
    std::shared_ptr<const grid::BrickMajorants> cells;
    pathtrace::PathTracer tracer(pathtrace::Options o = {}) const {
        return pathtrace::PathTracer(volume, table, cells, std::move(o));
    }
};

/// A medium of any volume (e.g. a phantom with its geometry changed) under `tf`.
inline Medium makeMedium(std::shared_ptr<const core::Volume> v,
                         const optics::TransferFunction& tf) {
    Medium s;
    s.table = std::make_shared<optics::TfTable>(tf);
    const grid::BrickGrid grid = grid::BrickGrid::build(*v);
    render::RenderOptions ro;
    ro.mode = render::Mode::EmissionAbsorption;
    s.cells =
        std::make_shared<grid::BrickMajorants>(render::buildSkipCells(*v, grid, tf, *s.table, ro));
    s.volume = std::move(v);
    return s;
}

inline Medium makeMedium(const std::string& phantom, const optics::TransferFunction& tf,
                         int size = 32) {
    return makeMedium(std::make_shared<core::Volume>(core::makePhantom(phantom, {.size = size})),
                      tf);
}

/// A TF that is empty below value 0.5 and holds σt = `sigma` with albedo `albedo` above (a sharp
/// step: the phantoms' matter is 1, their background 0).
inline optics::TransferFunction stepTf(float sigma, glm::vec3 albedo,
                                       const std::string& name = "step") {
    return optics::TransferFunction({{0.f, albedo, 0.f, {}},
                                     {0.499f, albedo, 0.f, {}},
                                     {0.501f, albedo, sigma, {}},
                                     {1.f, albedo, sigma, {}}},
                                    {0.5f, 1.f}, name);
}

/// The torso under a TF with soft tissue and bone (the thread-count and denoiser scenes).
inline Medium torsoMedium(int size = 48) {
    return makeMedium("torso",
                      optics::TransferFunction({{-200.f, {0.9f, 0.8f, 0.7f}, 0.f, {}},
                                                {300.f, {0.9f, 0.8f, 0.7f}, 0.3f, {}},
                                                {2000.f, {0.9f, 0.9f, 0.9f}, 0.5f, {}}},
                                               {900.f, 2200.f}, "bone"),
                      size);
}

/// RMS of RGB difference over the mean of the reference (NRMSE, as oiiotool's RMS over the mean).
inline double nrmse(const core::ImageRGBA& a, const core::ImageRGBA& ref) {
    double d = 0.0, m = 0.0;
    std::size_t n = 0;
    for (std::size_t p = 0; p < ref.pixels.size(); p += 4)
        for (int c = 0; c < 3; ++c) {
            d += std::pow(double(a.pixels[p + c]) - ref.pixels[p + c], 2);
            m += ref.pixels[p + c];
            ++n;
        }
    return std::sqrt(d / double(n)) / (m / double(n));
}

}  // namespace voxlight::test
