// SPDX-License-Identifier: MIT
#pragma once
// Internal to iso/: the seam between iso (extract.cpp) and the VTK module
// (libvoxlight_iso_vtk.so: flying_edges_module.cpp, vtkFlyingEdges3D).
//
// Why a module: VTK's libraries would otherwise be mapped and initialised before main() in every
// voxlight process (io/module_loader.h; tests/app's HeavyLibrariesAreLoadedOnlyWhenUsed). The module
// is found and opened by io's loader, like io's own modules; the seam passes voxlight and standard
// types and lets CancelledError through (same build, same compiler: io/volume_module.h).
#include <cstdint>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"

namespace voxlight::iso::fe_module {

/// Bumped whenever Api or the types it passes change layout or meaning.
inline constexpr int kAbiVersion = 1;
inline constexpr const char* kFileName = "libvoxlight_iso_vtk.so";
inline constexpr const char* kEntryPoint = "voxlight_iso_vtk_module";

/// Flying edges output in *index space* (voxel (i,j,k) at (i,j,k)), unmerged beyond what flying
/// edges itself shares (one point per crossed grid edge).
struct Soup {
    std::vector<float> points;             ///< x,y,z per point
    std::vector<std::uint32_t> triangles;  ///< 3 point indices per triangle, VTK's winding
};

struct Api {
    int abiVersion;  ///< first member (io/module_loader.h)
    /// vtkFlyingEdges3D of the volume's *stored* values at `storedIsovalue` (zero copy: VTK reads
    /// the volume's buffer). Normals, gradients and scalars are not computed.
    Soup (*flyingEdges)(const core::Volume& volume, double storedIsovalue,
                        const core::Progress& progress);
};

}  // namespace voxlight::iso::fe_module
