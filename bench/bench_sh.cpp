// SPDX-License-Identifier: MIT
// bench-deps: sh
// Micro-benchmarks of sh/: SH evaluation per direction (L = 1…8), rotation per coefficient vector,
// environment projection (cube map 6×256² through the generic accumulator, equirect 1024×512
// through the separable path) and DSF evaluation/projection. Time per iteration = per direction /
// per vector / per map.
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "core/rng.h"
#include "sh/dsf.h"
#include "sh/sh_basis.h"
#include "sh/sh_projection.h"
#include "sh/sh_rotation.h"

using namespace voxlight;
using namespace voxlight::sh;

namespace {
constexpr double kPi = std::numbers::pi;

const std::vector<glm::vec3>& directions() {
    static const std::vector<glm::vec3> dirs = [] {
        std::vector<glm::vec3> d;
        for (int i = 0; i < 4096; ++i) {
            core::CounterRng rng(i, 1);
            const double z = 1 - 2 * rng.uniformDouble(), phi = 2 * kPi * rng.uniformDouble();
            const double r = std::sqrt(1 - z * z);
            d.emplace_back(float(r * std::cos(phi)), float(r * std::sin(phi)), float(z));
        }
        return d;
    }();
    return dirs;
}

template <int L>
void BM_EvalShFixed(benchmark::State& state) {
    const auto& dirs = directions();
    std::array<float, shCount(L)> y;
    std::size_t i = 0;
    for (auto _ : state) {
        evalShFixed<L>(dirs[i++ & 4095], y.data());
        benchmark::DoNotOptimize(y.data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_EvalShFixed<1>)->Name("EvalShFixed/L=1");
BENCHMARK(BM_EvalShFixed<2>)->Name("EvalShFixed/L=2");
BENCHMARK(BM_EvalShFixed<3>)->Name("EvalShFixed/L=3");
BENCHMARK(BM_EvalShFixed<4>)->Name("EvalShFixed/L=4");

void BM_EvalShRecurrence(benchmark::State& state) {
    const int band = int(state.range(0));
    const auto& dirs = directions();
    std::array<float, kMaxCoeffs> y;
    std::size_t i = 0;
    for (auto _ : state) {
        evalShUnit(band, dirs[i++ & 4095], y);
        benchmark::DoNotOptimize(y.data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_EvalShRecurrence)->Name("EvalShRecurrence/L")->DenseRange(1, 8);

void BM_EvalShChecked(benchmark::State& state) {
    // The public checked entry point: normalises, rejects zero/NaN, dispatches (unrolled for L ≤
    // 4).
    const int band = int(state.range(0));
    const auto& dirs = directions();
    std::array<float, kMaxCoeffs> y;
    std::size_t i = 0;
    for (auto _ : state) {
        evalSh(band, dirs[i++ & 4095] * 3.0f, y);
        benchmark::DoNotOptimize(y.data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_EvalShChecked)->Name("EvalShChecked/L")->DenseRange(1, 8);

void BM_EvalShSlow(benchmark::State& state) {
    // The textbook reference (per (l, m), trigonometry), all (L+1)² functions of one direction: for
    // comparison.
    const int band = int(state.range(0));
    const auto& dirs = directions();
    std::size_t i = 0;
    for (auto _ : state) {
        const glm::dvec3 d(dirs[i++ & 4095]);
        double s = 0;
        for (int l = 0; l <= band; ++l)
            for (int m = -l; m <= l; ++m) s += evalShSlow(l, m, d);
        benchmark::DoNotOptimize(s);
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_EvalShSlow)->Name("EvalShSlow/L")->Arg(4)->Arg(8);

glm::dmat3 someRotation() {
    const double a = 0.3, b = 1.2, g = -0.7;
    auto rz = [](double t) {
        return glm::dmat3(std::cos(t), std::sin(t), 0, -std::sin(t), std::cos(t), 0, 0, 0, 1);
    };
    auto ry = [](double t) {
        return glm::dmat3(std::cos(t), 0, -std::sin(t), 0, 1, 0, std::sin(t), 0, std::cos(t));
    };
    return rz(a) * ry(b) * rz(g);
}

void BM_ShRotationBuild(benchmark::State& state) {
    const int band = int(state.range(0));
    const glm::dmat3 r = someRotation();
    for (auto _ : state) {
        ShRotation rot(r, band);
        benchmark::DoNotOptimize(rot.element(band, 0, 0));
    }
}
BENCHMARK(BM_ShRotationBuild)->Name("ShRotationBuild/L")->Arg(2)->Arg(4)->Arg(8);

void BM_ShRotationApply(benchmark::State& state) {
    const int band = int(state.range(0));
    const ShRotation rot(someRotation(), band);
    std::vector<float> in(shCount(band), 0.5f), out(shCount(band));
    for (auto _ : state) {
        rot.apply(in, out);
        benchmark::DoNotOptimize(out.data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ShRotationApply)->Name("ShRotationApply/L")->Arg(2)->Arg(4)->Arg(8);

void BM_ShRotationApplyRgb(benchmark::State& state) {
    const int band = int(state.range(0));
    const ShRotation rot(someRotation(), band);
    std::vector<glm::vec3> in(shCount(band), glm::vec3(0.5f)), out(shCount(band));
    for (auto _ : state) {
        rot.applyRgb(in, out);
        benchmark::DoNotOptimize(out.data());
        benchmark::ClobberMemory();
    }
}
BENCHMARK(BM_ShRotationApplyRgb)->Name("ShRotationApplyRgb/L")->Arg(4)->Arg(8);

void BM_RotateZ(benchmark::State& state) {
    const int band = int(state.range(0));
    std::vector<float> c(shCount(band), 0.5f);
    for (auto _ : state) {
        rotateZ(0.1, c, c);
        benchmark::DoNotOptimize(c.data());
        benchmark::ClobberMemory();
    }
}
BENCHMARK(BM_RotateZ)->Name("RotateZ/L")->Arg(4)->Arg(8);

// A 6×256² cube map: texel directions and exact solid angles (precomputed once, as a real cube map
// would).
struct CubeMap {
    std::vector<glm::dvec3> dirs;
    std::vector<double> omega;
    std::vector<glm::vec3> rgb;
};
const CubeMap& cubeMap() {
    static const CubeMap cm = [] {
        constexpr int kN = 256;
        CubeMap m;
        auto areaElement = [](double x, double y) {
            return std::atan2(x * y, std::sqrt(x * x + y * y + 1));
        };
        for (int face = 0; face < 6; ++face)
            for (int j = 0; j < kN; ++j)
                for (int i = 0; i < kN; ++i) {
                    const double u0 = -1 + 2.0 * i / kN, u1 = -1 + 2.0 * (i + 1) / kN;
                    const double v0 = -1 + 2.0 * j / kN, v1 = -1 + 2.0 * (j + 1) / kN;
                    const double u = 0.5 * (u0 + u1), v = 0.5 * (v0 + v1);
                    const int a = face / 2;
                    glm::dvec3 d(0.0);
                    d[a] = face % 2 ? -1 : 1;
                    d[(a + 1) % 3] = u;
                    d[(a + 2) % 3] = v;
                    m.dirs.push_back(glm::normalize(d));
                    m.omega.push_back(areaElement(u1, v1) - areaElement(u0, v1) -
                                      areaElement(u1, v0) + areaElement(u0, v0));
                    m.rgb.emplace_back(float(1 + u), float(1 + v), 0.5f);
                }
        return m;
    }();
    return cm;
}

void BM_ProjectCubeMap6x256(benchmark::State& state) {
    const int band = int(state.range(0));
    const CubeMap& cm = cubeMap();
    for (auto _ : state) {
        ShProjector p(band);
        for (std::size_t k = 0; k < cm.dirs.size(); ++k)
            p.add(cm.dirs[k], glm::dvec3(cm.rgb[k]) * cm.omega[k]);
        auto c = p.coefficientsRgb();
        benchmark::DoNotOptimize(c.data());
    }
    state.SetItemsProcessed(state.iterations() * std::int64_t(cm.dirs.size()));
}
BENCHMARK(BM_ProjectCubeMap6x256)
    ->Name("ProjectCubeMap6x256/L")
    ->Arg(2)
    ->Arg(4)
    ->Arg(8)
    ->Unit(benchmark::kMillisecond);

void BM_ProjectEquirect1024(benchmark::State& state) {
    const int band = int(state.range(0));
    constexpr int kW = 1024, kH = 512;
    std::vector<glm::vec3> img(kW * kH);
    for (std::size_t i = 0; i < img.size(); ++i)
        img[i] = glm::vec3(float(i % 7), float(i % 13), 1.0f);
    const EquirectLayout layout{kW, kH, kPi, -2 * kPi / kW};
    for (auto _ : state) {
        auto c = projectEquirect(band, layout, img);
        benchmark::DoNotOptimize(c.data());
    }
    state.SetItemsProcessed(state.iterations() * std::int64_t(img.size()));
}
BENCHMARK(BM_ProjectEquirect1024)
    ->Name("ProjectEquirect1024x512/L")
    ->Arg(4)
    ->Arg(8)
    ->Unit(benchmark::kMillisecond);

const Dsf& dsf642() {
    static const Dsf d(642);
    return d;
}

void BM_DsfEvaluate(benchmark::State& state) {
    const Dsf& d = dsf642();
    std::vector<glm::vec3> s(d.size(), glm::vec3(1.0f));
    const auto& dirs = directions();
    std::size_t i = 0;
    for (auto _ : state) {
        benchmark::DoNotOptimize(d.evaluateRgb(s, glm::dvec3(dirs[i++ & 4095])));
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_DsfEvaluate)->Name("DsfEvaluate/n=642");

void BM_DsfProjectEquirect(benchmark::State& state) {
    constexpr int kW = 1024, kH = 512;
    std::vector<glm::vec3> img(kW * kH, glm::vec3(1.0f));
    const EquirectLayout layout{kW, kH, kPi, -2 * kPi / kW};
    for (auto _ : state) {
        auto s = state.range(0) == 0 ? dsf642().sampleEquirect(layout, img)
                                     : dsf642().projectEquirect(layout, img);
        benchmark::DoNotOptimize(s.data());
    }
}
BENCHMARK(BM_DsfProjectEquirect)
    ->Name("DsfEquirect1024x512/n=642/(0=gaussian,1=energy)")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond);

void BM_DsfConstruct(benchmark::State& state) {
    for (auto _ : state) {
        Dsf d(int(state.range(0)));
        benchmark::DoNotOptimize(d.kernelRadius());
    }
}
BENCHMARK(BM_DsfConstruct)
    ->Name("DsfConstruct/n")
    ->Arg(162)
    ->Arg(642)
    ->Arg(2562)
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
