// SPDX-License-Identifier: MIT
#pragma once
// Regularising an irregular stack of parallel slices (gantry tilt, variable slice spacing) onto a
// regular grid in patient space, as 3D Slicer's acquisition-geometry regularisation does. Internal
// to io/ (used by the DICOM series reader; dicom_loader.cpp runs it in the calling process, outside
// the GDCM child).
//
// Input: `stack` holds the acquired slices as they were decoded, slice k at z-index k;
// stack.geometry().direction = [i, j, n] (row cosine, column cosine, slice normal = i × j),
// spacing.x/y = the in-plane pixel spacing (mm); its origin and spacing.z are ignored.
// positions[k] = Image Position (Patient) of slice k (the centre of its first pixel, mm, LPS),
// strictly increasing along n. Slice k's pixel (a, b) lies at positions[k] + a·sx·i + b·sy·j.
//
// Output grid: direction [i, j, n] unchanged; in-plane spacing unchanged and the in-plane lattice
// aligned with slice 0's pixels (an untilted stack keeps its pixels exactly); along n, from slice
// 0 to the last slice in equal steps no larger than the *smallest* gap between neighbouring slices
// (see kSliceStep in the .cpp for why the minimum); in-plane extent = the bounding box of all slices'
// footprints (a tilted stack grows along the shear).
//
// Values: at a grid point p at normal coordinate w between slices k and k+1, each of the two slices
// is sampled bilinearly at p's in-plane position (the sheared pixel position in that slice), and the
// two are blended linearly in w — trilinear interpolation in the sheared frame, exact for a field
// linear in patient position. Where p is outside the footprint of a slice it needs, the value is
// the stack's minimum stored value (air in CT, background in MR): never uninitialised memory.
// The voxel type is kept: every interpolated value is a convex combination of stored values, so it
// is within the stored range; integer types are rounded to nearest (≤ 0.5 stored unit, far below
// scanner noise). The value mapping (slope/intercept) commutes with the blend and is kept.
// Parallel over output slices with oneTBB; each voxel is computed independently, so the result does
// not depend on the thread count.
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"

namespace voxlight::io::detail {

struct SliceStackGrid {
    core::Geometry geometry;  ///< the regular output grid
    /// Output slice c lies between input slices below[c] and below[c] + 1 with weight t[c] on the
    /// upper one (t = 0 at an input slice).
    std::vector<int> below;
    std::vector<double> t;
};

/// The output grid for `positions` (see above). Throws InputError (source `source`, field
/// ImagePositionPatient) when the regular grid would exceed core::kMaxDim / kMaxVoxels, or hold more
/// than 64 times the acquired voxels (damaged positions; kMaxResampleGrowth in the .cpp).
SliceStackGrid sliceStackGrid(const core::Geometry& stack, const std::vector<glm::dvec3>& positions,
                              const std::string& source);

/// Resamples `stack` onto sliceStackGrid(...). Metadata (mapping, modality, description, format,
/// warnings) is copied. Reports progress as stage "dicom resample"; throws CancelledError when
/// `progress` is cancelled.
core::Volume resampleSliceStack(const core::Volume& stack, const std::vector<glm::dvec3>& positions,
                                const std::string& source,
                                const core::Progress& progress = core::Progress::none());

}  // namespace voxlight::io::detail
