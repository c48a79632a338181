// SPDX-License-Identifier: MIT
#pragma once
// Internal to io/: the seam between io (volume_io_loader.cpp) and the VTK module
// (libvoxlight_volume_vtk.so: volume_io.cpp, the DICOM loader and probes, voxlight::core, VTK).
//
// Why a module: VTK's libraries (~25 with their dependencies) cost every voxlight process ~20-30 ms
// of mapping, relocation and static constructors before main(), though `--version`, `scene` and a
// render of a phantom never read or write a volume file (module_loader.h).
//
// Like the DICOM module, this seam passes voxlight types and lets exceptions through (InputError
// from a reader, CancelledError from the progress callback): both sides are built by the same build
// with the same compiler and flags, and libstdc++ matches exception types by mangled name across
// the module's own copy of voxlight::core.
#include <filesystem>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "io/module_loader.h"
#include "io/volume_io.h"

namespace voxlight::io::volume_module {

/// Bumped whenever Api or the types it passes change layout or meaning.
inline constexpr int kAbiVersion = 3;
inline constexpr const char* kFileName = "libvoxlight_volume_vtk.so";
/// The one symbol the module exports: `const void* voxlight_volume_module()` returning an Api.
inline constexpr const char* kEntryPoint = "voxlight_volume_module";

/// One function per function of volume_io.h, same contracts.
struct Api {
    int abiVersion;  ///< first member (module_loader.h)
    core::Volume (*readVolume)(const std::filesystem::path& path, const ReadOptions& options,
                               const core::Progress& progress);
    void (*writeVolume)(const core::Volume& volume, const std::filesystem::path& path);
    void (*checkVolumeOutputPath)(const std::filesystem::path& path);
    std::vector<std::string> (*supportedVolumeFormats)();
    /// Makes the module count its loads in, and its reading children wait on, io's load counter
    /// (module_loader.h): called by io once, right after loading the module.
    void (*useLoadCounter)(const detail::LoadCounter& counter);
};

}  // namespace voxlight::io::volume_module

namespace voxlight::io::detail {
/// The implementations behind volume_io.h (in the module, volume_io.cpp).
core::Volume readVolumeWithVtk(const std::filesystem::path& path, const ReadOptions& options,
                               const core::Progress& progress);
void writeVolumeWithVtk(const core::Volume& volume, const std::filesystem::path& path);
void checkVolumeOutputPathWithVtk(const std::filesystem::path& path);
std::vector<std::string> supportedVolumeFormatsWithVtk();
}  // namespace voxlight::io::detail
