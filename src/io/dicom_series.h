// SPDX-License-Identifier: MIT
#pragma once
// DICOM series reading. Internal to io/; the public entry point is io::readVolume.
//
// The reading itself is GDCM's (dicom_series.cpp), built into the module libvoxlight_dicom_gdcm.so
// that readDicomSeries() loads on first use: GDCM builds its full DICOM dictionary in static
// constructors, which every voxlight process would otherwise pay before main() (module_loader.h).
// The probes below need no GDCM and are linked into io itself (dicom_probe.cpp).
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

/// Cheap probe of one file: "DICM" at byte 128 (Part 10 file), or — for old files without a
/// preamble — a first element in group 0x0002 or 0x0008 (little endian), which is how a bare DICOM
/// data set starts. *hasPreamble (if given) tells which.
bool looksLikeDicomFile(const std::filesystem::path& file, bool* hasPreamble = nullptr);

/// Reads the series in `path` (a directory, or a file whose directory holds the series). See
/// volume_io.h for the contract; in short: one series (or options.dicomSeriesUid), sorted by Image
/// Position (Patient) projected on the slice normal, spacing from positions (not SliceThickness),
/// rescale slope/intercept → HU, orientation from Image Orientation (Patient), refusal with a clear
/// InputError of mixed series, missing slices, inconsistent rows/columns/type, and unreadable
/// pixels. A series whose positions are sheared (gantry tilt: not along the normal) or variably
/// spaced beyond tolerance is refused when options.strictGeometry, and otherwise resampled onto a
/// regular grid (slice_stack.h) with one line in Volume::warnings.
/// InputError (field "dicom module") when the GDCM module cannot be loaded.
core::Volume readDicomSeries(const std::filesystem::path& path, const ReadOptions& options,
                             const core::Progress& progress);

}  // namespace voxlight::io::detail
