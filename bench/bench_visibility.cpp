// SPDX-License-Identifier: MIT
// SH visibility TF-update time (Kronander 2012 Table 1's "TF update"): LOD selection + local
// visibility on the 256³ torso phantom, 4 SH coefficients, 32 rays, r_s 16 voxels, at several
// data-reduction ratios (1:16, 1:32, 1:64), for the CT presets ct-bone and ct-soft-tissue, each by
// the march (32 rays) and by the line sweep (26 lattice rays; ratios printed at the end). The block
// pyramid is built
// once per volume (reported separately as BM_BlockPyramid). Counters: visibility rays/s and
// σt samples/s, grid samples and the visibility's MB.
// BM_VsLocal: Ritschel's hierarchical visibility (opacity pyramid + field, to the volume's
// boundary) against Kronander's local visibility (LOD + field, r_s 16) on the same volume and TF
// (ct-bone), 32 rays, 4 coefficients, at equal numbers of visibility points: Ritschel 1:2 / 1:4
// sub-sampling (one point per 8 / 64 voxels) vs local data reduction 1:8 / 1:64. Medians of 3
// runs; the end of the run prints the ratio of the medians (Ritschel / local).
// BM_TfEdit: a user's TF edit in the viewer — the field under the preset exists, one control point
// changes — computed in full (LOD + local visibility) against updateLocalVisibility from the
// previous field (LOD + only the blocks the edit reaches), 1:16, 32 rays, 4 coefficients, r_s 16.
// Edits: ct-bone's rim point (250 HU, σt ×2: values 140…450 change), ct-soft-tissue's bone point
// (600 HU, ×2: 220…3071), its fat point (−90 HU, ×2: −160…−30), and a colour-only change; arg 2:
// 0 = the march (32 rays), 1 = the line sweep (26). Counters: blocks recomputed / stored, and how
// many changed level. Medians of 3; the end prints the ratio per edit (update / full).
// BM_TfUpdateBonsai: the same total (LOD + line-sweep local + 64³ recursive global) on the shared
// bonsai CT (../shared/datasets/ct/bonsai.vti, 256³ uint8 — a real 256³ CT, Kronander's Fig. 15
// data set), `generic` preset on its robust range, at 1:8 (the pipeline's default) and 1:16;
// skipped with a message when the file is absent.
// bench-deps: visibility optics core io
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <string>

#include "core/phantoms.h"
#include "core/timing.h"
#include "io/volume_io.h"
#include "optics/presets.h"
#include "visibility/global_visibility.h"
#include "visibility/hierarchical_visibility.h"
#include "visibility/local_visibility.h"

using namespace voxlight;

namespace {

const core::Volume& torso() {
    static const core::Volume v = core::makePhantom("torso");
    return v;
}

std::shared_ptr<const visibility::BlockPyramid> torsoPyramid() {
    static const auto p =
        std::make_shared<const visibility::BlockPyramid>(visibility::BlockPyramid::build(torso()));
    return p;
}

const char* const kPresets[] = {"ct-bone", "ct-soft-tissue"};

/// arg 0: preset; arg 1: data reduction; arg 2: 0 = the march (32 rays), 1 = the line sweep (its
/// 26 lattice rays; the end of the run prints sweep / march per preset and reduction).
void BM_TfUpdate(benchmark::State& state) {
    const auto pyramid = torsoPyramid();
    const optics::TransferFunction tf = optics::makePreset(kPresets[state.range(0)]);
    const double ratio = double(state.range(1));
    const bool sweep = state.range(2) == 1;
    visibility::LocalVisibilityOptions o;
    o.coefficients = 4;
    o.rays = sweep ? visibility::kSweepRaysCoarse : 32;
    o.radiusVoxels = 16.0;
    o.algorithm =
        sweep ? visibility::VisibilityAlgorithm::Sweep : visibility::VisibilityAlgorithm::March;
    std::uint64_t rays = 0, samples = 0, points = 0, bytes = 0, skipped = 0;
    for (auto _ : state) {
        // A TF change: table, LOD selection, local visibility.
        const optics::TfTable table(tf);
        auto grid = std::make_shared<const visibility::MultiresGrid>(
            pyramid, visibility::selectLod(*pyramid, tf, table,
                                           visibility::LodBudget::fromReduction(
                                               ratio, pyramid->geometry().voxelCount())));
        const visibility::LocalVisibility vis = visibility::computeLocalVisibility(grid, table, o);
        rays += vis.raysTraced();
        samples += vis.samplesTaken();
        points = grid->selection().points;
        bytes = vis.bytes();
        skipped = vis.pointsSkipped();
        benchmark::DoNotOptimize(vis.blockData(0));
    }
    state.SetLabel(std::string(kPresets[state.range(0)]) + " 1:" + std::to_string(state.range(1)) +
                   (sweep ? " sweep" : " march"));
    state.counters["rays/s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
    state.counters["samples/s"] = benchmark::Counter(double(samples), benchmark::Counter::kIsRate);
    state.counters["grid_points"] = double(points);
    state.counters["vis_MB"] = double(bytes) / 1048576.0;
    state.counters["points_skipped"] = double(skipped);
}
BENCHMARK(BM_TfUpdate)
    ->ArgsProduct({{0, 1}, {16, 32, 64}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()  // the CPU column counts every thread, not the main one alone
    ->UseRealTime()
    ->Iterations(2)
    ->Repetitions(1);

/// The TF-update total (Kronander Table 1: local / global / total): table, LOD selection,
/// local visibility by the line sweep (26 lattice rays, 4 coefficients, r_s 16) and the 64³ global
/// field from it, per update of `tf` at 1:`ratio`. Counters: wall seconds of the local part (LOD
/// included) and of the global part, per update.
void runTfUpdates(benchmark::State& state,
                  const std::shared_ptr<const visibility::BlockPyramid>& pyramid,
                  const optics::TransferFunction& tf, double ratio, bool recursive) {
    visibility::LocalVisibilityOptions o;
    o.coefficients = 4;
    o.rays = visibility::kSweepRaysCoarse;
    o.radiusVoxels = 16.0;
    o.algorithm = visibility::VisibilityAlgorithm::Sweep;
    visibility::GlobalVisibilityOptions go;
    go.resolution = 64;
    go.integration = recursive ? visibility::GlobalIntegration::Recursive
                               : visibility::GlobalIntegration::Piecewise;
    double localSeconds = 0.0, globalSeconds = 0.0;
    using Clock = std::chrono::steady_clock;
    for (auto _ : state) {
        const auto t0 = Clock::now();
        const optics::TfTable table(tf);
        auto grid = std::make_shared<const visibility::MultiresGrid>(
            pyramid, visibility::selectLod(*pyramid, tf, table,
                                           visibility::LodBudget::fromReduction(
                                               ratio, pyramid->geometry().voxelCount())));
        auto local = std::make_shared<const visibility::LocalVisibility>(
            visibility::computeLocalVisibility(grid, table, o));
        const auto t1 = Clock::now();
        const visibility::GlobalVisibility g = visibility::computeGlobalVisibility(local, go);
        benchmark::DoNotOptimize(g.at({0, 0, 0}, 0));
        const auto t2 = Clock::now();
        localSeconds += std::chrono::duration<double>(t1 - t0).count();
        globalSeconds += std::chrono::duration<double>(t2 - t1).count();
    }
    state.counters["local_s"] = localSeconds / double(state.iterations());
    state.counters["global_s"] = globalSeconds / double(state.iterations());
}

/// The torso at 1:8 (the pipeline's default), 1:16 and 1:64, both CT presets (arg 2: 0 = piecewise, 1 = recursive integration);
/// medians of 3 runs of 2 updates.
void BM_TfUpdateTotal(benchmark::State& state) {
    const bool recursive = state.range(2) == 1;
    runTfUpdates(state, torsoPyramid(), optics::makePreset(kPresets[state.range(0)]),
                 double(state.range(1)), recursive);
    state.SetLabel(std::string(kPresets[state.range(0)]) + " 1:" + std::to_string(state.range(1)) +
                   " sweep + global 64^3" + (recursive ? " recursive" : " piecewise"));
}
/// How the TF-update benchmarks run: 3 runs of 2 updates, wall time, the whole process's CPU.
void tfUpdateRuns(benchmark::internal::Benchmark* b) {
    b->Unit(benchmark::kMillisecond)
        ->MeasureProcessCPUTime()
        ->UseRealTime()
        ->Iterations(2)
        ->Repetitions(3)
        ->ReportAggregatesOnly(true);
}
BENCHMARK(BM_TfUpdateTotal)->ArgsProduct({{0, 1}, {8, 16, 64}, {0, 1}})->Apply(tfUpdateRuns);

void BM_TfUpdateBonsai(benchmark::State& state) {
    static const std::filesystem::path file =
        std::filesystem::path(VOXLIGHT_SOURCE_DIR) / "../shared/datasets/ct/bonsai.vti";
    if (!std::filesystem::exists(file)) {
        state.SkipWithError("../shared/datasets/ct/bonsai.vti is absent");
        return;
    }
    static const core::Volume volume = io::readVolume(file);
    static const auto pyramid =
        std::make_shared<const visibility::BlockPyramid>(visibility::BlockPyramid::build(volume));
    runTfUpdates(state, pyramid, optics::makePreset("generic", optics::robustRange(volume)),
                 double(state.range(0)), true);
    state.SetLabel("bonsai generic 1:" + std::to_string(state.range(0)) +
                   " sweep + global 64^3 recursive");
}
BENCHMARK(BM_TfUpdateBonsai)->Arg(8)->Arg(16)->Apply(tfUpdateRuns);

/// Global visibility alone (Kronander's "global" column) on the 64³ grid, from the local
/// visibility of ct-bone at 1:16 (computed once); arg: 0 = piecewise (eq. 11 along every ray),
/// 1 = recursive integration.
void BM_GlobalVisibility(benchmark::State& state) {
    static const auto local = [] {
        const auto pyramid = torsoPyramid();
        const optics::TransferFunction tf = optics::makePreset("ct-bone");
        const optics::TfTable table(tf);
        auto grid = std::make_shared<const visibility::MultiresGrid>(
            pyramid, visibility::selectLod(*pyramid, tf, table,
                                           visibility::LodBudget::fromReduction(
                                               16.0, pyramid->geometry().voxelCount())));
        visibility::LocalVisibilityOptions o;
        o.coefficients = 4;
        o.rays = 32;
        return std::make_shared<const visibility::LocalVisibility>(
            visibility::computeLocalVisibility(grid, table, o));
    }();
    visibility::GlobalVisibilityOptions go;
    go.resolution = 64;
    go.integration = state.range(0) == 1 ? visibility::GlobalIntegration::Recursive
                                         : visibility::GlobalIntegration::Piecewise;
    state.SetLabel(state.range(0) == 1 ? "recursive" : "piecewise");
    std::uint64_t rays = 0;
    for (auto _ : state) {
        const visibility::GlobalVisibility g = visibility::computeGlobalVisibility(local, go);
        rays += g.raysTraced();
        benchmark::DoNotOptimize(g.at({0, 0, 0}, 0));
    }
    state.counters["rays/s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_GlobalVisibility)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Iterations(2);

void BM_BlockPyramid(benchmark::State& state) {
    for (auto _ : state) benchmark::DoNotOptimize(visibility::BlockPyramid::build(torso()));
}
BENCHMARK(BM_BlockPyramid)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

/// Voxels per visibility point of each compared pair (arg 1 of BM_VsLocal).
constexpr int kPairs[] = {8, 64};

/// arg 0: 0 = local (Kronander), 1 = Ritschel; arg 1: voxels per visibility point.
void BM_VsLocal(benchmark::State& state) {
    const auto pyramid = torsoPyramid();
    const optics::TransferFunction tf = optics::makePreset("ct-bone");
    const bool ritschel = state.range(0) == 1;
    const int voxelsPerPoint = int(state.range(1));
    std::uint64_t rays = 0, bytes = 0;
    for (auto _ : state) {
        // A TF change: table, then each method's TF-dependent stages.
        const optics::TfTable table(tf);
        if (ritschel) {
            auto op = std::make_shared<const visibility::OpacityPyramid>(
                visibility::OpacityPyramid::build(*pyramid, tf, table));
            visibility::HierarchicalVisibilityOptions o;
            o.coefficients = 4;
            o.rays = 32;
            o.subsample = int(std::lround(std::cbrt(double(voxelsPerPoint))));
            const visibility::HierarchicalVisibility v =
                visibility::computeHierarchicalVisibility(op, o);
            rays += v.raysTraced();
            bytes = v.bytes() + op->bytes();
            benchmark::DoNotOptimize(v.raysTraced());
        } else {
            auto grid = std::make_shared<const visibility::MultiresGrid>(
                pyramid, visibility::selectLod(
                             *pyramid, tf, table,
                             visibility::LodBudget::fromReduction(
                                 double(voxelsPerPoint), pyramid->geometry().voxelCount())));
            visibility::LocalVisibilityOptions o;
            o.coefficients = 4;
            o.rays = 32;
            o.radiusVoxels = 16.0;
            const visibility::LocalVisibility v =
                visibility::computeLocalVisibility(grid, table, o);
            rays += v.raysTraced();
            bytes = v.bytes();
            benchmark::DoNotOptimize(v.blockData(0));
        }
    }
    state.SetLabel(std::string(ritschel ? "ritschel" : "local") +
                   " 1:" + std::to_string(voxelsPerPoint));
    state.counters["rays/s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
    state.counters["vis_MB"] = double(bytes) / 1048576.0;
}
BENCHMARK(BM_VsLocal)
    ->ArgsProduct({{0, 1}, {kPairs[0], kPairs[1]}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

struct TfEdit {
    const char* name;
    const char* preset;
    float value;   ///< the control point edited
    float factor;  ///< σt × factor (1: colour only)
};
constexpr TfEdit kEdits[] = {{"ct-bone rim 250 HU x2", "ct-bone", 250.f, 2.f},
                             {"ct-soft-tissue bone 600 HU x2", "ct-soft-tissue", 600.f, 2.f},
                             {"ct-soft-tissue fat -90 HU x2", "ct-soft-tissue", -90.f, 2.f},
                             {"ct-bone colour of 450 HU", "ct-bone", 450.f, 1.f}};

optics::TransferFunction edited(const TfEdit& e) {
    const optics::TransferFunction base = optics::makePreset(e.preset);
    std::vector<optics::TfPoint> pts = base.points();
    for (optics::TfPoint& p : pts)
        if (p.value == e.value) {
            p.extinction *= e.factor;
            if (e.factor == 1.f) p.color = glm::vec3(0.9f, 0.2f, 0.2f);
        }
    return optics::TransferFunction(pts, base.window(), "edited");
}

/// arg 0: edit (kEdits); arg 1: 0 = full computation, 1 = update from the preset's field.
void BM_TfEdit(benchmark::State& state) {
    constexpr double kReduction = 16.0;
    const TfEdit& e = kEdits[state.range(0)];
    const bool update = state.range(1) == 1;
    const auto pyramid = torsoPyramid();
    const auto budget =
        visibility::LodBudget::fromReduction(kReduction, pyramid->geometry().voxelCount());
    const bool sweep = state.range(2) == 1;
    visibility::LocalVisibilityOptions o;
    o.coefficients = 4;
    o.rays = sweep ? visibility::kSweepRaysCoarse : 32;
    o.radiusVoxels = 16.0;
    o.algorithm =
        sweep ? visibility::VisibilityAlgorithm::Sweep : visibility::VisibilityAlgorithm::March;
    const optics::TransferFunction before = optics::makePreset(e.preset), after = edited(e);
    std::optional<visibility::LocalVisibility> previous;
    if (update) {
        const optics::TfTable table(before);
        previous = visibility::computeLocalVisibility(
            std::make_shared<const visibility::MultiresGrid>(
                pyramid, visibility::selectLod(*pyramid, before, table, budget)),
            table, o);
    }
    visibility::TfUpdateStats st;
    for (auto _ : state) {
        const optics::TfTable table(after);
        auto grid = std::make_shared<const visibility::MultiresGrid>(
            pyramid, visibility::selectLod(*pyramid, after, table, budget));
        const visibility::LocalVisibility v =
            update ? visibility::updateLocalVisibility(*previous, grid, table, o,
                                                       core::Progress::none(), &st)
                   : visibility::computeLocalVisibility(grid, table, o);
        benchmark::DoNotOptimize(v.blockData(0));
    }
    state.SetLabel(std::string(e.name) + (update ? " update" : " full") +
                   (sweep ? " sweep" : " march"));
    if (update) {
        state.counters["blocks_recomputed"] = double(st.blocksRecomputed);
        state.counters["blocks"] = double(st.blocks);
        state.counters["blocks_new_level"] = double(st.blocksLevelChanged);
    }
}
BENCHMARK(BM_TfEdit)
    ->ArgsProduct({{0, 1, 2, 3}, {0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

/// The console reporter that also keeps BM_VsLocal's medians, to print their ratios at the end.
class RatioReporter : public benchmark::ConsoleReporter {
  public:
    void ReportRuns(const std::vector<Run>& runs) override {
        for (const Run& r : runs) {
            if (r.run_type == Run::RT_Iteration && r.run_name.function_name == "BM_TfUpdate")
                update_[r.run_name.args] = {r.GetAdjustedRealTime(), r.GetAdjustedCPUTime()};
            if (r.aggregate_name == "median") {
                if (r.run_name.function_name.find("BM_VsLocal") != std::string::npos)
                    median_[r.run_name.args] = r.GetAdjustedRealTime();
                if (r.run_name.function_name.find("BM_TfEdit") != std::string::npos)
                    edit_[r.run_name.args] = r.GetAdjustedRealTime();
            }
        }
        ConsoleReporter::ReportRuns(runs);
    }
    void printRatios() const {
        for (int p = 0; p < 2; ++p)
            for (int r : {16, 32, 64}) {
                const std::string key = std::to_string(p) + "/" + std::to_string(r) + "/";
                const auto march = update_.find(key + "0"), sweep = update_.find(key + "1");
                if (march == update_.end() || sweep == update_.end()) continue;
                std::printf(
                    "TF update %s 1:%d, sweep / march: wall %.0f / %.0f ms = %.3f, process CPU "
                    "%.0f / %.0f ms = %.3f\n",
                    kPresets[p], r, sweep->second.first, march->second.first,
                    sweep->second.first / march->second.first, sweep->second.second,
                    march->second.second, sweep->second.second / march->second.second);
            }
        for (int v : kPairs) {
            const auto local = median_.find("0/" + std::to_string(v));
            const auto rit = median_.find("1/" + std::to_string(v));
            if (local == median_.end() || rit == median_.end()) continue;
            std::printf("Ritschel / local visibility at 1:%d: %.0f / %.0f ms = %.3f\n", v,
                        rit->second, local->second, rit->second / local->second);
        }
        for (std::size_t e = 0; e < std::size(kEdits); ++e)
            for (const char* integrator : {"0", "1"}) {
                const auto full = edit_.find(std::to_string(e) + "/0/" + integrator);
                const auto upd = edit_.find(std::to_string(e) + "/1/" + integrator);
                if (full == edit_.end() || upd == edit_.end()) continue;
                std::printf("TF edit '%s' (%s): update / full = %.0f / %.0f ms = %.3f\n",
                            kEdits[e].name, integrator[0] == '1' ? "sweep" : "march", upd->second,
                            full->second, upd->second / full->second);
            }
    }

  private:
    std::map<std::string, double> median_, edit_;
    std::map<std::string, std::pair<double, double>> update_;  ///< BM_TfUpdate: wall, CPU
};

}  // namespace

int main(int argc, char** argv) {
    voxlight::core::retainFreedMemory();  // as voxlight's main does (core/timing.h)
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    RatioReporter reporter;
    benchmark::RunSpecifiedBenchmarks(&reporter);
    reporter.printRatios();
    benchmark::Shutdown();
    return 0;
}
