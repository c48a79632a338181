// SPDX-License-Identifier: MIT
#pragma once
// Reading and writing volumes. Readers form a registry (tev-style): each reader either loads the
// file or says "not my format"; when none accepts it, the error lists every reader tried. All
// readers use VTK or GDCM for the data (raw files are read as the layout the user states); the NRRD
// and MetaImage text headers are parsed and validated here first (nrrd_header.h), because VTK 9.1
// and MetaIO crash, hang or zero-fill on bad ones.
//
// Supported: NIfTI (.nii, .nii.gz), NRRD (.nrrd, .nhdr), MetaImage (.mhd, .mha), VTK XML image
// (.vti), raw (any file, with an explicit RawLayout), DICOM series (a directory, or one file of it;
// GDCM).
//
// Geometry is converted to patient LPS (NIfTI's RAS sform/qform is flipped in x and y; NRRD's named
// space, space directions and space origin likewise; MetaImage's TransformMatrix and Offset are LPS
// as ITK writes them). Physical
// values: NIfTI scl_slope/scl_inter and DICOM Rescale Slope/Intercept become Volume::mapping.
// int32/float64/other types are converted to the narrowest native type that holds them exactly
// (int16/uint16) or to float32.
//
// Failure: every problem (missing file, unknown format, truncated data, absurd dims, non-finite
// voxels under the Reject policy, mixed DICOM series, missing slices; gantry tilt and variable
// slice spacing only under ReadOptions::strictGeometry) throws voxlight::InputError naming the
// file, the field and the fix. Otherwise a gantry-tilted or variably spaced DICOM series is
// resampled onto a regular grid in patient space (io/slice_stack.h) and Volume::warnings says so
// in one line. Sizes are checked against
// core::kMaxVoxels and the file's real length *before* allocating.
//
// VTK (and, for DICOM, GDCM) is loaded on the first call, from modules beside the executable
// (libvoxlight_volume_vtk.so, libvoxlight_dicom_gdcm.so; see volume_module.h). When a module cannot
// be loaded, the call throws InputError (field "volume module" / "dicom module") listing where it
// looked.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"

namespace voxlight::io {

struct RawLayout {
    glm::ivec3 dims{0};
    core::VoxelType type = core::VoxelType::UInt16;
    glm::dvec3 spacing{1.0};
    bool bigEndian = false;
    std::uint64_t headerBytes = 0;  ///< bytes to skip at the start of the file
};

enum class NonFinitePolicy {
    Reject,  ///< NaN/Inf voxels are an InputError (default: they break every optical integral)
    ReplaceWithMin,  ///< replace them by the lowest finite value (usually "air"/background)
};

struct ReadOptions {
    std::optional<RawLayout> raw;  ///< set to read a raw file; otherwise the format is detected
    std::string dicomSeriesUid;    ///< choose one series when a DICOM folder holds several
    NonFinitePolicy nonFinite = NonFinitePolicy::Reject;
    /// DICOM: refuse a gantry-tilted or variably spaced series (InputError, field
    /// ImagePositionPatient) instead of resampling it onto a regular grid with a warning.
    bool strictGeometry = false;
};

/// Loads a volume (file or DICOM directory).
core::Volume readVolume(const std::filesystem::path& path, const ReadOptions& options = {},
                        const core::Progress& progress = core::Progress::none());

/// Writes .nii / .nii.gz / .vti / .mha / .mhd / .nrrd (by extension) through VTK. Written to a
/// temporary file in the same directory and renamed, so a failure or cancel never leaves a
/// half-written file.
void writeVolume(const core::Volume& volume, const std::filesystem::path& path);

/// Throws the InputError writeVolume would throw for this path's extension or missing directory, so
/// that commands can fail before long work.
void checkVolumeOutputPath(const std::filesystem::path& path);

/// "NIfTI (.nii, .nii.gz)" etc., for help texts.
std::vector<std::string> supportedVolumeFormats();

}  // namespace voxlight::io
