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
#include <filesystem>

#include "core/progress.h"
#include "core/volume.h"
#include "io/volume_io.h"

namespace voxlight::io::dicom_module {

/// Bumped whenever Api or the types it passes change layout or meaning.
inline constexpr int kAbiVersion = 1;
inline constexpr const char* kFileName = "libvoxlight_dicom_gdcm.so";
/// The one symbol the module exports: `const void* voxlight_dicom_module()` returning an Api.
inline constexpr const char* kEntryPoint = "voxlight_dicom_module";

struct Api {
    int abiVersion;  ///< first member (module_loader.h)
    core::Volume (*readSeries)(const std::filesystem::path& path, const ReadOptions& options,
                               const core::Progress& progress);
};

}  // namespace voxlight::io::dicom_module

namespace voxlight::io::detail {
/// The GDCM implementation behind readDicomSeries (in the module).
core::Volume readDicomSeriesWithGdcm(const std::filesystem::path& path, const ReadOptions& options,
                                     const core::Progress& progress);
}  // namespace voxlight::io::detail
