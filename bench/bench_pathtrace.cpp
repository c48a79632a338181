// SPDX-License-Identifier: MIT
// The path tracer (pathtrace/path_tracer.h) on the 256³ torso phantom (int16, CT noise) under
// ct-soft-tissue and ct-bone. BM_PathTracerBuild: making the tracer (its majorant grid: fine
// majorants, octant skip distances and the blocks' voxel copies), arg = 0 soft tissue, 1 bone;
// counter: acceleration bytes per voxel of the volume. BM_PathTraceTorso: one 256² frame at 4
// samples per pixel (process CPU time: comparable on a shared machine), single scattering under the headlight (the tracer made once); counter:
// paths/s; label: a hash of the image's bits (the same image before and after a change).
// bench-deps: pathtrace render grid optics core
#include <benchmark/benchmark.h>

#include <cstring>
#include <memory>
#include <string>

#include "core/phantoms.h"
#include "grid/brick_grid.h"
#include "optics/presets.h"
#include "pathtrace/path_tracer.h"
#include "render/ray_caster.h"

using namespace voxlight;

namespace {

struct Scene {
    std::shared_ptr<const core::Volume> volume;
    std::shared_ptr<const optics::TfTable> table;
    std::shared_ptr<const grid::BrickMajorants> cells;
};

Scene makeScene(const char* preset) {
    Scene s;
    static const auto volume =
        std::make_shared<const core::Volume>(core::makePhantom("torso", {.size = 256}));
    const optics::TransferFunction tf = optics::makePreset(preset);
    s.table = std::make_shared<optics::TfTable>(tf);
    const grid::BrickGrid grid = grid::BrickGrid::build(*volume);
    render::RenderOptions ro;
    ro.mode = render::Mode::EmissionAbsorption;
    s.cells = std::make_shared<grid::BrickMajorants>(
        render::buildSkipCells(*volume, grid, tf, *s.table, ro));
    s.volume = volume;
    return s;
}

const Scene& scene(int which) {
    static const Scene soft = makeScene("ct-soft-tissue"), bone = makeScene("ct-bone");
    return which == 0 ? soft : bone;
}

void BM_PathTracerBuild(benchmark::State& state) {
    const Scene& s = scene(int(state.range(0)));
    std::size_t bytes = 0;
    for (auto _ : state) {
        const pathtrace::PathTracer tracer(s.volume, s.table, s.cells, {});
        bytes = tracer.accelerationBytes();
        benchmark::DoNotOptimize(bytes);
    }
    state.counters["B/voxel"] = double(bytes) / double(s.volume->geometry().voxelCount());
}
BENCHMARK(BM_PathTracerBuild)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PathTraceTorso(benchmark::State& state) {
    const Scene& s = scene(int(state.range(0)));
    pathtrace::Options o;
    o.samplesPerPixel = 4;
    const pathtrace::PathTracer tracer(s.volume, s.table, s.cells, o);
    const auto b = s.volume->geometry().worldBounds();
    const render::Camera cam(render::CameraSpec{}, b[0], b[1], 256, 256);
    std::uint64_t paths = 0, hash = 1469598103934665603ull;
    for (auto _ : state) {
        pathtrace::Stats st;
        const core::ImageRGBA im = tracer.render(cam, core::Progress::none(), &st);
        paths += st.paths;
        hash = 1469598103934665603ull;  // FNV-1a over the pixels' bytes
        for (const float f : im.pixels) {
            std::uint32_t u;
            std::memcpy(&u, &f, sizeof u);
            hash = (hash ^ u) * 1099511628211ull;
        }
    }
    state.SetLabel("image " + std::to_string(hash));
    state.counters["paths/s"] = benchmark::Counter(double(paths), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_PathTraceTorso)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
