// SPDX-License-Identifier: MIT
#pragma once
// DICOM series reading through GDCM (kept in its own translation unit: GDCM headers clash with
// OpenImageIO's). Internal to io/; the public entry point is io::readVolume.
#include <filesystem>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "io/volume_io.h"

namespace voxlight::io::detail {

/// True if `path` is a directory containing at least one DICOM file, or is itself a DICOM file
/// (DICM preamble or a parseable DICOM dataset).
bool looksLikeDicom(const std::filesystem::path& path);

/// Reads the series in `path` (a directory, or a file whose directory holds the series). See
/// volume_io.h for the contract; in short: one series (or options.dicomSeriesUid), sorted by Image
/// Position (Patient) projected on the slice normal, spacing from positions (not SliceThickness),
/// rescale slope/intercept → HU, orientation from Image Orientation (Patient), refusal with a clear
/// InputError of mixed series, missing slices / variable spacing beyond tolerance, gantry tilt
/// (positions not along the normal), inconsistent rows/columns/type, and unreadable pixels.
core::Volume readDicomSeries(const std::filesystem::path& path, const ReadOptions& options,
                             const core::Progress& progress);

}  // namespace voxlight::io::detail
