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
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "io/volume_io.h"

namespace voxlight::io::dicom_module {

/// Bumped whenever Api or the types it passes change layout or meaning.
inline constexpr int kAbiVersion = 3;
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

/// What the module read. When the slice positions are regular, `stack` is the volume and the
/// other fields are empty. When they are not (gantry tilt, variable spacing) and
/// options.strictGeometry is false, `stack` holds the acquired slices in order along the normal
/// (its origin and spacing.z are placeholders) and the caller resamples them onto a regular grid
/// (slice_stack.h) outside the GDCM child.
struct SeriesResult {
    core::Volume stack;
    std::vector<glm::dvec3> slicePositions;  ///< Image Position (Patient) of stack slice k
    /// What is irregular, for the warning: "gantry tilt of 15 degrees", "slice spacing varying
    /// from 1 to 2.5 mm", or both joined by " and ".
    std::string irregularity;
};

struct Api {
    int abiVersion;  ///< first member (module_loader.h)
    SeriesResult (*readSeries)(const std::filesystem::path& path, const ReadOptions& options,
                               const core::Progress& progress, const Hooks& hooks);
};

}  // namespace voxlight::io::dicom_module

namespace voxlight::io::detail {
/// The GDCM implementation behind readDicomSeries (in the module).
dicom_module::SeriesResult readDicomSeriesWithGdcm(const std::filesystem::path& path,
                                                   const ReadOptions& options,
                                                   const core::Progress& progress,
                                                   const dicom_module::Hooks& hooks);
}  // namespace voxlight::io::detail
