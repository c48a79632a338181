// SPDX-License-Identifier: MIT
// Isosurface extraction: iso::extractIsosurface (vtkFlyingEdges3D in its module, world transform,
// gradient normals, winding vote, OpenMesh half-edge mesh) against vtkFlyingEdges3D alone on the
// same voxels in the same process (the baseline: same zero-copy input, normals off, as the module
// calls it). Issue #14's goal: extraction + OpenMesh conversion ≤ 1.2× flying edges alone.
//
// Volumes: the 256³ torso phantom at 300 HU (bone), and the shared abdomen CT at 300 HU when
// ../shared/datasets/ct/abdomen-totalseg/example_ct.nii.gz exists (skipped with a message if not).
// After the Google Benchmark runs, main() times both in alternating pairs (kPairs) and prints the
// medians, the ratio of the medians and the range of the per-pair ratios, plus the breakdown of
// extract's own stages. Then the floor the goal meets (README, isosurface meshes): flying edges
// with its own gradient normals in the same alternation, and the time to write as many bytes as
// the extracted OpenMesh mesh holds (its properties and connectivity arrays) — into memory already
// mapped (a reused buffer) and into fresh pages.
// Run: build/bench_iso [--benchmark_repetitions=5 --benchmark_report_aggregates_only=true]
// bench-deps: iso io core
// bench-vtk
#include <benchmark/benchmark.h>
#include <vtkFloatArray.h>
#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkShortArray.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnsignedShortArray.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <vector>

#include "core/phantoms.h"
#include "core/timing.h"
#include "io/volume_io.h"
#include "iso/extract.h"

namespace fs = std::filesystem;
using namespace voxlight;

namespace {

/// Alternating pairs timed by main() for the ratio.
constexpr int kPairs = 7;
/// Bone on CT (HU).
constexpr double kBoneHu = 300.0;

struct Case {
    std::string name;
    std::unique_ptr<core::Volume> volume;  ///< null when absent
    std::string absent;
};

const std::vector<Case>& cases() {
    static const std::vector<Case> c = [] {
        std::vector<Case> out;
        out.push_back({"torso256", std::make_unique<core::Volume>(core::makePhantom("torso")), ""});
        const fs::path ct = fs::path(VOXLIGHT_SOURCE_DIR) / ".." / "shared" / "datasets" / "ct" /
                            "abdomen-totalseg" / "example_ct.nii.gz";
        if (fs::exists(ct))
            out.push_back({"abdomen_ct", std::make_unique<core::Volume>(io::readVolume(ct)), ""});
        else
            out.push_back({"abdomen_ct", nullptr, "absent: " + ct.string()});
        return out;
    }();
    return c;
}

template <class Array, class T>
vtkSmartPointer<vtkDataArray> wrapAs(const core::Volume& v) {
    auto a = vtkSmartPointer<Array>::New();
    a->SetArray(const_cast<T*>(v.dataAs<T>()), vtkIdType(v.voxelCount()), 1);
    return a;
}

/// The volume's voxels as a VTK array, zero copy (as iso's module wraps them).
vtkSmartPointer<vtkDataArray> wrap(const core::Volume& v) {
    switch (v.type()) {
        case core::VoxelType::UInt8:
            return wrapAs<vtkUnsignedCharArray, std::uint8_t>(v);
        case core::VoxelType::Int16:
            return wrapAs<vtkShortArray, std::int16_t>(v);
        case core::VoxelType::UInt16:
            return wrapAs<vtkUnsignedShortArray, std::uint16_t>(v);
        case core::VoxelType::Float32:
            return wrapAs<vtkFloatArray, float>(v);
    }
    throw InternalError("unknown voxel type");
}

/// vtkFlyingEdges3D alone (with `normals`: its own gradient normals on); returns the triangle
/// count.
vtkIdType flyingEdgesAlone(const core::Volume& v, double stored, bool normals = false) {
    vtkNew<vtkImageData> image;
    image->SetDimensions(v.dims().x, v.dims().y, v.dims().z);
    image->GetPointData()->SetScalars(wrap(v));
    vtkNew<vtkFlyingEdges3D> fe;
    fe->SetInputData(image);
    fe->SetValue(0, stored);
    fe->SetComputeNormals(normals);
    fe->ComputeGradientsOff();
    fe->ComputeScalarsOff();
    fe->InterpolateAttributesOff();
    fe->Update();
    return fe->GetOutput()->GetNumberOfCells();
}

iso::ExtractOptions bone() {
    iso::ExtractOptions o;
    o.isovalue = kBoneHu;
    return o;
}

double storedIso(const core::Volume& v) {
    return iso::extractIsosurface(v, bone()).stats.storedIsovalue;
}

void BM_FlyingEdgesAlone(benchmark::State& state, int which) {
    const Case& c = cases()[std::size_t(which)];
    if (!c.volume) return state.SkipWithError(c.absent.c_str());
    const double stored = storedIso(*c.volume);
    vtkIdType tris = 0;
    for (auto _ : state) tris = flyingEdgesAlone(*c.volume, stored);
    state.counters["triangles"] = double(tris);
    state.counters["voxels/s"] = benchmark::Counter(
        double(c.volume->voxelCount()) * state.iterations(), benchmark::Counter::kIsRate);
}

void BM_ExtractToOpenMesh(benchmark::State& state, int which) {
    const Case& c = cases()[std::size_t(which)];
    if (!c.volume) return state.SkipWithError(c.absent.c_str());
    std::size_t faces = 0;
    for (auto _ : state) faces = iso::extractIsosurface(*c.volume, bone()).mesh.n_faces();
    state.counters["triangles"] = double(faces);
    state.counters["voxels/s"] = benchmark::Counter(
        double(c.volume->voxelCount()) * state.iterations(), benchmark::Counter::kIsRate);
}

BENCHMARK_CAPTURE(BM_FlyingEdgesAlone, torso256, 0)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ExtractToOpenMesh, torso256, 0)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_FlyingEdgesAlone, abdomen_ct, 1)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ExtractToOpenMesh, abdomen_ct, 1)->Unit(benchmark::kMillisecond);

/// Bytes the OpenMesh mesh holds: every vertex, half-edge, edge and face property (points,
/// normals, colours, ...) and the kernel's connectivity arrays.
std::size_t meshBytes(const iso::Mesh& m) {
    std::size_t bytes = m.n_vertices() * sizeof(iso::Mesh::Vertex) +
                        m.n_edges() * sizeof(iso::Mesh::Edge) +
                        m.n_faces() * sizeof(iso::Mesh::Face);
    for (auto it = m.vprops_begin(); it != m.vprops_end(); ++it)
        if (*it) bytes += (*it)->size_of();
    for (auto it = m.hprops_begin(); it != m.hprops_end(); ++it)
        if (*it) bytes += (*it)->size_of();
    for (auto it = m.eprops_begin(); it != m.eprops_end(); ++it)
        if (*it) bytes += (*it)->size_of();
    for (auto it = m.fprops_begin(); it != m.fprops_end(); ++it)
        if (*it) bytes += (*it)->size_of();
    return bytes;
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

/// Alternating pairs: the ratio both see under the same (shared-machine) load.
void pairedRatio(const Case& c) {
    if (!c.volume) {
        std::printf("%s: skipped (%s)\n", c.name.c_str(), c.absent.c_str());
        return;
    }
    const double stored = storedIso(*c.volume);
    std::vector<double> fe, ex, ratio, feStage, normals, mesh, feNormals;
    std::size_t bytes = 0;
    for (int i = 0; i < kPairs; ++i) {
        // The first large allocation after a large free pays the kernel's page faults again
        // (tens of ms on this VM): an untimed flying-edges run first, so that both timed runs
        // follow a free of the same (flying-edges) size.
        flyingEdgesAlone(*c.volume, stored);
        core::Stopwatch sw;
        flyingEdgesAlone(*c.volume, stored);
        fe.push_back(sw.seconds());
        sw.restart();
        const iso::Extraction e = iso::extractIsosurface(*c.volume, bone());
        ex.push_back(sw.seconds());
        ratio.push_back(ex.back() / fe.back());
        bytes = meshBytes(e.mesh);
        flyingEdgesAlone(*c.volume, stored, true);
        sw.restart();
        flyingEdgesAlone(*c.volume, stored, true);
        feNormals.push_back(sw.seconds());
        feStage.push_back(e.stats.flyingEdgesSeconds);
        normals.push_back(e.stats.normalsSeconds);
        mesh.push_back(e.stats.meshSeconds);
    }
    const auto [lo, hi] = std::minmax_element(ratio.begin(), ratio.end());
    std::printf(
        "%s (%dx%dx%d, %d pairs): flying edges alone median %.1f ms; extract + OpenMesh median "
        "%.1f ms; ratio of medians %.2f (pairs %.2f-%.2f); extract's stages (medians): flying "
        "edges %.1f ms, normals %.1f ms, OpenMesh %.1f ms\n",
        c.name.c_str(), c.volume->dims().x, c.volume->dims().y, c.volume->dims().z, kPairs,
        1e3 * median(fe), 1e3 * median(ex), median(ex) / median(fe), *lo, *hi,
        1e3 * median(feStage), 1e3 * median(normals), 1e3 * median(mesh));
    // The floor: writing the mesh's bytes (one value per 8 bytes), into a buffer whose pages are
    // already mapped and into a freshly allocated one.
    std::vector<double> mapped, fresh;
    {
        std::vector<std::uint64_t> buffer(bytes / 8 + 1, 1);
        for (int i = 0; i < kPairs; ++i) {
            core::Stopwatch sw;
            std::fill(buffer.begin(), buffer.end(), std::uint64_t(i));
            benchmark::DoNotOptimize(buffer.data());
            mapped.push_back(sw.seconds());
        }
    }
    for (int i = 0; i < kPairs; ++i) {
        core::Stopwatch sw;
        std::unique_ptr<std::uint64_t[]> p(new std::uint64_t[bytes / 8 + 1]);
        std::fill_n(p.get(), bytes / 8 + 1, std::uint64_t(i));
        benchmark::DoNotOptimize(p.get());
        fresh.push_back(sw.seconds());
    }
    const double base = median(fe);
    std::printf(
        "%s floor: flying edges with its own normals median %.1f ms (%.2fx alone); the mesh's %.1f "
        "MB written in %.1f ms into mapped pages (%.2fx), %.1f ms into fresh ones (%.2fx)\n",
        c.name.c_str(), 1e3 * median(feNormals), median(feNormals) / base, double(bytes) / 1e6,
        1e3 * median(mapped), median(mapped) / base, 1e3 * median(fresh), median(fresh) / base);
}

}  // namespace

int main(int argc, char** argv) {
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    for (const Case& c : cases()) pairedRatio(c);
    return 0;
}
