// SPDX-License-Identifier: MIT
// bench-deps: pvrt core
// CPCA compression of PVRT transfer rows (pvrt/cpca.h) and its per-frame early evaluation
// (Cpca::radiance). Synthetic transfer-like rows: 96 groups, each a mean plus 8 directions of
// strength × 0.6 per direction and 1% noise, so the data are neither exactly clusterable nor of
// low rank. Sizes: 200k rows × dim 48 (SH 16 × RGB, the project's target: well under 10 s on 2
// cores), 500k × 48, 50k and 500k × 486 (DSF 162 × RGB) and 20k × 1926 (DSF 642 × RGB, where clusters of > 128 rows
// take the randomized subspace iteration). 128 clusters, 4 components, 20 Lloyd iterations, at 1
// and 2 threads (same result). Counters: rows/s, the relative L2 error, the Lloyd iterations run
// and the compressed MB.
// Run with --benchmark_repetitions=3 for medians.
#include <benchmark/benchmark.h>

#include <map>
#include <utility>
#include <vector>

#include "core/rng.h"
#include "pvrt/cpca.h"

using namespace voxlight;

namespace {

const std::vector<float>& transferRows(std::size_t rows, int dim) {
    static std::map<std::pair<std::size_t, int>, std::vector<float>> cache;
    auto& x = cache[{rows, dim}];
    if (!x.empty()) return x;
    constexpr int kGroups = 96, kRank = 8;
    auto u = [](std::uint64_t a, std::uint64_t b, std::uint64_t c) {
        return float(2 * core::toUnitDouble(core::hashCounters(a, b, c, 99)) - 1);
    };
    // Per group: mean and directions, then rows as mean + Σ w_j·s_j·d_j + noise.
    std::vector<float> basis(std::size_t(kGroups) * (kRank + 1) * dim);
    for (std::size_t i = 0; i < basis.size(); ++i) basis[i] = u(i, 1, 0);
    x.resize(rows * dim);
    for (std::size_t i = 0; i < rows; ++i) {
        const std::size_t g = core::hashCounters(i, 2, 0, 99) % kGroups;
        const float* b = basis.data() + g * (kRank + 1) * dim;
        float w[kRank];
        float s = 1.f;
        for (int j = 0; j < kRank; ++j, s *= 0.6f) w[j] = s * u(i, 3, std::uint64_t(j));
        for (int t = 0; t < dim; ++t) {
            float v = 2.f * b[t];
            for (int j = 0; j < kRank; ++j) v += w[j] * b[(j + 1) * dim + t];
            x[i * dim + t] = v + 0.01f * u(i, 4, std::uint64_t(t));
        }
    }
    return x;
}

void BM_CompressCpca(benchmark::State& state) {
    const std::size_t rows = std::size_t(state.range(0));
    const int dim = int(state.range(1));
    pvrt::CpcaOptions o;
    o.threads = int(state.range(2));
    const auto& x = transferRows(rows, dim);
    pvrt::Cpca c;
    for (auto _ : state) {
        c = pvrt::compressCpca(x, dim, o, core::Progress::none());
        benchmark::DoNotOptimize(c.weights.data());
    }
    state.counters["rows/s"] =
        benchmark::Counter(double(rows) * state.iterations(), benchmark::Counter::kIsRate);
    state.counters["rel_L2"] = c.relativeL2Error;
    state.counters["lloyd_iterations"] = c.iterations;
    state.counters["MB"] = double(c.bytes()) / 1048576.0;
}
BENCHMARK(BM_CompressCpca)
    ->ArgNames({"rows", "dim", "threads"})
    ->Args({200000, 48, 1})
    ->Args({200000, 48, 2})
    ->Args({500000, 48, 2})
    ->Args({50000, 486, 2})
    ->Args({500000, 486, 2})
    ->Args({20000, 1926, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

void BM_CpcaRadiance(benchmark::State& state) {
    const std::size_t rows = std::size_t(state.range(0));
    const int dim = int(state.range(1));
    const auto& x = transferRows(rows, dim);
    const auto c = pvrt::compressCpca(x, dim, pvrt::CpcaOptions{}, core::Progress::none());
    std::vector<glm::vec3> light(std::size_t(dim / 3));
    for (std::size_t k = 0; k < light.size(); ++k)
        light[k] = glm::vec3(1.f / float(k + 1), 0.5f, 0.25f);
    std::vector<glm::vec3> out(rows);
    for (auto _ : state) {
        c.radiance(light, out);
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["rows/s"] =
        benchmark::Counter(double(rows) * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_CpcaRadiance)
    ->ArgNames({"rows", "dim"})
    ->Args({200000, 48})
    ->Args({50000, 486})
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
