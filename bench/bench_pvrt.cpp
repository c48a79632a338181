// SPDX-License-Identifier: MIT
// PVRT's indirect transfer (pvrt/photons.h): volumetric photon mapping from the volume's boundary
// on the 32³ sphere phantom (σt 0.15/mm, albedo 0.9, transfer grid 32³) and the 128³ torso
// phantom under ct-soft-tissue (transfer grid 64³), 10 photons per boundary cell, kernel 2 grid
// steps, 7 scatterings, for the bases SH order 4 (16 lights) and DSF 162 (first arg 0 / 1), with
// the track-length and the collision estimator (second arg 0 / 1). Counters: photons/s,
// collisions and splats (flights or collisions scored) per photon, stored points. BM_DirectTorso128: the direct part (slice
// sweeps, 162 directions, SH order 4) on the same torso at transfer grids 64³ and 128³.
// BM_LightChange: pvrt_radiance's combination (pvrt::combineCpca) on the torso's 64³ grid with
// a synthetic CPCA of the pipeline's shape (128 clusters × 4 components, SH-16 basis lights), for
// n = 1 and 16 exitance coefficients (first arg), keeping the n coefficients (second arg 0) or
// evaluated toward a perspective eye per grid point (1).
// bench-deps: pvrt pathtrace render grid optics core
#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>
#include <vector>

#include "core/phantoms.h"
#include "grid/brick_grid.h"
#include "optics/presets.h"
#include "pvrt/direct.h"
#include "pvrt/photons.h"
#include "pvrt/radiance.h"
#include "render/ray_caster.h"

using namespace voxlight;

namespace {

struct Scene {
    std::shared_ptr<const core::Volume> volume;
    std::shared_ptr<const optics::TfTable> table;
    std::shared_ptr<const grid::BrickMajorants> cells;
    int resolution = 32;
};

Scene makeScene(const std::string& phantom, int size, const optics::TransferFunction& tf,
                int resolution) {
    Scene s;
    auto v = std::make_shared<core::Volume>(core::makePhantom(phantom, {.size = size}));
    s.table = std::make_shared<optics::TfTable>(tf);
    const grid::BrickGrid grid = grid::BrickGrid::build(*v);
    render::RenderOptions ro;
    ro.mode = render::Mode::EmissionAbsorption;
    s.cells =
        std::make_shared<grid::BrickMajorants>(render::buildSkipCells(*v, grid, tf, *s.table, ro));
    s.volume = v;
    s.resolution = resolution;
    return s;
}

const Scene& sphere() {
    static const Scene s = [] {
        const glm::vec3 a(0.9f);
        const optics::TransferFunction tf(
            {{0.f, a, 0.f, {}}, {0.499f, a, 0.f, {}}, {0.501f, a, 0.15f, {}}, {1.f, a, 0.15f, {}}},
            {0.5f, 1.f}, "step");
        return makeScene("sphere", 32, tf, 32);
    }();
    return s;
}

const Scene& torso() {
    static const Scene s = makeScene("torso", 128, optics::makePreset("ct-soft-tissue"), 64);
    return s;
}

void run(benchmark::State& state, const Scene& s, const pvrt::Basis& basis) {
    const pvrt::PhotonOptions options{.estimator = state.range(1) ? pvrt::Estimator::Collision
                                                                  : pvrt::Estimator::TrackLength};
    const pathtrace::PathTracer tracer(s.volume, s.table, s.cells, {});
    const pvrt::TransferLayout layout = pvrt::makeTransferLayout(*s.volume, *s.cells, s.resolution);
    pvrt::PhotonStats st;
    for (auto _ : state) {
        pvrt::Transfer t(layout, basis.size());
        st = pvrt::addIndirectTransfer(tracer, basis, t, options, core::Progress::none());
        benchmark::DoNotOptimize(t.values.data());
    }
    state.counters["photons/s"] =
        benchmark::Counter(double(st.photons), benchmark::Counter::kIsIterationInvariantRate);
    state.counters["photons"] = double(st.photons);
    state.counters["collisions/photon"] = double(st.collisions) / double(st.photons);
    state.counters["splats/photon"] = double(st.splats) / double(st.photons);
    state.counters["points"] = double(layout.points);
}

void BM_PhotonsSphere32(benchmark::State& state) {
    run(state, sphere(), state.range(0) ? pvrt::Basis::dsf(162) : pvrt::Basis::sh(4));
}
void BM_PhotonsTorso128(benchmark::State& state) {
    run(state, torso(), state.range(0) ? pvrt::Basis::dsf(162) : pvrt::Basis::sh(4));
}

/// The direct part on the 128³ torso, SH order 4, 162 quadrature directions, transfer grid 64³
/// (arg 64) and 128³ (arg 128): the slice sweeps and their projection into the basis.
void BM_DirectTorso128(benchmark::State& state) {
    const Scene& s = torso();
    const pvrt::Basis basis = pvrt::Basis::sh(4);
    const pvrt::TransferLayout layout =
        pvrt::makeTransferLayout(*s.volume, *s.cells, int(state.range(0)));
    pvrt::DirectStats st;
    for (auto _ : state) {
        pvrt::Transfer t(layout, basis.size());
        st = pvrt::addDirectTransfer(*s.volume, *s.table, basis, t, {});
        benchmark::DoNotOptimize(t.values.data());
    }
    state.counters["voxel updates/s"] =
        benchmark::Counter(double(st.voxelUpdates), benchmark::Counter::kIsIterationInvariantRate);
    state.counters["points"] = double(layout.points);
}

void BM_LightChange(benchmark::State& state) {
    const Scene& s = torso();
    const int n = int(state.range(0)), m = 16;
    const pvrt::TransferLayout layout = pvrt::makeTransferLayout(*s.volume, *s.cells, 64);
    pvrt::Cpca c;
    c.dim = n * m * 3;
    c.clusters = 128;
    c.components = 4;
    auto pseudo = [](std::size_t i) { return float(std::sin(0.37 * double(i) + 0.1)); };
    c.means.resize(std::size_t(c.clusters) * c.dim);
    c.basis.resize(std::size_t(c.clusters) * c.components * c.dim);
    for (std::size_t i = 0; i < c.means.size(); ++i) c.means[i] = pseudo(i);
    for (std::size_t i = 0; i < c.basis.size(); ++i) c.basis[i] = 0.1f * pseudo(i + 7);
    c.cluster.resize(std::size_t(layout.points));
    c.weights.resize(std::size_t(layout.points) * c.components);
    for (std::size_t i = 0; i < c.cluster.size(); ++i) c.cluster[i] = std::int32_t(i * 7 % 128);
    for (std::size_t i = 0; i < c.weights.size(); ++i) c.weights[i] = pseudo(i + 3);
    std::vector<glm::vec3> light(static_cast<std::size_t>(m));
    for (int k = 0; k < m; ++k) light[std::size_t(k)] = glm::vec3(pseudo(std::size_t(k) + 11));
    const pvrt::EyeFold eye{.g = 0.6f,
                            .geometry = s.volume->geometry(),
                            .eye = s.volume->geometry().indexToWorld(glm::dvec3(64, -400, 64))};
    for (auto _ : state) {
        const pvrt::RadianceVolume r =
            pvrt::combineCpca(layout, c, light, n, 0, state.range(1) ? &eye : nullptr);
        benchmark::DoNotOptimize(r.values.data());
    }
    state.counters["points"] = double(layout.points);
}

BENCHMARK(BM_PhotonsSphere32)
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_PhotonsTorso128)
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_DirectTorso128)->Arg(64)->Arg(128)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_LightChange)
    ->Args({1, 0})
    ->Args({16, 0})
    ->Args({16, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
