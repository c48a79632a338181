// SPDX-License-Identifier: MIT
#pragma once
// Internal to io/: the seam between io (dicom_loader.cpp) and the GDCM module
// (libvoxlight_dicom_gdcm.so, built from dicom_series.cpp + dicom_probe.cpp + voxlight::core).
//
// Unlike the image module, this seam passes voxlight types and lets exceptions through:
// readDicomSeriesWithGdcm builds a core::Volume and throws InputError/CancelledError from deep in
// the series checks, and both sides are built by the same build with the same compiler and flags.
// The module links its own copy of voxlight::core (stateless: value types, error classes);
// exceptions thrown from that copy are caught by type in io, since libstdc++ matches exception types
// by their mangled names.
#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>

#include "core/progress.h"
#include "core/volume.h"
#include "io/volume_io.h"

namespace voxlight::io::dicom_module {

/// Bumped whenever Api or the types it passes change layout or meaning.
inline constexpr int kAbiVersion = 2;
inline constexpr const char* kFileName = "libvoxlight_dicom_gdcm.so";
/// The one symbol the module exports: `const void* voxlight_dicom_module()` returning an Api.
inline constexpr const char* kEntryPoint = "voxlight_dicom_module";

/// What the caller (dicom_loader.cpp, which runs the module in a child process) needs to know while
/// GDCM works.
struct Hooks {
    /// Storage for the volume's voxels: `bytes` in all, `sliceBytes` of them per slice, called once
    /// after the headers were checked and before any pixel is decoded. Empty: the heap.
    std::function<std::shared_ptr<std::byte>(std::size_t bytes, std::size_t sliceBytes)> allocate;
    /// Called with the file (or folder, while headers are scanned) GDCM is about to read, so that a
    /// crash inside GDCM can be blamed on the right file.
    std::function<void(const std::filesystem::path&)> reading;
};

struct Api {
    int abiVersion;  ///< first member (module_loader.h)
    core::Volume (*readSeries)(const std::filesystem::path& path, const ReadOptions& options,
                               const core::Progress& progress, const Hooks& hooks);
};

}  // namespace voxlight::io::dicom_module

namespace voxlight::io::detail {
/// The GDCM implementation behind readDicomSeries (in the module).
core::Volume readDicomSeriesWithGdcm(const std::filesystem::path& path, const ReadOptions& options,
                                     const core::Progress& progress,
                                     const dicom_module::Hooks& hooks);
}  // namespace voxlight::io::detail
