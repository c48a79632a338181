// SPDX-License-Identifier: MIT
#pragma once
// What the viewer's info panel and TF editor show about a volume: its geometry and provenance in
// words, and a histogram of its physical values (HU for CT).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"

namespace voxlight::viewer {

/// The info panel's lines, computed once per loaded volume.
struct VolumeSummary {
    std::string description;  ///< file name, series description or phantom name
    std::string format;       ///< "NIfTI", "DICOM series", "phantom", ...
    std::string type;         ///< voxel type, e.g. "int16"
    std::string modality;     ///< "CT", "MR", "synthetic", "unknown"
    std::string unit;         ///< "HU" or empty
    std::string orientation;  ///< patient-orientation code of the axes ("LPS" = identity)
    glm::ivec3 dims{0};
    glm::dvec3 spacing{1.0};                ///< mm
    glm::dvec3 origin{0.0};                 ///< mm, world position of voxel (0,0,0)
    glm::dvec3 extent{0.0};                 ///< mm between the first and last voxel centres
    std::array<double, 2> range{0.0, 0.0};  ///< physical min/max
    std::vector<std::string> warnings;      ///< the loader's (e.g. a resampled tilted series)
};
VolumeSummary summarize(const core::Volume& volume);

/// Counts of physical values in `bins` equal bins over [lo, hi] (the volume's range); non-finite
/// voxels are not counted. Volumes over kHistogramFullScan voxels are sampled on a regular
/// sub-lattice (every n-th voxel along each axis), enough for a display histogram.
struct Histogram {
    double lo = 0.0, hi = 1.0;
    std::vector<std::uint64_t> counts;
    std::uint64_t total = 0;  ///< voxels counted
    /// Bin counts as log(1 + count) / log(1 + max count), in [0, 1] (what the editor draws).
    std::vector<float> logNormalized() const;
};
inline constexpr std::uint64_t kHistogramFullScan = std::uint64_t(1) << 24;
Histogram histogram(const core::Volume& volume, const std::array<double, 2>& range, int bins,
                    const core::Progress& progress = core::Progress::none());

}  // namespace voxlight::viewer
