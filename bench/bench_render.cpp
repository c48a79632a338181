// SPDX-License-Identifier: MIT
// Ray caster frame times: 512² gradient Blinn–Phong frames of the 256³ torso phantom (CT bone
// preset) and of a real CT from ../shared, at 1 and 2 threads; counters are rays/s and samples/s.
// The side-by-side comparison with VTK's vtkFixedPointVolumeRayCastMapper is
// tools/bench_render_vs_vtk.py (same volume, TF, view and image size; prints both and the ratio).
// bench-deps: render io
#include <benchmark/benchmark.h>

#include <filesystem>

#include "core/phantoms.h"
#include "grid/brick_grid.h"
#include "io/volume_io.h"
#include "optics/presets.h"
#include "render/ray_caster.h"

using namespace voxlight;

namespace {

struct Prepared {
    core::Volume volume;
    grid::BrickGrid grid;
    optics::TransferFunction tf;
};

const Prepared& torso() {
    static const Prepared p = [] {
        Prepared q{core::makePhantom("torso"), {}, optics::makePreset("ct-bone")};
        q.grid = grid::BrickGrid::build(q.volume);
        return q;
    }();
    return p;
}

const Prepared* bonsai() {
    static const std::unique_ptr<Prepared> p = []() -> std::unique_ptr<Prepared> {
        const std::filesystem::path f =
            std::filesystem::path(VOXLIGHT_SOURCE_DIR) / "../shared/datasets/ct/bonsai.vti";
        if (!std::filesystem::exists(f)) return nullptr;
        auto q = std::make_unique<Prepared>();
        q->volume = io::readVolume(f);
        q->grid = grid::BrickGrid::build(q->volume);
        q->tf = optics::makePreset("generic", optics::robustRange(q->volume));
        return q;
    }();
    return p.get();
}

void renderFrames(benchmark::State& state, const Prepared& p, render::Mode mode) {
    render::RenderOptions o;
    o.mode = mode;
    o.threads = int(state.range(0));
    const render::RayCaster caster(p.volume, p.grid, p.tf, o);
    render::CameraSpec s;  // orbit 30°/20°, fitted to what the TF shows: the CLI's and the VTK
                           // comparison's view
    const auto b = render::visibleWorldBounds(caster);
    const render::Camera cam(s, b[0], b[1], 512, 512);
    render::RenderStats stats;
    for (auto _ : state)
        benchmark::DoNotOptimize(caster.render(cam, core::Progress::none(), &stats));
    state.counters["rays/s"] =
        benchmark::Counter(double(stats.rays) * state.iterations(), benchmark::Counter::kIsRate);
    state.counters["samples/s"] =
        benchmark::Counter(double(stats.samples) * state.iterations(), benchmark::Counter::kIsRate);
}

void BM_TorsoGradient512(benchmark::State& state) {
    renderFrames(state, torso(), render::Mode::Gradient);
}
void BM_TorsoEmissionAbsorption512(benchmark::State& state) {
    renderFrames(state, torso(), render::Mode::EmissionAbsorption);
}
void BM_TorsoMip512(benchmark::State& state) { renderFrames(state, torso(), render::Mode::Mip); }
void BM_TorsoIso512(benchmark::State& state) {
    renderFrames(state, torso(), render::Mode::Isosurface);
}
void BM_BonsaiGradient512(benchmark::State& state) {
    const Prepared* p = bonsai();
    if (!p) {
        state.SkipWithError("../shared/datasets/ct/bonsai.vti is absent");
        return;
    }
    renderFrames(state, *p, render::Mode::Gradient);
}

}  // namespace

BENCHMARK(BM_TorsoGradient512)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_TorsoEmissionAbsorption512)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_TorsoMip512)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_TorsoIso512)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_BonsaiGradient512)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
