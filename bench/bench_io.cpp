// SPDX-License-Identifier: MIT
// Volume loading throughput (MB/s of decoded voxels), voxlight against plain VTK readers in the
// same process.
//   NIfTI: io::readVolume vs vtkNIFTIImageReader alone (the baseline: our geometry/type/size checks
//   are the overhead) DICOM: io::readVolume (GDCM, sorted, validated) vs vtkDICOMImageReader on the
//   same uncompressed series.
// Run: build/bench_io [--benchmark_repetitions=5 --benchmark_report_aggregates_only=true]
// bench-deps: io core
// bench-vtk
#include <benchmark/benchmark.h>
#include <vtkDICOMImageReader.h>
#include <vtkImageData.h>
#include <vtkNIFTIImageReader.h>
#include <vtkNew.h>

#include <filesystem>
#include <functional>
#include <iostream>

#include "core/phantoms.h"
#include "io/volume_io.h"

namespace fs = std::filesystem;
using namespace voxlight;

namespace {

fs::path shared(const std::string& rel) {
    return fs::path(VOXLIGHT_SOURCE_DIR) / ".." / "shared" / "datasets" / rel;
}

/// A 256³ int16 torso written once as uncompressed and gzipped NIfTI in the temp dir.
const fs::path& torsoFile(bool gz) {
    static const auto files = [] {
        const fs::path dir = fs::temp_directory_path() / "voxlight-bench-io";
        fs::create_directories(dir);
        const core::Volume v = core::makePhantom("torso");
        io::writeVolume(v, dir / "torso.nii");
        io::writeVolume(v, dir / "torso.nii.gz");
        return std::pair{dir / "torso.nii", dir / "torso.nii.gz"};
    }();
    return gz ? files.second : files.first;
}

void loadVoxlight(benchmark::State& state, const std::function<fs::path()>& where) {
    const fs::path path = where();
    if (!fs::exists(path)) {
        state.SkipWithError(("absent: " + path.string()).c_str());
        return;
    }
    std::size_t bytes = 0;
    for (auto _ : state) {
        core::Volume v = io::readVolume(path);
        bytes = v.sizeBytes();
        benchmark::DoNotOptimize(v.data());
    }
    state.SetBytesProcessed(std::int64_t(bytes) * state.iterations());
}

template <class Reader>
void loadVtk(benchmark::State& state, const std::function<fs::path()>& where) {
    const fs::path path = where();
    if (!fs::exists(path)) {
        state.SkipWithError(("absent: " + path.string()).c_str());
        return;
    }
    std::size_t bytes = 0;
    for (auto _ : state) {
        vtkNew<Reader> r;
        if constexpr (std::is_same_v<Reader, vtkDICOMImageReader>) {
            r->SetDirectoryName(path.c_str());
        } else {
            r->SetFileName(path.c_str());
        }
        try {
            r->Update();
        } catch (const std::exception& e) {
            state.SkipWithError((std::string("the VTK reader threw: ") + e.what()).c_str());
            return;
        }
        vtkImageData* img = r->GetOutput();
        if (!img || img->GetNumberOfPoints() == 0) {
            state.SkipWithError("the VTK reader produced no image for this input");
            return;
        }
        bytes = std::size_t(img->GetNumberOfPoints()) * std::size_t(img->GetScalarSize());
        benchmark::DoNotOptimize(img->GetScalarPointer());
    }
    state.SetBytesProcessed(std::int64_t(bytes) * state.iterations());
}

void loadVtkNifti(benchmark::State& s, const std::function<fs::path()>& w) {
    loadVtk<vtkNIFTIImageReader>(s, w);
}
void loadVtkDicom(benchmark::State& s, const std::function<fs::path()>& w) {
    loadVtk<vtkDICOMImageReader>(s, w);
}

const std::function<fs::path()> kTorsoNii = [] { return torsoFile(false); };
const std::function<fs::path()> kTorsoNiiGz = [] { return torsoFile(true); };
const std::function<fs::path()> kColin = [] {
    return fs::path("/usr/share/mricron/templates/ch2better.nii.gz");
};
const std::function<fs::path()> kCtDicom = [] { return shared("ct/abdomen-totalseg/dicom"); };
const std::function<fs::path()> kCtDicomJ2k = [] {
    return shared("ct/abdomen-totalseg/dicom-jpeg2000");
};
const std::function<fs::path()> kMrDicom = [] { return shared("mr/t1-brain-dicom-120"); };

#define VL_BENCH(fn, name, where) \
    BENCHMARK_CAPTURE(fn, name, where)->Unit(benchmark::kMillisecond)->UseRealTime()
VL_BENCH(loadVoxlight, nifti_torso256_int16, kTorsoNii);
VL_BENCH(loadVtkNifti, nifti_torso256_int16, kTorsoNii);
VL_BENCH(loadVoxlight, nifti_gz_torso256_int16, kTorsoNiiGz);
VL_BENCH(loadVtkNifti, nifti_gz_torso256_int16, kTorsoNiiGz);
VL_BENCH(loadVoxlight, nifti_gz_colin27_05mm, kColin);
VL_BENCH(loadVtkNifti, nifti_gz_colin27_05mm, kColin);
VL_BENCH(loadVoxlight, dicom_ct_abdomen_20, kCtDicom);
VL_BENCH(loadVtkDicom, dicom_ct_abdomen_20, kCtDicom);
VL_BENCH(loadVoxlight, dicom_jpeg2000_ct_abdomen_20, kCtDicomJ2k);
VL_BENCH(loadVoxlight, dicom_mr_t1_120, kMrDicom);
VL_BENCH(loadVtkDicom, dicom_mr_t1_120, kMrDicom);

}  // namespace

BENCHMARK_MAIN();
